#!/usr/bin/python3
"""Modes identified without a starting guess: random plants through `fit --modes N`.

What it does
------------
Draws PLANTS random plants of 1 to 6 resonant modes, simulates each in open
and in closed loop (`modalwatch simulate`), fits it with `modalwatch fit` from a
config whose model names only the number of modes (`model: {modes: N}`: the
start comes from the peaks of the frequency response estimate), and prints the
share of runs in which every true mode has a fitted mode within 1 % in wn and
20 % in zeta (both sorted by frequency; a run with another number of fitted
modes fails). A failed run is fitted again from the true modes (the config's
submodels set to the truth): when that fails too, the record or the estimator
is at fault, not the start; the count is printed.

How to run it
-------------
    scripts/study/no_guess_monte_carlo.py [--plants 30] [--seed 1] [--modalwatch build/modalwatch]
        [--output-hold zoh|foh] [--keep DIR] [--verbose]

Standard library only.

Rules (the same for every plant; nothing is tuned per plant)
-----------------------------------------------------------
Sampling at 100 Hz; K = 1..6 modes (uniform); frequencies log-uniform in
[2 %, 35 %] of the sampling rate, neighbours at least 1.3x apart; zeta uniform
in [0.01, 0.08]; gains of either sign with peak heights |gain| / (2 zeta)
log-uniform within a factor 4; output noise at 30 dB SNR; 120 s of PRBS
(14-bit register, one sample per bit, amplitude 1) as the input (open loop)
or the setpoint (closed loop). The closed loop is a proportional controller
at half the gain that would reach 1 at the largest peak of |G| (stable by the
small-gain theorem for these stable plants, and active at the modes).
The model's output_hold is the config's default (zoh) unless --output-hold
says otherwise: the sampled output of a mode above about 0.3 fs is far from
held, and the fit from the true modes fails there too with zoh.
"""
import argparse
import cmath
import math
import os
import random
import re
import subprocess
import sys
import tempfile

FS = 100.0


def draw_plant(rng):
    k = rng.randint(1, 6)
    modes = []
    while len(modes) < k:
        hz = FS * 0.02 * (0.35 / 0.02) ** rng.random()
        if any(abs(math.log(m["hz"] / hz)) < math.log(1.3) for m in modes):
            continue
        zeta = 0.01 + 0.07 * rng.random()
        peak = 4.0 ** rng.random()
        sign = -1.0 if rng.random() < 0.5 else 1.0
        modes.append({"hz": hz, "zeta": zeta, "gain": sign * 2.0 * zeta * peak})
    modes.sort(key=lambda m: m["hz"])
    return modes


def response(modes, w):
    g = 0j
    for m in modes:
        wn = 2 * math.pi * m["hz"]
        p = 1j * w
        g += m["gain"] / (p * p / wn ** 2 + 2 * m["zeta"] / wn * p + 1)
    return g


def proportional_gain(modes):
    largest = max(abs(response(modes, math.pi * FS * k / 4000)) for k in range(4001))
    return 0.5 / largest


def submodel_lines(modes):
    return ["    - {name: m%d, frequency_hz: %.17g, zeta: %.17g, gain: %.17g}" % (i + 1, m["hz"], m["zeta"], m["gain"])
            for i, m in enumerate(modes)]


def config_text(modes, closed, seed, hold, from_truth=False):
    lines = [
        "sample_rate_hz: %g" % FS,
        "model:",
        "  loop: %s" % ("closed" if closed else "open"),
        "  output_hold: %s" % hold,
    ]
    lines += ["  submodels:"] + submodel_lines(modes) if from_truth else ["  modes: %d" % len(modes)]
    if closed:
        lines += ["controller:", "  numerator: [%.17g]" % proportional_gain(modes), "  denominator: [1]"]
    lines += ["plant:", "  snr_db: 30", "  modes:"] + submodel_lines(modes)
    lines += [
        "simulation:",
        "  duration: 120",
        "  seed: %d" % seed,
        "  %s: {type: prbs, register_bits: 14, clock_period: 1, amplitude: 1}" % ("reference" if closed else "input"),
    ]
    return "\n".join(lines) + "\n"


def fitted_modes(yaml_path):
    """(hz, zeta) of every `kind: mode` submodel of a written model (config_to_yaml's layout)."""
    out, current = [], None
    in_model = False
    with open(yaml_path) as f:
        for line in f:
            if re.match(r"^\S", line):
                in_model = line.startswith("model:")
                continue
            if not in_model:
                continue
            if re.match(r"^    - name:", line):
                current = {}
                out.append(current)
            m = re.match(r"^      (kind|wn|zeta): (\S+)", line)
            if m and current is not None:
                current[m.group(1)] = m.group(2)
    return [(float(m["wn"]) / (2 * math.pi), float(m["zeta"])) for m in out if m.get("kind") == "mode"]


def fit_and_compare(binary, work, modes, closed, seed, hold, from_truth):
    tag = ("closed" if closed else "open") + ("-truth" if from_truth else "")
    cfg = os.path.join(work, "config-%s.yaml" % tag)
    rec = os.path.join(work, "record-%s.csv" % ("closed" if closed else "open"))
    fitted = os.path.join(work, "fitted-%s.yaml" % tag)
    with open(cfg, "w") as f:
        f.write(config_text(modes, closed, seed, hold, from_truth))
    if not from_truth:
        subprocess.run([binary, "simulate", "--config", cfg, "--out", rec], check=True, capture_output=True)
    fit = subprocess.run([binary, "fit", "--config", cfg, "--data", rec, "--out", fitted],
                         capture_output=True, text=True)
    if fit.returncode != 0:
        return False, "fit failed: " + fit.stdout + fit.stderr, fit.stdout
    got = sorted(fitted_modes(fitted))
    truth = [(m["hz"], m["zeta"]) for m in modes]
    why = ""
    ok = len(got) == len(truth)
    if not ok:
        why = "%d modes fitted of %d" % (len(got), len(truth))
    else:
        for (hz, zeta), (ghz, gzeta) in zip(truth, got):
            if abs(ghz - hz) > 0.01 * hz or abs(gzeta - zeta) > 0.2 * zeta:
                ok = False
                why += " %.3f Hz/%.4f fitted as %.3f Hz/%.4f;" % (hz, zeta, ghz, gzeta)
    return ok, why, fit.stdout


def run_one(binary, work, modes, closed, seed, hold, verbose):
    """(passed, passed from the truth or None when not tried, why)."""
    ok, why, out = fit_and_compare(binary, work, modes, closed, seed, hold, False)
    if verbose and "WARNING" in out:
        why += " [" + " | ".join(l for l in out.splitlines() if l.startswith("WARNING")) + "]"
    if ok:
        return True, None, why
    truth_ok, _, _ = fit_and_compare(binary, work, modes, closed, seed, hold, True)
    return False, truth_ok, why + (" (from the truth: passes)" if truth_ok else " (from the truth: fails too)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--plants", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--modalwatch", default=os.path.join(os.path.dirname(__file__), "../../build/modalwatch"))
    ap.add_argument("--output-hold", choices=["zoh", "foh"], default="zoh", help="model.output_hold of the fits")
    ap.add_argument("--keep", help="keep the configs, records and fitted models here")
    ap.add_argument("--verbose", action="store_true", help="one line per run")
    args = ap.parse_args()
    binary = os.path.abspath(args.modalwatch)
    if not os.access(binary, os.X_OK):
        sys.exit("no modalwatch binary at %s (--modalwatch)" % binary)
    rng = random.Random(args.seed)
    root = args.keep or tempfile.mkdtemp(prefix="no-guess-")
    passed = {False: 0, True: 0}
    truth_fails = {False: 0, True: 0}
    by_k = {}
    for i in range(args.plants):
        modes = draw_plant(rng)
        work = os.path.join(root, "plant%03d" % i)
        os.makedirs(work, exist_ok=True)
        for closed in (False, True):
            ok, truth_ok, why = run_one(binary, work, modes, closed, rng.randint(1, 2 ** 31 - 1), args.output_hold,
                                        args.verbose)
            passed[closed] += ok
            truth_fails[closed] += truth_ok is False
            k = by_k.setdefault(len(modes), [0, 0])
            k[0] += ok
            k[1] += 1
            if args.verbose or not ok:
                print("plant %3d K=%d %-6s %s %s" % (i, len(modes), "closed" if closed else "open",
                                                    "ok  " if ok else "FAIL", why.strip()))
    n = args.plants
    print("seed %d, %d plants, output_hold %s: every mode within 1 %% wn / 20 %% zeta in %d/%d open-loop runs (%.0f %%), "
          "%d/%d closed-loop (%.0f %%), %d/%d in all (%.0f %%)"
          % (args.seed, n, args.output_hold, passed[False], n, 100.0 * passed[False] / n, passed[True], n, 100.0 * passed[True] / n,
             passed[False] + passed[True], 2 * n, 100.0 * (passed[False] + passed[True]) / (2 * n)))
    print("failed runs whose fit from the true modes fails too: %d open, %d closed"
          % (truth_fails[False], truth_fails[True]))
    print("by number of modes: " + ", ".join("K=%d %d/%d" % (k, v[0], v[1]) for k, v in sorted(by_k.items())))
    if not args.keep:
        subprocess.run(["rm", "-rf", root])


if __name__ == "__main__":
    main()
