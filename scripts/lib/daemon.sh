# shellcheck shell=bash disable=SC2034
# Shell helpers shared by the scripts that build modalwatch and run modalwatchd
# (demo, fault injection, soak, daemon benchmark, lcm-spy). Source it; it
# defines functions and MW_ROOT (the repository root) and changes nothing else.
#
#   mw_ensure_build DIR [FILE...]     build DIR with scripts/setup.sh unless it
#                                     has modalwatch, modalwatchd and every FILE
#   mw_build DIR "TARGET..." [CMAKE_ARG...]
#                                     configure DIR and build the targets
#   mw_config SRC OUT [--no-drift] [SECTION.KEY=VALUE...]
#                                     a copy of a config with keys set
#   mw_start_daemon CONFIG LOG [REGEX]
#                                     start modalwatchd in the background
#   mw_wait_ready LOG [TIMEOUT_S]     wait for its start-up line
#   mw_stop_daemon                    SIGTERM, wait, exit code in MW_DAEMON_RC
#   mw_wait_for FILE REGEX TIMEOUT_S  wait for a line in a file
#
# Variables: MW_BUILD (the build the daemon comes from; set by mw_ensure_build
# and mw_build), MW_DAEMON_BIN (another modalwatchd binary, e.g. for an A/B
# comparison), MW_DAEMON_PID (the running daemon), MW_DAEMON_RC.
# Functions return non-zero on failure and never exit, so they work under
# `set -e` and without it.

MW_ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
MW_BUILD=${MW_BUILD:-build}
MW_DAEMON_PID=""
MW_DAEMON_RC=""

mw_ensure_build() {
  local dir=$1 f missing=0
  shift
  MW_BUILD=$dir
  for f in modalwatch modalwatchd "$@"; do
    [ -x "$dir/$f" ] || missing=1
  done
  [ "$missing" -eq 0 ] && return 0
  echo "== build: $dir (scripts/setup.sh)"
  BUILD_DIR="$dir" "$MW_ROOT/scripts/setup.sh" || return 1
  for f in modalwatch modalwatchd "$@"; do
    if [ ! -x "$dir/$f" ]; then
      echo "no $dir/$f after the build (benchmark targets need -DMODALWATCH_BENCHMARKS=ON)" >&2
      return 1
    fi
  done
}

# Output in DIR/build-script.log, printed when a step fails; JOBS (2) parallel jobs.
mw_build() {
  local dir=$1 targets=$2 t
  shift 2
  local args=()
  for t in $targets; do args+=(--target "$t"); done
  MW_BUILD=$dir
  mkdir -p "$dir"
  if ! { cmake -S "$MW_ROOT" -B "$dir" "$@" && cmake --build "$dir" -j"${JOBS:-2}" "${args[@]}"; } \
      >"$dir/build-script.log" 2>&1; then
    cat "$dir/build-script.log" >&2
    return 1
  fi
}

# SECTION.KEY=VALUE replaces KEY under the top-level SECTION, or adds it right
# after the section's line (a missing section is appended). --no-drift removes
# every `trajectory:` block, so the simulated plant does not change.
mw_config() {
  local src=$1 out=$2 nodrift=0 sets="" a
  shift 2
  for a in "$@"; do
    case $a in
      --no-drift) nodrift=1 ;;
      *.*=*) sets+="$a"$'\n' ;;
      *) echo "mw_config: not SECTION.KEY=VALUE: $a" >&2; return 1 ;;
    esac
  done
  awk -v sets="$sets" -v nodrift="$nodrift" '
    function section(line) { return substr(line, 1, index(line, ":") - 1) }
    function key(line) { sub(/^  /, "", line); return substr(line, 1, index(line, ":") - 1) }
    BEGIN {
      n = split(sets, list, "\n")
      for (i = 1; i <= n; i++) {
        if (list[i] == "") continue
        eq = index(list[i], "="); name = substr(list[i], 1, eq - 1); dot = index(name, ".")
        s = substr(name, 1, dot - 1); k = substr(name, dot + 1)
        value[s, k] = substr(list[i], eq + 1); keys[s] = keys[s] " " k
      }
    }
    NR == FNR {  # first pass: which keys and sections exist
      if ($0 ~ /^[A-Za-z_][A-Za-z0-9_]*:/) { cur = section($0); has_section[cur] = 1 }
      else if ($0 ~ /^  [A-Za-z_][A-Za-z0-9_]*:/) has[cur, key($0)] = 1
      next
    }
    FNR == 1 { cur = "" }
    skip != "" {  # inside a trajectory block: its lines are indented deeper
      if ($0 ~ /^ *(#.*)?$/) { print; next }
      match($0, /^ */)
      if (RLENGTH > length(skip)) next
      skip = ""
    }
    nodrift && $0 ~ /^ +trajectory:/ { match($0, /^ */); skip = substr($0, 1, RLENGTH); next }
    $0 ~ /^[A-Za-z_][A-Za-z0-9_]*:/ {
      cur = section($0); print
      m = split(keys[cur], ks, " ")
      for (j = 1; j <= m; j++) if (!has[cur, ks[j]]) print "  " ks[j] ": " value[cur, ks[j]]
      next
    }
    $0 ~ /^  [A-Za-z_][A-Za-z0-9_]*:/ && (cur, key($0)) in value { print "  " key($0) ": " value[cur, key($0)]; next }
    { print }
    END {
      for (s in keys) if (!has_section[s]) {
        print s ":"
        m = split(keys[s], ks, " ")
        for (j = 1; j <= m; j++) print "  " ks[j] ": " value[s, ks[j]]
      }
    }' "$src" "$src" >"$out" || return 1
  if [ "$nodrift" = 1 ] && grep -q 'trajectory:' "$out"; then
    echo "mw_config: could not remove the drift from $src" >&2
    return 1
  fi
}

# stderr goes to LOG; with REGEX, the lines matching it are also shown on stderr.
mw_start_daemon() {
  local config=$1 log=$2 show=${3:-} bin=${MW_DAEMON_BIN:-$MW_BUILD/modalwatchd}
  if [ -n "$show" ]; then
    "$bin" --config "$config" \
      2> >(tee "$log" | grep --line-buffered -E "$show" | sed -u 's/^/   [daemon] /' >&2) &
  else
    "$bin" --config "$config" 2>"$log" &
  fi
  MW_DAEMON_PID=$!
}

# The start-up line ("modalwatchd: <config> (fresh start|resumed ...)") comes
# just before the threads start and READY=1; the short sleep lets the LCM
# subscription open before anything is sent. Returns 1 and prints the log if
# the daemon exits first.
mw_wait_ready() {
  local log=$1 timeout=${2:-10}
  if ! mw_wait_for "$log" "modalwatchd: .*(fresh start|resumed from checkpoint)" "$timeout" "$MW_DAEMON_PID"; then
    echo "modalwatchd did not start:" >&2
    cat "$log" >&2
    return 1
  fi
  sleep 0.2
}

# SIGTERM (drain, final checkpoint), then the exit code in MW_DAEMON_RC.
mw_stop_daemon() {
  [ -n "$MW_DAEMON_PID" ] || return 0
  kill -TERM "$MW_DAEMON_PID" 2>/dev/null || true
  MW_DAEMON_RC=0
  wait "$MW_DAEMON_PID" || MW_DAEMON_RC=$?
  MW_DAEMON_PID=""
}

# For an EXIT trap: kills a daemon still running.
mw_kill_daemon() {
  if [ -n "$MW_DAEMON_PID" ]; then kill -9 "$MW_DAEMON_PID" 2>/dev/null || true; fi
  MW_DAEMON_PID=""
}

# Polls until FILE has a line matching REGEX (grep -E); 1 on timeout, or as soon
# as the process PID (optional) is gone.
mw_wait_for() {
  local file=$1 regex=$2 timeout=$3 pid=${4:-} deadline
  deadline=$(awk -v t="$EPOCHREALTIME" -v d="$timeout" 'BEGIN { printf "%.3f", t + d }')
  until grep -qE -- "$regex" "$file" 2>/dev/null; do
    if [ -n "$pid" ] && ! kill -0 "$pid" 2>/dev/null; then
      grep -qE -- "$regex" "$file" 2>/dev/null
      return
    fi
    awk -v t="$EPOCHREALTIME" -v d="$deadline" 'BEGIN { exit !(t > d) }' && return 1
    sleep 0.05
  done
}
