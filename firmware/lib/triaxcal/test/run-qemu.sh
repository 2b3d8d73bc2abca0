#!/bin/sh
# run-qemu.sh SECONDS LOG INPUT QEMU ARGS...: run the test program in QEMU with INPUT on its
# standard input (the serial line's receive side with -serial stdio; /dev/null for none) and
# its output (serial or semihosting, on QEMU's stdout) going to LOG, until the program prints
# its RESULT line or exits, or SECONDS pass (then QEMU is stopped); show LOG; succeed only when
# the RESULT line says 0 failures. (QEMU's AVR machine cannot exit: a program ends by sleeping
# for ever.)
set -u
secs=$1
log=$2
input=$3
shift 3
: > "$log"
"$@" > "$log" 2>&1 < "$input" &
pid=$!
waited=0
while kill -0 "$pid" 2>/dev/null; do
    if grep -q '^RESULT' "$log"; then
        sleep 0.2
        kill "$pid" 2>/dev/null
        break
    fi
    if [ "$waited" -ge $((secs * 10)) ]; then
        echo "run-qemu.sh: no RESULT line after $secs s; stopping QEMU" >> "$log"
        kill "$pid" 2>/dev/null
        break
    fi
    sleep 0.1
    waited=$((waited + 1))
done
wait "$pid" 2>/dev/null
grep -v "terminating on signal" "$log"
grep -q '^RESULT [0-9]* checks, 0 failures' "$log"
