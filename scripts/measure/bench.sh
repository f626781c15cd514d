#!/usr/bin/env bash
# Speed of the recursive estimator and of `modalwatch track`. Measures and
# prints; asserts nothing.
#
#   scripts/measure/bench.sh
#
# 1. Builds Release in build-release (benchmarks on) and runs bench_estimator
#    (Google Benchmark: step() for K=2/3, open/closed loop, M_s=0/2; the CSV
#    reader on 1M rows; track in process).
# 2. Instructions per sample of step() for K=3 closed loop, M_s=0: callgrind on
#    step_driver for two step counts N1 < N2, (Ir(N2) - Ir(N1)) / (N2 - N1),
#    so warm-up, simulation and start-up cancel. For each kernel of step():
#    avx2_fma (what the estimator picks on a CPU with AVX2 and FMA, and the
#    target's figure) and portable (x86-64 baseline, every other CPU).
# 3. `modalwatch track` end to end (CSV in and out) on a simulated 2M-sample
#    K=3 closed-loop record: samples/s of the wall-clock time.
#
# Environment: BUILD (build-release), JOBS (2), MIN_TIME (0.5, seconds per
# benchmark), N1/N2 (20000/120000), TRACK_SAMPLES (2000000), BENCH_FILTER
# (a --benchmark_filter regex).
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/lib/daemon.sh

BUILD=${BUILD:-build-release}
JOBS=${JOBS:-2}
MIN_TIME=${MIN_TIME:-0.5}
N1=${N1:-20000}
N2=${N2:-120000}
TRACK_SAMPLES=${TRACK_SAMPLES:-2000000}
CONFIG=config/paper-sim.yaml

WORK=$(mktemp -d "${TMPDIR:-/tmp}/modalwatch_bench.XXXXXX")
trap 'rm -rf "$WORK"' EXIT

echo "== build ($BUILD, Release)"
mw_build "$BUILD" "modalwatch bench_estimator step_driver" -DCMAKE_BUILD_TYPE=Release -DMODALWATCH_BENCHMARKS=ON
CLI="$BUILD/modalwatch"
BENCH="$BUILD/tests/bench/bench_estimator"
DRIVER="$BUILD/tests/bench/step_driver"

echo
echo "== Google Benchmark (items_per_second = samples/s)"
"$BENCH" --benchmark_min_time="$MIN_TIME" ${BENCH_FILTER:+--benchmark_filter="$BENCH_FILTER"}

echo
echo "== callgrind: instructions per sample of step(), K=3 closed loop, M_s=0"
if command -v valgrind >/dev/null; then
  ir() { awk '/^summary:/ {print $2; found=1; exit} END {if (!found) exit 1}' "$1"; }
  for kernel in avx2_fma portable; do
    if ! "$DRIVER" 0 "$kernel" >/dev/null 2>&1; then
      echo "  $kernel kernel: this CPU cannot run it, skipped"
      continue
    fi
    for n in "$N1" "$N2"; do
      out="$WORK/callgrind.$kernel.$n"
      valgrind --tool=callgrind --callgrind-out-file="$out" "$DRIVER" "$n" "$kernel" >"$out.driver" 2>"$out.valgrind"
      echo "  N=$n: Ir $(ir "$out")   ($(cat "$out.driver"))"
    done
    I1=$(ir "$WORK/callgrind.$kernel.$N1")
    I2=$(ir "$WORK/callgrind.$kernel.$N2")
    echo "  $kernel kernel: instructions per sample: $(( (I2 - I1) / (N2 - N1) ))   (target <= 2000)"
  done
else
  echo "  valgrind not installed: skipped"
fi

echo
echo "== modalwatch track end to end: $TRACK_SAMPLES samples, K=3 closed loop (CSV in and out)"
duration=$(awk -v n="$TRACK_SAMPLES" 'BEGIN {printf "%.6f", n / 20}')  # paper-sim.yaml samples at 20 Hz
"$CLI" simulate --config "$CONFIG" --out "$WORK/record.csv" --duration "$duration" 2>/dev/null
start=$(date +%s.%N)
"$CLI" track --config "$CONFIG" --data "$WORK/record.csv" --out "$WORK/est.csv" --no-progress \
  >"$WORK/track.out" 2>"$WORK/track.err"
end=$(date +%s.%N)
rows=$(($(wc -l <"$WORK/est.csv") - 1))
sed 's/^/  /' "$WORK/track.err"
awk -v s="$start" -v e="$end" -v n="$rows" -v in_mb="$(stat -c %s "$WORK/record.csv")" \
  -v out_mb="$(stat -c %s "$WORK/est.csv")" 'BEGIN {
    printf "  wall clock: %.3f s for %d rows (record %.0f MB, est.csv %.0f MB)\n", e - s, n, in_mb / 1e6, out_mb / 1e6
    printf "  track end to end: %.0f samples/s   (target >= 500000)\n", n / (e - s)
  }'
