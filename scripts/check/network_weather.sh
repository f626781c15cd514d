#!/usr/bin/env bash
# modalwatchd through bad network weather (a check, minutes long; not in ctest):
# the flexible-beam drift (config/flexible-beam-drift.yaml: flex loses 15 %
# stiffness at 30..32 s) at 4096 Hz for DURATION seconds of real time, sent by
# tests/bench/network_weather.cpp over udpm on loopback with 1 % random packet
# loss, duplicated and reordered packets, clusters of controller pauses (time
# gaps), NaN bursts, two sender restarts (seq and utime from 0), and one SIGHUP
# whose file changes the LCM URL (not applied without a restart: the baselines
# must stay). A clean replay of the same record first gives the fault's flag
# time. Checks:
#   - no false flag (a quantity the clean run never flagged), and the true
#     fault's flags raised as often as on clean input (no flapping);
#   - flex wn flagged within 1 s (record time) of its flag time on clean input;
#   - every sample accounted for: received = processed + non-finite + dropped +
#     duplicate + out of order, received = sent once + sent again (less what
#     the machine itself lost), and lost in transport = the sender's deliberate
#     losses + the machine's own socket overflow (reported).
# PAUSE_CLUSTERS and NAN_BURSTS (default DURATION / 10 each; 0 leaves only the
# transport's weather) and LOSS (0.01) set the weather.
#   scripts/check/network_weather.sh       DURATION=600 SPEED=1 SEED=1 BUILD_DIR=build JOBS=2
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/lib/daemon.sh
build="${BUILD_DIR:-build}"
duration="${DURATION:-600}"
speed="${SPEED:-1}"
seed="${SEED:-1}"
work="$(mktemp -d)"
trap 'mw_kill_daemon; rm -rf "$work"' EXIT
port=$((7800 + $$ % 90))
start_utime=1000000

mw_build "$build" "modalwatch modalwatchd modalwatch_network_weather" -DMODALWATCH_BENCHMARKS=ON
sender="$build/tests/bench/modalwatch_network_weather"

config="$work/weather.yaml"
mw_config config/flexible-beam-drift.yaml "$config" "lcm.url=udpm://239.255.76.67:${port}?ttl=0" \
  "simulation.duration=$duration"
"$build/modalwatch" simulate --config "$config" --out "$work/record.csv" >/dev/null

# "FLAG RAISED" lines as "mode quantity utime", in order.
flags() {
  sed -nE "s/.*FLAG RAISED: mode '([^']+)' ([a-z]+): .*\(utime ([0-9]+)\).*/\1 \2 \3/p" "$1"
}
# A counter from the "stopped:" line: stopped_count LOG 'lost in transport'.
stopped_count() {
  grep -E 'info stopped: ' "$1" | tail -1 | sed -nE "s/.*[:;,] ([0-9]+) $2.*/\1/p"
}

echo "== clean: $duration s of record at 20x"
mw_start_daemon "$config" "$work/clean.log"
mw_wait_ready "$work/clean.log"
"$build/modalwatch" replay --config "$config" --data "$work/record.csv" --speed 20 --batch 64 \
  --start-utime "$start_utime" >/dev/null
sleep 1
mw_stop_daemon
clean_flags=$(flags "$work/clean.log")
echo "$clean_flags" | sed 's/^/   flag: /'
clean_flex=$(echo "$clean_flags" | awk -v u0="$start_utime" '$1 == "flex" && $2 == "wn" { printf "%.3f", ($3 - u0) * 1e-6; exit }')
if [ -z "$clean_flex" ]; then
  echo "FAIL: the clean run did not flag flex wn" >&2
  grep -E 'stopped|FLAG' "$work/clean.log" >&2
  exit 1
fi
for k in 'dropped' 'lost in transport'; do
  if [ "$(stopped_count "$work/clean.log" "$k")" != 0 ]; then
    echo "note: the clean run itself had samples $k (machine load)"
  fi
done
echo "   flex wn flagged at record t = $clean_flex s"

restart1=20
restart2=$(awk -v d="$duration" -v f="$clean_flex" 'BEGIN { r = 0.6 * d; if (r < f + 8) r = f + 8; printf "%.1f", r }')
sighup_at=$(awk -v d="$duration" -v s="$speed" 'BEGIN { printf "%.2f", 0.4 * d / s }')
events=$(( duration / 10 > 3 ? duration / 10 : 3 ))
pause_clusters="${PAUSE_CLUSTERS:-$events}"
nan_bursts="${NAN_BURSTS:-$events}"
loss="${LOSS:-0.01}"
echo "== weather: $duration s at ${speed}x; restarts at t = $restart1 s and $restart2 s; SIGHUP (new URL) after ${sighup_at} s;" \
  "$pause_clusters pause clusters, $nan_bursts NaN bursts, loss $loss, 0.5 % duplicates, 0.5 % reordered"
mw_start_daemon "$config" "$work/weather.log"
mw_wait_ready "$work/weather.log"
"$sender" --config "$config" --data "$work/record.csv" --speed "$speed" --batch 64 --seed "$seed" \
  --loss "$loss" --duplicate 0.005 --reorder 0.005 --gap-clusters "$pause_clusters" --nan-bursts "$nan_bursts" \
  --restart-at "$restart1" --restart-at "$restart2" --start-utime "$start_utime" \
  --clear-at "$clean_flex" --clear-of 3 >"$work/sender.txt" &
sender_pid=$!
sleep "$sighup_at"
sed -i "s|udpm://239.255.76.67:${port}?ttl=0|udpm://239.255.76.67:$((port + 1))?ttl=0|" "$config"
kill -HUP "$MW_DAEMON_PID"
wait "$sender_pid"
sleep 1
mw_stop_daemon

val() { sed -n "s/^$1=//p" "$work/sender.txt"; }
sent_unique=$(val sent_unique); s_lost=$(val lost); s_dup=$(val duplicated); s_late=$(val late)
nan_sent=$(val nan_sent); skipped=$(val skipped); pauses=$(val pauses)
received=$(stopped_count "$work/weather.log" 'samples received')
processed=$(stopped_count "$work/weather.log" 'processed')
nonfinite=$(stopped_count "$work/weather.log" 'non-finite')
dropped=$(stopped_count "$work/weather.log" 'dropped')
duplicate=$(stopped_count "$work/weather.log" 'duplicate')
ooo=$(stopped_count "$work/weather.log" 'out of order')
lost=$(stopped_count "$work/weather.log" 'lost in transport')
restarts=$(stopped_count "$work/weather.log" 'sender restarts')
gaps=$(grep -E 'rates over|input gap' "$work/weather.log" | tail -1 | sed -nE 's/.* ([0-9]+) gaps.*/\1/p')
echo "   sender: sent once $sent_unique, again $s_dup (duplicates), late $s_late (reordered), lost $s_lost," \
  "NaN $nan_sent, $pauses pauses ($skipped samples never made), restarts $(grep -c '^restart record_t' "$work/sender.txt")"
echo "   daemon: received $received = processed $processed + non-finite $nonfinite + dropped $dropped +" \
  "duplicate $duplicate + out of order $ooo; lost in transport $lost; gaps ${gaps:-?}; sender restarts $restarts"
grep -E 'NOT applied|reload:' "$work/weather.log" | sed 's/^/   [daemon] /' || true
warnings=$(grep -cE 'warning (input gap|samples lost)' "$work/weather.log" || true)
echo "   gap and loss warnings: $warnings lines in $duration s"

fail=0
check() {  # description, condition (awk expression)
  if awk "BEGIN { exit !($2) }"; then echo "   ok: $1"; else echo "   FAIL: $1" >&2; fail=1; fi
}
check "received = processed + non-finite + dropped + duplicate + out of order" \
  "$received == $processed + $nonfinite + $dropped + $duplicate + $ooo"
machine_lost=$((sent_unique + s_dup - received))
check "received = sent once + sent again - the machine's own losses ($machine_lost)" \
  "$received + $machine_lost == $sent_unique + $s_dup && $machine_lost >= 0"
check "lost in transport ($lost) = the sender's losses ($s_lost) + the machine's own ($machine_lost, duplicates excepted)" \
  "$lost >= $s_lost && $lost <= $s_lost + $machine_lost"
check "two sender restarts seen" "$restarts == 2"
check "non-finite ($nonfinite) <= NaN samples sent ($nan_sent)" "$nonfinite <= $nan_sent"
check "duplicate + out of order ($((duplicate + ooo))) = duplicates + late + restart confirmation (<= 2 x 410)" \
  "$duplicate + $ooo >= $s_dup + $s_late && $duplicate + $ooo <= $s_dup + $s_late + 820"

# Flags: utime -> record time through the restarts the log saw before each flag.
weather_flags=$(sed -nE -e 's/.*sender restart: seq and utime started again.*/R/p' \
    -e "s/.*FLAG RAISED: mode '([^']+)' ([a-z]+): .*\(utime ([0-9]+)\).*/F \1 \2 \3/p" "$work/weather.log" |
  awk -v u0="$start_utime" -v r1="$restart1" -v r2="$restart2" '
    $1 == "R" { n++ }
    $1 == "F" { printf "%s %s %.3f\n", $2, $3, (n == 0 ? 0 : (n == 1 ? r1 : r2)) + ($4 - u0) * 1e-6 }')
echo "$weather_flags" | sed 's/^/   flag: /'
# A flag on a quantity the clean run never flagged is false; the true fault's
# flag raised again after it cleared is flapping.
false_flags=$(awk 'NR == FNR { if (NF) want[$1 " " $2]++; next } NF && !want[$1 " " $2] { n++ } END { print n + 0 }' \
  <(echo "$clean_flags") <(echo "$weather_flags"))
flapping=$(awk 'NR == FNR { if (NF) want[$1 " " $2]++; next } NF && want[$1 " " $2] { got[$1 " " $2]++ }
  END { n = 0; for (k in got) if (got[k] > want[k]) n += got[k] - want[k]; print n }' \
  <(echo "$clean_flags") <(echo "$weather_flags"))
check "no false flags ($false_flags)" "$false_flags == 0"
check "the true fault's flags raised once each (raised again: $flapping)" "$flapping == 0"
weather_flex=$(echo "$weather_flags" | awk '$1 == "flex" && $2 == "wn" { print $3; exit }')
check "flex wn flagged at t = ${weather_flex:-never} s, within 1 s of $clean_flex s" \
  "\"${weather_flex}\" != \"\" && (${weather_flex:-0} - $clean_flex) <= 1 && ($clean_flex - ${weather_flex:-0}) <= 1"
baselines_kept=$(grep -c "reload: mode" "$work/weather.log" || true)
check "the SIGHUP kept the baselines (no 'reload: mode' warning: $baselines_kept)" "$baselines_kept == 0"
exit "$fail"
