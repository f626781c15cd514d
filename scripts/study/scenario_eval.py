#!/usr/bin/python3
"""Tracking and detection figures of `modalwatch track` over a scenario bank.

What it does
------------
For every scenario DIR/<id>/ written by scenario_bank.py it runs
`modalwatch track --config config.yaml --data record.csv --out est.csv --faults
flags.csv` (unless est.csv and flags.csv are already there; --retrack forces
it), then compares the estimates with truth.csv and, when DIR/<id>/flags.csv
exists (the daemon's fault detector run on the record: columns t,mode,quantity,
event,value,baseline,relative,sigma with event raised|cleared), the flags with
the fault in meta.json.

It prints tables per class (healthy or fault kind; open or closed loop; rich
or poor excitation; the fault a step or a ramp; one memory of the excitation
determining every parameter (the bank's Fisher information full rank) or
leaving a direction open; the estimator reset after a divergence in the
record or not, the refit path and the recursive one):
  - tracking error |x_hat - x| / x of wn and zeta over the modes and samples of
    the class (median and p95, each record-mode weighted alike), outside the
    first memory after the warm-up and the window from the start of a change
    to one memory after its end; std(wn error) / Cramer-Rao bound; resets;
  - with flags: detection rate of the faults that change some quantity of
    their mode by at least 2x its relative threshold (a raise on the faulted
    mode after the change started), the delay from the time the TRUE
    deviation crosses the relative threshold to the raise (median, p95, in
    seconds and in memories), and false alarms per hour of monitored sample
    time (after warm-up and learning) on healthy records and on the healthy
    modes (and the faulted mode before its change) of fault records.

How to run it
-------------
    /usr/bin/python3 scripts/study/scenario_eval.py /tmp/bank [--modalwatch BIN]
        [--jobs 2] [--json figures.json] [--retrack] [--drop-est]
--json writes every scenario's figures (per mode errors, CRBs, flag events,
detection outcome and delay) for ROC plots. Needs numpy.

A bank too large for the disk is evaluated in parts (scripts/study/full_bank.sh
does it): each part with --json part.json --keep-errors --drop-est, its records
deleted after, then
    /usr/bin/python3 scripts/study/scenario_eval.py --combine part*.json
prints the tables of all parts together.
"""
import argparse
import concurrent.futures
import json
import os
import subprocess
import sys
import time

import numpy as np

from scenario_bank import binary_path, default_binary  # the same binary as the bank's

MAX_POINTS = 4000  # samples per record read for the error statistics (evenly spaced)
QUANTITIES = ("wn", "zeta", "gain")


def run_track(binary, d, retrack):
    est, flags = os.path.join(d, "est.csv"), os.path.join(d, "flags.csv")
    if os.path.exists(est) and os.path.exists(flags) and not retrack:
        return None
    t0 = time.time()
    out = subprocess.run([binary, "track", "--config", "config.yaml", "--data", "record.csv", "--out", "est.csv",
                          "--faults", "flags.csv", "--no-progress"], cwd=d, capture_output=True, text=True)
    with open(os.path.join(d, "track.log"), "w") as f:
        f.write(out.stdout + out.stderr)
    if out.returncode != 0:
        raise RuntimeError(f"{d}: track failed:\n{out.stderr}")
    return time.time() - t0


def read_decimated(path, step):
    """Header, every step-th data row, and the last row."""
    rows, last = [], None
    with open(path) as f:
        header = f.readline().strip().split(",")
        for k, line in enumerate(f):
            last = line
            if k % step == 0:
                rows.append(line)
    data = np.array([[float(x) for x in r.split(",")] for r in rows])
    return header, data, np.array([float(x) for x in last.split(",")])


def crossing_time(fault, thresholds):
    """When the true deviation of each quantity crosses its relative threshold (None: never)."""
    out = {}
    for q, rc in fault["relative_change"].items():
        th = thresholds[q]["relative"]
        out[q] = fault["t_start"] + fault["ramp_s"] * th / abs(rc) if abs(rc) >= th else None
    return out


def read_flags(path):
    events = []
    with open(path) as f:
        header = f.readline().strip().split(",")
        for line in f:
            v = dict(zip(header, line.strip().split(",")))
            if v:
                events.append({"t": float(v["t"]), "mode": v["mode"], "quantity": v["quantity"],
                               "event": v["event"], "relative": float(v.get("relative", "nan") or "nan")})
    return events


def evaluate(d, max_points):
    meta = json.load(open(os.path.join(d, "meta.json")))
    M = meta["memory_s"]
    n_rows = int(round(meta["duration_s"] * meta["sample_rate_hz"]))
    step = max(1, n_rows // max_points)
    header, est, last = read_decimated(os.path.join(d, "est.csv"), step)
    theader, truth, _ = read_decimated(os.path.join(d, "truth.csv"), step)
    col = {h: i for i, h in enumerate(header)}
    tcol = {h: i for i, h in enumerate(theader)}
    n = min(len(est), len(truth))
    est, truth = est[:n], truth[:n]
    t = est[:, 0]
    if not np.allclose(t, truth[:, 0]):
        raise RuntimeError(f"{d}: est.csv and truth.csv rows differ in time")
    keep = t >= meta["warmup_s"] + M
    fault = meta["fault"]
    if fault:
        keep &= ~((t >= fault["t_start"]) & (t < fault["t_start"] + fault["ramp_s"] + M))
    flags = est[:, col["flags"]].astype(int)
    res = {"id": meta["id"], "class": meta["class"], "loop": meta["loop"], "excitation": meta["excitation_class"],
           "excitation_type": meta["excitation"]["type"], "K": len(meta["truth"]), "memory_s": M,
           "duration_s": meta["duration_s"], "snr_db": meta["snr_db"], "wnT": meta["wnT"],
           "shape": fault["shape"] if fault else None, "resets": int(last[col["resets"]]),
           "low_excitation_share": float(np.mean((flags[keep] & 32) != 0)) if keep.any() else 0.0,
           "modes": [], "samples_used": int(keep.sum())}
    # Whether one memory of the excitation determines every parameter (the
    # Fisher information of scenario_bank.py full rank) or leaves a direction
    # open, and the faulted quantity's share of the weakest direction then.
    crb = meta["cramer_rao_one_memory"]
    res["fisher_rank"], res["parameters"] = crb["fisher_rank"], crb["parameters"]
    res["information"] = "full rank" if crb["fisher_rank"] >= crb["parameters"] else "open direction"
    if fault and res["information"] == "open direction":
        q = {"stiffness": "wn", "damping": "zeta", "gain": "gain"}[fault["kind"]]
        res["fault_in_open_direction"] = abs(crb["weakest_direction"].get(f"{fault['mode']}_{q}", 0.0))
    for i, m in enumerate(meta["truth"]):
        name = m["name"]
        crb = meta["cramer_rao_one_memory"]["modes"][i]
        mode = {"name": name, "faulted": bool(fault and fault["mode"] == name), "crb": crb}
        for q in ("wn", "zeta"):
            x, x0 = est[keep, col[f"{name}_{q}"]], truth[keep, tcol[f"{name}_{q}"]]
            e = (x - x0) / x0
            mode[f"{q}_abs_rel_err"] = np.abs(e)
            mode[f"{q}_median"] = float(np.median(np.abs(e))) if len(e) else float("nan")
            mode[f"{q}_p95"] = float(np.percentile(np.abs(e), 95)) if len(e) else float("nan")
            mode[f"{q}_bias"] = float(np.median(e)) if len(e) else float("nan")
            mode[f"{q}_std_over_crb"] = float(np.std(e) / crb[f"{q}_rel_std"]) if len(e) > 1 else float("nan")
        res["modes"].append(mode)
    flags_path = os.path.join(d, "flags.csv")
    if os.path.exists(flags_path):
        res["flags"] = detection(meta, read_flags(flags_path))
    return res


def at_least_twice(ratio):
    # A change of exactly twice its threshold counts: +-20 % of gain over a
    # threshold of 10 % is 1.9999999999999996 in floating point.
    return ratio >= 2.0 * (1.0 - 1e-9)


def detection(meta, events):
    M = meta["memory_s"]
    monitor_start = meta["warmup_s"] + meta["learn_window_s"]
    fault = meta["fault"]
    raised = [e for e in events if e["event"] == "raised"]
    out = {"events": events, "monitored_h": max(0.0, meta["duration_s"] - monitor_start) / 3600.0}
    if fault is None:
        out["false_alarms"] = len(raised)
        return out
    th = meta["thresholds"]
    cross = crossing_time(fault, th)
    ratio = max(abs(rc) / th[q]["relative"] for q, rc in fault["relative_change"].items())
    out["size_over_threshold"] = ratio
    out["detectable"] = at_least_twice(ratio)
    t_cross = min((c for c in cross.values() if c is not None), default=None)
    out["t_cross"] = t_cross
    hits = [e for e in raised if e["mode"] == fault["mode"] and e["t"] >= fault["t_start"]]
    out["false_alarms"] = len([e for e in raised if e not in hits])
    out["detected"] = bool(hits)
    if hits:
        out["t_flag"] = hits[0]["t"]
        out["quantity"] = hits[0]["quantity"]
        if t_cross is not None:
            out["delay_s"] = hits[0]["t"] - t_cross
            out["delay_memories"] = out["delay_s"] / M
    return out


def pct(x, q):
    return float(np.percentile(x, q)) if len(x) else float("nan")


def group_figures(results):
    modes = [m for r in results for m in r["modes"]]
    f = {"records": len(results), "modes": len(modes)}
    for q in ("wn", "zeta"):
        e = np.concatenate([m[f"{q}_abs_rel_err"] for m in modes]) if modes else np.array([])
        f[f"{q}_median_pct"] = 100 * pct(e, 50)
        f[f"{q}_p95_pct"] = 100 * pct(e, 95)
    f["wn_std_over_crb_median"] = pct([m["wn_std_over_crb"] for m in modes], 50)
    f["resets"] = sum(r["resets"] for r in results)
    flagged = [r for r in results if "flags" in r]
    if flagged:
        healthy = [r for r in flagged if r["class"] == "healthy"]
        faulty = [r for r in flagged if r["class"] != "healthy"]
        det = [r for r in faulty if r["flags"]["detectable"]]
        f["detectable_faults"] = len(det)
        f["detection_rate"] = float(np.mean([r["flags"]["detected"] for r in det])) if det else float("nan")
        small = [r for r in faulty if not r["flags"]["detectable"]]
        f["detection_rate_below_2x"] = float(np.mean([r["flags"]["detected"] for r in small])) if small \
            else float("nan")
        delays = [r["flags"]["delay_s"] for r in det if "delay_s" in r["flags"]]
        delays_m = [r["flags"]["delay_memories"] for r in det if "delay_memories" in r["flags"]]
        f["delay_s_median"], f["delay_s_p95"] = pct(delays, 50), pct(delays, 95)
        f["delay_memories_median"], f["delay_memories_p95"] = pct(delays_m, 50), pct(delays_m, 95)
        h = sum(r["flags"]["monitored_h"] for r in healthy)
        f["false_alarms_per_h_healthy"] = sum(r["flags"]["false_alarms"] for r in healthy) / h if h else float("nan")
        h = sum(r["flags"]["monitored_h"] for r in faulty)
        f["false_alarms_per_h_fault_records"] = sum(r["flags"]["false_alarms"] for r in faulty) / h if h \
            else float("nan")
    return f


def print_table(title, groups):
    flags = any("detection_rate" in g for _, g in groups)
    head = f"{title:<16}{'rec':>4}{'modes':>6}{'wn med%':>9}{'wn p95%':>9}{'z med%':>8}{'z p95%':>8}" \
           f"{'std/crb':>8}{'resets':>7}"
    if flags:
        head += f"{'n det':>6}{'det':>6}{'det<2x':>7}{'dly med s':>10}{'dly p95 s':>10}{'med M':>6}{'p95 M':>6}" \
                f"{'FA/h hl':>8}{'FA/h flt':>9}"
    print(head)
    for name, g in groups:
        line = f"{name:<16}{g['records']:>4}{g['modes']:>6}{g['wn_median_pct']:>9.3f}{g['wn_p95_pct']:>9.3f}" \
               f"{g['zeta_median_pct']:>8.2f}{g['zeta_p95_pct']:>8.2f}{g['wn_std_over_crb_median']:>8.2f}" \
               f"{g['resets']:>7}"
        if flags and "detection_rate" in g:
            line += f"{g['detectable_faults']:>6}{g['detection_rate']:>6.2f}{g['detection_rate_below_2x']:>7.2f}" \
                    f"{g['delay_s_median']:>10.3g}{g['delay_s_p95']:>10.3g}{g['delay_memories_median']:>6.2f}" \
                    f"{g['delay_memories_p95']:>6.2f}{g['false_alarms_per_h_healthy']:>8.3g}" \
                    f"{g['false_alarms_per_h_fault_records']:>9.3g}"
        print(line)
    print()


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("dir", nargs="?")
    p.add_argument("--modalwatch", default=default_binary(), type=binary_path)
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--json", help="write every scenario's figures and the tables to this file")
    p.add_argument("--retrack", action="store_true", help="run track even where est.csv exists")
    p.add_argument("--drop-est", action="store_true", help="delete est.csv once evaluated (large banks)")
    p.add_argument("--max-points", type=int, default=MAX_POINTS)
    p.add_argument("--keep-errors", action="store_true",
                   help="keep each mode's (decimated) error series in --json, for --combine")
    p.add_argument("--combine", nargs="+", metavar="JSON",
                   help="print the tables of banks evaluated in parts (--json --keep-errors), taken together; "
                        "dir is then ignored")
    args = p.parse_args()
    if args.combine:
        results = []
        for path in args.combine:
            for r in json.load(open(path))["scenarios"]:
                if "size_over_threshold" in r.get("flags", {}):
                    r["flags"]["detectable"] = at_least_twice(r["flags"]["size_over_threshold"])
                for m in r["modes"]:
                    for q in ("wn", "zeta"):
                        m[f"{q}_abs_rel_err"] = np.asarray(m[f"{q}_abs_rel_err"])
                results.append(r)
        print_tables(results)
        return 0
    if not args.dir:
        p.error("a bank directory (or --combine)")
    dirs = sorted(os.path.join(args.dir, x) for x in os.listdir(args.dir)
                  if os.path.exists(os.path.join(args.dir, x, "meta.json")))

    def one(d):
        seconds = run_track(args.modalwatch, d, args.retrack)
        r = evaluate(d, args.max_points)
        r["track_s"] = seconds
        if args.drop_est:
            os.remove(os.path.join(d, "est.csv"))
        return r

    with concurrent.futures.ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
        results = list(pool.map(one, dirs))
    for r in results:
        worst = max(r["modes"], key=lambda m: m["wn_p95"])
        extra = ""
        if "flags" in r:
            fl = r["flags"]
            extra = f" FA={fl['false_alarms']}" + (f" det={fl['detected']} delay={fl.get('delay_s', float('nan')):.3g}s"
                                                   if r["class"] != "healthy" else "")
        track = f" track {r['track_s']:.1f} s" if r["track_s"] is not None else ""
        print(f"{r['id']:<28} K={r['K']} worst wn p95 {100 * worst['wn_p95']:7.3f} % ({worst['name']}, "
              f"std/crb {worst['wn_std_over_crb']:.1f}) zeta p95 {100 * max(m['zeta_p95'] for m in r['modes']):7.2f} % "
              f"resets {r['resets']} low-exc {100 * r['low_excitation_share']:.0f} %{extra}{track}")
    print()
    tables = print_tables(results)
    if args.json:
        for r in results:
            for m in r["modes"]:
                for q in ("wn", "zeta"):
                    if args.keep_errors:
                        m[f"{q}_abs_rel_err"] = [float(x) for x in m[f"{q}_abs_rel_err"]]
                    else:
                        del m[f"{q}_abs_rel_err"]
        with open(args.json, "w") as f:
            json.dump({"scenarios": results, "tables": tables}, f, indent=1)


def group_of(r, key):
    """A record's group in the table of `key`; "path": whether the estimator reset after a divergence."""
    if key == "path":
        return "reset" if r["resets"] > 0 else "no reset"
    return r.get(key)  # None where an older --json lacks the key (the fault's shape)


def print_tables(results):
    """The tables by class, loop, excitation, the fault's shape, the
    information, the estimator's path (a divergence reset or none) and over all records;
    returns them."""
    tables = {}
    healthy_h = sum(r["flags"]["monitored_h"] for r in results if "flags" in r and r["class"] == "healthy")
    print(f"{len(results)} records, {healthy_h:.1f} h of monitored healthy sample time\n")
    for title, key, values in (("class", "class", ("healthy", "stiffness", "damping", "gain")),
                               ("loop", "loop", ("open", "closed")),
                               ("excitation", "excitation", ("rich", "poor")),
                               ("fault shape", "shape", ("step", "ramp")),
                               ("information", "information", ("full rank", "open direction")),
                               ("path", "path", ("no reset", "reset"))):
        members = {v: [r for r in results if group_of(r, key) == v] for v in values}
        groups = [(v, group_figures(members[v])) for v in values if members[v]]
        tables[title] = dict(groups)
        print_table(title, groups)
    tables["all"] = group_figures(results)
    print_table("all", [("all", tables["all"])])
    return tables


if __name__ == "__main__":
    sys.exit(main())
