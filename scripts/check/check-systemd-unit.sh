#!/usr/bin/env bash
# Checks the unit a build installs (systemd/modalwatch@.service.in with its
# paths filled in by CMake) offline, without a running systemd, as shipped and
# with the opt-in drop-in systemd/realtime.conf:
#   scripts/check/check-systemd-unit.sh [UNIT]   # default build/systemd/modalwatch@.service
#   - systemd-analyze security --offline=true rates it <= 2.0 (MAX_EXPOSURE);
#   - systemd-analyze verify reports nothing but the missing binary
#     (<prefix>/bin/modalwatchd exists only once installed);
#   - with the drop-in, the unit allows realtime scheduling and the
#     @resources calls (sched_setscheduler) that the shipped unit denies.
# Exit 0 pass, 1 fail, 77 skipped (no systemd-analyze); ctest runs it as
# systemd_unit. Prints the exposure score.
set -euo pipefail
unit="$(realpath "${1:-$(dirname "$0")/../../build/systemd/modalwatch@.service}")"
cd "$(dirname "$0")/../.."
max="${MAX_EXPOSURE:-2.0}"

if ! command -v systemd-analyze >/dev/null; then
  echo "SKIP: systemd-analyze not installed (Debian: systemd)"
  exit 77
fi

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT

# check LABEL UNIT: the score and verify; leaves the security report in $security.
check() {
  local label=$1 file=$2
  security=$(systemd-analyze security --offline=true "$file" 2>&1) || {
    echo "$security"
    echo "FAIL: systemd-analyze security failed ($label)"
    exit 1
  }
  local score
  score=$(sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p' <<<"$security")
  if [ -z "$score" ]; then
    echo "$security"
    echo "FAIL: no exposure level in the output ($label)"
    exit 1
  fi
  echo "$label: exposure level $score (limit $max)"
  if ! awk -v s="$score" -v m="$max" 'BEGIN { exit !(s <= m) }'; then
    grep '✗' <<<"$security" || true
    echo "FAIL: exposure $score > $max ($label)"
    exit 1
  fi
  local verify rest
  verify=$(systemd-analyze verify "$file" 2>&1 || true)
  rest=$(grep -v 'Command /.*/modalwatchd is not executable' <<<"$verify" | sed '/^$/d' || true)
  if [ -n "$rest" ]; then
    echo "$rest"
    echo "FAIL: systemd-analyze verify reports problems ($label)"
    exit 1
  fi
  echo "$label: verify clean apart from the binary path"
}

# verify needs an instance name: copies as modalwatch@check.service, the second
# with the drop-in beside it (the unit's directory is on the load path).
mkdir "$tmp/plain" "$tmp/realtime" "$tmp/realtime/modalwatch@check.service.d"
cp "$unit" "$tmp/plain/modalwatch@check.service"
cp "$unit" "$tmp/realtime/modalwatch@check.service"
cp systemd/realtime.conf "$tmp/realtime/modalwatch@check.service.d/"

check "shipped unit" "$tmp/plain/modalwatch@check.service"
grep -q '✓ RestrictRealtime=' <<<"$security" || { echo "FAIL: the shipped unit allows realtime scheduling"; exit 1; }
check "with realtime.conf" "$tmp/realtime/modalwatch@check.service"
if ! grep -q '✗ RestrictRealtime=' <<<"$security" || ! grep -q '@resources is included' <<<"$security"; then
  grep 'RestrictRealtime\|@resources' <<<"$security" || true
  echo "FAIL: realtime.conf does not allow SCHED_FIFO (RestrictRealtime, @resources)"
  exit 1
fi
echo "PASS"
