# Sourced by the .ci/test.d scripts that talk to the QEMU firmware over its UART.
# Needs `work` (a temp dir) and `fail` (prints and exits) from the caller.
#   piezo_cli                          sets $piezo: PIEZO_BIN, else the dev-profile CLI
#   qemu_boot <elf> <machine> <cpu>    boots with the UART on a free TCP port ($port, $qemu;
#                                      defmt to <elf>.defmt) and waits for `ok pong`
#   s <args>                           one `piezo serial` call against it
#   qemu_stop                          fails if the firmware exited early, then stops it
qemu=

piezo_cli() {
  if [ -n "${PIEZO_BIN:-}" ]; then
    piezo=$PIEZO_BIN
  else
    # Built by 10-host's `cargo test` already.
    cargo build -q -p hal-sim --bin piezo
    piezo=target/debug/piezo
  fi
}

# Waits inside `piezo serial` are bounded by the firmware's progress (`record` counts the
# control periods it reports); --timeout-s (each reply line) and the outer `timeout` are
# wall-clock caps for a dead link only, generous for a busy machine where QEMU runs far
# slower than real time.
s() { timeout 900 "$piezo" serial --tcp "127.0.0.1:$port" --timeout-s 60 "$@"; }

qemu_boot() {
  local elf=$1 machine=$2 cpu=$3
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  qemu-system-arm -M "$machine" -cpu "$cpu" -nographic -monitor none -icount shift=0 \
    -chardev socket,id=ser,host=127.0.0.1,port="$port",server=on,wait=off -serial chardev:ser \
    -semihosting-config enable=on,target=native -kernel "$elf" >"$elf.defmt" &
  qemu=$!
  # QEMU listens at once; the firmware answers after its boot-time bench table, which takes
  # as long as the emulator needs: keep asking while QEMU runs (a wall-clock cap of 30 min
  # only catches a hung emulator).
  local start=$SECONDS
  until s ping >"$work/ping.txt" 2>&1; do
    kill -0 "$qemu" 2>/dev/null || break
    [ $((SECONDS - start)) -lt 1800 ] || break
    sleep 0.2
  done
  cat "$work/ping.txt"
  grep -q '^ok pong' "$work/ping.txt" || fail "no answer to ping"
}

qemu_stop() {
  if [ -n "$qemu" ]; then
    kill -0 "$qemu" 2>/dev/null || fail "the firmware exited during the session"
    kill "$qemu" 2>/dev/null || true
    wait "$qemu" 2>/dev/null || true
    qemu=
  fi
}

# For the EXIT trap: stops QEMU whatever state it is in, removes $work.
qemu_cleanup() {
  if [ -n "$qemu" ]; then
    kill "$qemu" 2>/dev/null || true
    wait "$qemu" 2>/dev/null || true
  fi
  rm -rf "$work"
}
