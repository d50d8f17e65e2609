#!/usr/bin/env bash
# The XY scanner: the 2-axis firmware (`--features xy`, `Pipeline<f32, 2>`) boots on QEMU
# mps2-an386 with two simulated stages, each behind its own AD4020/AD5791 pair of mock
# chips, its UART on a TCP socket. `piezo serial` closes both loops (ff+hgo-robust with
# IMS), runs a raster and a Lissajous scan, reads both axes from the recorder and checks
# the tracking; a raster with 0 lines must be refused with err 8. Before the boot, the
# command executor of the xy build runs on the host (scan references, axis selection,
# modes and limits on both axes) and its pipeline type is compared with hal-sim's 2-axis
# one; the Q16.16 (Cortex-M3) xy firmware must build too.
# PIEZO_SERIAL_OUT=<dir> keeps the CSVs and SVGs there.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
cargo test -q -p piezo-core --features xy --test same_pipeline_executor --test same_pipeline
cargo build --release --target thumbv7m-none-eabi -p piezo-core --bin firmware \
  --no-default-features --features board-qemu,xy
target=thumbv7em-none-eabihf
cargo build --release --target "$target" -p piezo-core --bin firmware \
  --no-default-features --features board-qemu,xy
if [ -n "${PIEZO_BIN:-}" ]; then
  piezo=$PIEZO_BIN
else
  cargo build -q -p hal-sim --bin piezo
  piezo=target/debug/piezo
fi
work=$(mktemp -d)
cp "target/$target/release/firmware" "$work/firmware-xy.elf"
# The control interrupt runs the pipeline (its feedforward stage names it, see
# 20-firmware.sh) and both converter drivers.
python3 .ci/firmware-code.py "$work/firmware-xy.elf" SysTick \
  "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}|piezo_core::feedforward::MultiFeedforward::compensate|piezo_core::feedforward::MultiFeedforward::compensate::{{closure}}" \
  "piezo_core::drivers::ad4000::Ad4000::read|piezo_core::drivers::ad4000::decode" \
  piezo_core::drivers::ad5791::Ad5791::set_code
port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')

qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none -icount shift=0 \
  -chardev socket,id=ser,host=127.0.0.1,port="$port",server=on,wait=off -serial chardev:ser \
  -semihosting-config enable=on,target=native -kernel "$work/firmware-xy.elf" >"$work/defmt.bin" &
qemu=$!
cleanup() {
  kill "$qemu" 2>/dev/null || true
  wait "$qemu" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
fail() {
  echo "36-qemu-xy: FAIL: $*"
  exit 1
}

s() { timeout 60 "$piezo" serial --tcp "127.0.0.1:$port" --timeout-s 10 "$@"; }
for _ in $(seq 50); do
  if s ping >"$work/ping.txt" 2>&1; then break; fi
  sleep 0.2
done
cat "$work/ping.txt"
grep -q '^ok pong' "$work/ping.txt" || fail "no answer to ping"

run() {
  echo "\$ piezo serial $*"
  s "$@" | tee "$work/last.txt"
}
run axis
grep -qx 'ok axis 0 of 2' "$work/last.txt" || fail "not a 2-axis build"
run mode ff+hgo-robust --ff ims-cbw
grep -qx 'ok mode ff+hgo-robust' "$work/last.txt" || fail "mode not selected"
run limits --u-max 140V --slew 20V/ms
grep -qx 'output 0 V .. 140 V, slew limit 20000 V/s (20 V/ms)' "$work/last.txt" || fail "limits not set"

# check <csv> <frame_s> <x_lo> <x_hi> <y_lo> <y_hi> <rms_bound_um>: 1024 frames of
# frame_s, references covering the scan's rectangle and inside it, positions in the sensor
# range, both axes' RMS error below the bound.
check() {
  awk -F, -v dt="$2" -v xl="$3" -v xh="$4" -v yl="$5" -v yh="$6" -v bound="$7" '
    /^#/ || NR == 3 { next }
    {
      n++
      if ($1 != n - 1) { print "row " n ": index " $1; bad = 1 }
      if (n > 1 && ($2 - t - dt) ^ 2 > 1e-18) { print "row " n ": time step " $2 - t; bad = 1 }
      t = $2
      if ($3 < xl - 1e-3 || $3 > xh + 1e-3) { print "row " n ": ref_um " $3 " outside the scan"; bad = 1 }
      if ($5 < yl - 1e-3 || $5 > yh + 1e-3) { print "row " n ": ref1_um " $5 " outside the scan"; bad = 1 }
      if ($4 < -10 || $4 > 110 || $6 < -10 || $6 > 110) { print "row " n ": position outside the sensor"; bad = 1 }
      ex += ($3 - $4) ^ 2; ey += ($5 - $6) ^ 2
      if (n == 1 || $3 < x0) x0 = $3; if (n == 1 || $3 > x1) x1 = $3
      if (n == 1 || $5 < y0) y0 = $5; if (n == 1 || $5 > y1) y1 = $5
    }
    END {
      rx = sqrt(ex / n); ry = sqrt(ey / n)
      printf "%s: %d rows, ref x %.3f..%.3f y %.3f..%.3f um, RMS error x %.4f um, y %.4f um (bound %s)\n", FILENAME, n, x0, x1, y0, y1, rx, ry, bound
      if (n != 1024) { print "expected 1024 rows"; bad = 1 }
      if (!(rx < bound && ry < bound)) { print "tracking error above the bound"; bad = 1 }
      # The capture spans the whole scan (within 2 % of each side).
      if (x0 > xl + 0.02 * (xh - xl) || x1 < xh - 0.02 * (xh - xl) || y0 > yl + 0.02 * (yh - yl) || y1 < yh - 0.02 * (yh - yl)) {
        print "the reference does not cover the scan"; bad = 1
      }
      exit bad
    }' "$1"
}

# The simulated stage moves 0.16 um/V (less the CBW hysteresis): about 20 um at 140 V, so
# the scans stay within 4..16 um, and slow enough for the 20 V/ms slew limit (3.2 um/ms;
# the IMS inverse asks for more near the turning points): a 100 Hz line rate or a 6 um
# 100 Hz sine is slew-limited (measured 1.2 and 2.0 um RMS).
# Bound: 0.1 um RMS on each axis, 1 % of the 10 um scan. Measured in this script (QEMU,
# ff+hgo-robust + ims-cbw): raster x 0.026-0.028 / y 0.0015 um, Lissajous x 0.048 / y 0.025 um;
# open loop on the same Lissajous and a 20 Hz raster: 1.1 to 1.5 um on each axis.
bound=${XY_RMS_BOUND_UM:-0.1}

# Raster: 10 x 10 um around (10, 10), 4 lines at 20 Hz (x at 0.4 um/ms; at 40 Hz the
# triangle's corners give 0.077 um); one y sweep takes 200 ms, up and down 400 ms: every
# 50th period recorded, the 1024 frames span 512 ms, both turning points of y whenever
# the capture starts.
run wave raster 10um 10um 4 20Hz --center 10um,10um
grep -qx 'ok wave raster 10 10 4 20 10 10' "$work/last.txt" || fail "raster not started"
run record --xy --every 50 --out "$work/raster.csv" --svg "$work/raster.svg"
grep -q 'x-y path' "$work/raster.svg" || fail "no x-y panel in the SVG"
check "$work/raster.csv" 5e-4 5 15 5 15 "$bound" || fail "raster capture"

# Lissajous: 6 and 5 um at 40 and 30 Hz, y 90 deg ahead, around (10, 10); the figure
# repeats every 100 ms: every 10th period, 102.4 ms.
run wave lissajous 6um 5um 40Hz 30Hz --center 10um,10um
grep -qx 'ok wave lissajous 6 5 40 30 90 10 10' "$work/last.txt" || fail "Lissajous not started"
run record --xy --every 10 --out "$work/lissajous.csv" --svg "$work/lissajous.svg"
check "$work/lissajous.csv" 1e-4 4 16 5 15 "$bound" || fail "Lissajous capture"

# The 1-axis waves go to the selected axis.
run -- "axis 1" "wave sine 2 100 20" "axis 0"
grep -qx 'ok axis 1 of 2' "$work/last.txt" || fail "axis 1 not selected"

# A bad raster: refused with the firmware's numbered error, the scan keeps running.
echo "\$ piezo serial -- \"wave raster 10 10 0 100\""
if s -- "wave raster 10 10 0 100" >"$work/bad.txt" 2>&1; then fail "raster with 0 lines accepted"; fi
cat "$work/bad.txt"
grep -q '`wave raster 10 10 0 100`: firmware error 8: value out of range' "$work/bad.txt" ||
  fail "bad raster not refused with err 8"
run -- fault
grep -qx 'ok fault none sensor 0 nonfinite 0 dac 0' "$work/last.txt" || fail "fault state not clean"

kill -0 "$qemu" 2>/dev/null || fail "the firmware exited during the session"
if [ -n "${PIEZO_SERIAL_OUT:-}" ]; then
  mkdir -p "$PIEZO_SERIAL_OUT"
  cp "$work"/{raster,lissajous}.{csv,svg} "$PIEZO_SERIAL_OUT/"
  echo "wrote $PIEZO_SERIAL_OUT/{raster,lissajous}.{csv,svg}"
fi
echo "36-qemu-xy: ok"
