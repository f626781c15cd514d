#!/usr/bin/env bash
# Installs the Debian packages modalwatch needs, then configures and builds it in
# build/. Idempotent; run as root on a fresh Debian bookworm machine.
#   scripts/setup.sh            # packages + Release-with-debug-info build
#   BUILD_DIR=build-asan CMAKE_ARGS=-DMODALWATCH_SANITIZE=ON scripts/setup.sh
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake pkg-config
  libeigen3-dev libyaml-cpp-dev libspdlog-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  liblcm-dev liblcm-bin libglib2.0-dev libsystemd-dev
  python3 python3-numpy python3-matplotlib
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${missing[*]}"
  SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# LCM's udpm (the daemon's default URL, ttl=0) needs a route for multicast. A
# machine with a default route has one; a sandbox without a network does not:
# send multicast over loopback there (DESIGN.md).
if ! ip route get 239.255.76.67 >/dev/null 2>&1; then
  if [ "$(id -u)" -eq 0 ]; then
    echo "setup: no multicast route; routing 224.0.0.0/4 over lo"
    ip link set lo up
    ip link set lo multicast on
    ip route add 224.0.0.0/4 dev lo
  else
    echo "setup: no multicast route; as root run: ip link set lo multicast on; ip route add 224.0.0.0/4 dev lo" >&2
  fi
fi

build_dir="${BUILD_DIR:-build}"
jobs="${JOBS:-$(nproc)}"
# shellcheck disable=SC2086
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-RelWithDebInfo}" ${CMAKE_ARGS:-}
cmake --build "$build_dir" -j"$jobs"
echo "setup: built in $build_dir"
