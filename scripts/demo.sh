#!/usr/bin/env bash
# The main job, end to end, on a fresh Debian machine: installs and builds
# (scripts/setup.sh), simulates a 10 kHz motion stage (rigid body + modes at 150
# and 700 Hz, closed loop), identifies it with the offline additive SRIVC and
# prints the modal table next to the truth.
#   scripts/demo.sh [config/motion-stage.yaml]
set -euo pipefail
cd "$(dirname "$0")/.."
config="${1:-config/motion-stage.yaml}"
[ -x build/modalwatch ] || scripts/setup.sh
out="${DEMO_DIR:-$(mktemp -d)}"
mkdir -p "$out"
echo "== simulate: $config -> $out/record.csv"
build/modalwatch simulate --config "$config" --out "$out/record.csv" --truth "$out/truth.csv"
echo "== truth (from $config, plant section):"
python3 - "$out/truth.csv" <<'PY'
import csv, math, sys
row = next(csv.DictReader(open(sys.argv[1])))
for key in row:
    if key.endswith("_wn"):
        n = key[:-3]
        wn = float(row[key])
        print(f"  {n:10s} f = {wn/2/math.pi:10.5f} Hz  wn = {wn:11.5f} rad/s  zeta = {float(row[n+'_zeta']):.5f}  gain = {float(row[n+'_gain']):.5g}")
    elif key.endswith("_theta0"):
        print(f"  {key[:-7]:10s} b0 = {float(row[key]):.6g}")
PY
echo "== fit: modalwatch fit --config $config --data $out/record.csv --out $out/fitted.yaml"
build/modalwatch fit --config "$config" --data "$out/record.csv" --out "$out/fitted.yaml"
echo "== fitted model written to $out/fitted.yaml"
