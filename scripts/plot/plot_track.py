#!/usr/bin/python3
"""Plot the estimates of `modalwatch track` against time.

    scripts/plot/plot_track.py est.csv [--truth truth.csv] [--out est.png]

One row of subplots per submodel, columns wn [rad/s], zeta and gain: the
estimate with a +-2 sigma band and, given the truth CSV written by
`modalwatch simulate --truth` (its own t column, <name>_wn, <name>_zeta,
<name>_gain), the truth dashed. Debian's python3-matplotlib and numpy only;
writes a PNG (Agg backend, no display needed).
"""
import argparse
import csv
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

QUANTITIES = [("wn", r"$\omega_n$ [rad/s]"), ("zeta", r"$\zeta$ [-]"), ("gain", "gain")]
SUFFIXES = ["_wn", "_zeta", "_gain", "_wn_std", "_zeta_std", "_gain_std"]


def read_csv(path):
    """Columns of a numeric CSV with a header, as a dict of float arrays."""
    with open(path, newline="") as f:
        reader = csv.reader(f)
        try:
            header = [h.strip() for h in next(reader)]
        except StopIteration:
            sys.exit(f"{path}: empty file")
        rows = [r for r in reader if r and any(x.strip() for x in r)]
    if not rows:
        sys.exit(f"{path}: no data rows")
    try:
        data = np.array(rows, dtype=float)
    except ValueError as e:
        sys.exit(f"{path}: {e}")
    if data.ndim != 2 or data.shape[1] != len(header):
        sys.exit(f"{path}: rows do not match the header's {len(header)} columns")
    return {name: data[:, j] for j, name in enumerate(header)}


def submodel_names(columns):
    """Names with the full set of <name>_wn ... <name>_gain_std columns, in file order."""
    names = []
    for c in columns:
        if c.endswith("_wn") and not c.endswith("_std"):
            name = c[: -len("_wn")]
            if all(name + s in columns for s in SUFFIXES):
                names.append(name)
    return names


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("est", help="est.csv from modalwatch track")
    parser.add_argument("--truth", help="truth CSV from modalwatch simulate --truth")
    parser.add_argument("--out", help="PNG to write (default: est.csv with .png)")
    parser.add_argument("--from", dest="t_from", type=float, help="plot from this time [s]")
    args = parser.parse_args()

    est = read_csv(args.est)
    if "t" not in est:
        sys.exit(f"{args.est}: no column 't'")
    names = submodel_names(est)
    if not names:
        sys.exit(f"{args.est}: no <name>_wn, <name>_zeta, <name>_gain (and _std) columns")
    truth = read_csv(args.truth) if args.truth else None
    if truth is not None and "t" not in truth:
        sys.exit(f"{args.truth}: no column 't'")
    out = args.out or os.path.splitext(args.est)[0] + ".png"

    t = est["t"]
    keep = np.ones_like(t, dtype=bool) if args.t_from is None else t >= args.t_from
    fig, axes = plt.subplots(len(names), 3, figsize=(14, 2.8 * len(names) + 0.6), sharex=True, squeeze=False)
    for row, name in enumerate(names):
        for col, (q, label) in enumerate(QUANTITIES):
            ax = axes[row][col]
            value = est[f"{name}_{q}"][keep]
            std = est[f"{name}_{q}_std"][keep]
            ax.fill_between(t[keep], value - 2 * std, value + 2 * std, color="tab:blue", alpha=0.25, linewidth=0,
                            label=r"$\pm 2\sigma$")
            ax.plot(t[keep], value, color="tab:blue", linewidth=1.0, label="estimate")
            if truth is not None and f"{name}_{q}" in truth:
                tt = truth["t"]
                tk = np.ones_like(tt, dtype=bool) if args.t_from is None else tt >= args.t_from
                ax.plot(tt[tk], truth[f"{name}_{q}"][tk], "k--", linewidth=1.0, label="truth")
            # Scale to the estimate (and truth), not to a band blown up at start-up.
            lo, hi = np.percentile(value, [1, 99])
            if truth is not None and f"{name}_{q}" in truth:
                tv = truth[f"{name}_{q}"]
                lo, hi = min(lo, tv.min()), max(hi, tv.max())
            pad = 0.25 * (hi - lo) if hi > lo else 0.05 * max(abs(hi), 1e-12)
            ax.set_ylim(lo - pad, hi + pad)
            ax.set_ylabel(f"{name}  {label}")
            ax.grid(True, alpha=0.3)
            if row == 0 and col == 0:
                ax.legend(loc="best", fontsize="small")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(os.path.basename(args.est))
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(out)


if __name__ == "__main__":
    main()
