#!/usr/bin/env bash
# The main job on a fresh machine: install what is missing, build, then
#   1. analyse where a triangle rests at a straight node,
#   2. plan a sensorless sequence of plate modes that orients it from any start,
#   3. check the plan by Monte Carlo simulation,
#   4. from plate dimensions alone (the paper's setup 2, hinged and driven by a rod): solve its
#      modes, draw its Chladni figures, and plan for a rectangle on them,
#   5. start the controller in QEMU (`chladni emulator`), upload the plan and run it,
#      watching the drive step through it, as it would on the real feeder.
# Outputs (plan file, figures, logs) go to target/demo/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/install-deps.sh
cargo build --release --bin chladni
chladni=target/release/chladni
out=target/demo
mkdir -p "$out"
part=examples/parts/triangle.json
plate=examples/plates/four-lines.toml
say() { printf '\n$ %s\n' "$*"; }

say chladni analyze $part --field sign --plot $out/analysis.png
$chladni analyze $part --field sign --plot $out/analysis.png

say chladni plan $part --plate $plate --out $out/plan.json --plot $out/plan.png
$chladni plan $part --plate $plate --out $out/plan.json --plot $out/plan.png

say chladni simulate $part --plate $plate --plan $out/plan.json --trials 200 --plot $out/traces.png
$chladni simulate $part --plate $plate --plan $out/plan.json --trials 200 --plot $out/traces.png

say chladni plate modes examples/plate-hinged-rod.toml --count 4 --plot $out/modes --write-modes $out/hinged-rod.toml
$chladni plate modes examples/plate-hinged-rod.toml --count 4 --plot $out/modes --write-modes $out/hinged-rod.toml

say chladni plan examples/parts/rectangle.json --plate $out/hinged-rod.toml --out $out/rectangle-plan.json
$chladni plan examples/parts/rectangle.json --plate $out/hinged-rod.toml --out $out/rectangle-plan.json

# The controller: the firmware in QEMU, its link on a TCP port, its flash in a file.
source scripts/lib/emulator.sh
emu=""
trap 'kill $emu 2>/dev/null; wait $emu 2>/dev/null || true' EXIT
start_emulator $chladni $out --flash-file $out/flash.bin --log $out/firmware.log --time-limit-s 900

say chladni device info --port $port
$chladni device info --port "$port"

# Calibration: sweep the (simulated) plate, find its resonance, hold an acceleration on it.
say chladni device sweep --port $port --from 100 --to 300 --points 41 --plot $out/sweep.png --out $out/sweep.csv
$chladni device sweep --port "$port" --from 100 --to 300 --points 41 --plot "$out/sweep.png" --out "$out/sweep.csv"

say chladni device drive --port $port --freq 180 --accel 20
$chladni device drive --port "$port" --freq 180 --accel 20
sleep 1
say chladni device status --port $port
$chladni device status --port "$port"
$chladni device stop --port "$port" >/dev/null

# Plans are kept on the controller: upload, list, run by name (and they survive a restart).
say chladni device upload --port $port $out/plan.json --name demo-orient
$chladni device upload --port "$port" "$out/plan.json" --name demo-orient

say chladni device plans --port $port
$chladni device plans --port "$port"

say chladni device run --port $port demo-orient --wait
$chladni device run --port "$port" demo-orient --wait

# A file can also run straight away (it goes to the controller's scratch slot).
say chladni device run-file --port $port $out/rectangle-plan.json --wait
$chladni device run-file --port "$port" "$out/rectangle-plan.json" --wait

say chladni device status --port $port --json
$chladni device status --port "$port" --json

echo
echo "figures: $out/analysis.png $out/plan.png $out/traces.png $out/modes/ $out/sweep.png; firmware log: $out/firmware.log"
