#!/usr/bin/env bash
# Hardware in the loop: flashes the B-L475E-IOT01A with `chladni flash`, then runs the
# end-to-end suite (tests/e2e.rs, tests/drive.rs) against the board on PORT instead of QEMU.
#   scripts/hitl.sh /dev/ttyACM0              # ST-LINK virtual COM port (USART1, 115200 8N1)
#   scripts/hitl.sh /dev/ttyACM0 --no-flash   # the board already runs this tree's image
# Tests that need QEMU's powers (its process, its log, its flash file) print why they skip
# that part. Extra arguments after the port go to `chladni flash` (e.g. --probe VID:PID).
set -euo pipefail
cd "$(dirname "$0")/.."
port=${1:?usage: scripts/hitl.sh PORT [--no-flash] [chladni flash options]}
shift
flash=true
if [ "${1:-}" = --no-flash ]; then flash=false; shift; fi
case "$port" in
  tcp://*) ;;
  *) [ -e "$port" ] || { echo "hitl: no such port '$port' (the board's ST-LINK VCP is usually /dev/ttyACM0)" >&2; exit 2; } ;;
esac

scripts/install-deps.sh
if $flash; then
  cargo run --release --bin chladni -- flash "$@"
  sleep 1 # the board boots after the reset that ends flashing
fi
# One test at a time: there is one board (the tests also take turns within a file).
CHLADNI_PORT="$port" cargo test -p chladni-e2e --test e2e --test drive -- --test-threads=1 --nocapture
