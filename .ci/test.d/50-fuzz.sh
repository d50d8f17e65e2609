#!/usr/bin/env bash
# Short fuzz runs (10 s each) of the serial command parser, the CSV record reader and the
# stored-settings reader (decode, then all-or-nothing install) and the recorder's bulk-transfer
# packet decoder.
# The full campaign (10 min each): FUZZ_SECONDS=600 bash .ci/test.d/50-fuzz.sh
# cargo-fuzz needs a nightly toolchain; where none is installed (and none can be fetched)
# this step says so and skips.
set -euo pipefail
secs=${FUZZ_SECONDS:-10}
if ! rustup run nightly rustc --version >/dev/null 2>&1; then
  echo "fuzz: skipped, no nightly toolchain on this machine"
  exit 0
fi
if ! command -v cargo-fuzz >/dev/null 2>&1; then
  cargo install cargo-fuzz --locked --quiet
fi
cd hal-sim
for t in command_parser csv_record settings_record rec_packet; do
  cargo +nightly fuzz run -O "$t" -- -max_total_time="$secs" -rss_limit_mb=4096 2>&1 | tail -n 3
  echo "fuzz $t: ${secs} s, no crash"
done
