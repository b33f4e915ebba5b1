#!/usr/bin/env bash
# Proves that the README's two commands work on a fresh machine: clones the committed tree
# into a temporary folder, gives it an empty RUSTUP_HOME and CARGO_HOME (rustup-init with no
# toolchain at all, and a PATH without the machine's own ~/.cargo/bin), then runs `.ci/run` and
# `scripts/demo.sh` there and prints the wall time of each step.
#
#   scripts/check-fresh.sh            # the whole check (15-25 min on 2 cores)
#   KEEP=1 scripts/check-fresh.sh     # keep the temporary folder afterwards
#
# What it cannot make fresh: Debian packages (qemu-system-arm, binutils-arm-none-eabi) are
# system-wide; install-deps.sh checks and installs those by itself. It needs rustup on this
# machine only to copy its binary as rustup-init (the same multi-call binary).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)

rustup_bin=$(command -v rustup || true)
if [ -z "$rustup_bin" ]; then
  echo "check-fresh: rustup not found; it is needed as rustup-init" >&2
  exit 1
fi
if [ -n "$(git -C "$root" status --porcelain)" ]; then
  echo "check-fresh: note: uncommitted changes are not checked (the clone takes HEAD)" >&2
fi

tmp=$(mktemp -d /tmp/chladni-fresh.XXXXXX)
if [ -z "${KEEP:-}" ]; then trap 'rm -rf "$tmp"' EXIT; fi
echo "check-fresh: working in $tmp"

timings=()
timed() {
  local name=$1 t0=$SECONDS
  shift
  echo "== check-fresh: $name"
  "$@"
  timings+=("$(printf '%-22s %5d s' "$name" $((SECONDS - t0)))")
}

timed "clone" git clone -q "$root" "$tmp/repo"

# A machine with rustup and nothing else: no toolchain, no cargo tools.
export RUSTUP_HOME="$tmp/rustup" CARGO_HOME="$tmp/cargo"
PATH=$(printf '%s' "$PATH" | tr ':' '\n' | grep -v '/\.cargo/bin$' | paste -sd: -)
export PATH="$CARGO_HOME/bin:$PATH"
cp "$rustup_bin" "$tmp/rustup-init"
timed "rustup-init" "$tmp/rustup-init" -y --quiet --no-modify-path \
  --default-toolchain none --profile minimal
if command -v defmt-print >/dev/null || rustup toolchain list | grep -q -- "-unknown-linux"; then
  echo "check-fresh: the environment is not empty (found a toolchain or defmt-print)" >&2
  exit 1
fi

cd "$tmp/repo"
timed ".ci/run" env CI=true bash .ci/run </dev/null
timed "scripts/demo.sh" scripts/demo.sh </dev/null

echo
echo "check-fresh: passed from empty RUSTUP_HOME and CARGO_HOME"
printf '  %s\n' "${timings[@]}"
