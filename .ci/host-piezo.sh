# Sourced by the steps that run the release-speed CLI: builds it as 45-diagnose's
# `cargo test --profile host -p hal-sim` did (integration tests build the `piezo` binary with
# the dev-dependencies' features), so after that step it is fresh; `cargo build -p hal-sim
# --bin piezo` would compile hal-sim again with other dependency features. Sets $piezo.
host_piezo_log=$(mktemp)
if ! cargo test --profile host -q -p hal-sim --test diagnose_rate --no-run >"$host_piezo_log" 2>&1; then
  cat "$host_piezo_log"
  rm -f "$host_piezo_log"
  echo "host-piezo: cargo test --profile host -p hal-sim --no-run failed"
  exit 1
fi
rm -f "$host_piezo_log"
piezo=target/host/piezo
