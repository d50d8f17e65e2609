#!/usr/bin/env bash
# The RTIC firmware boots under QEMU (mps2-an386, Cortex-M4F) with a simulated stage:
# >= 10 000 control periods, serial commands answered, and the instructions per control step
# of every feedback law x feedforward (QEMU -icount shift=0: 1 instruction = 1 ns).
# Also the README's command for the instruction table.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
cargo build --release --target thumbv7em-none-eabihf -p piezo-core --bin firmware \
  --no-default-features --features board-qemu
elf=target/thumbv7em-none-eabihf/release/firmware
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cp "$elf" "$work/firmware-qemu.elf"
mkfifo "$work/uart.in" "$work/uart.out"
cat "$work/uart.out" >"$work/uart.txt" &
reader=$!
set +e
timeout 120 qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
  -icount shift=0 -chardev pipe,id=ser,path="$work/uart" -serial chardev:ser \
  -semihosting-config enable=on,target=native \
  -kernel "$work/firmware-qemu.elf" >"$work/defmt.bin" &
qemu=$!
printf 'ping\nbench\nget u_max\nset slew 0\nmode open-loop\nstats\n' >"$work/uart.in"
wait $qemu
status=$?
set -e
wait $reader || true
echo "--- serial port"
cat "$work/uart.txt"
if command -v defmt-print >/dev/null 2>&1; then
  echo "--- defmt (semihosting)"
  defmt-print -e "$work/firmware-qemu.elf" <"$work/defmt.bin" || true
else
  echo "--- defmt log not decoded (defmt-print not installed): $(wc -c <"$work/defmt.bin") bytes"
fi
echo "---"
[ "$status" -eq 0 ] || { echo "QEMU run failed with status $status"; exit 1; }
grep -q '^ok pong$' "$work/uart.txt" || { echo "no answer to ping"; exit 1; }
grep -q '^err 8 value out of range$' "$work/uart.txt" || { echo "bad set not rejected"; exit 1; }
periods=$(sed -n 's/^done periods \([0-9]*\) .*/\1/p' "$work/uart.txt")
[ -n "$periods" ] && [ "$periods" -ge 10000 ] || { echo "too few control periods: '$periods'"; exit 1; }
echo "QEMU: $periods control periods, commands answered"
