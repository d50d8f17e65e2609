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

s() { timeout 60 "$piezo" serial --tcp "127.0.0.1:$port" --timeout-s 10 "$@"; }

qemu_boot() {
  local elf=$1 machine=$2 cpu=$3
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  qemu-system-arm -M "$machine" -cpu "$cpu" -nographic -monitor none -icount shift=0 \
    -chardev socket,id=ser,host=127.0.0.1,port="$port",server=on,wait=off -serial chardev:ser \
    -semihosting-config enable=on,target=native -kernel "$elf" >"$elf.defmt" &
  qemu=$!
  # QEMU listens at once; the firmware answers after its boot-time bench table.
  for _ in $(seq 100); do
    if s ping >"$work/ping.txt" 2>&1; then break; fi
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
