#!/usr/bin/env bash
# Full Monte Carlo study of the offline additive SRIVC on the seed's system at its
# noise level (variance 0.01), open and closed loop: prints mean, empirical and
# mean reported standard deviation of every frequency, damping and gain.
#   scripts/study/monte_carlo.sh [RUNS]     (default 100; the test suite runs 20)   BUILD_DIR=build
set -euo pipefail
cd "$(dirname "$0")/../.."
source scripts/lib/daemon.sh
mw_ensure_build "${BUILD_DIR:-build}" tests/test_srivc
MODALWATCH_MC_RUNS="${1:-100}" "$MW_BUILD/tests/test_srivc" --gtest_filter='*MonteCarlo*'
