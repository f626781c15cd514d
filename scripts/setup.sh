#!/usr/bin/env bash
# Installs the Debian packages modalwatch needs, then configures and builds it in
# build/. Idempotent; run as root on a fresh Debian bookworm machine.
#   scripts/setup.sh            # packages + Release-with-debug-info build
#   BUILD_DIR=build-asan CMAKE_ARGS=-DMODALWATCH_SANITIZE=ON scripts/setup.sh
#   NO_JAVA=1 scripts/setup.sh  # without the Java packages (only lcm-spy needs them)
set -euo pipefail
cd "$(dirname "$0")/.."

packages=(
  build-essential cmake pkg-config
  libeigen3-dev libyaml-cpp-dev libspdlog-dev libcli11-dev
  libgtest-dev libgmock-dev libbenchmark-dev
  liblcm-dev liblcm-bin libglib2.0-dev libsystemd-dev
  prometheus-cpp-dev  # the daemon's metrics endpoint
  prometheus          # the server and promtool, for scripts/check/prometheus.sh
  python3 python3-numpy python3-scipy python3-matplotlib  # scipy: the scenario bank
  help2man pandoc  # the man pages (built only when both are found)
)
# Only for scripts/lcm-spy.sh (the types jar and lcm-spy itself): optional.
if [ "${NO_JAVA:-0}" != 1 ]; then
  packages+=(default-jdk-headless liblcm-java libjchart2d-java)
fi

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

# LCM's udpm:// (tests, demo, replay) on a machine without a multicast route,
# e.g. a container: let the loopback carry multicast (the LCM docs' recipe).
# Only as root, only when no route covers 224.0.0.0/4 yet; idempotent.
if [ "$(id -u)" -eq 0 ] && command -v ip >/dev/null; then
  if ! ip route get 239.255.76.67 >/dev/null 2>&1; then
    ip link set lo up
    ip link set lo multicast on
    ip route add 224.0.0.0/4 dev lo
    echo "setup: multicast routed over lo (224.0.0.0/4)"
  fi
fi

build_dir="${BUILD_DIR:-build}"
jobs="${JOBS:-$(nproc)}"
# shellcheck disable=SC2086
cmake -S . -B "$build_dir" -DCMAKE_BUILD_TYPE="${BUILD_TYPE:-RelWithDebInfo}" ${CMAKE_ARGS:-}
cmake --build "$build_dir" -j"$jobs"
echo "setup: built in $build_dir"
