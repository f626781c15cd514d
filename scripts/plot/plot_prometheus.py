#!/usr/bin/python3
"""Plot a mode quantity's drift and its fault flag as Prometheus stored them.

    scripts/plot/plot_prometheus.py --url http://127.0.0.1:9090 --start UNIX_S [--end UNIX_S]
        [--speed S] [--fault T0:T1] [--mode flex] [--quantity wn] [--out prometheus-fleet.png]

Reads modalwatch_mode_deviation_ratio and modalwatch_mode_flag for one mode
and quantity, every axis, through Prometheus's HTTP API (query_range, one
point a second), and draws them against the time since --start times --speed
(with --start the moment a replay at --speed began: record time, within the
scrape interval), the span --fault shaded: top, the relative deviation (x - x0) / |x0| from the baseline in percent (none until
the baseline is known); bottom, the flag (0 none, 1 pending, 2 raised). This
is the picture a Prometheus graph page would show, drawn without a browser.
Debian's python3-matplotlib and numpy only; writes a PNG (Agg backend).
"""
import argparse
import json
import sys
import time
import urllib.parse
import urllib.request

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

FLAG_STATES = ["none", "pending", "raised"]


def query_range(url, expr, start, end, step):
    """{axis: (t, value)} for every series of EXPR; NaN where the daemon exported NaN."""
    args = urllib.parse.urlencode({"query": expr, "start": start, "end": end, "step": step})
    try:
        with urllib.request.urlopen(f"{url}/api/v1/query_range?{args}", timeout=10) as r:
            reply = json.load(r)
    except OSError as e:
        sys.exit(f"{url}: {e}")
    if reply.get("status") != "success":
        sys.exit(f"query_range {expr}: {reply}")
    series = {}
    for s in reply["data"]["result"]:
        points = np.array([[float(t), float(v)] for t, v in s["values"]])
        series[s["metric"].get("axis", "")] = (points[:, 0] - start, points[:, 1])
    return series


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--url", required=True, help="Prometheus, e.g. http://127.0.0.1:9090")
    parser.add_argument("--start", type=float, required=True, help="first point, Unix time [s]")
    parser.add_argument("--end", type=float, help="last point, Unix time [s] (default: now)")
    parser.add_argument("--speed", type=float, default=1.0, help="replay speed: the time axis is record time")
    parser.add_argument("--fault", help="T0:T1, the fault's span in record time [s], shaded")
    parser.add_argument("--mode", default="flex", help="the submodel's name")
    parser.add_argument("--quantity", default="wn", choices=["wn", "zeta", "gain"])
    parser.add_argument("--out", default="prometheus-fleet.png", help="PNG to write")
    args = parser.parse_args()
    end = args.end if args.end is not None else time.time()
    if end <= args.start:
        sys.exit("--end must come after --start")

    labels = f'mode="{args.mode}",quantity="{args.quantity}"'
    ratio = query_range(args.url, f"modalwatch_mode_deviation_ratio{{{labels}}}", args.start, end, 1)
    flag = query_range(args.url, f"modalwatch_mode_flag{{{labels}}}", args.start, end, 1)
    if not ratio or not flag:
        sys.exit(f"Prometheus has no modalwatch_mode_deviation_ratio/modalwatch_mode_flag{{{labels}}} in that range")

    fault = None
    if args.fault:
        try:
            fault = [float(x) for x in args.fault.split(":")]
        except ValueError:
            fault = []
        if len(fault) != 2:
            sys.exit(f"--fault {args.fault}: not T0:T1")

    fig, axes = plt.subplots(2, 1, figsize=(9, 5), sharex=True, gridspec_kw={"height_ratios": [3, 1.4]})
    for axis in sorted(ratio):
        t, v = ratio[axis]
        axes[0].plot(args.speed * t, 100 * v, linewidth=1.2, label=f"axis {axis}")
    axes[0].axhline(0, color="k", linewidth=0.6)
    axes[0].set_ylabel(f"{args.mode} {args.quantity}: (x - x0)/|x0| [%]")
    axes[0].grid(True, alpha=0.3)
    for axis in sorted(flag):
        t, v = flag[axis]
        axes[1].step(args.speed * t, v, where="post", linewidth=1.2, label=f"axis {axis}")
    axes[1].set_yticks(range(len(FLAG_STATES)))
    axes[1].set_yticklabels(FLAG_STATES)
    axes[1].set_ylim(-0.3, len(FLAG_STATES) - 0.7)
    axes[1].set_ylabel("flag")
    axes[1].set_xlabel("record time [s] (Prometheus's clock since the replay began, x speed)")
    if fault is not None:
        for i, ax in enumerate(axes):
            ax.axvspan(fault[0], fault[1], color="tab:red", alpha=0.15, linewidth=0, label="fault" if i == 0 else None)
    axes[1].grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize="small")
    fig.suptitle(f"modalwatch_mode_deviation_ratio and modalwatch_mode_flag{{{labels}}}", fontsize="medium")
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(args.out)


if __name__ == "__main__":
    main()
