#!/usr/bin/env bash
# piezo diagnose: the hidden-cause suite with 5 seeds per cause, pairs and `none`, in release
# (the dev-profile `cargo test` runs 2 seeds per cause), and rate dependence named exactly
# where the stage has it (20/40/100 Hz drives, each record training in turn).
set -euo pipefail
DIAGNOSE_SEEDS=5 cargo test --release -p hal-sim --test diagnose --test diagnose_rate -- --nocapture
