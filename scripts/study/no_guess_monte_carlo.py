#!/usr/bin/python3
"""Modes identified without a starting guess: random plants through `fit --modes N`, beside Octave's moen4.

What it does
------------
Draws PLANTS random plants of 1 to 6 resonant modes, each at its own sampling
rate, simulates each in open and in closed loop (`modalwatch simulate`), fits
it with `modalwatch fit` from a config whose model names only the number of
modes (`model: {modes: N}`: the start comes from the peaks of the frequency
response estimate), and prints, per tool and loop, the share of runs in which
every true mode has a fitted mode within 1 % in wn and 20 % in zeta (both
sorted by frequency; a run with another number of fitted modes fails), the
median and 95th percentile of the wn and zeta errors over all modes of the runs
with the right number of modes, and the median time per fit. A failed run is
fitted again from the true modes (the config's submodels set to the truth):
when that fails too, the record or the estimator is at fault, not the start;
the count is printed.

With Octave and its control package on PATH (or --octave; --no-octave skips
it), the same records go through moen4 (subspace identification) of order 2K,
K the true number of modes as `fit` is told K: d2c (zoh) of the identified
model, its continuous poles of positive imaginary part as (wn, zeta), matched
to the truth as ours are (a real pole, i.e. a pair count other than K, fails
the run). In closed loop moen4 is given u -> y, as a user would give it; the
correlation of u with the noise through the loop is not corrected (an
instrument is what `fit` uses in closed loop). Time per fit: for `fit`, the
wall time of the process (reading the record included); for Octave, moen4 and
d2c timed inside Octave (tic/toc), the same with the reading of the record,
and the start-up of one Octave process with the control package loaded (all
records go through one Octave run).

How to run it
-------------
    scripts/study/no_guess_monte_carlo.py [--plants 100] [--seed 1] [--modalwatch build/modalwatch]
        [--output-hold zoh|foh] [--start data|truth] [--octave | --no-octave]
        [--runs-csv FILE] [--keep DIR] [--verbose]

Standard library only (Octave optional).

Rules (the same for every plant; nothing is tuned per plant)
-----------------------------------------------------------
Sampling rate log-uniform in [20 Hz, 10 kHz]; everything else is in fractions
of it, so that the plant class is the same at every rate: K = 1..6 modes
(uniform); frequencies log-uniform in [2 %, 35 %] of the sampling rate,
neighbours at least 1.3x apart; zeta uniform in [0.01, 0.08]; gains of either
sign with peak heights |gain| / (2 zeta) log-uniform within a factor 4; output
noise at 30 dB SNR; 12000 samples of PRBS (14-bit register, one sample per bit,
amplitude 1) as the input (open loop) or the setpoint (closed loop). The closed
loop is a proportional controller at half the gain that would reach 1 at the
largest peak of |G| (stable by the small-gain theorem for these stable plants,
and active at the modes). The model's output_hold is left unset (fit then
takes foh when a starting mode lies above 0.25 fs, else zoh) unless
--output-hold sets it. --start truth fits every run from the
true modes (a study of the estimator apart from the start); --runs-csv writes
one row per run and tool (rate, highest mode's fraction of it, errors, time).
"""
import argparse
import math
import os
import random
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

SAMPLES = 12000
TOLERANCE_WN = 0.01
TOLERANCE_ZETA = 0.2


def draw_plant(rng):
    fs = 20.0 * (10000.0 / 20.0) ** rng.random()
    k = rng.randint(1, 6)
    modes = []
    while len(modes) < k:
        hz = fs * 0.02 * (0.35 / 0.02) ** rng.random()
        if any(abs(math.log(m["hz"] / hz)) < math.log(1.3) for m in modes):
            continue
        zeta = 0.01 + 0.07 * rng.random()
        peak = 4.0 ** rng.random()
        sign = -1.0 if rng.random() < 0.5 else 1.0
        modes.append({"hz": hz, "zeta": zeta, "gain": sign * 2.0 * zeta * peak})
    modes.sort(key=lambda m: m["hz"])
    return fs, modes


def response(modes, w):
    g = 0j
    for m in modes:
        wn = 2 * math.pi * m["hz"]
        p = 1j * w
        g += m["gain"] / (p * p / wn ** 2 + 2 * m["zeta"] / wn * p + 1)
    return g


def proportional_gain(fs, modes):
    largest = max(abs(response(modes, math.pi * fs * k / 4000)) for k in range(4001))
    return 0.5 / largest


def submodel_lines(modes):
    return ["    - {name: m%d, frequency_hz: %.17g, zeta: %.17g, gain: %.17g}" % (i + 1, m["hz"], m["zeta"], m["gain"])
            for i, m in enumerate(modes)]


def config_text(fs, modes, closed, seed, hold, from_truth=False):
    lines = ["sample_rate_hz: %.17g" % fs, "model:", "  loop: %s" % ("closed" if closed else "open")]
    if hold:
        lines.append("  output_hold: %s" % hold)
    lines += ["  submodels:"] + submodel_lines(modes) if from_truth else ["  modes: %d" % len(modes)]
    if closed:
        lines += ["controller:", "  numerator: [%.17g]" % proportional_gain(fs, modes), "  denominator: [1]"]
    lines += ["plant:", "  snr_db: 30", "  modes:"] + submodel_lines(modes)
    lines += [
        "simulation:",
        "  duration: %.17g" % ((SAMPLES - 0.5) / fs),
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


def compare(fs, modes, got):
    """(passed, why, [(wn error, zeta error)] per mode or None on a count mismatch); errors relative."""
    truth = [(m["hz"], m["zeta"]) for m in modes]
    got = sorted(got)
    if len(got) != len(truth):
        return False, "%d modes fitted of %d" % (len(got), len(truth)), None
    ok, why, errors = True, "", []
    for (hz, zeta), (ghz, gzeta) in zip(truth, got):
        e = (abs(ghz - hz) / hz, abs(gzeta - zeta) / zeta)
        errors.append(e)
        if e[0] > TOLERANCE_WN or e[1] > TOLERANCE_ZETA:
            ok = False
            why += " %.4g Hz (%.3f fs)/%.4f fitted as %.4g Hz/%.4f;" % (hz, hz / fs, zeta, ghz, gzeta)
    return ok, why, errors


def fit_and_compare(binary, work, fs, modes, closed, seed, hold, from_truth):
    """(passed, why, errors, seconds, fit's stdout)."""
    tag = ("closed" if closed else "open") + ("-truth" if from_truth else "")
    cfg = os.path.join(work, "config-%s.yaml" % tag)
    rec = record_path(work, closed)
    fitted = os.path.join(work, "fitted-%s.yaml" % tag)
    with open(cfg, "w") as f:
        f.write(config_text(fs, modes, closed, seed, hold, from_truth))
    if not os.path.exists(rec):
        subprocess.run([binary, "simulate", "--config", cfg, "--out", rec], check=True, capture_output=True)
    start = time.perf_counter()
    fit = subprocess.run([binary, "fit", "--config", cfg, "--data", rec, "--out", fitted],
                         capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if fit.returncode != 0:
        return False, "fit failed: " + fit.stdout + fit.stderr, None, seconds, fit.stdout
    ok, why, errors = compare(fs, modes, fitted_modes(fitted))
    return ok, why, errors, seconds, fit.stdout


def record_path(work, closed):
    return os.path.join(work, "record-%s.csv" % ("closed" if closed else "open"))


OCTAVE_SCRIPT = r"""
pkg load control;
warning('off', 'all');
files = strsplit(fileread('%(list)s'), "\n");
out = fopen('%(out)s', 'w');
for i = 1:numel(files)
  f = strtrim(files{i});
  if isempty(f) continue; end
  n = str2double(regexprep(f, '^(\d+) .*', '$1'));
  path = regexprep(f, '^\d+ ', '');
  t0 = tic;
  d = dlmread(path, ',', 1, 0);
  Ts = (d(end, 1) - d(1, 1)) / (rows(d) - 1);
  t1 = tic;
  try
    sys = moen4(iddata(d(:, end), d(:, end - 1), Ts), n);
    sc = d2c(sys, 'zoh');
    p = pole(sc);
    fit_time = toc(t1);
    all_time = toc(t0);
    p = p(imag(p) > 0);
    fprintf(out, '%%d %%.6g %%.6g %%d', i, fit_time, all_time, numel(p));
    for k = 1:numel(p)
      fprintf(out, ' %%.17g %%.17g', abs(p(k)), -real(p(k)) / abs(p(k)));
    end
    fprintf(out, '\n');
  catch err
    fprintf(out, '%%d %%.6g %%.6g -1 %%s\n', i, toc(t1), toc(t0), strrep(err.message, "\n", ' '));
  end
end
fclose(out);
"""


def run_octave(records, work):
    """moen4 on every (order, record) in one Octave run: ([(fit s, fit and reading s, [(hz, zeta)] or why)], start-up
    s)."""
    lst, out, script = (os.path.join(work, n) for n in ("octave-records.txt", "octave-poles.txt", "octave-fit.m"))
    with open(lst, "w") as f:
        f.write("".join("%d %s\n" % (n, path) for n, path in records))
    with open(script, "w") as f:
        f.write(OCTAVE_SCRIPT % {"list": lst, "out": out})
    start = time.perf_counter()
    subprocess.run(["octave", "--no-gui", "--quiet", "--eval", "pkg load control"], check=True, capture_output=True)
    startup = time.perf_counter() - start
    subprocess.run(["octave", "--no-gui", "--quiet", script], check=True, capture_output=True)
    results = [None] * len(records)
    with open(out) as f:
        for line in f:
            fields = line.split()
            i, fit_s, all_s, status = int(fields[0]) - 1, float(fields[1]), float(fields[2]), int(fields[3])
            if status < 0:
                results[i] = (fit_s, all_s, "moen4/d2c failed: " + " ".join(fields[4:]))
            else:
                v = [float(x) for x in fields[4:]]
                results[i] = (fit_s, all_s, [(v[j] / (2 * math.pi), v[j + 1]) for j in range(0, len(v), 2)])
    return results, startup


def percentile(values, q):
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(math.ceil(q * len(s))) - 1)]


class Tally:
    def __init__(self):
        self.passed = self.runs = 0
        self.wn, self.zeta, self.seconds = [], [], []

    def add(self, ok, errors, seconds):
        self.runs += 1
        self.passed += ok
        for e in errors or []:
            self.wn.append(e[0])
            self.zeta.append(e[1])
        self.seconds.append(seconds)

    def row(self, tool, loop):
        return "%-16s %-6s %4d/%-4d %5.1f %%  %9.2e %9.2e  %9.2e %9.2e  %8.3f s" % (
            tool, loop, self.passed, self.runs, 100.0 * self.passed / max(1, self.runs), statistics.median(self.wn)
            if self.wn else float("nan"), percentile(self.wn, 0.95), statistics.median(self.zeta)
            if self.zeta else float("nan"), percentile(self.zeta, 0.95), statistics.median(self.seconds))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[1])
    ap.add_argument("--plants", type=int, default=100)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--modalwatch", default=os.path.join(os.path.dirname(__file__), "../../build/modalwatch"))
    ap.add_argument("--output-hold", choices=["zoh", "foh"], help="model.output_hold of the fits (default: none given)")
    ap.add_argument("--start", choices=["data", "truth"], default="data",
                    help="start every fit from the data (model.modes) or from the true modes")
    octave = ap.add_mutually_exclusive_group()
    octave.add_argument("--octave", action="store_true", help="also run moen4 (default: when octave is on PATH)")
    octave.add_argument("--no-octave", action="store_true", help="do not run moen4")
    ap.add_argument("--runs-csv", help="write one row per run and tool here")
    ap.add_argument("--keep", help="keep the configs, records and fitted models here")
    ap.add_argument("--verbose", action="store_true", help="one line per run")
    args = ap.parse_args()
    binary = os.path.abspath(args.modalwatch)
    if not os.access(binary, os.X_OK):
        sys.exit("no modalwatch binary at %s (--modalwatch)" % binary)
    use_octave = args.octave or (not args.no_octave and shutil.which("octave") is not None)
    if args.octave and shutil.which("octave") is None:
        sys.exit("--octave: no octave on PATH")
    rng = random.Random(args.seed)
    root = args.keep or tempfile.mkdtemp(prefix="no-guess-")
    from_truth = args.start == "truth"
    tool = "modalwatch fit" + (" (truth)" if from_truth else "")
    tallies = {(t, c): Tally() for t in (tool, "octave moen4") for c in (False, True)}
    truth_fails = {False: 0, True: 0}
    by_k = {}
    runs, octave_records = [], []
    for i in range(args.plants):
        fs, modes = draw_plant(rng)
        work = os.path.join(root, "plant%03d" % i)
        os.makedirs(work, exist_ok=True)
        for closed in (False, True):
            seed = rng.randint(1, 2 ** 31 - 1)
            ok, why, errors, seconds, out = fit_and_compare(binary, work, fs, modes, closed, seed, args.output_hold,
                                                            from_truth)
            if args.verbose and "WARNING" in out:
                why += " [" + " | ".join(l for l in out.splitlines() if l.startswith("WARNING")) + "]"
            if not ok and not from_truth:
                truth_ok = fit_and_compare(binary, work, fs, modes, closed, seed, args.output_hold, True)[0]
                truth_fails[closed] += not truth_ok
                why += " (from the truth: passes)" if truth_ok else " (from the truth: fails too)"
            tallies[(tool, closed)].add(ok, errors, seconds)
            k = by_k.setdefault(len(modes), [0, 0])
            k[0] += ok
            k[1] += 1
            runs.append({"plant": i, "modes": modes, "k": len(modes), "fs": fs, "top": modes[-1]["hz"] / fs, "closed": closed,
                         "tool": tool, "ok": ok, "errors": errors, "seconds": seconds})
            if use_octave:
                octave_records.append((2 * len(modes), record_path(work, closed), runs[-1]))
            if args.verbose or not ok:
                print("plant %3d K=%d fs %7.1f Hz top %.3f fs %-6s %s %s" % (
                    i, len(modes), fs, modes[-1]["hz"] / fs, "closed" if closed else "open", "ok  " if ok else "FAIL",
                    why.strip()), flush=True)
    startup = None
    if octave_records:
        results, startup = run_octave([(n, p) for n, p, _ in octave_records], root)
        for (_, _, ours), (fit_s, all_s, got) in zip(octave_records, results):
            if isinstance(got, str):
                ok, why, errors = False, got, None
            else:
                ok, why, errors = compare(ours["fs"], ours["modes"], got)
            tallies[("octave moen4", ours["closed"])].add(ok, errors, fit_s)
            runs.append(dict(ours, tool="octave moen4", ok=ok, errors=errors, seconds=fit_s, record_seconds=all_s))
            if args.verbose:
                print("plant %3d %-6s octave %s %s" % (ours["plant"], "closed" if ours["closed"] else "open",
                                                      "ok  " if ok else "FAIL", why.strip()))
    n = args.plants
    print("seed %d, %d plants, output_hold %s, start from the %s: every mode within 1 %% wn / 20 %% zeta"
          % (args.seed, n, args.output_hold or "(config default)", args.start))
    print("%-16s %-6s %-9s %7s  %9s %9s  %9s %9s  %10s" % ("tool", "loop", "passed", "", "wn med", "wn p95",
                                                           "zeta med", "zeta p95", "time/fit"))
    for (t, closed), tally in tallies.items():
        if tally.runs:
            print(tally.row(t, "closed" if closed else "open"))
    if startup is not None:
        record_s = [r["record_seconds"] for r in runs if "record_seconds" in r]
        print("octave: time/fit is moen4 + d2c; with reading the record %.3f s (median); start-up of octave with the "
              "control package %.2f s" % (statistics.median(record_s), startup))
    if not from_truth:
        print("failed runs of fit whose fit from the true modes fails too: %d open, %d closed"
              % (truth_fails[False], truth_fails[True]))
    print("fit, by number of modes: " + ", ".join("K=%d %d/%d" % (k, v[0], v[1]) for k, v in sorted(by_k.items())))
    if args.runs_csv:
        with open(args.runs_csv, "w") as f:
            f.write("seed,plant,k,fs,top_fraction,loop,tool,passed,max_wn_error,max_zeta_error,seconds\n")
            for r in runs:
                e = r["errors"]
                f.write("%d,%d,%d,%.6g,%.6g,%s,%s,%d,%s,%s,%.6g\n" % (
                    args.seed, r["plant"], r["k"], r["fs"], r["top"], "closed" if r["closed"] else "open", r["tool"],
                    r["ok"], "%.6g" % max(x[0] for x in e) if e else "", "%.6g" % max(x[1] for x in e) if e else "",
                    r["seconds"]))
    if not args.keep:
        shutil.rmtree(root)


if __name__ == "__main__":
    main()
