#!/usr/bin/env bash
# The lab console in a real browser: the QEMU firmware (stage with the 2.5 kHz resonance of
# 39-bode), `piezo ui` connected to it over the same TCP link `piezo serial` uses, and headless
# Chromium driven through chromedriver (WebDriver) by hal-sim/examples/ui_browser.rs: the
# scope streams at >= 20 updates/s and triggers on the wave's start; a valid setting reaches
# the firmware (read back with `get`); an out-of-range value shows the range and sends
# nothing; the firmware's `err N` shows by its field; a mode change is reflected; bode finds
# the resonance within 50 Hz and applies the notch; identify cuts the tracking error of a
# mismatched stage 3x and loads the model; save is refused in closed loop with its reason,
# taken after Stop, and load restores it; Stop leaves the DAC at the safe code; a lost link
# is shown; a report (`piezo demo --out`'s index.html) opens from the console. Then `piezo ui
# --port` on QEMU's -serial pty (a board's serial-port path). Screenshots in out/ui/. Every
# wait is on a condition (page state, a reply); the wall-clock caps only end a run whose
# emulator, server or browser stopped.
set -euo pipefail
cd "$(dirname "$0")/../.."
if ! command -v chromium >/dev/null 2>&1 || ! command -v chromedriver >/dev/null 2>&1; then
  (apt-get update -qq && apt-get install -y -qq --no-install-recommends chromium chromium-driver) >/dev/null
fi
. .ci/qemu-serial.sh
qemu_session 56-ui
cargo build -q -p hal-sim --example ui_browser
ui_pid= driver_pid=
cleanup() {
  [ -z "$ui_pid" ] || kill "$ui_pid" 2>/dev/null || true
  [ -z "$driver_pid" ] || kill "$driver_pid" 2>/dev/null || true
  qemu_cleanup
}
trap cleanup EXIT
free_port() { python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])'; }
listening() { python3 -c 'import socket,sys; socket.create_connection(("127.0.0.1", int(sys.argv[1])), 1)' "$1" 2>/dev/null; }

# The stage's mechanical resonance (QEMU harness line; no reply, the next ping answers after it).
exec 3<>"/dev/tcp/127.0.0.1/$port"
printf 'resonance 2500 0.05\n' >&3
# A stage that differs from the firmware's model (as 40-identify's): identify has work to do.
printf 'stage 1.25 1.6 1\n' >&3
exec 3>&-
s ping >/dev/null

# A report for the console to open (`piezo demo`'s index.html; 100 Hz keeps it small).
"$piezo" demo --rate-hz 100 --out "$work/demo" >/dev/null

# start_ui <log> <piezo ui args...>: starts the console, sets $ui_pid and $url once it listens.
start_ui() {
  local log=$1 start=$SECONDS
  shift
  "$piezo" ui --timeout-s 60 --listen 0 "$@" >"$log" 2>&1 &
  ui_pid=$!
  until grep -q '^piezo ui: http://' "$log"; do
    kill -0 "$ui_pid" 2>/dev/null || { cat "$log"; fail "piezo ui $* exited"; }
    [ $((SECONDS - start)) -lt 120 ] || fail "piezo ui $* did not start listening"
    sleep 0.1
  done
  url=$(sed -n 's/^piezo ui: \(http:[^ ]*\)$/\1/p' "$log")
}
start_ui "$work/ui.txt" --tcp "127.0.0.1:$port" --work "$work/ui" --report "$work/demo"
echo "$url"

wd_port=$(free_port)
chromedriver --port="$wd_port" >"$work/chromedriver.txt" 2>&1 &
driver_pid=$!
start=$SECONDS
until listening "$wd_port"; do
  kill -0 "$driver_pid" 2>/dev/null || { cat "$work/chromedriver.txt"; fail "chromedriver exited"; }
  [ $((SECONDS - start)) -lt 60 ] || fail "chromedriver did not start listening"
  sleep 0.1
done

mkdir -p out/ui
timeout 1200 target/debug/examples/ui_browser --ui "$url" --webdriver "http://127.0.0.1:$wd_port" \
  --out out/ui --chromium "$(command -v chromium)" --resonance-hz 2500 --safe-code 0 \
  --kill-pid "$qemu" --report "piezo demo: hysteresis loops" --identify | tee "$work/browser.txt" || { tail -20 "$work/ui.txt"; fail "browser checks"; }
grep -q '^ui: [0-9]* browser checks passed$' "$work/browser.txt" || fail "no summary line"
# The example ended QEMU on purpose (the lost-link check).
wait "$qemu" 2>/dev/null || true
qemu=
kill "$ui_pid" 2>/dev/null || true
wait "$ui_pid" 2>/dev/null || true
ui_pid=

# A board's port: `piezo ui --port` on a serial device, here the tty QEMU makes of the UART
# (`-serial pty`), through the serial-port path a Nucleo's /dev/ttyACM0 takes (termios, no
# TCP). The console answers a raw line and streams the scope to a finished capture.
# QEMU names the tty on its stdout, beside the defmt bytes: line-buffered, so it comes at once.
stdbuf -oL qemu-system-arm -M mps2-an386 -cpu cortex-m4 -nographic -monitor none \
  -icount shift=0,sleep=off -chardev pty,id=ser -serial chardev:ser \
  -semihosting-config enable=on,target=native -kernel "$work/firmware.elf" \
  >"$work/pty.out" 2>"$work/pty.err" &
qemu=$!
start=$SECONDS
until grep -aq 'char device redirected to /dev/' "$work/pty.out"; do
  kill -0 "$qemu" 2>/dev/null || { cat "$work/pty.err"; fail "QEMU with -serial pty exited"; }
  [ $((SECONDS - start)) -lt 60 ] || fail "QEMU named no pty"
  sleep 0.1
done
tty=$(grep -ao 'char device redirected to /dev/[^ ]*' "$work/pty.out" | sed 's/.* //')
start=$SECONDS
until timeout 900 "$piezo" serial --port "$tty" --timeout-s 60 ping >"$work/ping.txt" 2>&1; do
  kill -0 "$qemu" 2>/dev/null || fail "QEMU exited before answering on $tty"
  [ $((SECONDS - start)) -lt 1800 ] || fail "no answer on $tty"
  sleep 0.2
done
start_ui "$work/ui-port.txt" --port "$tty" --work "$work/ui-port"
python3 - "$url" "$tty" <<'PY' || fail "piezo ui --port"
import json, sys, time, urllib.error, urllib.request
url, tty = sys.argv[1], sys.argv[2]
req = urllib.request.Request(url + "api/raw", data=json.dumps({"line": "get sample_hz"}).encode(),
                             headers={"content-type": "application/json"})
try:
    reply = json.load(urllib.request.urlopen(req, timeout=120))["reply"]
except urllib.error.HTTPError as e:
    sys.exit(f"api/raw: HTTP {e.code}: {e.read().decode()}")
assert reply == "ok sample_hz 100000", reply
# Wall-clock cap only for a dead emulator: the scope streams as fast as the firmware runs.
end = time.time() + 600
while True:
    try:
        csv = urllib.request.urlopen(url + "api/scope/csv", timeout=120).read().decode()
    except urllib.error.HTTPError as e:  # no capture yet
        csv = f"HTTP {e.code}: {e.read().decode()}"
    if csv.startswith("# piezo serial record: 256 frames"):
        break
    assert time.time() < end, "no finished 256-frame capture: " + csv[:200]
    time.sleep(0.05)
rows = [l for l in csv.splitlines()[3:] if l]
assert len(rows) == 256, len(rows)
print(f"ui: board port {tty}: `get sample_hz` -> `{reply}`; the scope streamed a "
      f"{len(rows)}-frame capture")
PY
echo "56-ui: ok"
