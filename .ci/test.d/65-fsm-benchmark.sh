#!/usr/bin/env bash
# Fine-steering-mirror benchmark, reduced: one linear state-space model (order 28, few
# iterations) for all three levels from realizations r1-r2, scored with the benchmark's rule
# (simulate from rest, RMSE over the second period, mean over outputs) on the held-back r5
# of every level. Asserts each level below a bound measured with margin (README,
# "Fine-steering-mirror benchmark"). The dev-profile CLI (.ci/host-piezo.sh); a few minutes
# on a 2-core machine.
set -euo pipefail
D=../shared/data/fsm-benchmark
if [ ! -d "$D" ]; then
    echo "skipped: $D not found"
    exit 0
fi
# PIEZO=path skips the build (to try the script with another build of the binary).
if [ -z "${PIEZO:-}" ]; then
    . .ci/host-piezo.sh
fi
P=${PIEZO:-$piezo}
OUT=$(mktemp -d)
trap 'rm -rf "$OUT"' EXIT
T=()
for l in 100 200 300; do for r in 1 2; do T+=(--train "$D/fsm_${l}mV_r$r.csv"); done; done
$P fit --model ss --order 28 --lm-iterations 10 "${T[@]}" --out "$OUT" --quiet
fail=0
for l in 100:0.50 200:0.50 300:0.78; do
    level=${l%%:*}
    bound=${l##*:}
    $P predict --model "$OUT/fit.json" --input "$D/fsm_${level}mV_r5.csv" --out "$OUT/y.csv" | tee "$OUT/score.txt"
    mean=$(sed -n 's/.*mean \([0-9.e+-]*\),.*/\1/p' "$OUT/score.txt")
    if awk -v m="$mean" -v b="$bound" 'BEGIN { exit !(m < b) }'; then
        echo "fsm ${level} mV: RMSE $mean um < $bound um: ok"
    else
        echo "fsm ${level} mV: RMSE $mean um, bound $bound um: FAILED"
        fail=1
    fi
done
# A predict of every kind of fit.json: the file written above, run on an inputs-only record.
cut -d, -f1-4 "$D/fsm_100mV_r5.csv" > "$OUT/u.csv"
$P predict --model "$OUT/fit.json" --input "$OUT/u.csv" --out "$OUT/y_only.csv"
head -c 300 "$OUT/y_only.csv" | grep -q '^t,y1,y2,y3' || { echo "predict: no t,y1..y3 header"; fail=1; }
exit $fail
