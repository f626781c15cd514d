#!/usr/bin/env bash
# Fuzzes the decoders of untrusted bytes with libFuzzer (+ASan+UBSan):
# decode_checkpoint (fuzz_checkpoint) and parse_lcm_log (fuzz_lcm_log).
#   scripts/fuzz.sh                 # 60 s each
#   FUZZ_SECONDS=600 scripts/fuzz.sh
# Builds in build-fuzz with clang++ (-DMODALWATCH_FUZZ=ON), seeds the corpora in
# build-fuzz/corpus/ from make_seeds (a real checkpoint, a log written by
# liblcm), then runs each target. A crash leaves crash-* in build-fuzz/ and
# fails the script.
set -euo pipefail
cd "$(dirname "$0")/.."
dir="${FUZZ_DIR:-build-fuzz}"
seconds="${FUZZ_SECONDS:-60}"
CXX=clang++ cmake -S . -B "$dir" -DMODALWATCH_FUZZ=ON -DMODALWATCH_BENCHMARKS=OFF -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
cmake --build "$dir" -j"${JOBS:-2}" --target fuzz_checkpoint fuzz_lcm_log make_seeds
"$dir/tests/fuzz/make_seeds" "$dir/corpus"
status=0
for target in checkpoint lcm_log; do
  echo "== fuzz_$target: ${seconds} s"
  rc=0
  (cd "$dir" && ASAN_OPTIONS=detect_leaks=1 "./tests/fuzz/fuzz_$target" -max_total_time="$seconds" -max_len=65536 \
      -print_final_stats=1 "corpus/$target") >"$dir/fuzz_$target.log" 2>&1 || rc=$?
  grep -E "^#[0-9]+[[:space:]]+DONE|stat::number_of_executed_units|ERROR|SUMMARY|crash-" "$dir/fuzz_$target.log" || true
  if [ "$rc" -ne 0 ]; then
    echo "fuzz_$target FAILED (exit $rc): see $dir/fuzz_$target.log"
    status=1
  fi
done
exit $status
