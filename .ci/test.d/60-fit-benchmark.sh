#!/usr/bin/env bash
# Bouc-Wen benchmark: identify the structural Bouc-Wen model on the training record only,
# assert e_RMS below PNLSS (1.87e-5 m) on both test records. Release: the fit integrates
# 40960 samples upsampled 5x many times over.
set -euo pipefail
cargo test --profile host -p hal-sim --test benchmark_boucwen -- --ignored --nocapture
