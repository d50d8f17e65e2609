#!/usr/bin/env bash
# The Python client (hal-sim/python/python/piezo/client.py, `piezo.client`) against the QEMU
# firmware (mps2-an386, f32) with its UART on TCP: parameters, numbered errors as
# exceptions (checked against src/command/error.rs), a mode, a sine and a recorder capture
# as a NumPy array. Waits are bounded by the firmware's progress (`rec status`).
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 -c 'import numpy' 2>/dev/null || python3 -m pip install -q numpy pyserial
. .ci/qemu-serial.sh
qemu_session 38-python-client
PYTHONPATH=hal-sim/python/python timeout 1800 python3 hal-sim/python/tests/client_on_qemu.py "127.0.0.1:$port" ||
  fail "the Python client test failed"
qemu_stop
