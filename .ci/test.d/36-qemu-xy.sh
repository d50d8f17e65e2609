#!/usr/bin/env bash
# The XY scanner: the 2-axis firmware (`--features xy`, `Pipeline<_, 2>`) boots on QEMU
# with two simulated stages, each behind its own AD4020/AD5791 pair of mock chips, its UART
# on a TCP socket, twice: mps2-an386 (Cortex-M4F, f32, 100 kHz) and mps2-an385 (Cortex-M3,
# Q16.16, 16 384 Hz). `piezo serial` closes both loops (ff+hgo-robust with IMS), runs a
# raster and a Lissajous scan, reads both axes from the recorder (divided: whole scans)
# and checks the tracking; a raster with 0 lines must be refused with err 8. Before the
# boots, the command executor of the xy build runs on the host (scan references, axis
# selection, modes and limits on both axes) and its pipeline type is compared with
# hal-sim's 2-axis one.
# PIEZO_SERIAL_OUT=<dir> keeps the CSVs and SVGs there.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
cargo test -q -p piezo-core --features xy --test same_pipeline_executor --test same_pipeline
for target in thumbv7m-none-eabi thumbv7em-none-eabihf; do
  cargo build --release --target "$target" -p piezo-core --bin qemu \
    --features xy
done
. .ci/qemu-serial.sh
piezo_cli
work=$(mktemp -d)
trap qemu_cleanup EXIT
fail() {
  echo "36-qemu-xy: FAIL ($name): $*"
  exit 1
}

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
# Bounds: f32 (M4F, 100 kHz) 0.1 um RMS on each axis, 1 % of the 10 um scan; Q16.16 (M3,
# 16 384 Hz, 15-bit codes) 0.25 um. Measured in this script (ff+hgo-robust + ims-cbw):
# f32 raster x 0.026-0.028 / y 0.0015 um, Lissajous x 0.048 / y 0.025 um; Q16.16 raster
# x 0.048 / y 0.0046 um, Lissajous x 0.114 / y 0.071 um. Open loop on the same Lissajous
# and a 20 Hz raster: 1.1 to 1.5 um on each axis (f32).
#
# session <name> <target> <machine> <cpu> <frame_s raster> <every raster> <frame_s
# Lissajous> <every Lissajous> <bound um>: boots the xy firmware and runs the scans.
session() {
  name=$1
  local target=$2 machine=$3 cpu=$4 dt_r=$5 every_r=$6 dt_l=$7 every_l=$8 bound=$9
  local elf="$work/$name.elf"
  cp "target/$target/release/qemu" "$elf"
  # The control interrupt runs the pipeline and both drivers.
  python3 .ci/firmware-code.py "$elf" SysTick \
    "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}" \
    "piezo_core::drivers::ad4000::Ad4000::read|piezo_core::drivers::ad4000::Ad4000::convert|piezo_core::drivers::ad4000::decode" \
    piezo_core::drivers::ad5791::Ad5791::set_code
  qemu_boot "$elf" "$machine" "$cpu"
  run() {
    echo "\$ piezo serial $*"
    s "$@" | tee "$work/last.txt"
  }

  run axis
  grep -qx 'ok axis 0 of 2' "$work/last.txt" || fail "not a 2-axis build"
  # The two-axis worst-case table (the H743 xy build's mode budget) must bound every f32
  # measurement of this board's boot-time bench (issue 27 item 4), as 30-qemu checks the
  # one-axis table.
  if [ "$name" = m4f-f32-xy ]; then
    run bench >/dev/null
    grep '^budget' "$work/last.txt"
    grep -q '^budget table: 0 of .* above WORST_M4F_XY' "$work/last.txt" ||
      fail "WORST_M4F_XY understates a measured two-axis worst case"
  fi
  run mode ff+hgo-robust --ff ims-cbw
  grep -qx 'ok mode ff+hgo-robust' "$work/last.txt" || fail "mode not selected"
  run limits --u-max 140V --slew 20V/ms
  grep -qx 'output 0 V .. 140 V, slew limit 20000 V/s (20 V/ms)' "$work/last.txt" || fail "limits not set"

  # Raster: 10 x 10 um around (10, 10), 4 lines at 20 Hz (x at 0.4 um/ms; at 40 Hz the
  # triangle's corners give 0.077 um); one y sweep takes 200 ms, up and down 400 ms: the
  # divided capture spans about 500 ms, both turning points of y whenever it starts.
  run wave raster 10um 10um 4 20Hz --center 10um,10um
  grep -qx 'ok wave raster 10 10 4 20 10 10' "$work/last.txt" || fail "raster not started"
  # The captures check the tracking, not the scan's start: 20 000 periods of the firmware's
  # time first (a reply takes under 1 ms, so nothing else lets the loop settle).
  settle 20000
  run record --xy --every "$every_r" --out "$work/$name-raster.csv" --svg "$work/$name-raster.svg"
  grep -q 'x-y path' "$work/$name-raster.svg" || fail "no x-y panel in the SVG"
  check "$work/$name-raster.csv" "$dt_r" 5 15 5 15 "$bound" || fail "raster capture"

  # Lissajous: 6 and 5 um at 40 and 30 Hz, y 90 deg ahead, around (10, 10); the figure
  # repeats every 100 ms, the divided capture spans at least that.
  run wave lissajous 6um 5um 40Hz 30Hz --center 10um,10um
  grep -qx 'ok wave lissajous 6 5 40 30 90 10 10' "$work/last.txt" || fail "Lissajous not started"
  settle 20000
  run record --xy --every "$every_l" --out "$work/$name-lissajous.csv" --svg "$work/$name-lissajous.svg"
  check "$work/$name-lissajous.csv" "$dt_l" 4 16 5 15 "$bound" || fail "Lissajous capture"

  # The 1-axis waves go to the selected axis.
  run -- "axis 1" "wave sine 2 20 10" "axis 0"
  grep -qx 'ok axis 1 of 2' "$work/last.txt" || fail "axis 1 not selected"

  # A bad raster: refused with the firmware's numbered error, nothing latched.
  refused "wave raster 10 10 0 20" "firmware error 8: value out of range"
  run -- fault
  grep -qx 'ok fault none sensor 0 nonfinite 0 dac 0' "$work/last.txt" || fail "fault state not clean"

  qemu_stop
  if [ -n "${PIEZO_SERIAL_OUT:-}" ]; then
    mkdir -p "$PIEZO_SERIAL_OUT"
    cp "$work/$name"-{raster,lissajous}.{csv,svg} "$PIEZO_SERIAL_OUT/"
    echo "wrote $PIEZO_SERIAL_OUT/$name-{raster,lissajous}.{csv,svg}"
  fi
  echo "=== $name: ok"
}

# f32 at 100 kHz: every 50th / 10th period; Q16.16 at 16 384 Hz: every 8th / 2nd.
session m4f-f32-xy thumbv7em-none-eabihf mps2-an386 cortex-m4 5e-4 50 1e-4 10 "${XY_RMS_BOUND_UM:-0.1}"
session m3-q16-xy thumbv7m-none-eabi mps2-an385 cortex-m3 0.00048828125 8 0.0001220703125 2 "${XY_Q16_RMS_BOUND_UM:-0.25}"
echo "36-qemu-xy: ok"
