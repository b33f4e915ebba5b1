#!/usr/bin/env bash
# The main job on a fresh machine: install what is missing, build, start the controller in QEMU
# (`chladni emulator`), and talk to it from the host (`chladni device …`).
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cargo build --release --bin chladni
chladni=target/release/chladni

log=$(mktemp -d)/emulator
$chladni emulator --log "$log.defmt" --time-limit-s 600 >"$log.out" 2>"$log.err" &
emu=$!
trap 'kill $emu 2>/dev/null; wait $emu 2>/dev/null || true' EXIT
for _ in $(seq 1 600); do
  port=$(grep -o 'tcp://[0-9.:]*' "$log.out" | head -n 1 || true)
  [ -n "$port" ] && break
  kill -0 $emu 2>/dev/null || { cat "$log.err"; exit 1; }
  sleep 0.2
done
[ -n "$port" ] || { echo "emulator did not come up"; cat "$log.err"; exit 1; }
echo "controller (QEMU) on $port"

echo; echo "\$ chladni device info --port $port"
$chladni device info --port "$port"
echo; echo "\$ chladni device info --port $port --json"
$chladni device info --port "$port" --json
echo; echo "\$ chladni device ping --port $port --count 100"
$chladni device ping --port "$port" --count 100

echo; echo "firmware log:"; cat "$log.defmt"
