# Sourced by the steps that run the `piezo` CLI on longer jobs (diagnose bench, sims, the
# Python package's comparisons, the mirror benchmark): the dev-profile binary 10-host's
# `cargo test --workspace` built, found fresh by the same command (`cargo build -p hal-sim
# --bin piezo` would compile hal-sim again with other dependency features). Dependencies are
# at opt-level 2 in the dev profile: measured 1.0-1.5x the host profile's run time on these
# jobs, where a separate host-profile build cost about 300 s of a clean CI run. Sets $piezo
# (an absolute path).
host_piezo_log=$(mktemp)
if ! cargo test -q --workspace --no-run >"$host_piezo_log" 2>&1; then
  cat "$host_piezo_log"
  rm -f "$host_piezo_log"
  echo "host-piezo: cargo test --workspace --no-run failed"
  exit 1
fi
rm -f "$host_piezo_log"
piezo=$PWD/target/debug/piezo
