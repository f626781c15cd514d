#!/usr/bin/python3
"""Every measured record through `modalwatch diagnose`, without a starting guess.

What it does
------------
Runs `modalwatch diagnose --modes N` on each record of the shared measured
data (the model starts from the N largest resonance peaks of the frequency
response estimate, nothing configured), writes each report to OUT/<record>/,
and prints a markdown table: the record, its samples (estimation / validation),
the modes found (Hz, zeta; cycles/sample for records without a sample rate),
the effects added, the validation RMS and fit % at step 0 and at the end, the
run time, and a check of every step's model in summary.json:

  - unstable: a mode with zeta <= 0, or a submodel whose A(p) has a root in the
    closed right half plane (poles at the origin of a rigid body aside);
  - above Nyquist: a mode with wn >= pi fs;
  - cancelling: two modes on one input with opposite gains whose natural
    frequencies are closer than their joint standard deviation
    sqrt(s_i^2 + s_j^2) and than their half-power half-widths
    zeta_i wn_i + zeta_j wn_j (peaks further apart do not cancel; two inputs'
    views of one resonance share its poles);

which must all be "none". The physical check inside diagnose corrects such
modes as it goes; the last column counts what it corrected (summary.json's
`physical`). The exit status is 1 when a record fails the check or errors,
or ends below --min-fit; 77 when the records' folder is missing (ctest's skip).

How to run it
-------------
    scripts/study/measured_records.py DATA_DIR BUILD_DIR OUT [--records a,b] [--check-only] [--min-fit PCT]

DATA_DIR (or the environment variable MODALWATCH_SHARED_DATA when DATA_DIR is
"-") holds the CSV records; BUILD_DIR holds the `modalwatch` binary.
--records runs only those (names as in the table); --check-only reads the
reports already in OUT. Standard library only.

Settings (one line per record in RECORDS below)
-----------------------------------------------
The same diagnose defaults for every record (all effects, split 0.7, the
default step and mode caps and --min-improvement); per record only what the
data's description gives: the columns, the sample rate, the loop and its
controller, the validation file or sample ranges, the input's intersample
behaviour, and N from the resonances it lists or a look at the spectrum.
Records with a shipped config (config/emps.yaml, silverbox.yaml, f16.yaml)
use it for the sample rate, loop and controller, with the modes from the data.
Multi-output records: one output (named in the line). The flexible
structure: both shakers, y1 read as acceleration (its sensors are
accelerometers), N from `fit --max-modes`; the CD-player arm: u1 only. The
F-16 sine sweep runs down from 15 to 2 Hz, so a split in time would validate
below the band it was estimated on: it is estimated whole and validated on the
level-7 multisine. Closed-loop records without a documented controller
(HSM150 feedback run, ball and beam) are treated as open loop from u to y.
"""
import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))

# name: (data file, options, config) where config is a shipped file under
# config/ or a dict {fs, loop} written for the run. Long records last.
RECORDS = [
    ("robot_arm", "daisy_robot_arm.csv", "--t-column n --modes 2", {"fs": 1}),
    ("flutter", "daisy_flutter.csv", "--t-column n --split 0.6 --modes 3", {"fs": 1}),
    ("cd_player_arm", "daisy_cd_player_arm.csv", "--t-column n --u-column u1 --y-column y1 --modes 3", {"fs": 1}),
    ("ballbeam", "daisy_ballbeam.csv", "--modes 1", {"fs": 10}),
    ("cascaded_tanks", "cascaded_tanks_est.csv", "--validate {data}/cascaded_tanks_val.csv --modes 1", {"fs": 0.25}),
    ("flexible_structure", "daisy_flexible_structure.csv",
     "--u-column u1 --u-column u2 --y-column y1 --output acceleration --input-hold foh --modes 12", {"fs": 1024}),
    ("hsm150_step", "hsm150_ident_step_pos_0.065_2.csv", "--modes 1", {"fs": 1000}),
    ("hsm150_feedback", "hsm150_feedback_constant_1.csv", "--modes 1", {"fs": 1000}),
    ("emps", "emps_train.csv", "--validate {data}/emps_pulses_test.csv --modes 1", "emps.yaml"),
    ("silverbox_snls80mv", "silverbox_snls80mv.csv",
     "--estimate-samples 40650:127400 --validate-samples 100:40575 --input-hold foh --substeps 8 --modes 1",
     "silverbox.yaml"),
    ("silverbox_schroeder80mv", "silverbox_schroeder80mv.csv", "--input-hold foh --substeps 8 --modes 1",
     "silverbox.yaml"),
    ("f16_fullmsine_level1", "f16_fullmsine_level1.csv", "--y-column y2 --modes 6", "f16.yaml"),
    ("f16_fullmsine_level7", "f16_fullmsine_level7.csv", "--y-column y2 --modes 6", "f16.yaml"),
    ("f16_sinesw_level7", "f16_sinesw_level7.csv",
     "--y-column y2 --validate {data}/f16_fullmsine_level7.csv --modes 6", "f16.yaml"),
]


def config_path(name, config, out):
    if isinstance(config, str):
        return os.path.join(REPO, "config", config)
    os.makedirs(os.path.join(out, "configs"), exist_ok=True)
    path = os.path.join(out, "configs", name + ".yaml")
    with open(path, "w") as f:
        f.write(f"sample_rate_hz: {config['fs']}\nmodel:\n  loop: {config.get('loop', 'open')}\n  modes: 1\n")
    return path


def sample_rate(config):
    if isinstance(config, dict):
        return float(config["fs"])
    with open(os.path.join(REPO, "config", config)) as f:
        for line in f:
            if line.startswith("sample_rate_hz:"):
                return float(line.split(":")[1].split("#")[0])
    raise ValueError(config + ": no sample_rate_hz")


def hurwitz(a):
    """A(p) = 1 + a1 p + ... + an p^n has all roots in the open left half plane (Routh)."""
    c = [float(x) for x in reversed([1.0] + list(a))]  # descending powers
    if not all(math.isfinite(x) and x > 0 for x in c):
        return False
    r0, r1 = c[0::2], c[1::2]
    for _ in range(len(c) - 1):
        if not r1 or not r1[0] > 0:
            return False
        at = lambda r, k: r[k] if k < len(r) else 0.0
        r0, r1 = r1, [(r1[0] * at(r0, k + 1) - r0[0] * at(r1, k + 1)) / r1[0] for k in range(len(r0) - 1)]
    return True


def check_step(step, fs):
    """The three failures of one step's model, as short texts."""
    bad = []
    modes = [s for s in step["submodels"] if s["kind"] == "mode"]
    for s in step["submodels"]:
        if s["kind"] == "mode":
            if not s["zeta"] > 0 or not s["wn"] > 0:
                bad.append(f"{s['name']} unstable (zeta {s['zeta']:.3g})")
            if not s["wn"] < math.pi * fs:
                bad.append(f"{s['name']} above Nyquist ({s['wn'] / (2 * math.pi):.4g} Hz)")
        elif s["a"] and not hurwitz(s["a"]):
            bad.append(f"{s['name']} unstable (A = {s['a']})")
    for i in range(len(modes)):
        for j in range(i + 1, len(modes)):
            a, b = modes[i], modes[j]
            # Two inputs' views of one resonance share its poles; only modes
            # that one input drives can cancel.
            if a.get("input") != b.get("input") or a["gain"] * b["gain"] >= 0:
                continue
            joint = math.hypot(a.get("wn_std", 0.0), b.get("wn_std", 0.0))
            overlap = abs(a["zeta"]) * a["wn"] + abs(b["zeta"]) * b["wn"]
            if abs(a["wn"] - b["wn"]) <= min(joint, overlap):
                bad.append(f"{a['name']}/{b['name']} cancel ({abs(a['wn'] - b['wn']):.3g} <= {joint:.3g} rad/s)")
    return bad


def effect_text(step):
    p = step["params"]
    e = step["effect"]
    if e == "mode":
        return f"mode {p['hz']:.4g}"
    if e == "offset":
        return "offset (" + ("input" if p.get("input") else "output") + f") {p['value']:.3g}"
    if e == "coulomb":
        return f"Coulomb {p['fc']:.4g}"
    if e == "cubic":
        return f"cubic {p['c']:.4g}"
    if e == "delay":
        return f"delay {int(p['samples'])}"
    if e == "drift":
        return f"drift {p['slope']:.3g}"
    if e == "rigid_body":
        return f"rigid body {p['gain']:.3g}"
    return e


def modes_text(step):
    out = []
    modes = sorted((s for s in step["submodels"] if s["kind"] == "mode"), key=lambda s: s["wn"])
    for s in modes:
        text = f"{s['wn'] / (2 * math.pi):.4g} ({s['zeta']:.3g})"
        if not out or out[-1] != text:  # a resonance once, however many inputs see it
            out.append(text)
    for s in step["submodels"]:
        if s["kind"] == "mode":
            continue
        if len(s["a"]) == 1 and s["a"][0] > 0:  # a lag of one pole: its corner 1 / (2 pi a1)
            out.append(("rigid body, " if s["rigid_poles"] else "") + f"lag {1 / (2 * math.pi * s['a'][0]):.4g}")
        elif s["rigid_poles"]:
            out.append("rigid body")
        elif not s["a"]:
            out.append("feedthrough")
        else:
            out.append("transfer function")
    return ", ".join(out) or "-"


def samples_of(report):
    with open(os.path.join(report, "report.md")) as f:
        for line in f:
            if "Estimation part:" in line:
                est = line.split("Estimation part:")[1].split("samples")[0].strip()
                val = line.split("validation part:")[1].split("samples")[0].strip()
                return f"{est} / {val}"
    return "?"


def row(name, report, fs, seconds, error):
    if error:
        return [name, "-", "-", "-", "-", "-", f"{seconds:.0f} s", f"error: {error}", "-"]
    with open(os.path.join(report, "summary.json")) as f:
        summary = json.load(f)
    steps = summary["steps"]
    first, last = steps[0], steps[-1]
    bad = sorted({b for s in steps for b in check_step(s, fs)})
    fixed = {}
    for s in steps:
        for p in s.get("physical", []):
            fixed[p["verdict"]] = fixed.get(p["verdict"], 0) + 1
    unit = "" if summary.get("time_unit") == "s" else " [cycles/sample]"
    return [
        name,
        samples_of(report),
        modes_text(last) + unit,
        ", ".join(effect_text(s) for s in steps[1:]) or "-",
        f"{first['validation_rms']:.4g} / {first['fit_percent']:.2f} %",
        f"{last['validation_rms']:.4g} / {last['fit_percent']:.2f} %",
        f"{seconds:.0f} s",
        "; ".join(bad) or "none",
        ", ".join(f"{n} {v}" for v, n in sorted(fixed.items())) or "-",
    ]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("data", help='the records\' folder ("-": $MODALWATCH_SHARED_DATA)')
    ap.add_argument("build", help="build folder with the modalwatch binary")
    ap.add_argument("out", help="reports go to OUT/<record>/")
    ap.add_argument("--records", default="", help="comma-separated names (default: all)")
    ap.add_argument("--check-only", action="store_true", help="read the reports in OUT, run nothing")
    ap.add_argument("--min-fit", type=float, default=None, help="fail when a record's final fit %% is below this")
    args = ap.parse_args()
    data = os.environ.get("MODALWATCH_SHARED_DATA", "") if args.data == "-" else args.data
    if not os.path.isdir(data):
        print(f"no records folder '{data}': nothing to run", file=sys.stderr)
        return 77
    binary = os.path.join(args.build, "modalwatch")
    wanted = [r for r in args.records.split(",") if r]
    unknown = set(wanted) - {r[0] for r in RECORDS}
    if unknown:
        sys.exit("unknown records: " + ", ".join(sorted(unknown)))
    rows, failed = [], False
    times_file = os.path.join(args.out, "times.json")
    times = {}
    if os.path.exists(times_file):
        with open(times_file) as f:
            times = json.load(f)
    for name, file, options, config in RECORDS:
        if wanted and name not in wanted:
            continue
        report = os.path.join(args.out, name)
        log = os.path.join(args.out, name + ".log")  # the progress lines as they come
        error = ""
        if not args.check_only:
            shutil.rmtree(report, ignore_errors=True)
            cmd = [binary, "diagnose", "--config", config_path(name, config, args.out), "--data",
                   os.path.join(data, file), "--report", report] + options.format(data=data).split()
            print("+ " + " ".join(cmd), file=sys.stderr, flush=True)
            os.makedirs(args.out, exist_ok=True)
            start = time.monotonic()
            with open(log, "w") as f:
                code = subprocess.run(cmd, stdout=f, stderr=subprocess.STDOUT).returncode
            times[name] = time.monotonic() - start
            with open(times_file, "w") as f:
                json.dump(times, f)
        if not os.path.exists(os.path.join(report, "summary.json")):
            lines = []
            if os.path.exists(log):
                with open(log) as f:
                    lines = [l.strip() for l in f if l.strip()]
            error = lines[-1] if lines else "no report"
            error = error.replace("modalwatch diagnose: ", "").replace(os.path.join(data, ""), "")
        r = row(name, report, sample_rate(config), times.get(name, float("nan")), error)
        failed |= r[7] != "none"
        if args.min_fit is not None and not r[7].startswith("error"):
            final_fit = float(r[5].split("/")[1].rstrip(" %"))
            if not final_fit >= args.min_fit:
                print(f"{name}: final fit {final_fit} % is below {args.min_fit} %", file=sys.stderr)
                failed = True
        rows.append(r)
    head = ["record", "samples (est. / val.)", "modes found: Hz (zeta)", "effects added",
            "val. RMS / fit, step 0", "val. RMS / fit, final", "time", "check", "corrected on the way"]
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    for r in rows:
        print("| " + " | ".join(r) + " |")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
