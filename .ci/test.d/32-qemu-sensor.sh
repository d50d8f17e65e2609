#!/usr/bin/env bash
# A position channel that fails mid-stroke reaches the safe state within a bounded number of
# samples, on the QEMU board (M4F f32 at 100 kHz and M3 Q16.16 at 16 384 Hz): in closed loop
# (ff+hgo-robust on IMS-CBW, a sine mid-stroke) the harness line `sensor <fault>` injects each
# fault of the mock AD4020 (src/bin/qemu/chips.rs) and `sensor report` prints the samples from
# the first faulty conversion to the period that turned the amplifier off:
#   stuck-low, stuck-high (SDO held): the status bits, 1 sample;
#   floating (the code frozen): the stuck-code detector, at most `stuck` (100) samples;
#   disconnected (97 % of full scale, no over-voltage): the guard band, 1 sample.
# Each fault is cleared (`sensor none`, `fault clear`) and the loop must run clean before the
# next. No wall-clock wait: `wait <n>` runs in virtual time. About 1 min on a quiet machine.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# run <name> <target> <machine> <cpu>
run() {
  local name=$1 target=$2 machine=$3 cpu=$4 dir="$work/$1" reader qemu status lines f bound n
  cargo build -q --release --target "$target" -p piezo-core --bin qemu
  mkdir -p "$dir"
  cp "target/$target/release/qemu" "$dir/firmware.elf"
  mkfifo "$dir/uart.in" "$dir/uart.out"
  cat "$dir/uart.out" >"$dir/uart.txt" &
  reader=$!
  lines='ff ims-cbw\nmode ff+hgo-robust\nwave sine 8 100 12\nwait 3000\nfault\n'
  for f in stuck-low stuck-high floating disconnected; do
    lines+="sensor $f\nwait 300\nsensor report\nfault\nsensor none\nfault clear\nwait 3000\nfault\n"
  done
  lines+='exit\n'
  timeout 1800 qemu-system-arm -M "$machine" -cpu "$cpu" -nographic -monitor none \
    -icount shift=0,sleep=off -chardev pipe,id=ser,path="$dir/uart" -serial chardev:ser \
    -semihosting-config enable=on,target=native -kernel "$dir/firmware.elf" >/dev/null &
  qemu=$!
  # shellcheck disable=SC2059 # the lines are a printf format (\n escapes)
  printf "$lines" >"$dir/uart.in"
  status=0
  wait $qemu || status=$?
  wait $reader || true
  echo "=== $name: serial port"
  grep -E '^(ok (sensor|fault|mode)|sensor:|err|done|chips)' "$dir/uart.txt" || true
  [ "$status" -eq 0 ] || { echo "$name: QEMU run failed with status $status"; exit 1; }
  # Healthy before the first fault and after each one is cleared: 5 clean `fault` answers
  # (the counters count the faulty samples, so only the state is checked).
  [ "$(grep -c '^ok fault none sensor' "$dir/uart.txt")" -ge 5 ] ||
    { echo "$name: a fault while healthy (false alarm)"; exit 1; }
  mapfile -t reports < <(grep '^sensor: ' "$dir/uart.txt")
  [ "${#reports[@]}" -eq 4 ] || { echo "$name: expected 4 sensor reports"; exit 1; }
  local i=0
  for f in stuck-low:1 stuck-high:1 floating:100 disconnected:1; do
    bound=${f#*:}
    n=$(sed -n 's/^sensor: safe after \([0-9]*\) samples$/\1/p' <<<"${reports[$i]}")
    [ -n "$n" ] && [ "$n" -le "$bound" ] ||
      { echo "$name: ${f%%:*}: '${reports[$i]}', bound $bound samples"; exit 1; }
    echo "$name: ${f%%:*}: safe after $n samples (bound $bound)"
    i=$((i + 1))
  done
  grep -q '^ok fault sensor-stuck ' "$dir/uart.txt" || { echo "$name: floating not seen as sensor-stuck"; exit 1; }
  grep -q '^chips: 0 data-sheet rule violations' "$dir/uart.txt" || { echo "$name: a chip rule broken"; exit 1; }
}

run m4f-f32 thumbv7em-none-eabihf mps2-an386 cortex-m4
run m3-q16 thumbv7m-none-eabi mps2-an385 cortex-m3
