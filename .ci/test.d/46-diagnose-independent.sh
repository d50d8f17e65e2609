#!/usr/bin/env bash
# piezo diagnose on stages it was not tuned to: 12 fixed cases (150-161) of the independent
# generator's 300-case table of seed 1 (hal-sim/src/independent.rs). Floors from the
# measurement of these cases with the lag rule (7 of 12 named exactly, 11 of 14 hidden causes
# named; before it 2 and 10) minus a margin: at least 5 exact and 9 of 14 named. They catch
# regressions; the goal (every case exact) is above them. See docs/src/diagnose-independent.md.
set -euo pipefail
cd "$(dirname "$0")/../.."
. .ci/host-piezo.sh
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cases=()
for i in $(seq 150 161); do cases+=(--case "$i"); done
"$piezo" diagnose-bench --cases 300 --seed 1 "${cases[@]}" --jobs 2 --out "$out" \
  --min-exact 0.4 --min-recall 0.6
