#!/usr/bin/env bash
# Runs every libFuzzer harness in tests/fuzz for a given time and reports the
# executions and findings of each; exits non-zero when there is a finding.
#
#   scripts/check/fuzz.sh                 # 60 s per harness
#   scripts/check/fuzz.sh 600             # 10 min per harness
#   FUZZERS="fuzz_config" scripts/check/fuzz.sh 30
#   RUNS=10000000 scripts/check/fuzz.sh 86400   # until 10 M executions each (or the time)
#   NICE=19 scripts/check/fuzz.sh 600     # on a shared machine
#
# Harnesses: fuzz_messages (LCM sample/batch decode), fuzz_config (YAML loader),
# fuzz_csv (CSV reader), fuzz_lcm_log (lcm-logger files), fuzz_checkpoint
# (checkpoint loader). Builds build-fuzz with clang++ and -DMODALWATCH_FUZZ=ON
# (libraries instrumented for coverage, ASan and UBSan; the checkpoint CRC check
# is compiled out so mutations reach the decoder). Seeds: a checkpoint and an
# LCM log from make_seeds, the shipped configs, a small CSV, and whatever
# earlier runs left in build-fuzz/corpus/<harness>. A crash leaves its
# input in build-fuzz/findings/<harness>/; turn each into a regression test
# (tests/fuzz/regressions/<harness>/, replayed by the normal test suite).
#
# Input size: -max_len 2048 for the YAML config and 1024 for the CSV reader
# (MAX_LEN_<harness> overrides; libFuzzer's default is 4096): their cost grows
# with the input. The shipped configs are seeded as they are (truncated: the
# comments) and without comments (1.5 KiB at most, so complete); measured over
# 6,000 runs from the same corpus, 2048 reaches the coverage of 4096 (1700 vs
# 1719 edges), 1024 does not (1617). ASan keeps no allocation stacks while
# fuzzing (malloc_context_size=0: recording them took ~9 % of the YAML harness's
# time); replay a finding under the normal ASan build for the full report.
set -uo pipefail
cd "$(dirname "$0")/../.." || exit 1

SECONDS_EACH=${1:-60}
DIR=${FUZZ_DIR:-build-fuzz}
JOBS=${JOBS:-2}
ALL="fuzz_messages fuzz_config fuzz_csv fuzz_lcm_log fuzz_checkpoint"
FUZZERS=${FUZZERS:-$ALL}

command -v clang++ >/dev/null || { echo "fuzz.sh: clang++ not found (apt-get install clang libclang-rt-14-dev)"; exit 1; }

targets=()
for f in $FUZZERS; do [ -f "tests/fuzz/$f.cpp" ] && targets+=("$f"); done
[ ${#targets[@]} -gt 0 ] || { echo "fuzz.sh: no harness among: $FUZZERS"; exit 1; }

mkdir -p "$DIR"
CXX=clang++ cmake -S . -B "$DIR" -DCMAKE_BUILD_TYPE=RelWithDebInfo -DMODALWATCH_FUZZ=ON \
  -DMODALWATCH_BENCHMARKS=OFF >"$DIR/configure.log" 2>&1 || { tail -30 "$DIR/configure.log"; exit 1; }
build_args=(--target make_seeds)
for t in "${targets[@]}"; do build_args+=(--target "$t"); done
cmake --build "$DIR" -j"$JOBS" "${build_args[@]}" >"$DIR/build.log" 2>&1 || { tail -40 "$DIR/build.log"; exit 1; }

# Seeds: a real checkpoint, an LCM log written by liblcm and one packet of each
# input type (make_seeds), the shipped configs, a small CSV.
mkdir -p "$DIR/corpus/fuzz_config" "$DIR/corpus/fuzz_csv" "$DIR/corpus/fuzz_checkpoint" "$DIR/corpus/fuzz_lcm_log" \
  "$DIR/corpus/fuzz_messages"
"$DIR/tests/fuzz/make_seeds" "$DIR/seeds" >/dev/null || { echo "fuzz.sh: make_seeds failed"; exit 1; }
cp "$DIR"/seeds/checkpoint/* "$DIR/corpus/fuzz_checkpoint/" 2>/dev/null
cp "$DIR"/seeds/lcm_log/* "$DIR/corpus/fuzz_lcm_log/" 2>/dev/null
cp "$DIR"/seeds/messages/* "$DIR/corpus/fuzz_messages/" 2>/dev/null
cp config/*.yaml "$DIR/corpus/fuzz_config/" 2>/dev/null
for f in config/*.yaml; do
  sed -e 's/[[:space:]]#.*$//' -e '/^[[:space:]]*#/d' -e '/^[[:space:]]*$/d' "$f" \
    >"$DIR/corpus/fuzz_config/$(basename "$f" .yaml)-no-comments.yaml"
done
printf 't,u,y,r\n0,1,2,3\n0.05,1.5,nan,0\n0.1,-1,2e-3,inf\n' >"$DIR/corpus/fuzz_csv/seed.csv"

export ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1:halt_on_error=1:malloc_context_size=0}
export UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1}

summary=()
total_findings=0
for t in "${targets[@]}"; do
  corpus="$DIR/corpus/$t"
  findings="$DIR/findings/$t"
  mkdir -p "$corpus" "$findings"
  log="$DIR/$t.log"
  echo "==> $t for ${SECONDS_EACH}s"
  # -fork keeps fuzzing past a finding, so one run reports all of them.
  max_len_var="MAX_LEN_$t"
  case $t in
    fuzz_config) max_len=${!max_len_var:-2048} ;;
    fuzz_csv) max_len=${!max_len_var:-1024} ;;
    *) max_len=${!max_len_var:-0} ;;  # 0: libFuzzer's default
  esac
  runs=()
  [ -n "${RUNS:-}" ] && runs=(-runs="$RUNS")
  t0=$SECONDS
  stamp="$DIR/.started-$t"
  touch "$stamp"
  nice -n "${NICE:-0}" "$DIR/tests/fuzz/$t" "$corpus" -max_total_time="$SECONDS_EACH" "${runs[@]}" \
    -max_len="$max_len" -print_final_stats=1 \
    -artifact_prefix="$findings/" -fork=1 -ignore_crashes=1 -ignore_ooms=1 -ignore_timeouts=1 \
    -rss_limit_mb=2048 -timeout=10 >"$log" 2>&1
  elapsed=$((SECONDS - t0))
  # -fork prints "#<executions>: cov: ..." progress lines; the last one is the total.
  execs=$(grep -oE '^#[0-9]+' "$log" | tail -n 1 | tr -d '#')
  # slow-unit-* is libFuzzer's note of an input that took > 10 s of wall time:
  # at nice 19 on a busy machine that is the scheduler (one such input, replayed,
  # ran in 60 ms with the process start), so it is listed, not counted as a
  # finding; crash-, leak-, oom- and timeout- files are.
  # This run's findings; those of earlier runs stay in the folder and are listed.
  found=$(find "$findings" -type f ! -name 'slow-unit-*' -newer "$stamp" | wc -l)
  earlier=$(find "$findings" -type f ! -name 'slow-unit-*' ! -newer "$stamp" | wc -l)
  [ "$earlier" -gt 0 ] && echo "$t: $earlier finding(s) of earlier runs in $findings (keep them in tests/fuzz/regressions/$t/)"
  slow=$(find "$findings" -type f -name 'slow-unit-*' -newer "$stamp" | wc -l)
  [ "$slow" -gt 0 ] && echo "$t: $slow slow-unit input(s) in $findings (replay them to check)"
  total_findings=$((total_findings + found))
  cov=$(grep -oE 'cov: [0-9]+' "$log" | tail -n 1)
  rate=$(( ${execs:-0} / (elapsed > 0 ? elapsed : 1) ))
  summary+=("$(printf '%-16s %12s execs %6ds %8s/s  %3d findings  %s' "$t" "${execs:-?}" "$elapsed" "$rate" "$found" "$cov")")
done

echo
echo "==== fuzz.sh summary (${SECONDS_EACH}s each) ===="
printf '%s\n' "${summary[@]}"
[ $total_findings -eq 0 ] && echo "RESULT: no findings" || { echo "RESULT: $total_findings findings (see $DIR/findings)"; exit 1; }
