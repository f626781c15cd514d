#!/usr/bin/env bash
# Full Monte Carlo study of the offline additive SRIVC on the seed's system at its
# noise level (variance 0.01), open and closed loop: prints mean, empirical and
# mean reported standard deviation of every frequency, damping and gain.
#   scripts/monte_carlo.sh [RUNS]     (default 100; CI runs 20 inside the tests)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x build/tests/test_srivc ] || scripts/setup.sh
MODALWATCH_MC_RUNS="${1:-100}" build/tests/test_srivc --gtest_filter='*MonteCarlo*'
