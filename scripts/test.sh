#!/usr/bin/env bash
# Sets up (packages, build) and runs the test suite: the README's test command.
set -euo pipefail
cd "$(dirname "$0")/.."
CMAKE_ARGS="${CMAKE_ARGS:-} -DMODALWATCH_WERROR=ON" scripts/setup.sh
cd "${BUILD_DIR:-build}"
ctest --output-on-failure -j"${JOBS:-$(nproc)}"
