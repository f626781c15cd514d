#!/usr/bin/env bash
# A small scenario bank as a test (ctest scenario_bank_small): six randomised
# records of scripts/study/scenario_bank.py (seed 5, small scale: plants,
# excitations, noise and faults drawn by its rules, configs written from a
# nominal model with default settings, nothing tuned per record) are tracked
# with `track --faults` by scripts/study/scenario_eval.py, and
#   - no healthy record raises a flag, nor does any healthy mode of a fault record;
#   - every fault that changes a quantity by at least twice its relative
#     threshold is flagged;
#   - on the first three fault records the daemon, fed over LCM, changes the
#     same flags at the same sample times as `track --faults`
#     (test_daemon's DaemonOnBankRecords).
# Delays and tracking errors are printed, not judged (the full bank is
# scripts/study/full_bank.sh). Exit 77 (skipped) without numpy and scipy.
#   scripts/check/scenario_bank_small.sh    BUILD_DIR=build SEED=5 COUNT=6
set -euo pipefail
cd "$(dirname "$0")/../.."
build="$(realpath "${BUILD_DIR:-build}")"
py=/usr/bin/python3
if ! "$py" -c "import numpy, scipy" 2>/dev/null; then
  echo "SKIP: the scenario bank needs python3-numpy and python3-scipy"
  exit 77
fi
out="$(mktemp -d)"
trap 'rm -rf "$out"' EXIT
"$py" scripts/study/scenario_bank.py generate --out "$out/bank" --count "${COUNT:-6}" --seed "${SEED:-5}" \
  --scale small --modalwatch "$build/modalwatch"
"$py" scripts/study/scenario_eval.py "$out/bank" --modalwatch "$build/modalwatch" --json "$out/eval.json"
"$py" - "$out/eval.json" <<'PY'
import json, sys
scenarios = json.load(open(sys.argv[1]))["scenarios"]
failures = []
for r in scenarios:
    f = r["flags"]
    if f["false_alarms"]:
        failures.append(f"{r['id']}: {f['false_alarms']} false alarm(s)")
    if r["class"] != "healthy" and f["detectable"] and not f["detected"]:
        failures.append(f"{r['id']}: a fault of {f['size_over_threshold']:.1f}x its threshold was not flagged")
faults = [r for r in scenarios if r["class"] != "healthy"]
print(f"{len(scenarios)} records ({len(faults)} with a fault): "
      f"{sum(r['flags']['false_alarms'] for r in scenarios)} false alarms, "
      f"{sum(r['flags']['detected'] for r in faults if r['flags']['detectable'])} of "
      f"{sum(r['flags']['detectable'] for r in faults)} faults of at least 2x their threshold flagged")
for msg in failures:
    print("FAIL:", msg)
sys.exit(1 if failures else 0)
PY
MODALWATCH_BANK_DIR="$out/bank" "$build/tests/test_daemon" --gtest_filter='DaemonOnBankRecords.*'
