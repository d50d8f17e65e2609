#!/usr/bin/env bash
# FEEDBACK done-when: every registered controller on the robustness scenarios (1/10/50 Hz,
# 37 % force disturbance, +-20 % model error, 10x sensor noise) keeps the applied voltage
# inside the pipeline range (0..150 V) with no non-finite command, and the HGO robust law
# tracks the 10 Hz sine (60 um stroke) to RMSE <= 0.05 % of the stroke (issue #5's target).
set -euo pipefail
cargo build --release -q -p hal-sim --bin piezo
out=$(target/release/piezo sim --json --amplitude-um 30 \
  --scenario sine-1hz --scenario sine-10hz --scenario sine-50hz --scenario force-37pct \
  --scenario sine-10hz-model+20pct --scenario sine-10hz-model-20pct --scenario sine-10hz-noise10x)
runs=$(echo "$out" | grep -o '{[^{}]*}')
n=$(echo "$runs" | wc -l)
[ "$n" -ge 7 ] || { echo "expected runs, got: $out"; exit 1; }
field() { echo "$1" | sed -E "s/.*\"$2\":\"?([^,\"}]*).*/\1/"; }
hgo_ok=0
while read -r run; do
  sc=$(field "$run" scenario); c=$(field "$run" controller)
  lo=$(field "$run" volts_min); hi=$(field "$run" volts_max); nf=$(field "$run" nonfinite_commands)
  [ -n "$lo" ] && [ -n "$hi" ] && [ -n "$nf" ] || { echo "cannot parse: $run"; exit 1; }
  awk -v lo="$lo" -v hi="$hi" 'BEGIN { exit !(lo >= 0 && hi <= 150) }' \
    || { echo "$sc / $c: applied voltage $lo..$hi V outside 0..150 V"; exit 1; }
  [ "$nf" = 0 ] || { echo "$sc / $c: $nf non-finite commands"; exit 1; }
  if [ "$sc" = sine-10hz ] && [ "$c" = hgo-robust ]; then
    pct=$(field "$run" rmse_pct)
    awk -v p="$pct" 'BEGIN { exit !(p <= 0.05) }' \
      || { echo "hgo-robust on sine-10hz: RMSE $pct % of stroke > 0.05 %"; exit 1; }
    echo "hgo-robust sine-10hz RMSE $pct % of stroke"
    hgo_ok=1
  fi
done <<< "$runs"
[ "$hgo_ok" = 1 ] || { echo "no hgo-robust run on sine-10hz"; exit 1; }
echo "feedback sim: $n runs, all voltages inside 0..150 V"
