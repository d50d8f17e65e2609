#!/usr/bin/env bash
# Host: formatting, lints, every unit/property/integration test of the workspace.
set -euo pipefail
cargo fmt --all -- --check
cargo clippy --workspace --all-targets -- -D warnings
cargo test --workspace
