#!/usr/bin/env bash
# Target: the firmware builds for the Cortex-M7 (thumbv7em-none-eabihf); print flash/RAM use.
set -euo pipefail
cargo build --release --target thumbv7em-none-eabihf --bin firmware
