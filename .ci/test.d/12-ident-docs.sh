#!/usr/bin/env bash
# piezo-ident, the identification library: builds alone, its rustdoc has no warnings (broken
# links, bad code blocks) and the examples in it run.
set -euo pipefail
cd "$(dirname "$0")/../.."
cargo build -q -p piezo-ident
RUSTDOCFLAGS="-D warnings" cargo doc -q -p piezo-ident --no-deps
cargo test -q -p piezo-ident --doc
