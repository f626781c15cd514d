#!/usr/bin/python3
"""Receiver-operating curve of the fault detector over a scenario bank.

What it does
------------
For each setting of the detector's two knobs, the stated false-alarm interval
(faults.false_alarm_interval, hours between false alarms per mode: the
chi-square and CUSUM thresholds follow from it) and the hold (each quantity's
hold and clear_time, scaled), it runs `modalwatch track --faults` on every
scenario of DIR (written by scenario_bank.py) with that setting in place of the
config's, everything else as the user's config has it, and prints one row per
setting: detection rate of the faults of at least twice their relative
threshold, delay (median and p95, in memories, hold included) and false alarms
per hour on healthy records and on the healthy modes of fault records, with
the figures of scenario_eval.py. Delay against false-alarm rate over the rows
is the curve.

How to run it
-------------
    /usr/bin/python3 scripts/study/scenario_roc.py /tmp/bank [--modalwatch BIN]
        [--intervals 0.01,1,100,10000] [--hold-scales 0.1,0.3,1] [--jobs 2]
Each setting costs one `track` of every record (the estimates do not depend on
it, the flags do). Needs numpy.
"""
import argparse
import concurrent.futures
import json
import os
import re
import subprocess
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scenario_eval  # noqa: E402  (the same detection figures)


def flags_for(binary, d, interval, hold_scale):
    """The flag events of `track --faults` on scenario d with the given setting."""
    with open(os.path.join(d, "config.yaml")) as f:
        text = f.read()
    text, n = re.subn(r"(?m)^(\s*false_alarm_interval:\s*)\S+", rf"\g<1>{interval:g}", text)
    if n != 1:
        raise RuntimeError(f"{d}: config.yaml has no faults.false_alarm_interval")
    text, n = re.subn(r"\b(hold|clear_time): ([0-9.eE+-]+)",
                      lambda m: f"{m.group(1)}: {float(m.group(2)) * hold_scale:.9g}", text)
    if n != 6:
        raise RuntimeError(f"{d}: config.yaml has not the hold and clear_time of wn, zeta and gain")
    tag = f"roc-{interval:g}-{hold_scale:g}"
    cfg, est, flags = (os.path.join(d, f"{tag}.{x}") for x in ("yaml", "est.csv", "flags.csv"))
    with open(cfg, "w") as f:
        f.write(text)
    try:
        out = subprocess.run([binary, "track", "--config", cfg, "--data", "record.csv", "--out", est, "--faults", flags,
                              "--no-progress"], cwd=d, capture_output=True, text=True)
        if out.returncode != 0:
            raise RuntimeError(f"{d}: track failed:\n{out.stderr}")
        return scenario_eval.read_flags(flags)
    finally:
        for p in (cfg, est, flags):
            if os.path.exists(p):
                os.remove(p)


def row(binary, dirs, interval, hold_scale, jobs):
    with concurrent.futures.ThreadPoolExecutor(jobs) as pool:
        events = list(pool.map(lambda d: flags_for(binary, d, interval, hold_scale), dirs))
    healthy_h = fault_h = healthy_fa = fault_fa = 0.0
    detected, delays = [], []
    for d, ev in zip(dirs, events):
        meta = json.load(open(os.path.join(d, "meta.json")))
        det = scenario_eval.detection(meta, ev)
        if meta["fault"] is None:
            healthy_h += det["monitored_h"]
            healthy_fa += det["false_alarms"]
            continue
        fault_h += det["monitored_h"]
        fault_fa += det["false_alarms"]
        if det["detectable"]:
            detected.append(det["detected"])
            if "delay_memories" in det:
                delays.append(det["delay_memories"])
    return {"interval_h": interval, "hold_scale": hold_scale, "detectable": len(detected),
            "detection_rate": float(np.mean(detected)) if detected else float("nan"),
            "delay_median_M": scenario_eval.pct(delays, 50), "delay_p95_M": scenario_eval.pct(delays, 95),
            "fa_per_h_healthy": healthy_fa / healthy_h if healthy_h else float("nan"),
            "fa_per_h_fault_records": fault_fa / fault_h if fault_h else float("nan")}


def main():
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("dir")
    p.add_argument("--modalwatch", default=scenario_eval.default_binary(), type=scenario_eval.binary_path)
    p.add_argument("--intervals", default="0.01,1,100,10000",
                   help="false-alarm intervals in hours, comma-separated")
    p.add_argument("--hold-scales", default="0.1,0.3,1",
                   help="factors on the config's hold and clear_time, comma-separated")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--json", help="write the rows to this file")
    args = p.parse_args()
    dirs = sorted(os.path.join(args.dir, x) for x in os.listdir(args.dir)
                  if os.path.exists(os.path.join(args.dir, x, "meta.json")))
    if not dirs:
        sys.exit(f"{args.dir}: no scenarios (meta.json) found")
    rows = []
    print(f"{len(dirs)} records; one track of each per setting")
    print(f"{'interval h':>11}{'hold x':>7}{'n det':>6}{'det':>6}{'dly med M':>10}{'dly p95 M':>10}{'FA/h hl':>9}"
          f"{'FA/h flt':>9}")
    for hold_scale in (float(x) for x in args.hold_scales.split(",")):
        for interval in (float(x) for x in args.intervals.split(",")):
            r = row(args.modalwatch, dirs, interval, hold_scale, args.jobs)
            rows.append(r)
            print(f"{r['interval_h']:>11g}{r['hold_scale']:>7g}{r['detectable']:>6}{r['detection_rate']:>6.2f}"
                  f"{r['delay_median_M']:>10.2f}{r['delay_p95_M']:>10.2f}{r['fa_per_h_healthy']:>9.3g}"
                  f"{r['fa_per_h_fault_records']:>9.3g}", flush=True)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
