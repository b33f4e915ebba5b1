#!/usr/bin/env bash
# Hardware in the loop: flashes the B-L475E-IOT01A with `chladni flash`, then runs the
# end-to-end suite (tests/e2e.rs, drive.rs, sessions.rs, store.rs) against the board on PORT
# instead of QEMU.
#   scripts/hitl.sh /dev/ttyACM0              # the board's USB CDC-ACM port (`chladni device list`)
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
  *) [ -e "$port" ] || { echo "hitl: no such port '$port' (\`chladni device list\` shows the board's USB port)" >&2; exit 2; } ;;
esac

scripts/install-deps.sh
if $flash; then
  cargo run --release --bin chladni -- flash "$@"
  # The board resets when flashing ends, then enumerates on USB again: wait for its port.
  case "$port" in
    tcp://*) ;;
    *) for _ in $(seq 50); do sleep 0.2; [ -e "$port" ] && break; done
       [ -e "$port" ] || { echo "hitl: $port did not come back within 10 s of flashing" >&2; exit 1; } ;;
  esac
fi
# One test at a time: there is one board (the tests also take turns within a file).
CHLADNI_PORT="$port" cargo test -p chladni-e2e --test e2e --test drive --test sessions --test store \
  -- --test-threads=1 --nocapture
