# Sourced by the .ci/test.d scripts that talk to the QEMU firmware over its UART.
# Needs `work` (a temp dir) from the caller or qemu_session; `fail` (prints, exits) may be redefined.
#   piezo_cli                          sets $piezo: PIEZO_BIN, else the dev-profile CLI
#   qemu_boot <elf> <machine> <cpu>    boots with the UART on a free TCP port ($port, $qemu;
#                                      defmt to <elf>.defmt) and waits for `ok pong`
#   s <args>                           one `piezo serial` call against it
#   refused <line> <message>           the raw line must fail (exit status 1) naming it and
#                                      <message> (the firmware's numbered error)
#   settle <periods>                   returns once the firmware has run <periods> more control
#                                      periods (its own `stats` count: virtual time)
#   qemu_stop                          fails if the firmware exited early, then stops it
#   qemu_session <step>                the f32 build (mps2-an386) built and booted: sets
#                                      $work (removed with QEMU at exit) and fail()
qemu=

piezo_cli() {
  if [ -n "${PIEZO_BIN:-}" ]; then
    piezo=$PIEZO_BIN
  else
    # 10-host's `cargo test --workspace` built it (integration tests run the binary): the same
    # command finds everything fresh. (`cargo build -p hal-sim --bin piezo` would rebuild
    # hal-sim: without the dev-dependencies its dependencies' features differ.)
    local log
    log=$(mktemp)
    if ! cargo test -q --workspace --no-run >"$log" 2>&1; then
      cat "$log"
      rm -f "$log"
      echo "piezo_cli: cargo test --workspace --no-run failed"
      exit 1
    fi
    rm -f "$log"
    piezo=target/debug/piezo
  fi
}

# Waits inside `piezo serial` are bounded by the firmware's progress (`record` counts the
# control periods it reports); --timeout-s (each reply line) and the outer `timeout` are
# wall-clock caps for a dead link only, generous for a busy machine where QEMU runs far
# slower than real time.
s() { timeout 900 "$piezo" serial --tcp "127.0.0.1:$port" --timeout-s 60 "$@"; }

refused() {
  local line=$1 message=$2
  echo "\$ piezo serial -- \"$line\""
  if s -- "$line" >"$work/bad.txt" 2>&1; then fail "\`$line\` accepted"; fi
  cat "$work/bad.txt"
  grep -qF "\`$line\`: $message" "$work/bad.txt" || fail "\`$line\` not refused with: $message"
}

qemu_boot() {
  local elf=$1 machine=$2 cpu=$3
  port=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
  # QEMU writes the UART's bytes one at a time with Nagle on: the clients ask for quick ACKs
  # (serial/link.rs), else every reply waits for the host's 40 ms delayed ACK.
  qemu-system-arm -M "$machine" -cpu "$cpu" -nographic -monitor none -icount shift=0,sleep=off \
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

# settle <periods>: waits for the firmware's own time, not the host's: a reply takes 0.5 ms
# over the socket, so a script that needs a loop to settle (a wave just started, a law just
# rebuilt) must say so. The wall-clock cap only catches a firmware that stopped counting.
settle() {
  local want=$1 from now start=$SECONDS
  from=$(s stats | sed -n 's/^samples \([0-9]*\) .*/\1/p')
  [ -n "$from" ] || fail "settle: no sample count in stats"
  while :; do
    now=$(s stats | sed -n 's/^samples \([0-9]*\) .*/\1/p')
    [ -n "$now" ] || fail "settle: no sample count in stats"
    [ "$now" -ge $((from + want)) ] && return 0
    [ $((SECONDS - start)) -lt 600 ] || fail "settle: the firmware ran $((now - from)) of $want periods in 600 s"
    sleep 0.05
  done
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

# qemu_session <step name>: builds the f32 QEMU firmware, boots it on mps2-an386 with its UART
# on TCP and answers `ping`; `fail` names the step. Leaves $work, $port and $piezo set.
qemu_session() {
  step=$1
  command -v flip-link >/dev/null 2>&1 || cargo install flip-link --locked
  cargo build --release --target thumbv7em-none-eabihf -p piezo-core --bin qemu
  piezo_cli
  work=$(mktemp -d)
  trap qemu_cleanup EXIT
  cp target/thumbv7em-none-eabihf/release/qemu "$work/firmware.elf"
  qemu_boot "$work/firmware.elf" mps2-an386 cortex-m4
}

fail() {
  echo "${step:-qemu}: FAIL: $*"
  exit 1
}
