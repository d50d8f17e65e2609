#!/usr/bin/env bash
# Target: the firmware builds for the Nucleo-H743ZI2 (Cortex-M7, thumbv7em-none-eabihf),
# linked through flip-link (stack overflow protection); print flash/RAM use.
set -euo pipefail
command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
cargo build --release --target thumbv7em-none-eabihf --bin firmware
size="$(rustc --print sysroot)/lib/rustlib/x86_64-unknown-linux-gnu/bin/llvm-size"
elf=target/thumbv7em-none-eabihf/release/firmware
"$size" -A "$elf" | grep -E '^(section|\.vector_table|\.text|\.rodata|\.data|\.bss|\.uninit)' || true
"$size" -B "$elf" | awk 'NR==2 {printf "firmware (H743): flash %d bytes (text+data), RAM %d bytes (data+bss, stack not included)\n", $1+$2, $2+$3}'
