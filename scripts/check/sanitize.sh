#!/usr/bin/env bash
# Sanitizer runs: the test suite under ASan+UBSan, the threaded tests under
# TSan. Prints a summary; exits non-zero if any step fails.
#
#   scripts/check/sanitize.sh                 # both (the ASan build is the long part)
#   SKIP_ASAN=1 scripts/check/sanitize.sh     # TSan only
#   ASAN_TARGETS="test_messages test_csv" ASAN_TESTS="Messages|Csv" scripts/check/sanitize.sh
#                                             # ASan+UBSan on some suites only
#
# 1. ASan+UBSan: configures build-asan with -DMODALWATCH_SANITIZE=ON (benchmarks
#    off: they are not tests), builds everything (or ASAN_TARGETS), runs ctest
#    without the tests whose names match ASAN_EXCLUDE (MonteCarlo: long
#    statistical runs that exercise no code the other tests do not), and only
#    those matching ASAN_TESTS when it is set. With ASAN_TARGETS, the tests of
#    the targets not built (ctest's *_NOT_BUILT placeholders) are left out.
# 2. TSan: configures build-tsan with -fsanitize=thread passed through
#    CMAKE_CXX_FLAGS / CMAKE_EXE_LINKER_FLAGS (Debug with "-O1 -g1": line tables
#    are all a report needs, and assertions stay on), builds only TSAN_TARGETS and runs
#    the ctest tests matching TSAN_TESTS. Tests of targets not built show up in
#    ctest as *_NOT_BUILT and do not match the filter.
#
# Environment: JOBS (2), ASAN_DIR (build-asan), TSAN_DIR (build-tsan),
# ASAN_EXCLUDE (MonteCarlo), ASAN_TARGETS (all), ASAN_TESTS (all, a ctest -R regex),
# ASAN_CORE_UBSAN (1; 0 builds the numerical core under ASan alone, half its
# build time), TSAN_TARGETS ("test_spsc_ring test_doorbell", space separated),
# TSAN_TESTS (^(SpscRing|Doorbell), a ctest -R regex), SKIP_ASAN / SKIP_TSAN (1 to skip),
# MODALWATCH_STRESS_ITEMS (items per threaded stress test; the tests pick a
# smaller default under sanitizers), and ASAN_OPTIONS / UBSAN_OPTIONS /
# TSAN_OPTIONS to override the defaults below.
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1

JOBS=${JOBS:-2}
ASAN_DIR=${ASAN_DIR:-build-asan}
TSAN_DIR=${TSAN_DIR:-build-tsan}
ASAN_EXCLUDE=${ASAN_EXCLUDE:-MonteCarlo}
ASAN_TARGETS=${ASAN_TARGETS:-}
ASAN_TESTS=${ASAN_TESTS:-}
ASAN_CORE_UBSAN=${ASAN_CORE_UBSAN:-1}
TSAN_TARGETS=${TSAN_TARGETS:-test_spsc_ring test_doorbell}
TSAN_TESTS=${TSAN_TESTS:-^(SpscRing|Doorbell)}
SKIP_ASAN=${SKIP_ASAN:-0}
SKIP_TSAN=${SKIP_TSAN:-0}

# Every report is fatal, so ctest sees a failing test.
export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:halt_on_error=1:check_initialization_order=1}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}
# tests/tsan.supp: liblcm's GLib (futex) mutexes are invisible to TSan.
export TSAN_OPTIONS=${TSAN_OPTIONS:-halt_on_error=1:second_deadlock_stack=1:suppressions=$PWD/tests/tsan.supp}

# TSan needs a fixed memory layout; on kernels with large mmap randomisation
# (vm.mmap_rnd_bits > 28) it dies with "unexpected memory mapping" unless ASLR is
# off. Run the TSan build (gtest discovery runs the binaries) and tests under
# `setarch -R` when the sandbox allows it.
NO_ASLR=()
if setarch "$(uname -m)" -R true 2>/dev/null; then
  NO_ASLR=(setarch "$(uname -m)" -R)
fi

summary=()
failed=0

# step NAME LOG CMD...: runs CMD with its output in LOG (and on the terminal when
# LOG is "-"), records pass/fail and the time taken.
step() {
  local name=$1 log=$2
  shift 2
  local t0=$SECONDS rc
  echo "==> $name"
  if [ "$log" = "-" ]; then
    "$@"
    rc=$?
  else
    "$@" >"$log" 2>&1
    rc=$?
    if [ $rc -ne 0 ]; then
      echo "--- last 60 lines of $log ---"
      tail -n 60 "$log"
    fi
  fi
  local status=PASS
  if [ $rc -ne 0 ]; then
    status="FAIL (exit $rc)"
    failed=1
  fi
  summary+=("$(printf '%-38s %-14s %5ds' "$name" "$status" $((SECONDS - t0)))")
  return $rc
}

# ---- ASan + UBSan: the suite ---------------------------------------------------
if [ "$SKIP_ASAN" != 1 ]; then
  mkdir -p "$ASAN_DIR"
  if step "asan: configure" "$ASAN_DIR/sanitize-configure.log" \
      cmake -S . -B "$ASAN_DIR" -DMODALWATCH_SANITIZE=ON -DMODALWATCH_BENCHMARKS=OFF \
        -DMODALWATCH_SANITIZE_CORE_UNDEFINED="$([ "$ASAN_CORE_UBSAN" = 0 ] && echo OFF || echo ON)" &&
     step "asan: build ${ASAN_TARGETS:-all} (-j$JOBS)" "$ASAN_DIR/sanitize-build.log" \
      cmake --build "$ASAN_DIR" -j"$JOBS" $(for t in $ASAN_TARGETS; do printf -- '--target %s ' "$t"; done); then
    asan_filter=()
    [ -n "$ASAN_TESTS" ] && asan_filter=(-R "$ASAN_TESTS")
    # With some targets only, the suites of the others are placeholders.
    asan_exclude=$ASAN_EXCLUDE
    [ -n "$ASAN_TARGETS" ] && asan_exclude="$asan_exclude|_NOT_BUILT\$"
    step "asan: ctest -E '$asan_exclude' ${ASAN_TESTS:+-R '$ASAN_TESTS'}" - \
      ctest --test-dir "$ASAN_DIR" -j"$JOBS" -E "$asan_exclude" "${asan_filter[@]}" --output-on-failure --no-tests=error
  fi
fi

# ---- TSan: the threaded tests --------------------------------------------------
if [ "$SKIP_TSAN" != 1 ]; then
  mkdir -p "$TSAN_DIR"
  read -r -a tsan_targets <<<"$TSAN_TARGETS"
  target_args=()
  for t in "${tsan_targets[@]}"; do target_args+=(--target "$t"); done
  if step "tsan: configure" "$TSAN_DIR/sanitize-configure.log" \
      cmake -S . -B "$TSAN_DIR" -DCMAKE_BUILD_TYPE=Debug -DMODALWATCH_BENCHMARKS=OFF \
        "-DCMAKE_CXX_FLAGS=-fsanitize=thread" "-DCMAKE_CXX_FLAGS_DEBUG=-O1 -g1" \
        "-DCMAKE_EXE_LINKER_FLAGS=-fsanitize=thread" &&
     step "tsan: build $TSAN_TARGETS" "$TSAN_DIR/sanitize-build.log" \
      "${NO_ASLR[@]}" cmake --build "$TSAN_DIR" -j"$JOBS" "${target_args[@]}"; then
    # Guard against a silently uninstrumented build (flags lost in a cache edit).
    uninstrumented=()
    for t in "${tsan_targets[@]}"; do
      bin=$(find "$TSAN_DIR" -type f -name "$t" -perm -u+x | head -n 1)
      # Any __tsan_ hook (GCC references __tsan_read*/__tsan_func_entry, clang
      # also __tsan_init); grep without -q so nm never dies of SIGPIPE under pipefail.
      if [ -z "$bin" ] || ! nm "$bin" 2>/dev/null | grep '__tsan_' >/dev/null; then
        uninstrumented+=("$t")
      fi
    done
    step "tsan: targets instrumented" - \
      bash -c '[ $# -eq 0 ] || { echo "not instrumented with TSan: $*"; exit 1; }' _ "${uninstrumented[@]}"
    step "tsan: ctest -R '$TSAN_TESTS'" - \
      "${NO_ASLR[@]}" ctest --test-dir "$TSAN_DIR" -j"$JOBS" -R "$TSAN_TESTS" --output-on-failure --no-tests=error
  fi
fi

echo
echo "==== sanitize.sh summary ===="
if [ ${#summary[@]} -eq 0 ]; then
  echo "(nothing run)"
else
  printf '%s\n' "${summary[@]}"
fi
if [ $failed -ne 0 ]; then
  echo "RESULT: FAIL"
  exit 1
fi
echo "RESULT: PASS"
