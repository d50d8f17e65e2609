#!/usr/bin/env bash
# Firmware static checks (no heap linked; no panic path and no indirect call reachable from
# any interrupt handler; worst-case stack per handler from -Z emit-stack-sizes), for both
# converter variants of the H743 build and the two-axis (xy) build. Needs nightly; skipped with a message where none
# is installed.
set -euo pipefail
if ! rustup run nightly rustc --version >/dev/null 2>&1; then
  echo "firmware safety: skipped, no nightly toolchain on this machine"
  exit 0
fi
rustup target add thumbv7em-none-eabihf --toolchain nightly >/dev/null
python3 .ci/firmware-safety.py
python3 .ci/firmware-safety.py --features spi-converters
python3 .ci/firmware-safety.py --features xy
