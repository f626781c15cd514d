#!/usr/bin/env bash
# modalwatchd's Prometheus endpoint end to end: Debian's prometheus (its own
# storage in a temporary directory, 1 s scrape and rule evaluation, the alerting
# rules of config/prometheus/) scrapes two daemons, axes x and y, each on its
# own LCM channels and metrics port. The demo's fault record (the flexible beam
# whose flex mode loses 15 % stiffness at t = 30..32 s) is replayed onto axis
# x, the same beam without the drift onto axis y. Passes when Prometheus sees
# modalwatch_mode_flag{axis="x",mode="flex",quantity="wn"} at 2 (raised) while
# axis y, which processed samples, never flagged.
# PLOT=FILE.png (a path from the repository's root) then lets axis x's replay
# finish and draws, from Prometheus's query_range, both axes' flex wn deviation
# and flag across the fault (scripts/plot/plot_prometheus.py).
#   scripts/check/prometheus.sh      BUILD_DIR=build, SPEED=2 (replay, times real time), TIMEOUT=180 (s), PLOT=
# Exit 77 (skipped) without prometheus or promtool, or when modalwatchd does not
# know the `axis:` and `daemon.metrics:` keys.
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/lib/daemon.sh

for tool in prometheus promtool python3; do
  if ! command -v "$tool" >/dev/null; then
    echo "prometheus.sh: skipped, no $tool (scripts/setup.sh installs it)"
    exit 77
  fi
done
speed="${SPEED:-2}"
timeout_s="${TIMEOUT:-180}"
deadline=$((SECONDS + timeout_s))
mw_ensure_build "${BUILD_DIR:-build}"
build=$MW_BUILD
rules="$MW_ROOT/config/prometheus/modalwatch-rules.yml"
promtool check rules "$rules" >/dev/null

out=$(mktemp -d)
prom_pid="" pid_x="" pid_y="" replay_x="" replay_y=""
cleanup() {
  local p
  for p in $replay_x $replay_y $pid_x $pid_y $prom_pid; do kill -9 "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
  rm -rf "$out"
}
trap cleanup EXIT

# Ports the kernel hands out free now (bound and released; nothing else on the
# host takes them in the seconds until the servers bind them).
read -r port_x port_y port_prom < <(python3 -c '
import socket
socks = [socket.socket() for _ in range(3)]
for s in socks: s.bind(("127.0.0.1", 0))
print(*[s.getsockname()[1] for s in socks])')

# Prometheus's HTTP API: the instant query EXPR, one "labels value" line per series.
query() {
  python3 - "$port_prom" "$1" <<'EOF'
import json, sys, urllib.parse, urllib.request
url = "http://127.0.0.1:%s/api/v1/query?%s" % (sys.argv[1], urllib.parse.urlencode({"query": sys.argv[2]}))
with urllib.request.urlopen(url, timeout=5) as r:
    reply = json.load(r)
if reply.get("status") != "success":
    sys.exit("query failed: %s" % reply)
for s in reply["data"]["result"]:
    print(",".join("%s=%s" % kv for kv in sorted(s["metric"].items())), s["value"][1])
EOF
}

# One daemon config per axis: its channels, its metrics port, no checkpoint.
axis_config() {  # AXIS PORT SRC OUT
  local upper=${1^^}
  mw_config "$3" "$4" \
    lcm.channels="{samples: ${upper}_SAMPLES, batches: ${upper}_BATCHES, estimates: ${upper}_ESTIMATES, fault_status: ${upper}_FAULT_STATUS, heartbeat: ${upper}_HEARTBEAT}" \
    daemon.metrics="{listen: 127.0.0.1:$2}"
  echo "axis: $1" >>"$4"
}
mw_config config/flexible-beam-drift.yaml "$out/steady.yaml" --no-drift
axis_config x "$port_x" config/flexible-beam-drift.yaml "$out/x.yaml"
axis_config y "$port_y" "$out/steady.yaml" "$out/y.yaml"

start_axis() {  # AXIS: starts its daemon, sets pid_AXIS; 77 when the keys are unknown
  mw_start_daemon "$out/$1.yaml" "$out/$1.log"
  printf -v "pid_$1" '%s' "$MW_DAEMON_PID"
  if ! mw_wait_ready "$out/$1.log" 10 2>/dev/null; then
    if grep -qE "key '(axis|daemon\.metrics)[^']*': unknown key" "$out/$1.log"; then
      echo "prometheus.sh: skipped, this modalwatchd has no metrics endpoint (axis:, daemon.metrics:)"
      exit 77
    fi
    echo "modalwatchd (axis $1) did not start:" >&2
    cat "$out/$1.log" >&2
    exit 1
  fi
}
echo "== start: modalwatchd for axis x (metrics on $port_x) and axis y (metrics on $port_y)"
start_axis x
start_axis y
MW_DAEMON_PID=""

# The example scrape config with this run's ports, 1 s intervals and the rules.
cat >"$out/prometheus.yml" <<EOF
global:
  scrape_interval: 1s
  evaluation_interval: 1s
rule_files:
  - $rules
scrape_configs:
  - job_name: modalwatch
    static_configs:
      - targets: ["127.0.0.1:$port_x", "127.0.0.1:$port_y"]
EOF
promtool check config "$out/prometheus.yml" >/dev/null
echo "== start: prometheus on 127.0.0.1:$port_prom (log: prometheus.log)"
prometheus --config.file="$out/prometheus.yml" --storage.tsdb.path="$out/tsdb" \
  --web.listen-address="127.0.0.1:$port_prom" --log.level=warn 2>"$out/prometheus.log" &
prom_pid=$!
until python3 -c "import urllib.request, sys; urllib.request.urlopen('http://127.0.0.1:$port_prom/-/ready', timeout=1)" \
    2>/dev/null; do
  if ! kill -0 "$prom_pid" 2>/dev/null || ((SECONDS > deadline)); then
    echo "prometheus did not become ready:" >&2
    cat "$out/prometheus.log" >&2
    exit 1
  fi
  sleep 0.2
done
rules_loaded=$(python3 - "$port_prom" <<'EOF'
import json, sys, urllib.request
with urllib.request.urlopen("http://127.0.0.1:%s/api/v1/rules" % sys.argv[1], timeout=5) as r:
    print(sum(len(g["rules"]) for g in json.load(r)["data"]["groups"]))
EOF
)
echo "   rules loaded: $rules_loaded"
if [ "$rules_loaded" -lt 1 ]; then
  echo "prometheus loaded no rules from $rules" >&2
  exit 1
fi

# Both targets up before any input: the endpoints answer from the start.
until [ "$(query 'sum(up{job="modalwatch"})' | awk '{print $NF}')" = 2 ]; do
  if ((SECONDS > deadline)); then
    echo "the daemons' endpoints are not both up:" >&2
    query 'up{job="modalwatch"}' >&2
    exit 1
  fi
  sleep 0.5
done
echo "   both endpoints up"

echo "== simulate: the fault record (axis x) and the same beam without the drift (axis y)"
"$build/modalwatch" simulate --config config/flexible-beam-drift.yaml --out "$out/x.csv" --truth "$out/x-truth.csv"
"$build/modalwatch" simulate --config "$out/steady.yaml" --out "$out/y.csv" --truth "$out/y-truth.csv"

echo "== replay: both records at ${speed}x real time"
replay_started=$EPOCHREALTIME
"$build/modalwatch" replay --config "$out/x.yaml" --data "$out/x.csv" --speed "$speed" --batch 64 \
  --start-utime 0 >/dev/null &
replay_x=$!
"$build/modalwatch" replay --config "$out/y.yaml" --data "$out/y.csv" --speed "$speed" --batch 64 \
  --start-utime 0 >/dev/null &
replay_y=$!

flag_x='modalwatch_mode_flag{axis="x",mode="flex",quantity="wn"}'
flag_y='modalwatch_mode_flag{axis="y"} == 2'
raised=0
while ((SECONDS <= deadline)); do
  if [ -n "$(query "$flag_y")" ]; then
    echo "axis y flagged:" >&2
    query "$flag_y" >&2
    exit 1
  fi
  if [ "$(query "$flag_x" | awk '{print $NF}')" = 2 ]; then
    raised=1
    break
  fi
  sleep 1
done
if [ "$raised" != 1 ]; then
  echo "no raised flag for axis x flex wn within ${timeout_s} s; last values:" >&2
  query 'modalwatch_mode_flag{axis="x"}' >&2 || true
  query 'modalwatch_state' >&2 || true
  grep -E "FLAG|baseline|warm-up" "$out/x.log" >&2 || true
  exit 1
fi
echo "   Prometheus sees $flag_x = 2 (after $SECONDS s)"

# Axis y over the whole run: it processed samples and no flag rose (the
# counter of flag changes also sees a flag raised and cleared between scrapes).
wait "$replay_y"
replay_y=""
sleep 2  # two scrapes after the replay's end
processed_y=$(query 'modalwatch_samples_processed_total{axis="y"}' | awk '{print $NF}')
ever_y=$(query 'max(max_over_time(modalwatch_mode_flag{axis="y"}[10m]))' | awk '{print $NF}')
changes_y=$(query 'modalwatch_flag_changes_total{axis="y"}' | awk '{print $NF}')
echo "   axis y: $processed_y samples processed, $changes_y flag changes, highest flag state $ever_y (1: pending)"
if [ -z "$processed_y" ] || [ "$processed_y" = 0 ] || [ "$changes_y" != 0 ] || [ "$ever_y" = 2 ]; then
  echo "axis y did not run clean" >&2
  exit 1
fi

if [ -n "${PLOT:-}" ]; then
  echo "== plot: axis x's replay to its end, then $PLOT"
  wait "$replay_x" || true
  replay_x=""
  sleep 2  # two scrapes after the replay's end
  # The fault's span in record time, from the config's header.
  scripts/plot/plot_prometheus.py --url "http://127.0.0.1:$port_prom" --start "$replay_started" --speed "$speed" \
    --fault 30:32 --mode flex --quantity wn --out "$PLOT"
fi

echo "== stop"
kill "$replay_x" 2>/dev/null || true
wait "$replay_x" 2>/dev/null || true
replay_x=""
for axis in x y; do
  pid_var="pid_$axis"
  MW_DAEMON_PID=${!pid_var}
  mw_stop_daemon
  printf -v "pid_$axis" '%s' ""
  if [ "$MW_DAEMON_RC" != 0 ]; then
    echo "modalwatchd (axis $axis) exited with $MW_DAEMON_RC:" >&2
    tail -20 "$out/$axis.log" >&2
    exit 1
  fi
done
echo "== passed"
