#!/usr/bin/env bash
# From `piezo fit` to the firmware: the QEMU build (mps2-an386, f32) boots with its UART on
# TCP; `piezo serial load-fit` sends the CBW of a fit.json (the shape `piezo fit --model cbw
# --out <dir>` writes), `piezo serial params` must read it back, ff+hgo-robust with IMS must
# run on it, and a model the core refuses (d below the largest hysteresis slope: IMS cannot invert it)
# must fail with the file named and the firmware's error, leaving the model as it was.
set -euo pipefail
cd "$(dirname "$0")/../.."
. .ci/qemu-serial.sh
qemu_session 37-load-fit

# fit <file> <d> <alpha> <beta> <gamma/beta>: a one-part CBW report as `piezo fit` writes it.
fit() {
  cat >"$1" <<JSON
{"model": "cbw", "train": "rec.csv", "valid": null, "linear_step": null,
 "parts": [{"kind": "siso", "input": 0, "output": 0,
   "fit": {"model": "cbw", "params": [["d", $2], ["alpha", $3], ["beta", $4], ["gamma/beta", $5]],
           "sign": 1.0, "offset": 0.0, "upsample": 1, "linear": []}}],
 "train_metrics": [], "valid_metrics": [], "valid_from_rest_metrics": [], "seconds": 0.1}
JSON
}
fit "$work/fit.json" 0.21 0.06 0.005 0.4
fit "$work/refused.json" 0.05 0.07 0.02 0.5

echo "\$ piezo serial load-fit fit.json"
s load-fit "$work/fit.json" | tee "$work/load.txt"
grep -qx 'ok cbw 0.21 0.06 0.005 0.002' "$work/load.txt" || fail "model not installed"
echo "\$ piezo serial params"
s params | tee "$work/params.txt"
for kv in 'cbw_d 0.21' 'cbw_alpha 0.06' 'cbw_beta 0.005' 'cbw_gamma 0.002' 'hgo_eps 0.0002' 'pid_kp 0.5'; do
  set -- $kv
  awk -v k="$1" -v v="$2" '$1 == k && ($2 - v) ^ 2 < 1e-14 { ok = 1 } END { exit !ok }' \
    "$work/params.txt" || fail "params: $1 is not $2"
done
s mode ff+hgo-robust --ff ims-cbw | tee "$work/mode.txt"
grep -qx 'ok mode ff+hgo-robust' "$work/mode.txt" || fail "mode on the loaded model"
s --keep-going -- "set lambda1 1500" "set hgo_eps 0" >"$work/gains.txt" 2>&1 || true
cat "$work/gains.txt"
grep -qx 'ok lambda1 1500' "$work/gains.txt" || fail "gain not set"
grep -qx 'err 8 value out of range' "$work/gains.txt" || fail "eps 0 not refused"

echo "\$ piezo serial load-fit refused.json"
if s load-fit "$work/refused.json" >"$work/refused.txt" 2>&1; then fail "refused model accepted"; fi
cat "$work/refused.txt"
grep -q "refused.json: the firmware refused the CBW model of parts\[0\]: .*error 8" "$work/refused.txt" ||
  fail "refusal does not name the file and the firmware error"
# Here-strings, not pipes: `grep -q` may stop reading before the writer is done (pipefail).
grep -qx 'ok cbw_d 0.21' <<< "$(s -- "get cbw_d")" || fail "a refused model changed the firmware"
grep -qx 'ok fault none sensor 0 nonfinite 0 dac 0' <<< "$(s -- "fault")" || fail "fault after the changes"
qemu_stop
echo "37-load-fit: ok"
