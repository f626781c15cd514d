#!/usr/bin/env bash
# The main job, end to end: the daemon watching a motion system whose mode
# drifts. Installs and builds when needed (scripts/setup.sh), simulates the
# flexible beam of config/flexible-beam-drift.yaml (4096 Hz, closed loop; the
# flexible mode loses 15 % stiffness at t = 30..32 s), starts modalwatchd,
# replays the record onto LCM faster than real time, prints the estimates and
# the fault flags as they arrive (`modalwatch watch`), then stops the daemon
# with SIGTERM (drain, checkpoint, exit 0).
#   scripts/demo.sh [config]          SPEED=2 (times real time), DEMO_DIR=dir, BUILD_DIR=build
set -euo pipefail
cd "$(dirname "$0")/.."
source scripts/lib/daemon.sh
config="${1:-config/flexible-beam-drift.yaml}"
speed="${SPEED:-2}"
mw_ensure_build "${BUILD_DIR:-build}"
build=$MW_BUILD
out="${DEMO_DIR:-$(mktemp -d)}"
mkdir -p "$out"

# The daemon's own copy of the config, with a checkpoint in the demo directory.
mw_config "$config" "$out/daemon.yaml" daemon.checkpoint="{path: $out/modalwatchd.ckpt, period: 10}"
rm -f "$out/modalwatchd.ckpt"

echo "== simulate: $config -> $out/record.csv (60 s at 4096 Hz; flex mode -15 % stiffness at t = 30..32 s)"
"$build/modalwatch" simulate --config "$config" --out "$out/record.csv" --truth "$out/truth.csv"

echo "== start: modalwatchd --config $out/daemon.yaml (log: $out/modalwatchd.log)"
mw_start_daemon "$out/daemon.yaml" "$out/modalwatchd.log" \
  "modalwatchd:|FLAG|flag cleared|baseline|warm-up|reset|gap|stale|SIGTERM|checkpoint|stopped"
cleanup() { mw_kill_daemon; kill "${watcher:-}" 2>/dev/null || true; }
trap cleanup EXIT
mw_wait_ready "$out/modalwatchd.log"

echo "== watch: modalwatch watch (every 10th message: one line per second of sample time per channel)"
"$build/modalwatch" watch --config "$out/daemon.yaml" --every 10 &
watcher=$!
sleep 0.5

echo "== replay: modalwatch replay $out/record.csv at ${speed}x real time"
"$build/modalwatch" replay --config "$out/daemon.yaml" --data "$out/record.csv" --speed "$speed" --batch 64 \
  --start-utime 0 >/dev/null
sleep 1.5

echo "== stop: SIGTERM"
mw_stop_daemon
kill "$watcher" 2>/dev/null || true
wait "$watcher" 2>/dev/null || true
trap - EXIT
echo "== modalwatchd exited with code $MW_DAEMON_RC; checkpoint: $(ls "$out"/modalwatchd.ckpt 2>/dev/null || echo none)"
echo "== flag changes logged by the daemon:"
grep -E "FLAG RAISED|flag cleared" "$out/modalwatchd.log" | sed 's/^/   /' || echo "   (none)"
exit "$MW_DAEMON_RC"
