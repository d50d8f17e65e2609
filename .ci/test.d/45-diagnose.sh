#!/usr/bin/env bash
# piezo diagnose: the hidden-cause suite with 5 seeds per cause, pairs and `none` (the plain
# `cargo test` runs 2 seeds per cause), and rate dependence named exactly where the stage has
# it (20/40/100 Hz drives, each record training in turn). In the dev profile that 10-host
# built: a release build of these tests recompiled 224 crates with the dev-dependencies'
# features (292 s of CI for a run 35 s shorter).
set -euo pipefail
DIAGNOSE_SEEDS=5 cargo test -p hal-sim --test diagnose --test diagnose_rate -- --nocapture
