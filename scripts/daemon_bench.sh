#!/usr/bin/env bash
# modalwatchd figures (not a test): at 4096 Hz input with K = 2 (the flexible
# beam of config/flexible-beam-drift.yaml), dropped samples, the latency from a
# sample's utime to the arrival of the estimate that includes it (p50/p99), the
# daemon's CPU use; then the highest sustained batch input rate without drops.
# Runs over udpm on loopback (ttl=0) on a port of its own.
# Latency is measured with an estimate every 10 ms of sample time (publish_period
# 0.01) so that there are enough of them, after the 5 s warm-up (its fit runs on
# the estimation thread and stalls it once), at two loop rates.
#   scripts/daemon_bench.sh            LOOPS="2000 10000" SECONDS_PER_RUN=30 BUILD_DIR=build
set -euo pipefail
cd "$(dirname "$0")/.."
build="${BUILD_DIR:-build}"
loops="${LOOPS:-2000 10000}"
run_s="${SECONDS_PER_RUN:-30}"
work="$(mktemp -d)"
trap 'kill "${daemon:-}" 2>/dev/null || true; rm -rf "$work"' EXIT
port=$((7900 + $$ % 90))

# The drift config on its own port; 10 s of record to cycle.
sed -e "s#url: udpm://239.255.76.67:7667?ttl=0#url: \"udpm://239.255.76.67:${port}?ttl=0\"#" \
    config/flexible-beam-drift.yaml > "$work/base.yaml"
grep -q "239.255.76.67:${port}" "$work/base.yaml"
"$build/modalwatch" simulate --config "$work/base.yaml" --duration 10 --out "$work/record.csv" >/dev/null
config_for() {  # loop rate, publish period
  sed -e "s#loop_rate_hz: 2000 #loop_rate_hz: $1 #" -e "s#publish_period: 0.1 #publish_period: $2 #" \
    "$work/base.yaml" > "$work/bench.yaml"
}

cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }

start_daemon() {
  "$build/modalwatchd" --config "$work/bench.yaml" 2> "$work/daemon.log" &
  daemon=$!
  sleep 0.5
}
stop_daemon() {
  kill -TERM "$daemon"
  wait "$daemon" || true
  daemon=""
}

echo "== machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg)"
hz=$(getconf CLK_TCK)
for loop_hz in $loops; do
  echo "== 4096 Hz, one sample_t per packet, ${run_s} s, loop ${loop_hz} Hz, an estimate every 10 ms"
  config_for "$loop_hz" 0.01
  start_daemon
  c0=$(cpu_ticks "$daemon"); t0=$(date +%s.%N)
  "$build/tests/bench/modalwatch_daemon_bench" latency --config "$work/bench.yaml" --data "$work/record.csv" --rate 4096 \
    --seconds "$run_s" --skip 6
  c1=$(cpu_ticks "$daemon"); t1=$(date +%s.%N)
  awk -v c="$((c1 - c0))" -v hz="$hz" -v a="$t0" -v b="$t1" \
    'BEGIN { printf "  daemon CPU: %.1f %% of one core (user+system over %.1f s, warm-up fit included)\n", 100 * c / hz / (b - a), b - a }'
  stop_daemon
done
config_for 2000 0.1

echo "== highest sustained batch rate without drops (batches of 256 samples, 3 s per rate)"
for rate in 50000 100000 150000 200000 300000 400000; do
  start_daemon
  line=$("$build/tests/bench/modalwatch_daemon_bench" rate --config "$work/bench.yaml" --data "$work/record.csv" \
           --rate "$rate" --seconds 3 --batch 256 | grep "daemon:")
  stop_daemon
  echo "  $rate samples/s: $line"
done
