#!/usr/bin/env bash
# Builds the Debian package and checks it on this machine, as root: installs it,
# runs both programs' --version, verifies the installed systemd unit, finds the
# man pages, then purges it and checks that none of its files is left behind.
# It installs into the system, so it is not a ctest.
#   sudo scripts/check/package.sh             # build tree build-deb/ (prefix /usr, Release)
#   BUILD_DIR=/tmp/deb scripts/check/package.sh
# Needs dpkg-dev (dpkg-shlibdeps) besides the build dependencies; help2man and
# pandoc for the man pages (scripts/setup.sh installs them).
set -euo pipefail
here="$(cd "$(dirname "$0")/../.." && pwd)"
build="${BUILD_DIR:-$here/build-deb}"
jobs="${JOBS:-2}"
[ "$(id -u)" -eq 0 ] || { echo "package.sh: run as root (it installs the package)" >&2; exit 1; }

launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
# The installation alone: no tests, and cpack's install step does not build them.
echo "== build ($build, prefix /usr)"
log="$build/package.log"
mkdir -p "$build"
run() { "$@" >>"$log" 2>&1 || { tail -40 "$log"; echo "FAIL: $* (log: $log)"; exit 1; }; }
: >"$log"
run cmake -S "$here" -B "$build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_INSTALL_PREFIX=/usr \
  -DCMAKE_SKIP_INSTALL_ALL_DEPENDENCY=ON -DMODALWATCH_BENCHMARKS=OFF "${launcher[@]}"
run cmake --build "$build" -j"$jobs" --target modalwatch_installation
echo "== cpack"
rm -f "$build"/modalwatch_*.deb
(cd "$build" && run cpack -G DEB)
deb=$(ls "$build"/modalwatch_*.deb)
echo "package: $(basename "$deb")"
dpkg-deb --field "$deb" Package Version Architecture Depends Suggests

if dpkg-query -W -f='${Status}' modalwatch 2>/dev/null | grep -q installed; then
  echo "== removing the modalwatch package installed before"
  apt-get remove --purge -y -qq modalwatch >/dev/null
fi
echo "== apt-get install ./$(basename "$deb")"
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "$deb" >/dev/null
dpkg -L modalwatch | sort >"$build/files.txt"
echo "installed $(wc -l <"$build/files.txt") paths"

fail=0
check() {  # check LABEL COMMAND...: runs it, prints its output, counts a failure
  local label=$1; shift
  local out
  if out=$("$@" 2>&1); then
    echo "$label: ok${out:+: $out}"
  else
    echo "$label: FAIL: $out"
    fail=1
  fi
}
check "/usr/bin/modalwatchd --version" /usr/bin/modalwatchd --version
check "modalwatch --version" modalwatch --version
check "ExecStart is /usr/bin/modalwatchd" grep -x 'ExecStart=/usr/bin/modalwatchd --config /etc/modalwatch/%i.yaml' \
  /lib/systemd/system/modalwatch@.service
# verify needs an instance of the template: it is found on the unit load path.
check "systemd-analyze verify modalwatch@check.service" systemd-analyze verify modalwatch@check.service
check "man -w modalwatch" man -w modalwatch
check "man -w modalwatchd" man -w 8 modalwatchd
check "man -w modalwatch.yaml" man -w 5 modalwatch.yaml
check "conffile /etc/modalwatch/example.yaml" grep -q '^ /etc/modalwatch/example.yaml ' \
  <(dpkg-query -W -f='${Conffiles}\n' modalwatch)
check "no instance enabled or started" test -z "$(find /etc/systemd/system -name 'modalwatch@*' 2>/dev/null)"

echo "== apt-get remove --purge modalwatch"
apt-get remove --purge -y -qq modalwatch >/dev/null
# Left behind: any file of the package, and any directory of its own (named
# modalwatch*); shared directories (/usr/bin, man1, ...) stay.
left=()
while read -r path; do
  if [ -d "$path" ] && [ ! -L "$path" ]; then
    case "$(basename "$path")" in modalwatch*) left+=("$path") ;; esac
  elif [ -e "$path" ] || [ -L "$path" ]; then
    left+=("$path")
  fi
done <"$build/files.txt"
[ -e /var/lib/modalwatch ] && left+=(/var/lib/modalwatch)
if ((${#left[@]})); then
  printf 'left behind: %s\n' "${left[@]}"
  fail=1
else
  echo "purge: none of the $(wc -l <"$build/files.txt") paths left behind"
fi
if [ "$fail" -ne 0 ]; then
  echo "FAIL"
  exit 1
fi
echo "PASS"
