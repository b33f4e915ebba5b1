#!/usr/bin/env bash
# The main job on a fresh machine: install what is missing, build, then
#   1. `chladni demo`: plan a sensorless sequence of plate modes that orients a triangle from
#      any start, draw it, check it by Monte Carlo simulation, start the controller in QEMU,
#      store the plan on it (closed loop: the controller holds each step's acceleration) and
#      run it while watching its telemetry, then sum up: the predicted pose, the success rate,
#      the run's timing by the controller's own sample clock against the plan's, faults;
#   2. where the triangle rests at a straight node (the analysis behind the plan's steps);
#   3. from plate dimensions alone (the paper's setup 2, hinged and driven by a rod): solve its
#      modes, draw its Chladni figures, and plan for a rectangle on them;
#   4. the controller again on the same flash file: the plan stored in 1 is still there, and a
#      calibration sweep finds the (simulated) plate's resonance;
#   5. `chladni demo --steer`: the feeder with a camera, without hardware. A virtual rig (three
#      triangles on the free plate, its modes warped) follows a new QEMU controller; the tool
#      learns what each mode really does from bursts seen by the rig's camera, steers the three
#      parts to three goals, plans sensorless on the learned plate, runs the plan and checks the
#      part it was made for in one frame (about 10 minutes; files named steer-*, learned.toml,
#      true-plate.toml).
# Outputs (plan files, figures, logs) go to target/demo/. `scripts/demo.sh --fast` runs the plan
# in 1 time-scaled (about 25 s instead of 71 s).
set -euo pipefail
cd "$(dirname "$0")/.."
fast=()
[ "${1:-}" = "--fast" ] && fast=(--fast)
scripts/install-deps.sh
cargo build --release --bin chladni
chladni=target/release/chladni
out=target/demo
mkdir -p "$out"
part=examples/parts/triangle.json
say() { printf '\n$ %s\n' "$*"; }

say chladni demo "${fast[@]}"
$chladni demo "${fast[@]}" --out $out

say chladni analyze $part --field sign --plot $out/analysis.png
$chladni analyze $part --field sign --plot $out/analysis.png

say chladni plate modes examples/plate-hinged-rod.toml --count 4 --plot $out/modes --write-modes $out/hinged-rod.toml
$chladni plate modes examples/plate-hinged-rod.toml --count 4 --plot $out/modes --write-modes $out/hinged-rod.toml

say chladni plan examples/parts/rectangle.json --plate $out/hinged-rod.toml --out $out/rectangle-plan.json
$chladni plan examples/parts/rectangle.json --plate $out/hinged-rod.toml --out $out/rectangle-plan.json

# The controller again, on the flash file `chladni demo` used: its plans survive a restart.
source scripts/lib/emulator.sh
emu=""
trap 'kill $emu 2>/dev/null; wait $emu 2>/dev/null || true' EXIT
start_emulator $chladni $out --flash-file $out/flash.bin --log $out/firmware-sweep.log --time-limit-s 300

say chladni device plans --port $port
$chladni device plans --port "$port"

# Calibration: sweep the (simulated) plate and find its resonance.
say chladni device sweep --port $port --from 100 --to 300 --points 41 --plot $out/sweep.png --out $out/sweep.csv
$chladni device sweep --port "$port" --from 100 --to 300 --points 41 --plot "$out/sweep.png" --out "$out/sweep.csv"

# The sweep's controller is done: stopped, so the next one (in QEMU, timed) has the cores.
kill $emu 2>/dev/null; wait $emu 2>/dev/null || true
emu=""

say chladni demo --steer --out $out
$chladni demo --steer --out $out

echo
echo "figures: $out/plan.png $out/traces.png $out/traces-plan.png $out/analysis.png $out/modes/ $out/sweep.png"
echo "plan files: $out/plan.json (as planned) $out/device-plan.json (as stored); firmware log: $out/firmware.log"
echo "camera story: $out/learned.toml (learned) $out/true-plate.toml (the rig's truth) $out/steer-plan.json $out/steer-verify.png"
