#!/usr/bin/env bash
# Soak: long runs on a plant that does not drift, in two parts:
#   1. the estimator: HOURS (24) of simulated 4096 Hz data (about 350 million
#      samples) through RecursiveEstimator and FaultDetector, faster than real
#      time (tests/bench/soak_estimator: RSS per simulated hour, NaN, flags,
#      resets, final error);
#   2. the daemon: DAEMON_SECONDS (3600) of the flexible beam replayed over LCM
#      (udpm, ttl=0) at real time into modalwatchd; the daemon's RSS sampled
#      every 10 s into $OUT/daemon_rss.csv; at the end: no flag change, no reset,
#      no NaN in any estimate, the final estimates within 1 % (frequency) of
#      the truth, RSS after the first 5 min flat within 1 MiB.
# Exits non-zero when a check fails.
#
#   scripts/check/soak.sh                   # both (about 8 min + 1 h)
#   HOURS=1 DAEMON_SECONDS=300 scripts/check/soak.sh
#   SKIP_ESTIMATOR=1 / SKIP_DAEMON=1        # one part only
# Needs a build in BUILD_DIR (build), with benchmarks (scripts/setup.sh's default)
# for part 1; builds it when missing.
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1
source scripts/lib/daemon.sh
if [ "${SKIP_ESTIMATOR:-0}" != 1 ]; then
  mw_ensure_build "${BUILD_DIR:-build}" tests/bench/soak_estimator || exit 1
else
  mw_ensure_build "${BUILD_DIR:-build}" || exit 1
fi
build=$MW_BUILD
HOURS=${HOURS:-24}
DAEMON_SECONDS=${DAEMON_SECONDS:-3600}
OUT=${OUT:-$(mktemp -d /tmp/modalwatch-soak.XXXXXX)}
mkdir -p "$OUT"
failed=0

if [ "${SKIP_ESTIMATOR:-0}" != 1 ]; then
  echo "== estimator soak: $HOURS h of 4096 Hz data (log: $OUT/estimator.log)"
  /usr/bin/time -v "$build/tests/bench/soak_estimator" "$HOURS" >"$OUT/estimator.log" 2>&1 || failed=1
  grep -E "^ +[0-9.]+ +[0-9]+ |error|PASS|FAIL|Elapsed|Maximum resident" "$OUT/estimator.log" | tail -n 12
fi

if [ "${SKIP_DAEMON:-0}" != 1 ]; then
  echo "== daemon soak: $DAEMON_SECONDS s at real time over LCM (files in $OUT)"
  # The drifting demo config without its drift, with a checkpoint, on a port of its own.
  port=$((7700 + RANDOM % 200))
  mw_config config/flexible-beam-drift.yaml "$OUT/soak.yaml" --no-drift \
    lcm.url="udpm://239.255.76.67:$port?ttl=0" daemon.checkpoint="{path: $OUT/soak.ckpt, period: 60}" \
    simulation.duration="$DAEMON_SECONDS" || exit 1
  "$build/modalwatch" simulate --config "$OUT/soak.yaml" --out "$OUT/record.csv" >/dev/null || exit 1
  mw_start_daemon "$OUT/soak.yaml" "$OUT/daemon.log"
  daemon=$MW_DAEMON_PID
  trap 'mw_kill_daemon; kill ${watcher:-} ${sampler:-} 2>/dev/null' EXIT
  mw_wait_ready "$OUT/daemon.log" || exit 1
  "$build/modalwatch" watch --config "$OUT/soak.yaml" --every 100 >"$OUT/watch.log" 2>&1 &
  watcher=$!
  sleep 0.5
  ( echo "wall_s,rss_kib"; t0=$SECONDS
    while kill -0 "$daemon" 2>/dev/null; do
      echo "$((SECONDS - t0)),$(awk '/VmRSS/ {print $2}' /proc/$daemon/status 2>/dev/null)"; sleep 10
    done ) >"$OUT/daemon_rss.csv" &
  sampler=$!
  "$build/modalwatch" replay --config "$OUT/soak.yaml" --data "$OUT/record.csv" --speed 1 --batch 16 \
    >"$OUT/replay.log" 2>&1 || failed=1
  sleep 2
  mw_stop_daemon
  kill "$watcher" "$sampler" 2>/dev/null; trap - EXIT
  [ "$MW_DAEMON_RC" -eq 0 ] || { echo "FAIL: modalwatchd exited with $MW_DAEMON_RC"; failed=1; }
  /usr/bin/python3 - "$OUT" <<'PY' || failed=1
import csv, re, sys
out = sys.argv[1]
rows = [r for r in csv.DictReader(open(f"{out}/daemon_rss.csv")) if r["rss_kib"]]
rss = [(int(r["wall_s"]), int(r["rss_kib"])) for r in rows]
after = [v for t, v in rss if t >= 300]
log = open(f"{out}/daemon.log").read()
watch = open(f"{out}/watch.log").read()
est = [l for l in watch.splitlines() if l.startswith("estimates")]
ok = True
def check(cond, what):
    global ok
    print(("ok:   " if cond else "FAIL: ") + what)
    ok &= cond
print(f"daemon RSS: start {rss[0][1]} KiB, at 5 min {after[0] if after else '-'} KiB, "
      f"max after {max(after) if after else '-'} KiB, end {rss[-1][1]} KiB ({len(rss)} samples over {rss[-1][0]} s)")
check(bool(after) and max(after) - after[0] <= 1024, "RSS flat after the first 5 min (within 1 MiB)")
check("FLAG RAISED" not in log, "no fault flag on a plant that does not drift")
check(not re.search(r"estimator reset", log), "no estimator reset")
check(not re.search(r"\bnan\b|\binf\b", watch, re.I), "no NaN/Inf in any published estimate")
check(len(est) > 0, f"{len(est)} estimates lines watched")
if est:
    last = est[-1]
    f = [float(x) for x in re.findall(r"f = +([0-9.]+) Hz", last)]
    print("last:", last[:160])
    check(len(f) == 2 and abs(f[0] / 6.0 - 1) < 0.01 and abs(f[1] / 90.0 - 1) < 0.01,
          "final frequencies within 1 % of the truth (6 Hz, 90 Hz)")
m = re.findall(r"stopped: (\d+) samples received, (\d+) processed, (\d+) dropped", log)
if m:
    print(f"samples received {m[-1][0]}, processed {m[-1][1]}, dropped {m[-1][2]}")
    check(m[-1][2] == "0", "no sample dropped")
sys.exit(0 if ok else 1)
PY
fi
[ $failed -eq 0 ] && echo "RESULT: PASS" || { echo "RESULT: FAIL"; exit 1; }
