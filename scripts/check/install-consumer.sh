#!/usr/bin/env bash
# Installs a build into a temporary prefix and uses it as another project would:
#   - tests/consumer configured with CMAKE_PREFIX_PATH=<prefix> (find_package,
#     modalwatch::core), built and run (it fits a known two-mode plant);
#   - the same main.cpp compiled with `pkg-config --cflags --libs modalwatch`
#     from <prefix>'s pkgconfig directory, and run.
#   scripts/check/install-consumer.sh BUILD_DIR [CXX]
# Exit 0 pass, 1 fail; ctest runs it as install_consumer. Nothing outside the
# temporary directory is written.
set -euo pipefail
here="$(cd "$(dirname "$0")/../.." && pwd)"
build="$(cd "${1:?usage: install-consumer.sh BUILD_DIR [CXX]}" && pwd)"
cxx="${2:-c++}"
launcher=()
command -v ccache >/dev/null && launcher=(-DCMAKE_CXX_COMPILER_LAUNCHER=ccache)

tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
prefix="$tmp/prefix"

echo "== cmake --install $build --prefix <tmp>/prefix"
cmake --install "$build" --prefix "$prefix" >"$tmp/install.log" || { cat "$tmp/install.log"; exit 1; }
echo "installed $(grep -c '^-- Installing' "$tmp/install.log") files"

echo "== find_package(modalwatch): tests/consumer"
cmake -S "$here/tests/consumer" -B "$tmp/build" -DCMAKE_BUILD_TYPE=Release -DCMAKE_CXX_COMPILER="$cxx" \
  "${launcher[@]}" -DCMAKE_PREFIX_PATH="$prefix" >"$tmp/configure.log" || { cat "$tmp/configure.log"; exit 1; }
cmake --build "$tmp/build" -j2 >"$tmp/build.log" || { cat "$tmp/build.log"; exit 1; }
"$tmp/build/modalwatch_consumer"

echo "== pkg-config modalwatch"
pcdir=$(dirname "$(find "$prefix" -name modalwatch.pc -print -quit)")
flags=$(PKG_CONFIG_PATH="$pcdir" pkg-config --cflags --libs modalwatch)
echo "pkg-config --cflags --libs modalwatch: $flags"
# shellcheck disable=SC2086
${launcher:+ccache} "$cxx" -std=c++20 -O2 "$here/tests/consumer/main.cpp" -o "$tmp/consumer_pc" $flags
"$tmp/consumer_pc"
echo "PASS"
