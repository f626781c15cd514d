#!/usr/bin/env bash
# Checks systemd/modalwatch@.service offline, without a running systemd:
#   - systemd-analyze security --offline=true rates it <= 2.0 (MAX_EXPOSURE);
#   - systemd-analyze verify reports nothing but the missing binary
#     (/usr/local/bin/modalwatchd exists only once installed).
# Exit 0 pass, 1 fail, 77 skipped (no systemd-analyze); ctest runs it as
# systemd_unit. Prints the exposure score.
set -euo pipefail
cd "$(dirname "$0")/.."
unit=systemd/modalwatch@.service
max="${MAX_EXPOSURE:-2.0}"

if ! command -v systemd-analyze >/dev/null; then
  echo "SKIP: systemd-analyze not installed (Debian: systemd)"
  exit 77
fi

security=$(systemd-analyze security --offline=true "$unit" 2>&1) || {
  echo "$security"
  echo "FAIL: systemd-analyze security failed"
  exit 1
}
score=$(sed -n 's/.*Overall exposure level for [^:]*: \([0-9.]*\).*/\1/p' <<<"$security")
if [ -z "$score" ]; then
  echo "$security"
  echo "FAIL: no exposure level in the output"
  exit 1
fi
echo "exposure level: $score (limit $max)"
if ! awk -v s="$score" -v m="$max" 'BEGIN { exit !(s <= m) }'; then
  grep '✗' <<<"$security" || true
  echo "FAIL: exposure $score > $max"
  exit 1
fi

# verify needs an instance name: a copy as modalwatch@check.service.
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cp "$unit" "$tmp/modalwatch@check.service"
verify=$(systemd-analyze verify "$tmp/modalwatch@check.service" 2>&1 || true)
rest=$(grep -v 'Command /usr/local/bin/modalwatchd is not executable' <<<"$verify" | sed '/^$/d' || true)
if [ -n "$rest" ]; then
  echo "$rest"
  echo "FAIL: systemd-analyze verify reports problems"
  exit 1
fi
echo "verify: clean apart from the binary path"
echo "PASS"
