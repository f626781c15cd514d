#!/usr/bin/env bash
# modalwatchd figures (not a test): at 4096 Hz input with K = 2 (the flexible
# beam of config/flexible-beam-drift.yaml), dropped samples, the latency from a
# sample's utime to the delivery of the estimate that includes it (p50/p99;
# see tests/bench/daemon_bench.cpp for how delivery is timed and how the
# sender's own lateness is told apart), the daemon's CPU use; then the highest
# sustained batch input rate without drops.
# Runs over udpm on loopback (ttl=0) on a port of its own.
# Latency is measured with an estimate every 10 ms of sample time (publish_period
# 0.01) so that there are enough of them, after the 5 s warm-up and the catch-up
# on the input held during its fit (SKIP_SECONDS, 10: check the fit's duration
# in the "warm-up over" line), at two loop rates.
# RT_PRIORITY=N (needs CAP_SYS_NICE or an RLIMIT_RTPRIO of N) runs the daemon with
# daemon.realtime_priority N and the bench's sender and listener at SCHED_FIFO N+1:
# the bench stands for the motion controller, which outranks a monitor beside it.
# RATES (the batch rates tried, samples/s; empty skips that part). DAEMON=path runs
# another modalwatchd build (an A/B comparison; the bench stays this tree's).
# MACHINE_SECONDS (10; 0 skips) runs `modalwatch_daemon_bench machine` first: the
# machine's own wake-up latency and CPU preemption, the floor under the figures.
# METRICS=1 turns the Prometheus endpoint on (daemon.metrics on a port of its
# own) and scrapes it every SCRAPE_PERIOD s (1) with curl during each latency
# run, as a Prometheus with that scrape_interval would; the scraper's own CPU
# is not in the daemon's figure. A run with METRICS=0 against one with
# METRICS=1 is the endpoint's cost.
#   scripts/measure/daemon_bench.sh    LOOPS="2000 10000" SECONDS_PER_RUN=30 BUILD_DIR=build-release JOBS=2 RT_PRIORITY=0 METRICS=0
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/lib/daemon.sh
build="${BUILD_DIR:-build-release}"
loops="${LOOPS:-2000 10000}"
rt="${RT_PRIORITY:-0}"
skip="${SKIP_SECONDS:-10}"  # the warm-up (5 s), its fit and the catch-up on the input held meanwhile
run_s="${SECONDS_PER_RUN:-30}"
metrics="${METRICS:-0}"
scrape_period="${SCRAPE_PERIOD:-1}"
work="$(mktemp -d)"
scraper=""
trap '[ -z "$scraper" ] || kill "$scraper" 2>/dev/null; mw_kill_daemon; rm -rf "$work"' EXIT
port=$((7900 + $$ % 90))
metrics_port=$((9500 + $$ % 90))

# Release, with the benchmark drivers; the same tree scripts/measure/bench.sh uses.
mw_build "$build" "modalwatch modalwatchd modalwatch_daemon_bench" -DCMAKE_BUILD_TYPE=Release -DMODALWATCH_BENCHMARKS=ON
MW_DAEMON_BIN=${DAEMON:-}

# The drift config on its own port; 10 s of record to cycle.
config=config/flexible-beam-drift.yaml
url="lcm.url=udpm://239.255.76.67:${port}?ttl=0"
mw_config "$config" "$work/base.yaml" "$url"
"$build/modalwatch" simulate --config "$work/base.yaml" --duration 10 --out "$work/record.csv" >/dev/null
config_for() {  # loop rate, publish period
  local realtime=()
  if [ "$rt" -gt 0 ]; then realtime=(daemon.realtime_priority="$rt"); fi
  if [ "$metrics" = 1 ]; then realtime+=(daemon.metrics="{listen: 127.0.0.1:$metrics_port}"); fi
  mw_config "$config" "$work/bench.yaml" "$url" daemon.loop_rate_hz="$1" daemon.publish_period="$2" "${realtime[@]}"
}
# GET /metrics every scrape_period s while $work/scraping exists; one line per
# scrape (HTTP code, bytes) in $work/scrapes.
start_scraper() {
  [ "$metrics" = 1 ] || return 0
  : >"$work/scrapes"
  touch "$work/scraping"
  while sleep "$scrape_period" && [ -e "$work/scraping" ]; do
    curl -s -o /dev/null -w '%{http_code} %{size_download}\n' --max-time 1 \
      "http://127.0.0.1:$metrics_port/metrics" >>"$work/scrapes" || echo "000 0" >>"$work/scrapes"
  done &
  scraper=$!
}
stop_scraper() {  # the loop ends within a scrape period
  [ -n "$scraper" ] || return 0
  rm -f "$work/scraping"
  wait "$scraper" 2>/dev/null || true
  scraper=""
  awk '$1 == 200 { ok++; bytes += $2 } END { printf "  metrics endpoint: %d scrapes of %d, %.0f bytes each\n", ok, NR, ok ? bytes / ok : 0 }' \
    "$work/scrapes"
}
bench() {
  if [ "$rt" -gt 0 ]; then chrt -f $((rt + 1)) "$build/tests/bench/modalwatch_daemon_bench" "$@"
  else "$build/tests/bench/modalwatch_daemon_bench" "$@"; fi
}

cpu_ticks() { awk '{print $14 + $15}' "/proc/$1/stat"; }
# One line per thread: tid, name, user+system ticks (comm has no spaces here;
# a tick is 1/CLK_TCK s, the resolution of the per-thread figures).
thread_ticks() {
  for t in /proc/"$1"/task/*; do
    echo "${t##*/} $(cat "$t/comm") $(awk '{print $14 + $15}' "$t/stat")"
  done 2>/dev/null
}

start_daemon() {
  mw_start_daemon "$work/bench.yaml" "$work/daemon.log"
  mw_wait_ready "$work/daemon.log"
  daemon=$MW_DAEMON_PID
}

echo "== machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg); realtime priority ${rt} (0: off);" \
  "metrics endpoint $([ "$metrics" = 1 ] && echo "on, scraped every ${scrape_period} s" || echo off)"
# The floor under every figure below: the machine's own wake-up latency and the
# time it takes CPUs away, measured without modalwatch (at the bench's priority).
if [ "${MACHINE_SECONDS:-10}" != 0 ]; then bench machine --seconds "${MACHINE_SECONDS:-10}"; fi
hz=$(getconf CLK_TCK)
for loop_hz in $loops; do
  echo "== 4096 Hz, one sample_t per packet, ${run_s} s, loop ${loop_hz} Hz, an estimate every 10 ms"
  config_for "$loop_hz" 0.01
  start_daemon
  start_scraper
  c0=$(cpu_ticks "$daemon"); t0=$(date +%s.%N); thread_ticks "$daemon" > "$work/threads0"
  bench latency --config "$work/bench.yaml" --data "$work/record.csv" --rate 4096 \
    --seconds "$run_s" --skip "$skip"
  c1=$(cpu_ticks "$daemon"); t1=$(date +%s.%N); thread_ticks "$daemon" > "$work/threads1"
  stop_scraper
  awk -v c="$((c1 - c0))" -v hz="$hz" -v a="$t0" -v b="$t1" \
    'BEGIN { printf "  daemon CPU: %.1f %% of one core (user+system over %.1f s, warm-up fit included)\n", 100 * c / hz / (b - a), b - a }'
  # Per thread (LCM's receive thread is the second "modalwatchd").
  awk -v hz="$hz" -v a="$t0" -v b="$t1" 'NR == FNR { before[$1] = $3; next }
    { line = line sprintf(" %s %.2f,", $2, 100 * ($3 - before[$1]) / hz / (b - a)) }
    END { sub(/,$/, "", line); print "    per thread (%):" line }' "$work/threads0" "$work/threads1"
  echo "  load average now: $(cut -d' ' -f1-3 /proc/loadavg)"
  grep -o "warm-up over.*" "$work/daemon.log" | sed 's/^/  daemon: /' || true
  mw_stop_daemon
done
config_for 2000 0.1

[ -n "${RATES-x}" ] && echo "== highest sustained batch rate without drops (batches of 256 samples, 3 s per rate)"
for rate in ${RATES-50000 100000 150000 200000 300000 400000}; do
  start_daemon
  line=$(bench rate --config "$work/bench.yaml" --data "$work/record.csv" \
           --rate "$rate" --seconds 3 --batch 256 | grep "daemon:")
  mw_stop_daemon
  echo "  $rate samples/s: $line"
done
