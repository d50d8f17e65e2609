#!/usr/bin/env bash
# piezo-ident, the identification library: builds alone (the doctests build it with its own
# features, not the workspace's), its rustdoc has no warnings (broken links, bad code
# blocks) and the examples in it run.
set -euo pipefail
cd "$(dirname "$0")/../.."
RUSTDOCFLAGS="-D warnings" cargo doc -q -p piezo-ident --no-deps
cargo test -q -p piezo-ident --doc
