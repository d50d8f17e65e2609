#!/usr/bin/env bash
# Nothing stalls the control loop (issue 15 item 3): on QEMU mps2-an386 (M4F, f32, 100 kHz)
# the command interrupt runs at the H743's USART3 priority with its locking; a flood of
# every command (law rebuilds, `rec read`, bench, selftest; .ci/qemu-flood.py) during
# closed-loop control must give 0 overruns and a bounded control-interrupt delay. The
# firmware prints `flood: <n> commands, max control delay <k> instructions, overruns <m>`.
# No wall-clock wait: QEMU exits on the harness line `exit` after the flood (the 1800 s
# cap only catches a hung emulator). About 1 min on a quiet 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
# Bound on the control interrupt's delay (instructions, SysTick resolution 40): the lock
# holds copies only (a law and compensator hand-over, a recorder frame, the timing); the
# bumpless restart runs in the control task's next period. Measured 880 to 1 080 in 18 of
# 19 floods (one lock per compensator or law copy), once 1 560 (not traced to a command).
# The bound is the mode budgets' BLOCKING_M4F (src/firmware/budget.rs, which every mode's
# allowance subtracts) plus 600 for that outlier: a lock that grows past it fails here.
blocking=$(sed -nE 's/^pub const BLOCKING_M4F: u32 = ([0-9_]+);.*/\1/p' src/firmware/budget.rs | tr -d _)
[ -n "$blocking" ] || { echo "flood: BLOCKING_M4F not found in src/firmware/budget.rs"; exit 1; }
DELAY_MAX=${DELAY_MAX:-$((blocking + 600))}
# Bound on the longest control interrupt during the flood (instructions): 3480 to 3600 in
# six floods (2026-11-30); a configuration check in f64 (software arithmetic on the M4F)
# re-run whenever the pipeline re-decided its fused path made it 4840 to 4880.
ISR_MAX=${ISR_MAX:-4200}
ROUNDS=${ROUNDS:-5}
work=$(mktemp -d)
[ -n "${KEEP:-}" ] || trap 'rm -rf "$work"' EXIT; echo "work: $work"
target=thumbv7em-none-eabihf
cargo build --release --target "$target" -p piezo-core --bin qemu
cp "target/$target/release/qemu" "$work/firmware.elf"
mkfifo "$work/uart.in" "$work/uart.out"
cat "$work/uart.out" >"$work/uart.txt" &
reader=$!
python3 .ci/qemu-flood.py "$ROUNDS" >"$work/flood.txt"
set +e
timeout 1800 qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
  -icount shift=0,sleep=off -chardev pipe,id=ser,path="$work/uart" -serial chardev:ser \
  -semihosting-config enable=on,target=native -kernel "$work/firmware.elf" >/dev/null &
qemu=$!
cat "$work/flood.txt" >"$work/uart.in"
wait $qemu
status=$?
set -e
wait $reader || true
grep -E '^(flood|done|chips|err)' "$work/uart.txt" | sort | uniq -c | sort -rn | head -20
[ "$status" -eq 0 ] || { echo "flood: QEMU run failed with status $status"; tail -5 "$work/uart.txt"; exit 1; }
sent=$(sed -n '/^flood start$/,/^flood stop$/p' "$work/flood.txt" | grep -cvE '^flood (start|stop)$')
line=$(grep -E '^flood: [0-9]+ commands, max control delay [0-9]+ instructions, overruns [0-9]+' "$work/uart.txt") ||
  { echo "flood: no flood line"; exit 1; }
echo "$line"
read -r n k m <<<"$(sed -E 's/^flood: ([0-9]+) commands, max control delay ([0-9]+) instructions, overruns ([0-9]+).*/\1 \2 \3/' <<<"$line")"
[ "$n" -eq "$sent" ] || { echo "flood: $n of $sent commands answered"; exit 1; }
[ "$m" -eq 0 ] || { echo "flood: $m overruns"; exit 1; }
[ "$k" -le "$DELAY_MAX" ] || { echo "flood: control delay $k instructions > $DELAY_MAX"; exit 1; }
isr=$(sed -nE 's/.*max control interrupt ([0-9]+) instructions.*/\1/p' <<<"$line")
[ -n "$isr" ] || { echo "flood: no max control interrupt in the flood line"; exit 1; }
[ "$isr" -le "$ISR_MAX" ] || { echo "flood: control interrupt $isr instructions > $ISR_MAX"; exit 1; }
grep -q '^chips: 0 data-sheet rule violations' "$work/uart.txt" || { echo "flood: a chip rule broken"; exit 1; }
streamed=$(grep -c '^ok rec read 64$' "$work/uart.txt" || true)
[ "$streamed" -eq $((2 * ROUNDS)) ] || { echo "flood: $streamed of $((2 * ROUNDS)) rec reads streamed 64 frames"; exit 1; }
echo "flood: all $n commands answered, 0 overruns, max delay $k <= $DELAY_MAX, max interrupt $isr <= $ISR_MAX instructions"
