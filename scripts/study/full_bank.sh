#!/usr/bin/env bash
# The full scenario bank (scenario_bank.py --scale full: healthy records of 100
# memories) in parts, so that it fits on a disk: each part of PART records is
# generated, evaluated (scenario_eval.py --json --keep-errors --drop-est) and
# its records deleted; the tables of all parts together are printed at the end
# and written to OUT/tables.txt. A part already evaluated (OUT/part-<k>.json)
# is skipped, so an interrupted run goes on where it stopped.
#   scripts/study/full_bank.sh   OUT=/tmp/full-bank PARTS=40 PART=10 SEED=31 MODALWATCH=build/modalwatch JOBS=2
# Part k uses seed SEED + k (records <k>/0000...). FAULTS=1 runs only the
# bank's fault records (scenario_bank.py --skip-healthy), HEALTHY=1 only its
# healthy ones (--skip-faults). Needs numpy and scipy.
set -euo pipefail
cd "$(dirname "$0")/../.."
out="${OUT:-/tmp/full-bank}"
parts="${PARTS:-40}"
part="${PART:-10}"
seed="${SEED:-31}"
bin="$(realpath "${MODALWATCH:-build/modalwatch}")"
jobs="${JOBS:-2}"
skip=()
[[ "${FAULTS:-0}" == 1 ]] && skip=(--skip-healthy)
[[ "${HEALTHY:-0}" == 1 ]] && skip=(--skip-faults)
py=/usr/bin/python3
mkdir -p "$out"
for ((k = 0; k < parts; ++k)); do
  json="$out/part-$k.json"
  [[ -f "$json" ]] && continue
  dir="$out/part-$k"
  rm -rf "$dir"
  "$py" scripts/study/scenario_bank.py generate --out "$dir" --count "$part" --seed $((seed + k)) --scale full \
    "${skip[@]}" --modalwatch "$bin" >"$out/part-$k.log"
  "$py" scripts/study/scenario_eval.py "$dir" --modalwatch "$bin" --jobs "$jobs" --json "$json.tmp" --keep-errors \
    --drop-est >>"$out/part-$k.log"
  mv "$json.tmp" "$json"
  rm -rf "$dir"
  echo "part $((k + 1)) of $parts done ($(date +%T))"
done
"$py" scripts/study/scenario_eval.py --combine "$out"/part-*.json | tee "$out/tables.txt"
