#!/usr/bin/env bash
# The Python client (hal-sim/python/piezo_client.py, issue 17 item 7) against the QEMU
# firmware (mps2-an386, f32) with its UART on TCP: parameters, numbered errors as
# exceptions (checked against src/command/error.rs), a mode, a sine and a recorder capture
# as a NumPy array. Waits are bounded by the firmware's progress (`rec status`).
set -euo pipefail
cd "$(dirname "$0")/../.."
python3 -c 'import numpy' 2>/dev/null || python3 -m pip install -q numpy pyserial
. .ci/qemu-serial.sh
qemu_session 38-python-client
(cd hal-sim/python && timeout 1800 python3 test_piezo_client.py "127.0.0.1:$port") ||
  fail "the Python client test failed"
qemu_stop
