#!/usr/bin/python3
"""The stabilisation diagram of `modalwatch fit --max-modes N --stabilisation DIR`.

Usage: scripts/plot/plot_stabilisation.py DIR

Reads DIR/frf.csv (the measured frequency response, its coherence and the
chosen model's response) and DIR/stabilisation.csv (per number of modes the
modes found and their stability marks) and writes DIR/stabilisation.png: the
measured |H| with the chosen model's, and over it, per number of modes (right
axis), each mode found: a filled star when the order below has a mode within
1 % in frequency and 5 % in damping, a plus when only the frequency agrees, a
circle otherwise. Needs Debian's python3-matplotlib (Agg backend).
"""
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from plot_diagnose import axis_labels  # noqa: E402


def main():
    if len(sys.argv) != 2:
        sys.stderr.write(__doc__)
        return 2
    d = sys.argv[1]
    frf = np.atleast_1d(np.genfromtxt(os.path.join(d, "frf.csv"), delimiter=",", names=True))
    st = np.atleast_1d(np.genfromtxt(os.path.join(d, "stabilisation.csv"), delimiter=",", names=True))
    _, freq_label = axis_labels(d)
    fig, ax = plt.subplots(figsize=(10, 6))
    ax.semilogy(frf["f_hz"], frf["mag_measured"], color="0.6", lw=1, label="measured |H|")
    if np.isfinite(frf["mag_model"]).any():
        ax.semilogy(frf["f_hz"], frf["mag_model"], color="C0", lw=1.2, label="chosen model")
    ax.set_xlabel(freq_label)
    ax.set_ylabel("|H|")
    ax.grid(True, which="both", alpha=0.3)
    right = ax.twinx()
    if st.size:
        stable = st["stable"] > 0
        freq_only = (st["stable_frequency"] > 0) & ~stable
        new = st["stable_frequency"] == 0
        right.plot(st["f_hz"][stable], st["modes"][stable], "k*", ms=9, label="stable (f and zeta)")
        right.plot(st["f_hz"][freq_only], st["modes"][freq_only], "k+", ms=9, label="stable in f")
        right.plot(st["f_hz"][new], st["modes"][new], "o", mfc="none", mec="C3", ms=7, label="new")
        chosen = st["chosen"] > 0
        if chosen.any():
            right.axhline(st["modes"][chosen][0], color="C0", ls=":", lw=1)
        right.set_ylim(0.5, st["modes"].max() + 0.5)
    right.set_ylabel("number of modes fitted")
    lines = ax.get_legend_handles_labels()
    more = right.get_legend_handles_labels()
    ax.legend(lines[0] + more[0], lines[1] + more[1], loc="upper right", fontsize=8)
    ax.set_title("stabilisation diagram")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "stabilisation.png"), dpi=110)
    return 0


if __name__ == "__main__":
    sys.exit(main())
