#!/usr/bin/env bash
# `piezo serial identify` against the QEMU firmware (issue 17 item 3). The simulated stage is
# made to differ from the firmware's built-in model with the harness line `stage 1.25 1.6 1`:
# 25 % more gain, a loop 1.6 times wider on top of that, and creep the firmware's CBW does
# not have. A value out of range must be refused (`err stage`) and change nothing. identify
# then measures the tracking error of a feedforward-only sine (the firmware's model alone),
# excites, fits, diagnoses, loads and measures again; the test parses
# `identify: rmse before <a> um, after <b> um` and requires a >= 3 b, the firmware's model
# changed, no fault, and the files of --out. Records are short (the loop runs in QEMU's
# virtual time; every wait is on the firmware's replies, none on the wall clock).
# PIEZO_SERIAL_OUT=<dir> keeps identify's output there.
set -euo pipefail
cd "$(dirname "$0")/../.."
. .ci/qemu-serial.sh
qemu_session 40-identify

# stage_line <line>: sends a `stage` harness line, prints its answer (`ok stage ...` or
# `err stage ...`; the other harness lines answer nothing).
stage_line() {
  local reply=
  exec 3<>"/dev/tcp/127.0.0.1/$port"
  printf '%s\n' "$1" >&3
  while IFS= read -r -t 120 reply <&3; do
    case $reply in "ok stage"* | "err stage"*) break ;; esac
    reply=
  done
  exec 3>&-
  echo "$reply"
}

for bad in "stage 3 1 0" "stage 1 0.1 0" "stage 1 1 5" "stage 1 1 nan" "stage 1 1" "stage 1 1 1 1"; do
  r=$(stage_line "$bad")
  echo "$bad -> $r"
  case $r in "err stage"*) ;; *) fail "\`$bad\` not refused: $r" ;; esac
done
r=$(stage_line "stage 1.25 1.6 1")
echo "stage 1.25 1.6 1 -> $r"
[ "$r" = "ok stage 1.250 1.600 1.000" ] || fail "stage line not taken: $r"
s ping >/dev/null

s -- "get cbw_d" "get cbw_alpha" | tee "$work/model_before.txt"
start=$SECONDS
echo "\$ piezo serial identify --out ident"
s identify --out "$work/ident" | tee "$work/identify.txt"
echo "40-identify: identify took $((SECONDS - start)) s"
line=$(grep '^identify: rmse before ' "$work/identify.txt") || fail "no identify summary line"
before=$(sed -n 's/^identify: rmse before \([0-9.e+-]*\) um, after \([0-9.e+-]*\) um$/\1/p' <<<"$line")
after=$(sed -n 's/^identify: rmse before \([0-9.e+-]*\) um, after \([0-9.e+-]*\) um$/\2/p' <<<"$line")
[ -n "$before" ] && [ -n "$after" ] || fail "cannot parse: $line"
awk -v b="$before" -v a="$after" 'BEGIN { exit !(a > 0 && b >= 3 * a) }' ||
  fail "tracking error after ($after um) is not 3x smaller than before ($before um)"
awk -v b="$before" 'BEGIN { exit !(b > 0.5) }' ||
  fail "the stage does not differ from the model before identify (before $before um)"

s -- "fault" "get cbw_d" "get cbw_alpha" | tee "$work/after.txt"
grep -q '^ok fault none ' "$work/after.txt" || fail "the firmware faulted"
d0=$(sed -n 's/^ok cbw_d //p' "$work/model_before.txt")
d1=$(sed -n 's/^ok cbw_d //p' "$work/after.txt")
awk -v a="$d0" -v b="$d1" 'BEGIN { exit !(b > 1.1 * a) }' ||
  fail "cbw_d $d0 -> $d1: the identified gain should be above the built-in one (stage gain 1.25)"
for f in fit.json prbs.csv sines.csv held_back.csv before.csv after.csv diagnose.txt identify.svg; do
  [ -s "$work/ident/$f" ] || fail "identify wrote no $f"
done
grep -q '<svg' "$work/ident/identify.svg" || fail "identify.svg is not an SVG"

qemu_stop
if [ -n "${PIEZO_SERIAL_OUT:-}" ]; then
  mkdir -p "$PIEZO_SERIAL_OUT"
  cp -r "$work/ident" "$PIEZO_SERIAL_OUT/"
fi
echo "40-identify: $line"
echo "40-identify: ok"
