#!/usr/bin/env bash
# The RTIC firmware boots under QEMU with a simulated stage, twice:
#   mps2-an386 (Cortex-M4F, thumbv7em-none-eabihf, f32) and
#   mps2-an385 (Cortex-M3, thumbv7m-none-eabi, Q16.16 fixed point);
# each runs >= 10 000 control periods (SysTick) through the core's Ad4000/Ad5791 drivers on
# mock chips backed by the stage, answers commands on its serial port and
# prints the instructions per control step of every feedback law x feedforward
# (QEMU -icount shift=0: 1 instruction = 1 ns of virtual time). This script is also the
# README's command for the instruction tables.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# The defmt decoder (its own small crate: the project's workspace does not build it).
cargo build -q --release --manifest-path .ci/defmt-log/Cargo.toml
defmt_log=.ci/defmt-log/target/release/defmt-log

# pipe_run <dir> <elf> <machine> <cpu> <defmt out> <lines>: QEMU with its UART on the FIFOs
# in <dir> (what it sends kept in <dir>/uart.txt), <lines> (a printf format) written to it; returns
# QEMU's exit status. The firmware ends the run itself (`exit`, `panic`): the wall-clock
# cap only catches a hung emulator and is generous for a busy machine.
pipe_run() {
  local dir=$1 elf=$2 machine=$3 cpu=$4 defmt=$5 lines=$6 reader qemu status
  mkfifo "$dir/uart.in" "$dir/uart.out"
  cat "$dir/uart.out" >"$dir/uart.txt" &
  reader=$!
  timeout 1800 qemu-system-arm -M "$machine" -cpu "$cpu" -nographic -monitor none \
    -icount shift=0,sleep=off -chardev pipe,id=ser,path="$dir/uart" -serial chardev:ser \
    -semihosting-config enable=on,target=native -kernel "$elf" >"$defmt" &
  qemu=$!
  # shellcheck disable=SC2059 # the lines are a printf format (\n escapes)
  printf "$lines" >"$dir/uart.in"
  status=0
  wait $qemu || status=$?
  wait $reader || true
  return $status
}

# run <name> <target> <qemu machine> <qemu cpu> <SysTick ticks per control period>
run() {
  local name=$1 target=$2 machine=$3 cpu=$4 period_ticks=$5 status periods
  cargo build --release --target "$target" -p piezo-core --bin qemu
  local dir="$work/$name" elf
  mkdir -p "$dir"
  elf="$dir/firmware.elf"
  cp "target/$target/release/qemu" "$elf"
  status=0
  pipe_run "$dir" "$elf" "$machine" "$cpu" "$dir/defmt.bin" \
    'ping\nbench\nget u_max\nset slew 0\nset pid_kp 0.75\nsave\nwait 1000\nset pid_kp 0.25\nload\nwait 1000\nget pid_kp\ndefaults\nget pid_kp\nmode nmpc\nmode ff+hgo-robust\nwave sine 5 100 10\nsave\nrec sel ref_um y_um u_volts error_um\nrec arm\nfault\nstats\nselftest\nwave prbs 9 11 10 5000\nwait 500\nwave chirp 1 10 2000 0.05 10\nwait 500\nwave multisine 1 100 32 10 3\nwait 500\nfault\nexit\n' ||
    status=$?
  echo "=== $name: serial port"
  cat "$dir/uart.txt"
  [ "$status" -eq 0 ] || { echo "$name: QEMU run failed with status $status"; exit 1; }
  # The defmt log (semihosting), decoded with the ELF's table (.ci/defmt-log, the
  # defmt-decoder crate); its timing lines must be sane: min <= last <= max, the step
  # within the interrupt, the interrupt within the period (SysTick ticks), no overrun.
  echo "=== $name: defmt log (semihosting, $(wc -c <"$dir/defmt.bin") bytes)"
  "$defmt_log" "$elf" "$dir/defmt.bin" --period "$period_ticks" ||
    { echo "$name: defmt log check failed"; exit 1; }
  grep -q '^ok pong$' "$dir/uart.txt" || { echo "$name: no answer to ping"; exit 1; }
  grep -q '^err 8 value out of range$' "$dir/uart.txt" || { echo "$name: bad set not rejected"; exit 1; }
  # Settings in the (RAM-backed) settings flash: save, load back, defaults; no save while
  # the loop drives the stage. Idle runs save and load (as on the H743) and commands are
  # refused until their reply went out: the script waits 10 ms of virtual time for each.
  grep -Eq '^ok save [0-9]+ settings [0-9]+ B$' "$dir/uart.txt" || { echo "$name: save failed"; exit 1; }
  [ "$(grep -A1 -E '^ok load [0-9]+ settings$' "$dir/uart.txt" | tail -1)" = "ok pid_kp 0.75" ] || { echo "$name: load did not restore pid_kp"; exit 1; }
  [ "$(grep -A1 '^ok defaults$' "$dir/uart.txt" | tail -1)" = "ok pid_kp 0.5" ] || { echo "$name: defaults did not restore pid_kp"; exit 1; }
  [ "$(grep -A1 '^ok wave sine' "$dir/uart.txt" | tail -1)" = "err 12 not possible in the current state" ] || { echo "$name: save not refused while driving"; exit 1; }
  grep -q '^ok mode ff+hgo-robust$' "$dir/uart.txt" || { echo "$name: mode switch failed"; exit 1; }
  grep -q '^ok rec sel ref_um y_um u_volts error_um$' "$dir/uart.txt" || { echo "$name: recorder setup failed"; exit 1; }
  grep -q '^ok fault none sensor 0 nonfinite 0 dac 0$' "$dir/uart.txt" || { echo "$name: fault state not clean"; exit 1; }
  # Mode budgets (issue 15 item 4): the bench's worst case of each law x feedforward
  # against the period. NMPC fits the M4F's 10 us with its solve in the priority-2 solver
  # task (issue 27 item 7): its step and its solver's run per MPC boundary are both
  # measured and checked. The library's tables (the H743's budget: WORST_M4F, SOLVE_M4F,
  # the solver's lock) must bound every f32 measurement.
  grep -E '^budget: [0-9]+ instr per period' "$dir/uart.txt" || { echo "$name: no budget line"; exit 1; }
  if [ "$name" = m4f-f32 ]; then
    [ "$(grep -A1 '^ok pid_kp 0.5$' "$dir/uart.txt" | tail -1)" = "ok mode nmpc" ] ||
      { echo "$name: nmpc not selectable at 100 kHz"; exit 1; }
    grep -q '^bench: solver task (deferred NMPC, priority 2) nmpc ims-cbw: worst ' "$dir/uart.txt" ||
      { echo "$name: no solver-task bench"; exit 1; }
    # micromath's cost per call against the step's own math (README, issue 15 item 7).
    grep -q '^bench: math .*micromath' "$dir/uart.txt" || { echo "$name: no math bench"; exit 1; }
    grep -q '^budget table: 0 of ' "$dir/uart.txt" ||
      { grep '^budget table' "$dir/uart.txt"; echo "$name: WORST_M4F, SOLVE_M4F or the solver's lock understates a measured worst case"; exit 1; }
  fi
  # The identification excitations (issue 17 item 1) run in closed loop, 500 periods each
  # (harness line `wait`: virtual time), without a fault.
  for w in 'prbs 9 11 10 5000 1 1023' 'chirp 1 10 2000 0.05' 'multisine 1 100 32 10 3'; do
    grep -q "^ok wave $w" "$dir/uart.txt" || { echo "$name: 'wave ${w%% *}' refused"; exit 1; }
  done
  [ "$(grep -c '^ok fault none sensor 0 nonfinite 0 dac 0$' "$dir/uart.txt")" -eq 2 ] ||
    { echo "$name: a fault after the excitations"; exit 1; }
  periods=$(sed -n 's/^done periods \([0-9]*\) .*/\1/p' "$dir/uart.txt")
  [ -n "$periods" ] && [ "$periods" -ge 10000 ] || { echo "$name: too few control periods: '$periods'"; exit 1; }
  echo "=== $name: $periods control periods, commands answered"
  # The strict mock chips (issue 15): no data-sheet rule broken by the drivers in the whole
  # run; selftest read the DAC register back equal to the code written, the ADC code inside
  # the sensor window, the amplifier enabled (no fault).
  grep -q '^chips: 0 data-sheet rule violations' "$dir/uart.txt" || { echo "$name: the drivers broke a chip rule"; exit 1; }
  grep -Eq '^ok selftest reset n/a dac (-?[0-9]+)/\1 ok adc -?[0-9]+ in amp on chips 0 none$' "$dir/uart.txt" ||
    { echo "$name: selftest did not pass"; exit 1; }
  # The control interrupt runs the pipeline and both converter drivers (on the mock chips).
  python3 .ci/firmware-code.py "$elf" SysTick "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}" \
    "piezo_core::drivers::ad4000::Ad4000::read|piezo_core::drivers::ad4000::Ad4000::convert|piezo_core::drivers::ad4000::decode" \
    piezo_core::drivers::ad5791::Ad5791::set_code
}

# fault_run <name> <qemu machine> <qemu cpu> <harness line> <tag> <status>: after 10 000
# periods, with the output driven away from the safe code by a 30 um sine, the harness line
# makes the firmware fail; its handler must leave the safe code in the DAC model, which
# prints its output code before and after (`<tag>: dac 0 out <before> -> <after> safe
# <code> amp off`), and end the run with <status>. Fails if the handler did not write it.
#   panic     forces a panic (status 101).
#   overflow  recurses until the stack (at the bottom of RAM, flip-link) runs into unmapped
#             memory: the HardFault entry must move MSP to the stack's top before anything
#             is pushed (status 102). A handler that pushes first faults again inside the
#             HardFault: QEMU reports a lockup and aborts (status 134), the DAC where it was.
fault_run() {
  local name=$1 machine=$2 cpu=$3 harness=$4 tag=$5 want=$6 status line before after safe
  local dir="$work/$name-$harness" elf="$work/$name/firmware.elf"
  mkdir -p "$dir"
  status=0
  pipe_run "$dir" "$elf" "$machine" "$cpu" /dev/null "ping\nwave sine 5 100 30\n$harness\n" || status=$?
  echo "=== $name: $harness"
  grep -E "^($tag|ok|chips)" "$dir/uart.txt" || true
  [ "$status" -eq "$want" ] || { echo "$name: $harness ended with status $status, not $want"; exit 1; }
  line=$(grep -E "^$tag: dac 0 out " "$dir/uart.txt") || { echo "$name: no DAC report after $harness"; exit 1; }
  read -r before after safe <<<"$(sed -E "s/^$tag: dac 0 out (-?[0-9]+) -> (-?[0-9]+) safe (-?[0-9]+) amp off\$/\1 \2 \3/" <<<"$line")"
  [ "$before" != "$safe" ] || { echo "$name: the DAC was at the safe code before $harness: the check would prove nothing"; exit 1; }
  [ "$after" = "$safe" ] || { echo "$name: after $harness the DAC model holds $after, not the safe code $safe"; exit 1; }
  echo "=== $name: $harness: the $tag handler put the DAC from $before back to the safe code $safe, amplifier off"
}

run m4f-f32 thumbv7em-none-eabihf mps2-an386 cortex-m4 250
fault_run m4f-f32 mps2-an386 cortex-m4 panic panic 101
fault_run m4f-f32 mps2-an386 cortex-m4 overflow hardfault 102
run m3-q16 thumbv7m-none-eabi mps2-an385 cortex-m3 1525
