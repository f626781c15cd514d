#!/usr/bin/env bash
# modalwatchd figures (not a test): at 4096 Hz input with K = 2 (the flexible
# beam of config/flexible-beam-drift.yaml), dropped samples, the latency from a
# sample's utime to the arrival of the estimate that includes it (p50/p99), the
# daemon's CPU use; then the highest sustained batch input rate without drops.
# Runs over udpm on loopback (ttl=0) on a port of its own.
#   scripts/daemon_bench.sh            LOOP_HZ=10000 SECONDS_PER_RUN=10 BUILD_DIR=build
set -euo pipefail
cd "$(dirname "$0")/.."
build="${BUILD_DIR:-build}"
loop_hz="${LOOP_HZ:-10000}"
run_s="${SECONDS_PER_RUN:-10}"
work="$(mktemp -d)"
trap 'kill "${daemon:-}" 2>/dev/null || true; rm -rf "$work"' EXIT
port=$((7900 + $$ % 90))

# The drift config on its own port, with the loop rate of the bench; 10 s of record to cycle.
sed -e "s#url: udpm://239.255.76.67:7667?ttl=0#url: \"udpm://239.255.76.67:${port}?ttl=0\"#" \
    -e "s#loop_rate_hz: 2000 #loop_rate_hz: ${loop_hz} #" \
    -e "s#sample_ring: .*##" config/flexible-beam-drift.yaml > "$work/bench.yaml"
grep -q "239.255.76.67:${port}" "$work/bench.yaml"
"$build/modalwatch" simulate --config "$work/bench.yaml" --duration 10 --out "$work/record.csv" >/dev/null

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

echo "== 4096 Hz, one sample_t per packet, ${run_s} s, loop ${loop_hz} Hz"
start_daemon
hz=$(getconf CLK_TCK)
c0=$(cpu_ticks "$daemon"); t0=$(date +%s.%N)
"$build/modalwatch_daemon_bench" latency --config "$work/bench.yaml" --data "$work/record.csv" --rate 4096 --seconds "$run_s"
c1=$(cpu_ticks "$daemon"); t1=$(date +%s.%N)
awk -v c="$((c1 - c0))" -v hz="$hz" -v a="$t0" -v b="$t1" \
  'BEGIN { printf "  daemon CPU: %.1f %% of one core (user+system over %.1f s, warm-up fit included)\n", 100 * c / hz / (b - a), b - a }'
stop_daemon

echo "== highest sustained batch rate without drops (batches of 256 samples, 3 s per rate)"
for rate in 50000 100000 200000 400000 800000 1600000; do
  start_daemon
  line=$("$build/modalwatch_daemon_bench" rate --config "$work/bench.yaml" --data "$work/record.csv" \
           --rate "$rate" --seconds 3 --batch 256 | grep "daemon:")
  stop_daemon
  echo "  $rate samples/s: $line"
done
