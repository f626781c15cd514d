#!/usr/bin/env bash
# Fault injection (issue 6): modalwatchd's failure behaviour, one PASS/FAIL line
# per check plus the figures; exits non-zero when any check fails.
#   1. kill -9 at KILLS (5) random moments during a replay at SPEED (1) x real
#      time of the flexible beam (config/flexible-beam-drift.yaml without its
#      drift), checkpoint every PERIOD (2) s; restarted each time. After each
#      restart: (a) it resumed from the checkpoint (log: "restored checkpoint",
#      "resumed from checkpoint", "estimating from the restored checkpoint (no
#      warm-up)", no "warm-up over"); (b) the restored checkpoint is the last one
#      written before the kill and its newest sample is at most one period
#      (+ slack) older than the newest sample at the kill (sample time from the
#      time-stamped `modalwatch watch` output); (c) `modalwatch watch` shows
#      estimates again within one period of the restart, with no NaN/Inf.
#      Figures per kill: samples lost (processed after the checkpoint, sent
#      while down), time to the first estimate, out-of-order/duplicate counts.
#   2. An unusable LCM URL at start (bogus://x, udpm://999.1.1.1:7667): a clear
#      message on stderr naming lcm.url and the URL, a non-zero exit code.
#   3. A full disk for the checkpoint (64 KiB tmpfs, filled; without mount
#      permission: a missing directory): the failure is logged, estimates keep
#      coming, SIGTERM still exits 0, no temporary file is left behind.
#   4. An invalid config at start (exit code 2, message with file:line and the
#      key) and SIGHUP with an invalid config (logged with key and line, the
#      daemon keeps running and publishing; a valid SIGHUP then applies).
# On a shared machine every process of this test can stop for seconds at once
# (freezes.csv records it): a kill check that fails while that happened is
# printed as SKIP with the figures, not counted as a failure.
#
#   scripts/check/fault_inject.sh                 # about 2 min
#   KILLS=10 PERIOD=1 SPEED=2 BUILD_DIR=/path/to/build OUT=dir scripts/check/fault_inject.sh
# Needs build/modalwatch and build/modalwatchd (BUILD_DIR), /usr/bin/python3, a
# multicast route (scripts/setup.sh adds one), root for the tmpfs of check 3.
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1
build=${BUILD_DIR:-build}
KILLS=${KILLS:-5}
PERIOD=${PERIOD:-2}
SPEED=${SPEED:-1}
OUT=${OUT:-$(mktemp -d /tmp/modalwatch-fault.XXXXXX)}
PY=/usr/bin/python3
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
for b in modalwatch modalwatchd; do
  [ -x "$build/$b" ] || { echo "fault_inject.sh: no $build/$b (set BUILD_DIR)"; exit 1; }
done
port=$((7900 + RANDOM % 200))
url="udpm://239.255.76.67:$port?ttl=0"
echo "== fault injection: $build, files in $OUT, LCM $url"

failures=0
result() {  # result 0|1 "what" ["figures"]
  if [ "$1" -eq 0 ]; then echo "PASS  $2${3:+  [$3]}"; else echo "FAIL  $2${3:+  [$3]}"; failures=$((failures + 1)); fi
}
now() { echo "$EPOCHREALTIME"; }
# wait_for FILE REGEX TIMEOUT_S: polls until FILE has a line matching REGEX (grep -E).
wait_for() {
  local deadline
  deadline=$(awk -v t="$EPOCHREALTIME" -v d="$3" 'BEGIN { printf "%.3f", t + d }')
  until grep -qE -- "$2" "$1" 2>/dev/null; do
    awk -v t="$EPOCHREALTIME" -v d="$deadline" 'BEGIN { exit !(t > d) }' && return 1
    sleep 0.05
  done
}
count_lines() { grep -cE -- "$2" "$1" 2>/dev/null || true; }
# `modalwatch watch` with every line prefixed by the wall-clock time it arrived.
start_watch() {  # start_watch CONFIG OUTFILE; sets $watcher
  "$build/modalwatch" watch --config "$1" --every 1 \
    > >(while IFS= read -r l; do printf '%s %s\n' "$EPOCHREALTIME" "$l"; done >"$2") 2>"$2.err" &
  watcher=$!
}
pids=()
mnt=""
# This machine is shared: record when this test's own processes stopped running
# (a 0.1 s sleep that took more than 0.6 s), so that a pause of everything is not
# blamed on the daemon.
( prev=${EPOCHREALTIME/./}
  while sleep 0.1; do n=${EPOCHREALTIME/./}; (( n - prev > 600000 )) && echo "$((prev / 1000)),$((n / 1000))"; prev=$n; done
) >"$OUT/freezes.csv" &
pids+=("$!")
cleanup() {
  for p in "${pids[@]}"; do kill -9 "$p" 2>/dev/null; done
  [ -n "$mnt" ] && umount "$mnt" 2>/dev/null
}
trap cleanup EXIT

# The drifting demo config without its drift, on our port, with a short checkpoint period.
duration=$(awk -v n="$KILLS" -v p="$PERIOD" -v s="$SPEED" 'BEGIN { d = s * (8 + n * (3 * p + 2)) + 5 / s + 5; print (d < 20 ? 20 : int(d + 1)) }')
make_config() {  # make_config OUT.yaml [checkpoint path]
  sed -e '/trajectory:/,/gain: \[\[/d' \
      -e "s#^  url: .*#  url: $url#" \
      -e "s/^  duration: .*/  duration: $duration/" \
      -e "s/^  log_level: .*/  log_level: debug/" \
      ${2:+-e "/^daemon:/a\\  checkpoint: {path: $2, period: $PERIOD}"} \
      config/flexible-beam-drift.yaml >"$1"
}
make_config "$OUT/fault.yaml" "$OUT/ckpt/modalwatchd.ckpt"
mkdir -p "$OUT/ckpt"
rm -f "$OUT/ckpt/modalwatchd.ckpt"
grep -q trajectory "$OUT/fault.yaml" && { echo "fault_inject.sh: could not remove the drift"; exit 1; }
echo "== simulate: $duration s of the flexible beam at 4096 Hz -> $OUT/record.csv"
"$build/modalwatch" simulate --config "$OUT/fault.yaml" --out "$OUT/record.csv" >/dev/null || exit 1

# ---------------------------------------------------------------- 1. kill -9
echo "== 1. kill -9 at $KILLS random moments, checkpoint every $PERIOD s, replay at ${SPEED}x"
start_daemon() {  # start_daemon CONFIG LOG; sets $daemon
  "$build/modalwatchd" --config "$1" 2>"$2" &
  daemon=$!
  pids+=("$daemon")
}
: >"$OUT/kills.csv"
start_daemon "$OUT/fault.yaml" "$OUT/daemon.0.log"
wait_for "$OUT/daemon.0.log" "modalwatchd: " 10 || { echo "modalwatchd did not start:"; cat "$OUT/daemon.0.log"; exit 1; }
start_watch "$OUT/fault.yaml" "$OUT/watch.log"
pids+=("$watcher")
sleep 0.3
"$build/modalwatch" replay --config "$OUT/fault.yaml" --data "$OUT/record.csv" --speed "$SPEED" --batch 16 \
  >"$OUT/replay.log" 2>&1 &
replay=$!
pids+=("$replay")
kill1_ok=1
if ! wait_for "$OUT/daemon.0.log" "warm-up over after" $((20 / SPEED + 10)); then
  echo "FAIL  the first daemon did not finish its warm-up"; kill1_ok=0
fi
for k in $(seq 1 "$KILLS"); do
  [ "$kill1_ok" = 1 ] || break
  prev="$OUT/daemon.$((k - 1)).log"
  # A checkpoint of this instance first (the first is written PERIOD s after
  # its start), then a random moment within the next two periods.
  if ! wait_for "$prev" "checkpoint written" $((PERIOD + 10)); then
    echo "FAIL  instance $((k - 1)) wrote no checkpoint"; kill1_ok=0; break
  fi
  delay=$(awk -v r="$RANDOM" -v p="$PERIOD" 'BEGIN { printf "%.3f", r / 32768 * 2 * p }')
  sleep "$delay"
  kill -0 "$replay" 2>/dev/null || { echo "FAIL  the replay ended before kill $k (record too short)"; kill1_ok=0; break; }
  wk=$(now)
  kill -9 "$daemon"
  wait "$daemon" 2>/dev/null
  rk=$(now)
  start_daemon "$OUT/fault.yaml" "$OUT/daemon.$k.log"
  echo "$k,$wk,$rk,$delay" >>"$OUT/kills.csv"
  echo "   kill $k at +$delay s after the first checkpoint of instance $((k - 1)); restarted"
  wait_for "$OUT/daemon.$k.log" "estimating from the restored checkpoint|warm-up over after" $((PERIOD + 10)) ||
    { echo "   instance $k: no estimation within $((PERIOD + 10)) s"; }
done
# The last instance: let it publish for a period, then stop it properly.
sleep "$PERIOD"
kill -TERM "$daemon"; wait "$daemon"; last_rc=$?
kill "$replay" "$watcher" 2>/dev/null; wait "$replay" 2>/dev/null
sleep 0.2
$PY - "$OUT" "$KILLS" "$PERIOD" "$SPEED" "$last_rc" "$kill1_ok" <<'PY' || failures=$((failures + 1))
import datetime, math, re, sys
out, kills, period, speed, last_rc, kill_ok = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5]), sys.argv[6] == "1"
T = 1.0 / 4096
ok = True
freezes = [tuple(int(x) * 1e-3 for x in l.split(",")) for l in open(f"{out}/freezes.csv").read().split()]
def frozen(a, b):  # s during which this test's processes did not run, within [a, b]
    return sum(max(0.0, min(b, f1) - max(a, f0)) for f0, f1 in freezes)
def check(cond, what, fig="", froze=0.0):
    global ok
    if not cond and froze > 0.3:  # everything stopped, the daemon included: not its failure
        print(f"SKIP  {what}  [{fig}; this test's processes were all stopped for {froze:.2f} s meanwhile]")
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
print(f"      this test's processes were all stopped {len(freezes)} times (0.6 s or more), "
      f"{sum(b - a for a, b in freezes):.1f} s in all (files: freezes.csv)")
last = log(kills if kill_ok else 0)
check(last_rc == 0 and any("checkpoint written" in l and "info" in l for l in last),
      "last instance: SIGTERM -> exit 0 with a final checkpoint", f"exit {last_rc}")
sys.exit(0 if ok else 1)
PY

# ---------------------------------------------------------------- 2. bad LCM URL
echo "== 2. unusable LCM URL at start"
make_config "$OUT/good.yaml"
for bad in "bogus://x" "udpm://999.1.1.1:7667"; do
  sed "s#^  url: .*#  url: $bad#" "$OUT/good.yaml" >"$OUT/badurl.yaml"
  timeout 20 "$build/modalwatchd" --config "$OUT/badurl.yaml" >/dev/null 2>"$OUT/badurl.err"; rc=$?
  msg=$(grep -m1 "lcm.url" "$OUT/badurl.err")
  [ "$rc" -ne 0 ] && [ "$rc" -ne 124 ] && grep -qF "$bad" <<<"$msg"; ok=$?
  result $ok "lcm.url '$bad': non-zero exit, message on stderr" "exit $rc; $(tr '\n' ' ' <"$OUT/badurl.err" | cut -c1-220)"
done
echo "      (exit 2; the unit's Restart=on-failure restarts on any non-zero exit, every RestartSec=2s until its start limit)"

# ---------------------------------------------------------------- 3. full disk
echo "== 3. checkpoint on a full disk"
full="$OUT/full"
mkdir -p "$full"
if mount -t tmpfs -o size=64k tmpfs "$full" 2>"$OUT/mount.err"; then
  mnt=$full
  dd if=/dev/zero of="$full/fill" bs=4k >/dev/null 2>&1
  ckdir=$full
  how="64 KiB tmpfs, $(df -k --output=avail "$full" | tail -1 | tr -d ' ') KiB free after filling"
else
  ckdir="$full/missing"  # mkstemp fails as on a full disk; root ignores permissions, so no read-only dir
  how="no mount permission ($(cat "$OUT/mount.err")): a missing directory instead"
fi
make_config "$OUT/full.yaml" "$ckdir/modalwatchd.ckpt"
start_daemon "$OUT/full.yaml" "$OUT/daemon.full.log"
wait_for "$OUT/daemon.full.log" "modalwatchd: " 10
start_watch "$OUT/full.yaml" "$OUT/watch.full.log"
pids+=("$watcher")
sleep 0.3
"$build/modalwatch" replay --config "$OUT/full.yaml" --data "$OUT/record.csv" --speed 2 --batch 16 \
  >"$OUT/replay.full.log" 2>&1 &
replay=$!
pids+=("$replay")
wait_for "$OUT/daemon.full.log" "warm-up over after" 20
wait_for "$OUT/daemon.full.log" "checkpoint NOT written" $((PERIOD + 5)); seen=$?
t_fail=$(now)
n0=$(count_lines "$OUT/watch.full.log" " estimates ")
# Estimates after the failure: at least one period's worth.
sleep "$PERIOD"
n1=$(count_lines "$OUT/watch.full.log" " estimates ")
alive=0; kill -0 "$daemon" 2>/dev/null && alive=1
kill -TERM "$daemon"; wait "$daemon"; rc=$?
kill "$replay" "$watcher" 2>/dev/null; wait "$replay" 2>/dev/null
nfail=$(count_lines "$OUT/daemon.full.log" "checkpoint NOT written")
left=$(ls -A "$ckdir" 2>/dev/null | grep -v '^fill$' | tr '\n' ' ')
nan=$(grep -ciE "\bnan\b|\binf\b" <(grep " estimates " "$OUT/watch.full.log") || true)
msg=$(grep -m1 "checkpoint NOT written" "$OUT/daemon.full.log" | cut -c25-260)
[ "$seen" -eq 0 ]; result $? "full disk: the failed checkpoint is logged" "$how; $nfail failures logged; first: $msg"
[ "$alive" -eq 1 ] && [ $((n1 - n0)) -ge 5 ] && [ "$nan" -eq 0 ]
result $? "full disk: the daemon keeps estimating and publishing" "$((n1 - n0)) estimates in the $PERIOD s after the failure, $nan with NaN/Inf"
[ "$rc" -eq 0 ]; result $? "full disk: SIGTERM -> exit 0 (final checkpoint failure logged)" "exit $rc"
[ -z "$left" ]; result $? "full disk: no checkpoint or temporary file left in the directory" "${left:-empty}"
[ -n "$mnt" ] && { umount "$mnt" && mnt=""; }

# ---------------------------------------------------------------- 4. invalid config
echo "== 4. invalid config at start and on SIGHUP"
sed 's/^  publish_period: .*/  publish_perid: 0.1/' "$OUT/good.yaml" >"$OUT/badkey.yaml"
sed 's/^  loop_rate_hz: .*/  loop_rate_hz: -5/' "$OUT/good.yaml" >"$OUT/badval.yaml"
for bad in badkey:daemon.publish_perid:publish_perid badval:daemon.loop_rate_hz:loop_rate_hz; do
  IFS=: read -r f key word <<<"$bad"
  line=$(grep -n "^  $word:" "$OUT/$f.yaml" | cut -d: -f1)
  timeout 20 "$build/modalwatchd" --config "$OUT/$f.yaml" >/dev/null 2>"$OUT/$f.err"; rc=$?
  [ "$rc" -eq 2 ] && grep -qF "$f.yaml:$line: key '$key'" "$OUT/$f.err"
  result $? "invalid config at start ($key at line $line): exit 2, file:line and key named" \
    "exit $rc; $(head -c 200 "$OUT/$f.err" | tr '\n' ' ' | cut -c25-)"
done
cp "$OUT/good.yaml" "$OUT/hup.yaml"
start_daemon "$OUT/hup.yaml" "$OUT/daemon.hup.log"
wait_for "$OUT/daemon.hup.log" "modalwatchd: " 10
start_watch "$OUT/hup.yaml" "$OUT/watch.hup.log"
pids+=("$watcher")
sleep 0.5
cp "$OUT/badkey.yaml" "$OUT/hup.yaml"
line=$(grep -n "^  publish_perid:" "$OUT/hup.yaml" | cut -d: -f1)
kill -HUP "$daemon"
wait_for "$OUT/daemon.hup.log" "reload rejected" 10
t_hup=$(now)
sleep 1.5
alive=0; kill -0 "$daemon" 2>/dev/null && alive=1
n_after=$(awk -v t="$t_hup" '$1 > t && $2 == "faults"' "$OUT/watch.hup.log" | wc -l)
msg=$(grep -m1 "reload rejected" "$OUT/daemon.hup.log" | cut -c25-)
[ "$alive" -eq 1 ] && [ "$n_after" -ge 5 ] && grep -qF "hup.yaml:$line: key 'daemon.publish_perid'" <<<"$msg"
result $? "SIGHUP with an invalid config: logged with key and line, keeps running and publishing" \
  "alive: $alive, $n_after fault status messages in 1.5 s after; $msg"
cp "$OUT/good.yaml" "$OUT/hup.yaml"
sed -i 's/^  log_level: .*/  log_level: info/' "$OUT/hup.yaml"
kill -HUP "$daemon"
wait_for "$OUT/daemon.hup.log" "reloaded .*hup.yaml" 10
result $? "SIGHUP with the config fixed: applied" "$(grep -m1 -o "reloaded .*log level [a-z]*" "$OUT/daemon.hup.log")"
kill -TERM "$daemon"; wait "$daemon"; rc=$?
kill "$watcher" 2>/dev/null
[ "$rc" -eq 0 ]; result $? "after the reloads: SIGTERM -> exit 0" "exit $rc"

echo "== files: $OUT"
[ "$failures" -eq 0 ] && { echo "RESULT: PASS"; exit 0; }
echo "RESULT: FAIL ($failures)"; exit 1
