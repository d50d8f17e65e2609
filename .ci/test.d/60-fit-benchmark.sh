#!/usr/bin/env bash
# Bouc-Wen benchmark: identify the structural Bouc-Wen model on the training record only,
# assert e_RMS below PNLSS (1.87e-5 m) on both test records. The fit integrates 40960
# samples upsampled 5x many times over: in the dev profile with the workspace's features,
# as 10-host built it (its dependencies at opt-level 2: 20 s, as fast as the host profile,
# whose own build cost 3 min).
set -euo pipefail
cargo test --workspace --test benchmark_boucwen -- --ignored --nocapture
