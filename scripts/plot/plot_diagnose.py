#!/usr/bin/python3
"""PNGs for a `modalwatch diagnose` report directory.

Usage: scripts/plot/plot_diagnose.py REPORT_DIR

Reads spectra.csv, validation.csv, bode.csv and frf.csv (the measured
frequency response with its coherence) written by `modalwatch diagnose` and
writes residual_spectrum.png, validation.png and bode.png next to them (the
report links these). When summary.json's time_unit is "samples" (the
record's time is a sample index, no sample rate) the axes are in samples and
cycles/sample. Needs Debian's python3-matplotlib (Agg backend).
"""
import json
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def load(path):
    data = np.genfromtxt(path, delimiter=",", names=True)
    return data


def axis_labels(report_dir):
    """(time label, frequency label) for the report's unit of time."""
    try:
        with open(os.path.join(report_dir, "summary.json"), encoding="utf-8") as f:
            unit = json.load(f).get("time_unit", "s")
    except FileNotFoundError:
        unit = "s"
    if unit == "samples":
        return "t [samples]", "frequency [cycles/sample]"
    return "t [s]", "frequency [Hz]"


def main():
    if len(sys.argv) != 2:
        sys.stderr.write(__doc__)
        return 2
    d = sys.argv[1]
    t_label, f_label = axis_labels(d)

    s = load(os.path.join(d, "spectra.csv"))
    f = s["f_hz"][1:]
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax[0].semilogy(f, s["psd_before"][1:], label="before (configured model)")
    ax[0].semilogy(f, s["psd_after"][1:], label="after (augmented)")
    ax[0].set_ylabel("residual PSD")
    ax[0].legend()
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].semilogy(f, s["e_to_u_before"][1:], label="before")
    ax[1].semilogy(f, s["e_to_u_after"][1:], label="after")
    ax[1].set_ylabel("|S_eu / S_uu|")
    ax[1].set_xlabel(f_label)
    ax[1].grid(True, which="both", alpha=0.3)
    fig.suptitle("Residual spectrum on the validation part (Welch)")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "residual_spectrum.png"), dpi=110)
    plt.close(fig)

    v = load(os.path.join(d, "validation.csv"))
    fig, ax = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    ax[0].plot(v["t"], v["y"], "k", lw=0.8, label="measured")
    ax[0].plot(v["t"], v["y_before"], lw=0.8, label="configured model")
    ax[0].plot(v["t"], v["y_after"], lw=0.8, label="augmented model")
    ax[0].set_ylabel("y")
    ax[0].legend(loc="upper right")
    ax[1].plot(v["t"], v["y"] - v["y_before"], lw=0.8, label="error before")
    ax[1].plot(v["t"], v["y"] - v["y_after"], lw=0.8, label="error after")
    ax[1].set_ylabel("y - y_sim")
    ax[1].set_xlabel(t_label)
    ax[1].legend(loc="upper right")
    fig.suptitle("Simulated against measured, validation part")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "validation.png"), dpi=110)
    plt.close(fig)

    b = load(os.path.join(d, "bode.csv"))
    frf_path = os.path.join(d, "frf.csv")
    m = load(frf_path) if os.path.exists(frf_path) else None
    rows = 3 if m is not None else 2
    fig, ax = plt.subplots(rows, 1, figsize=(8, 8 if m is not None else 6), sharex=True,
                           gridspec_kw={"height_ratios": [3, 2, 1][:rows]})
    if m is not None:
        # Measured: thin line with dots, below the models.
        ax[0].loglog(m["f_hz"], m["mag_measured"], ".-", color="0.45", lw=0.5, ms=2.5,
                     label="measured (estimation part)")
        # Wrapped to within 180 degrees of the augmented model's phase: no jumps where both are near -180.
        phase = m["phase_measured_deg"]
        phase = phase - 360.0 * np.round((phase - m["phase_after_deg"]) / 360.0)
        ax[1].semilogx(m["f_hz"], phase, ".-", color="0.45", lw=0.5, ms=2.5)
    ax[0].loglog(b["f_hz"], b["mag_before"], label="configured model")
    ax[0].loglog(b["f_hz"], b["mag_after"], "--", label="augmented (linear part)")
    ax[0].set_ylabel("|G|")
    ax[0].legend()
    ax[0].grid(True, which="both", alpha=0.3)
    ax[1].semilogx(b["f_hz"], b["phase_before_deg"])
    ax[1].semilogx(b["f_hz"], b["phase_after_deg"], "--")
    ax[1].set_ylabel("phase [deg]")
    ax[1].grid(True, which="both", alpha=0.3)
    if m is not None:
        # Where the coherence is low the measured response is not to be trusted.
        ax[2].semilogx(m["f_hz"], m["coherence"], color="0.3", lw=0.8)
        ax[2].fill_between(m["f_hz"], 0, m["coherence"], color="0.3", alpha=0.2)
        ax[2].set_ylim(0, 1.05)
        ax[2].set_ylabel("coherence")
        ax[2].grid(True, which="both", alpha=0.3)
    ax[-1].set_xlabel(f_label)
    fig.suptitle("Bode of both models and the measured frequency response" if m is not None
                 else "Bode of both models")
    fig.tight_layout()
    fig.savefig(os.path.join(d, "bode.png"), dpi=110)
    plt.close(fig)
    return 0


if __name__ == "__main__":
    sys.exit(main())
