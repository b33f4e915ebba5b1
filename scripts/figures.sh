#!/usr/bin/env bash
# Regenerates every figure in docs/img from the tool's own commands, so none goes stale.
#
#   scripts/figures.sh [--out DIR] [--no-device]
#
# --out DIR     write the figures there instead of docs/img (to compare before replacing)
# --no-device   skip the two figures that need the QEMU controller (sweep.png: `chladni
#               emulator` + `device sweep`; dashboard.png: `chladni serve --http` in headless
#               Chromium, the cli_serve_http test); all others need only the host binary.
#
# The binary is the workspace's debug build (built here if needed); CHLADNI=PATH runs
# another one (e.g. target/release/chladni). Times are in docs/plan.md ("Figures").
set -euo pipefail

root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
out="$root/docs/img"
device=1
while [ $# -gt 0 ]; do
    case "$1" in
        --out) out="$(mkdir -p "$2" && cd "$2" && pwd)"; shift 2 ;;
        --no-device) device=0; shift ;;
        *) echo "usage: scripts/figures.sh [--out DIR] [--no-device]" >&2; exit 2 ;;
    esac
done
if [ -z "${CHLADNI:-}" ]; then
    cargo build -q -p chladni --bin chladni
    CHLADNI="$root/target/debug/chladni"
fi
scratch="$(mktemp -d)"
emulator_pid=""
cleanup() {
    if [ -n "$emulator_pid" ]; then kill "$emulator_pid" 2>/dev/null || true; fi
    rm -rf "$scratch"
}
trap cleanup EXIT
chladni() { "$CHLADNI" "$@" >/dev/null; }
step() { printf '%-34s' "$1"; SECONDS=0; }
done_() { echo "${SECONDS} s"; }

ex=examples
step "rest analyses (6)"
chladni analyze $ex/parts/rectangle.json --field sign --plot "$out/rectangle-sign.png"
chladni analyze $ex/parts/triangle.json --field sign --plot "$out/triangle-sign.png"
chladni analyze $ex/parts/trapezoid.json --field linear --plot "$out/trapezoid-linear.png"
chladni analyze $ex/parts/l-shape.json --field sine --wavelength 80 --plot "$out/l-shape-sine.png"
chladni analyze $ex/parts/plate-with-hole.json --field sign --gain-right 2.5 \
    --plot "$out/plate-with-hole-sign-skewed.png"
chladni analyze $ex/parts/key.svg --field linear --plot "$out/key-linear.png"
done_

step "plan figure"
chladni plan $ex/parts/triangle.json --plate $ex/plates/four-lines.toml \
    --plot "$out/plan-triangle.png"
done_

step "simulate: triangle (1000 trials)"
chladni simulate $ex/parts/triangle.json --plate $ex/plates/four-lines.toml \
    --plan $ex/plans/triangle-four-lines.json --trials 1000 --plot "$out/sim-triangle.png"
done_

step "simulate: animation (200 trials)"
chladni simulate $ex/parts/triangle.json --plate $ex/plates/four-lines.toml \
    --plan $ex/plans/triangle-four-lines.json --trials 200 --animate "$out/sim-triangle.gif"
done_

step "simulate: hyperbola (6 trials)"
chladni simulate $ex/parts/triangle.json --plate $ex/plates/hyperbola.toml \
    --plan $ex/plans/triangle-hyperbola-settle.json --trials 6 --plot "$scratch/hyp.png"
mv "$scratch/hyp.png" "$out/sim-hyperbola.png"
done_

step "plate modes (3 plates)"
chladni plate modes $ex/plate-cantilever.toml --count 5 --plot "$scratch/cantilever"
chladni plate modes $ex/plate-hinged-rod.toml --count 2 --plot "$scratch/hinged-rod"
chladni plate modes $ex/plate-free.toml --count 3 --plot "$scratch/free"
cp "$scratch/cantilever/mode-02.png" "$out/cantilever-mode-02.png"
cp "$scratch/cantilever/mode-05.png" "$out/cantilever-mode-05.png"
cp "$scratch/hinged-rod/mode-02.png" "$out/hinged-rod-mode-02.png"
cp "$scratch/free/mode-03.png" "$out/free-mode-03.png"
done_

step "particle on a string (2 runs)"
chladni physics string --e 0.9 --plot "$out/string-e0.9.png"
chladni physics string --e 0.1 --freq-hz 6.1 --x0 1.45 --duration 1500 \
    --plot "$out/string-e0.1.png"
done_

step "synthetic photos (2)"
cargo run -q -p chladni-core --example synthetic_photo -- "$out/synthetic-photo.png" >/dev/null
cargo run -q -p chladni-core --example synthetic_photo -- "$scratch/curved-photo.png" --curved \
    "$out/synthetic-photo-curved.png" >/dev/null
done_

if [ "$device" = 1 ]; then
    step "sweep on the QEMU controller"
    "$CHLADNI" emulator --json --time-limit-s 600 >"$scratch/emulator.json" 2>"$scratch/emulator.log" &
    emulator_pid=$!
    for _ in $(seq 600); do
        # The firmware's log lines come first; the ready line is the JSON with the port.
        if grep -q '"port"' "$scratch/emulator.json" || ! kill -0 "$emulator_pid" 2>/dev/null
        then break; fi
        sleep 0.5
    done
    port="$(sed -n 's/.*"port": *"\([^"]*\)".*/\1/p' "$scratch/emulator.json")"
    if [ -z "$port" ]; then
        echo "the emulator did not start:" >&2
        cat "$scratch/emulator.log" >&2
        exit 1
    fi
    chladni device sweep --port "$port" --from 100 --to 300 --points 41 --dwell-ms 120 \
        --plot "$out/sweep.png"
    kill "$emulator_pid"
    wait "$emulator_pid" 2>/dev/null || true
    emulator_pid=""
    done_

    step "dashboard (headless Chromium)"
    cargo test -q -p chladni --test integration cli_serve_http:: >"$scratch/http.log" 2>&1 ||
        { cat "$scratch/http.log" >&2; exit 1; }
    cp target/cell/dashboard.png "$out/dashboard.png"
    done_
fi
echo "figures in $out"
