#!/usr/bin/env bash
# Everything CI checks, from a fresh clone: installs what is missing, then formatting, lints,
# both firmware boards, and all tests (host unit/property tests, on-target tests on Cortex-M in
# QEMU, end-to-end tests of the host against the firmware in QEMU).
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
step() { printf '\n== %s (%ds)\n' "$*" $(( $(date +%s) - start )); }

step "install dependencies"
scripts/install-deps.sh

step "format"
cargo fmt --all -- --check

step "clippy (host crates)"
cargo clippy --all-targets -- -D warnings

for board in qemu stm32l475; do
  step "clippy + build firmware ($board)"
  scripts/firmware.sh clippy "$board"
  scripts/firmware.sh size "$board"
done

step "tests (host, on-target in QEMU, end-to-end)"
cargo test

step "done in $(( $(date +%s) - start )) s"
