#!/bin/bash
# run.sh SCENARIO_DIR IMAGE MACHINE OUT_DIR: single-steps QEMU over the scenario run's stimulus.bin (the image the
# scenarios built, target/qemu/firmware/<board>-<rev>; MACHINE netduino2 for the F1 boards, netduinoplus2 for
# PowerManagement) and counts the log as it is written (through a FIFO: a whole run's log is tens of GB), leaving
# OUT_DIR/unstamped.txt and OUT_DIR/records.txt. Takes minutes per scenario; run it with nice.
set -e
here=$(cd "$(dirname "$0")" && pwd)
image=$(realpath "$2")
mkdir -p "$4"
cp "$1/stimulus.bin" "$4/"
cd "$4"
rm -f log.fifo
mkfifo log.fifo
python3 "$here/tee.py" "$image" < log.fifo &
reader=$!
qemu-system-arm -machine "$3" -nographic -monitor none -serial none \
  -semihosting-config enable=on,target=native -icount shift=3,align=off,sleep=off \
  -singlestep -d exec,nochain,int -D log.fifo -kernel "$image" > output.log 2>&1 || true
wait $reader
rm -f log.fifo
