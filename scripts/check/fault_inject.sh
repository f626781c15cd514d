#!/usr/bin/env bash
# kill -9 at random moments: modalwatchd killed KILLS (5) times while a replay
# at SPEED (1) x real time of the flexible beam (config/flexible-beam-drift.yaml
# without its drift) runs, checkpoint every PERIOD (2) s, restarted each time
# from the previous instance's checkpoint. The test suite kills the daemon once,
# at a fixed moment, in process-level isolation; this runs the real processes
# (`modalwatch replay`, `modalwatch watch`) for minutes, kills several times in
# a row at random moments (one may land inside a checkpoint write) and reports
# the figures. After each restart:
#   (a) it resumed from the checkpoint ("restored checkpoint", "resumed from
#       checkpoint", "estimating from the restored checkpoint (no warm-up)", no
#       "warm-up over");
#   (b) the restored checkpoint is the last one written before the kill, and its
#       newest sample is at most one period (+ 0.5 s) older than the newest
#       sample at the kill (sample time from the time-stamped watch output);
#   (c) `modalwatch watch` shows estimates again within one period of the
#       restart, with no NaN/Inf.
# Figures per kill: samples lost (processed after the checkpoint, sent while
# down), time to the first estimate, out-of-order/duplicate counts; then the
# temporary checkpoint files the kills left. The last instance must stop on
# SIGTERM with exit 0 and a final checkpoint.
# On a shared machine every process of this script can stop for seconds at once
# (freezes.csv records it): a check that fails while that happened is printed as
# SKIP with the figures, not counted as a failure.
# One PASS/FAIL line per check; exits non-zero when any check fails.
#
#   scripts/check/fault_inject.sh          # about 30 s
#   KILLS=10 PERIOD=1 SPEED=2 BUILD_DIR=build OUT=dir scripts/check/fault_inject.sh
# Needs /usr/bin/python3 and a multicast route (scripts/setup.sh adds one);
# builds BUILD_DIR (build) when it has no modalwatch and modalwatchd.
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1
source scripts/lib/daemon.sh
mw_ensure_build "${BUILD_DIR:-build}" || exit 1
build=$MW_BUILD
KILLS=${KILLS:-5}
PERIOD=${PERIOD:-2}
SPEED=${SPEED:-1}
OUT=${OUT:-$(mktemp -d /tmp/modalwatch-fault.XXXXXX)}
PY=/usr/bin/python3
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
port=$((7900 + RANDOM % 200))
url="udpm://239.255.76.67:$port?ttl=0"
echo "== fault injection: $build, files in $OUT, LCM $url"

now() { echo "$EPOCHREALTIME"; }
pids=()
# The machine may be shared: record when this script's own processes stopped
# running (a 0.1 s sleep that took more than 0.6 s), so that a pause of
# everything is not blamed on the daemon.
( prev=${EPOCHREALTIME/./}
  while sleep 0.1; do n=${EPOCHREALTIME/./}; (( n - prev > 600000 )) && echo "$((prev / 1000)),$((n / 1000))"; prev=$n; done
) >"$OUT/freezes.csv" &
pids+=("$!")
cleanup() {
  mw_kill_daemon
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
}
trap cleanup EXIT

# The drifting demo config without its drift, on our port, with a short checkpoint period.
duration=$(awk -v n="$KILLS" -v p="$PERIOD" -v s="$SPEED" 'BEGIN { d = s * (8 + n * (3 * p + 2)) + 5 / s + 5; print (d < 20 ? 20 : int(d + 1)) }')
mkdir -p "$OUT/ckpt"
rm -f "$OUT/ckpt/modalwatchd.ckpt"
mw_config config/flexible-beam-drift.yaml "$OUT/fault.yaml" --no-drift lcm.url="$url" \
  simulation.duration="$duration" daemon.log_level=debug \
  daemon.checkpoint="{path: $OUT/ckpt/modalwatchd.ckpt, period: $PERIOD}" || exit 1
echo "== simulate: $duration s of the flexible beam at 4096 Hz -> $OUT/record.csv"
"$build/modalwatch" simulate --config "$OUT/fault.yaml" --out "$OUT/record.csv" >/dev/null || exit 1

echo "== kill -9 at $KILLS random moments, checkpoint every $PERIOD s, replay at ${SPEED}x"
: >"$OUT/kills.csv"
mw_start_daemon "$OUT/fault.yaml" "$OUT/daemon.0.log"
mw_wait_ready "$OUT/daemon.0.log" || exit 1
# `modalwatch watch` with every line prefixed by the wall-clock time it arrived.
"$build/modalwatch" watch --config "$OUT/fault.yaml" --every 1 \
  > >(while IFS= read -r l; do printf '%s %s\n' "$EPOCHREALTIME" "$l"; done >"$OUT/watch.log") 2>"$OUT/watch.log.err" &
watcher=$!
pids+=("$watcher")
sleep 0.3
"$build/modalwatch" replay --config "$OUT/fault.yaml" --data "$OUT/record.csv" --speed "$SPEED" --batch 16 \
  >"$OUT/replay.log" 2>&1 &
replay=$!
pids+=("$replay")
kill_ok=1
if ! mw_wait_for "$OUT/daemon.0.log" "warm-up over after" $((20 / SPEED + 10)); then
  echo "FAIL  the first daemon did not finish its warm-up"; kill_ok=0
fi
for k in $(seq 1 "$KILLS"); do
  [ "$kill_ok" = 1 ] || break
  prev="$OUT/daemon.$((k - 1)).log"
  # A checkpoint of this instance first (the first is written PERIOD s after
  # its start), then a random moment within the next two periods.
  if ! mw_wait_for "$prev" "checkpoint written" $((PERIOD + 10)); then
    echo "FAIL  instance $((k - 1)) wrote no checkpoint"; kill_ok=0; break
  fi
  delay=$(awk -v r="$RANDOM" -v p="$PERIOD" 'BEGIN { printf "%.3f", r / 32768 * 2 * p }')
  sleep "$delay"
  kill -0 "$replay" 2>/dev/null || { echo "FAIL  the replay ended before kill $k (record too short)"; kill_ok=0; break; }
  wk=$(now)
  kill -9 "$MW_DAEMON_PID"
  wait "$MW_DAEMON_PID" 2>/dev/null
  rk=$(now)
  mw_start_daemon "$OUT/fault.yaml" "$OUT/daemon.$k.log"
  echo "$k,$wk,$rk,$delay" >>"$OUT/kills.csv"
  echo "   kill $k at +$delay s after the first checkpoint of instance $((k - 1)); restarted"
  mw_wait_for "$OUT/daemon.$k.log" "estimating from the restored checkpoint|warm-up over after" $((PERIOD + 10)) ||
    echo "   instance $k: no estimation within $((PERIOD + 10)) s"
done
# The last instance: let it publish for a period, then stop it properly.
sleep "$PERIOD"
mw_stop_daemon
kill "$replay" "$watcher" 2>/dev/null; wait "$replay" 2>/dev/null
sleep 0.2
$PY - "$OUT" "$KILLS" "$PERIOD" "$SPEED" "$MW_DAEMON_RC" "$kill_ok" <<'PY'
import datetime, math, re, sys
out, kills, period, speed, last_rc, kill_ok = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]), sys.argv[6] == "1"
T = 1.0 / 4096
ok = True
freezes = [tuple(int(x) * 1e-3 for x in l.split(",")) for l in open(f"{out}/freezes.csv").read().split()]
def frozen(a, b):  # s during which this script's processes did not run, within [a, b]
    return sum(max(0.0, min(b, f1) - max(a, f0)) for f0, f1 in freezes)
def check(cond, what, fig="", froze=0.0):
    global ok
    if not cond and froze > 0.3:  # everything stopped, the daemon included: not its failure
        print(f"SKIP  {what}  [{fig}; this script's processes were all stopped for {froze:.2f} s meanwhile]")
        return
    print(("PASS  " if cond else "FAIL  ") + what + (f"  [{fig}]" if fig else ""))
    ok &= bool(cond)
def stamp(line):  # spdlog's local time stamp
    return datetime.datetime.strptime(line[:23], "%Y-%m-%d %H:%M:%S.%f").timestamp()
def log(k):
    return open(f"{out}/daemon.{k}.log").read().splitlines()
watch = []
for l in open(f"{out}/watch.log"):
    w, _, rest = l.rstrip("\n").partition(" ")
    watch.append((float(w), rest))
est = [(w, l) for w, l in watch if l.startswith("estimates")]
def est_fields(l):
    u = float(re.search(r"t = +([0-9.]+) s", l).group(1))
    n = int(re.search(r"([0-9]+) samples$", l).group(1))
    f = [float(x) for x in re.findall(r"f = +([-0-9.naif]+) Hz", l)]
    return u, n, f
rows = [l.split(",") for l in open(f"{out}/kills.csv").read().split()]
c_replay = max((est_fields(l)[0] * 1e6 - speed * w * 1e6 for w, l in est), default=float("nan"))
check(kill_ok and len(rows) == kills, f"{len(rows)} of {kills} kills done")
lost, ttfe, ages, ooo_total = [], [], [], []
for k, wk, rk, delay in rows:
    k, wk, rk = int(k), float(wk), float(rk)
    prev, cur = log(k - 1), log(k)
    nxt = float(rows[k][1]) if k < len(rows) else float("inf")
    # (a) resumed without a warm-up
    restored = [re.search(r"restored checkpoint \S+: last sample utime (\d+) us, seq (\d+); no warm-up", l) for l in cur]
    restored = [m for m in restored if m]
    resumed = any("resumed from checkpoint" in l and "no warm-up" in l for l in cur)
    estimating = any("estimating from the restored checkpoint (no warm-up)" in l for l in cur)
    warmup = any("warm-up over after" in l for l in cur)
    check(bool(restored) and resumed and estimating and not warmup,
          f"kill {k}: resumed from the checkpoint, no new warm-up",
          f"restored: {'yes' if restored else 'NO'}, start line says resumed: {resumed}, "
          f"'estimating from the restored checkpoint': {estimating}, warm-up: {warmup}")
    if not restored:
        continue
    u_ck, s_ck = int(restored[0].group(1)), int(restored[0].group(2))
    # (b) the restored checkpoint is the last written before the kill, at most one period old
    written = [(stamp(l), int(m.group(1))) for l in prev
               for m in [re.search(r"checkpoint written: .* \(last seq (\d+)\)", l)] if m and stamp(l) <= wk]
    last_w = written[-1] if written else (float("nan"), -1)
    # The newest sample the replay had sent at the kill: utime = speed * wall + c,
    # c from the estimate that arrived soonest after its sample (an estimate that
    # comes out of a stalled loop is late, never early).
    before = [(w, l) for w, l in est if w < wk]
    u_kill = speed * wk * 1e6 + c_replay
    age = (u_kill - u_ck) * 1e-6
    ages.append(age)
    wall_age = wk - last_w[0]
    # The longest pause of the killed instance's estimates (wall clock): a stalled
    # estimation loop makes the checkpoint it is captured from old.
    mine = [w for w, l in est if float(rows[k - 2][2] if k > 1 else 0) < w < wk]
    mine.append(wk)
    stall = max([b - a for a, b in zip(mine, mine[1:])], default=float("nan"))
    check(last_w[1] == s_ck and age <= speed * period + 0.5,
          f"kill {k}: the checkpoint's newest sample at most one period (+0.5 s) before the kill's",
          f"restored seq {s_ck} = last written seq {last_w[1]}: {last_w[1] == s_ck}; written {wall_age:.2f} s (wall) "
          f"before the kill; its newest sample {age:.2f} s (sample time) before the kill's (limit {speed * period:.1f}"
          f" + 0.5); longest pause of its estimates (up to the kill) {stall:.2f} s",
          frozen(last_w[0] - period - 0.5, wk))
    # (c) estimates again within one period, no NaN
    after = [(w, l) for w, l in est if rk < w < nxt]
    bad = [l for w, l in after if re.search(r"\bnan\b|\binf\b", l, re.I)]
    if after:
        w1, l1 = after[0]
        u1, n1, f1 = est_fields(l1)
        ttfe.append(w1 - rk)
        u_first = u1 * 1e6 - (n1 - 1) * T * 1e6  # the first sample this instance took
        lost_total = round((u_first - u_ck) * 1e-6 / T) - 1
        lost_redo = round((u_kill - u_ck) * 1e-6 / T)
        lost.append((lost_total, lost_redo))
        fb = est_fields(before[-1][1])[2] if before else []
        check(w1 - rk <= period and not bad,
              f"kill {k}: estimates again {w1 - rk:.2f} s after the restart (limit {period:g} s), no NaN/Inf",
              f"{len(after)} estimates, {len(bad)} with NaN/Inf; f before kill {fb}, first after {f1} Hz; "
              f"samples lost {lost_total} ({lost_total * T:.2f} s): {lost_redo} processed after the checkpoint, "
              f"{lost_total - lost_redo} sent while down", frozen(rk, w1))
    else:
        check(False, f"kill {k}: estimates again after the restart", "none seen")
    gaps = sum("input gap" in l for l in cur)
    resets = [l[24:].split(";")[0] for l in cur if "estimator reset" in l]
    faults = [l for w, l in watch if rk < w < nxt and l.startswith("faults")]
    m = re.search(r"dup (\d+), ooo (\d+), gaps (\d+)", faults[-1]) if faults else None
    print(f"      instance {k}: {gaps} input-gap log lines, {len(resets)} estimator resets"
          + (f" (first: {resets[0]})" if resets else "") + "; "
          + (f"duplicates {m.group(1)}, out of order {m.group(2)}, gaps {m.group(3)}" if m else "no fault status seen"))
    ooo_total.append(int(m.group(2)) if m else 0)
if lost:
    print(f"      summary: samples lost per kill {[a for a, _ in lost]} (period {period:g} s = {period * speed / T:.0f} samples), "
          f"checkpoint age at kill {min(ages):.2f}..{max(ages):.2f} s, first estimate after restart "
          f"{min(ttfe):.2f}..{max(ttfe):.2f} s")
if ooo_total:
    print(f"      input policy: the replay kept counting, so every restarted instance saw seq above the checkpoint's "
          f"last_seq: {sum(ooo_total)} samples dropped as out of order in all; the samples sent while the daemon was "
          f"down are simply lost, and the first one after the restart is a gap (prefilters restart)")
import glob
temps = glob.glob(f"{out}/ckpt/.modalwatchd.ckpt.*")
print(f"      temporary checkpoint files left by the kills (a kill during a write): {len(temps)}")
print(f"      this script's processes were all stopped {len(freezes)} times (0.6 s or more), "
      f"{sum(b - a for a, b in freezes):.1f} s in all (files: freezes.csv)")
last = log(kills if kill_ok else 0)
check(last_rc == 0 and any("checkpoint written" in l and "info" in l for l in last),
      "last instance: SIGTERM -> exit 0 with a final checkpoint", f"exit {last_rc}")
sys.exit(0 if ok else 1)
PY
rc=$?
echo "== files: $OUT"
[ "$rc" -eq 0 ] && { echo "RESULT: PASS"; exit 0; }
echo "RESULT: FAIL"; exit 1
