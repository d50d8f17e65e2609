#!/usr/bin/env bash
# `piezo serial bode` against the QEMU firmware (issue 17 item 4): the simulated stage gets a
# mechanical resonance (harness line `resonance 2500 0.05`: 2.5 kHz, damping 0.05, Q 10, behind
# its 500 Hz lag), the open-loop response is measured with the firmware's own multisine and
# the resonance must be found within 50 Hz, half the line spacing of a 1024-frame record at
# 100 kHz (97.7 Hz): the peak is interpolated between lines, and a Q-10 mode is 2.6 lines wide
# at half power. The suggested notch is applied (`--apply`) and the closed loop
# (ff+hgo-robust + ims-cbw, 0.2 um: a 1 um multisine to 3 kHz asks more than the 20 V/ms
# slew limit) measured with it, four random-phase realizations averaged (the best linear
# approximation: the hysteresis and the IMS distort the closed loop): no fault, and the loop
# follows up to 1 kHz: the median |H| of those lines within 0.6..1.4 (a stage that does not
# follow gives |H| near 0).
# PIEZO_SERIAL_OUT=<dir> keeps the CSVs and SVGs there.
set -euo pipefail
cd "$(dirname "$0")/../.."
. .ci/qemu-serial.sh
qemu_session 39-bode

harness() { # a harness line: no reply; the next `ping` answers after it
  exec 3<>"/dev/tcp/127.0.0.1/$port"
  printf '%s\n' "$1" >&3
  exec 3>&-
  s ping >/dev/null
}
run() {
  echo "\$ piezo serial $*"
  s "$@" | tee "$work/last.txt"
}

harness "resonance 2500 0.05"
run bode --loop open --out "$work/open.csv" --svg "$work/open.svg" --apply
f=$(sed -n 's/^resonance: \([0-9.]*\) Hz.*/\1/p' "$work/last.txt")
[ -n "$f" ] || fail "no resonance found"
awk -v f="$f" 'BEGIN { d = f - 2500; if (d < 0) d = -d; exit !(d <= 50) }' ||
  fail "resonance at $f Hz, not within 50 Hz of 2500 Hz"
grep -q '^ok notch_hz ' "$work/last.txt" || fail "notch_hz not applied"
grep -q '^ok notch_q ' "$work/last.txt" || fail "notch_q not applied"
[ "$(sed -n 3p "$work/open.csv")" = "f_hz,magnitude,phase_deg,coherence" ] || fail "CSV header"
[ "$(grep -c '^[0-9]' "$work/open.csv")" -ge 30 ] || fail "fewer than 30 lines"
grep -q '<svg' "$work/open.svg" || fail "no SVG"

run bode --loop closed --amplitude 0.2um --out "$work/closed.csv" --svg "$work/closed.svg"
run -- "fault" "get notch_hz" "get notch_q"
grep -q '^ok fault none ' "$work/last.txt" || fail "closed loop with the notch faulted"
awk -F, '/^[0-9]/ && $1 <= 1000 { m[n++] = $2 }
  END { for (i = 1; i < n; i++) for (j = i; j > 0 && m[j - 1] > m[j]; j--) { t = m[j]; m[j] = m[j - 1]; m[j - 1] = t }
        med = m[int((n - 1) / 2)]
        printf "closed loop: median |H| %.3f over the %d lines up to 1 kHz\n", med, n
        exit !(n >= 5 && med > 0.6 && med < 1.4) }' \
  "$work/closed.csv" || fail "closed loop does not follow up to 1 kHz"

qemu_stop
if [ -n "${PIEZO_SERIAL_OUT:-}" ]; then
  mkdir -p "$PIEZO_SERIAL_OUT"
  cp "$work"/open.csv "$work"/open.svg "$work"/closed.csv "$work"/closed.svg "$PIEZO_SERIAL_OUT/"
fi
echo "39-bode: open-loop resonance found at $f Hz (set: 2500 Hz)"
echo "39-bode: ok"
