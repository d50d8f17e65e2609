#!/usr/bin/env bash
# Target: the firmware builds for the Nucleo-H743ZI2 (Cortex-M7, thumbv7em-none-eabihf),
# linked through flip-link (stack overflow protection), in both converter variants: the
# on-chip ADC/DAC (default) and the external SPI pair through the core's Ad4000/Ad5791
# drivers (feature spi-converters), and the two-axis XY scanner on the on-chip converters
# (feature xy: ADC1 + ADC2, DAC1 channels 1 + 2). Prints flash/RAM use of each and checks in
# the ELF that the control interrupt runs the core's pipeline step (and, with SPI, both
# drivers). xy with spi-converters must not compile (the SPI pair drives one axis).
# First, clippy on the firmware's own targets (the host's clippy sees neither the boards nor
# the Q16.16 build): both boards, every feature, both targets of the QEMU board.
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
for args in "--target thumbv7em-none-eabihf --bin h743 --bin qemu" \
  "--target thumbv7em-none-eabihf --bin h743 --features spi-converters" \
  "--target thumbv7em-none-eabihf --bin h743 --bin qemu --features xy" \
  "--target thumbv7m-none-eabi --bin qemu" "--target thumbv7m-none-eabi --bin qemu --features xy"; do
  # shellcheck disable=SC2086
  cargo clippy -q --release -p piezo-core $args -- -D warnings
done
echo "firmware: clippy clean on both targets, both boards, every feature"
size="$(rustc --print sysroot)/lib/rustlib/x86_64-unknown-linux-gnu/bin/llvm-size"
elf=target/m7/thumbv7em-none-eabihf/release/h743
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# build <name> <cargo features...>
build() {
  local name=$1
  shift
  cargo h743 "$@" # .cargo/config.toml: target-cpu=cortex-m7, target/m7
  cp "$elf" "$work/$name.elf"
  # The per-sample path lies in ITCM in the build that is flashed (stable's symbol scheme).
  python3 .ci/firmware-safety.py --elf "$work/$name.elf" --itcm-only | grep -E '^(HardFault entry|ADC1_2|TIM2|ITCM|__pre_init|firmware ITCM|  in flash)'
  "$size" -A "$work/$name.elf" | grep -E '^(section|\.vector_table|\.text|\.rodata|\.data|\.bss|\.uninit)' || true
  "$size" -B "$work/$name.elf" | awk -v n="$name" 'NR==2 {printf "firmware (H743, %s): flash %d bytes (text+data), RAM %d bytes (data+bss, stack not included)\n", n, $1+$2, $2+$3}'
}

build on-chip
build spi-converters --features spi-converters
build xy --features xy
if cargo h743 --features xy,spi-converters \
  >"$work/xy-spi.log" 2>&1; then
  echo "firmware: xy with spi-converters built, expected a compile_error"
  exit 1
fi
grep -q 'feature `xy` (two axes) needs the on-chip converters' "$work/xy-spi.log" ||
  { cat "$work/xy-spi.log"; echo "firmware: xy + spi-converters failed for another reason"; exit 1; }
echo "firmware (H743, xy + spi-converters): refused at compile time, as intended"
# Ad4000Config::frame_bytes: only `read` and `decode` call it; with target-cpu=cortex-m7
# the debug info names no other instruction of them (all merged into their callees).
# Likewise Ad5791::write_code is one call of write_register (the DAC register); since the
# AXI-SRAM recorder build, its instructions all merge into write_register.
python3 .ci/firmware-code.py "$work/on-chip.elf" ADC1_2 "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}"
python3 .ci/firmware-code.py "$work/xy.elf" ADC1_2 "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}"
python3 .ci/firmware-code.py "$work/spi-converters.elf" TIM2 "piezo_core::pipeline::Pipeline::step|piezo_core::pipeline::Pipeline::step::{{closure}}" \
  "piezo_core::drivers::ad4000::Ad4000::read|piezo_core::drivers::ad4000::decode|piezo_core::drivers::ad4000::Ad4000Config::frame_bytes" \
  "piezo_core::drivers::ad5791::Ad5791::write_code|piezo_core::drivers::ad5791::Ad5791::set_code|piezo_core::drivers::ad5791::Ad5791::write_register"
