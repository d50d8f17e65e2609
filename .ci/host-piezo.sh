# Sourced by the steps that run the release-speed CLI: builds it as 60-fit-benchmark's
# `cargo test --profile host -p hal-sim` does (integration tests build the `piezo` binary with
# the dev-dependencies' features), so one host-profile build serves every step; `cargo build
# -p hal-sim --bin piezo` would compile hal-sim again with other dependency features. The
# first step that sources it (46) pays that build: about 300 s of a clean CI run. Sets $piezo.
host_piezo_log=$(mktemp)
if ! cargo test --profile host -q -p hal-sim --test diagnose_rate --no-run >"$host_piezo_log" 2>&1; then
  cat "$host_piezo_log"
  rm -f "$host_piezo_log"
  echo "host-piezo: cargo test --profile host -p hal-sim --no-run failed"
  exit 1
fi
rm -f "$host_piezo_log"
piezo=target/host/piezo
