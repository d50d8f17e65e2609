#!/usr/bin/env bash
# piezo diagnose: the hidden-cause suite with seeds 3-5 per cause, pairs and `none` (the plain
# `cargo test` of 10-host ran seeds 1-2), and rate dependence named exactly where the stage has
# it (20/40/100 Hz drives, each record training in turn). In the dev profile and with the
# workspace's features, as 10-host built them (`-p hal-sim` resolves other features and
# rebuilds dependencies); the host-profile build it made before now falls to 46.
set -euo pipefail
DIAGNOSE_SEED_FROM=3 DIAGNOSE_SEEDS=5 cargo test --workspace --test diagnose --test diagnose_rate -- --nocapture
