#!/usr/bin/env bash
# The Python package (hal-sim/python: `piezo.fit`, `predict`, `diagnose` on piezo-ident, and
# `piezo.client`): `pip install ./hal-sim/python` into a fresh virtual environment (maturin
# comes from PyPI through pip's build isolation and builds the native part), then its pytest
# suite on the measured records, each answer checked against the `piezo` CLI's for the same
# record (`diagnose --json`, fit.json, `predict`), and the example script.
set -euo pipefail
cd "$(dirname "$0")/../.."
repo=$PWD
export PIEZO_DATA="${PIEZO_DATA:-$repo/../shared/data}"
[ -d "$PIEZO_DATA" ] || { echo "55-python-package: no records at $PIEZO_DATA"; exit 1; }
# The CLI the answers are compared with, built from this checkout (50-feedback-sim built it
# already: a no-op then).
. .ci/host-piezo.sh
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
if ! python3 -m venv "$work/venv" >/dev/null 2>&1; then
  # Debian's python3 keeps ensurepip (what venv needs) in python3-venv.
  (apt-get update -qq && apt-get install -y -qq --no-install-recommends python3-venv) >/dev/null
  python3 -m venv "$work/venv"
fi
py=$work/venv/bin/python
start=$(date +%s)
"$py" -m pip install -q ./hal-sim/python pytest
echo "55-python-package: pip install ./hal-sim/python took $(( $(date +%s) - start )) s"
# Exit code 5 (no test collected) fails the step like any other.
rc=0
(cd "$work" && PIEZO_BIN="$piezo" PIEZO_REQUIRE=1 \
  "$py" -m pytest -q -p no:cacheprovider "$repo/hal-sim/python/tests") || rc=$?
[ "$rc" -eq 0 ] || { echo "55-python-package: pytest exited with $rc"; exit 1; }
(cd "$work" && "$py" "$repo/hal-sim/python/examples/diagnose_record.py" \
  "$PIEZO_DATA/backlash-micromanipulator/model_1Hz.csv" | tee example.txt)
grep -q '^cause: ' "$work/example.txt" || { echo "55-python-package: the example printed no cause"; exit 1; }
