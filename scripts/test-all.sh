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

# The firmware boards and the fuzz targets build in target directories of their own, so they
# start now, beside the host crates' clippy, rustdoc and debug build, whose long one-crate
# stretches (chladni-core, the test binaries' links) leave a core idle. Their output is
# printed, and their failure fails the run, at their own step below.
background=$(mktemp -d)
emu=""
hitl_dir=""
# On any exit: no build left running, no emulator, no temporary files.
cleanup() {
  local job
  for job in $(jobs -p); do pkill -P "$job" 2>/dev/null || true; done
  kill $(jobs -p) $emu 2>/dev/null || true
  rm -rf "$background" ${hitl_dir:+"$hitl_dir"}
}
trap cleanup EXIT
(
  for board in qemu stm32l475 stm32l475-pwm; do
    echo "== clippy + build firmware ($board)"
    scripts/firmware.sh clippy "$board"
    scripts/firmware.sh size "$board"
  done
) >"$background/firmware.log" 2>&1 &
firmware_job=$!
scripts/fuzz.sh build >"$background/fuzz.log" 2>&1 &
fuzz_job=$!
# A background job's log, and its status.
finish() {
  local rc=0
  wait "$1" || rc=$?
  cat "$2"
  [ $rc = 0 ] || { echo "test-all: $3 failed (exit $rc)" >&2; exit $rc; }
}

step "clippy (host crates)"
cargo clippy --all-targets -- -D warnings

# Intra-doc links and the doc comments themselves: a broken link or a link to a private item
# fails here.
step "rustdoc (host crates, warnings are errors)"
RUSTDOCFLAGS="-D warnings" cargo doc --no-deps

# The README's and docs' marked command examples, run on the debug binary and compared with the
# output they show (scripts/docs-check.sh --update rewrites outdated ones).
# One debug build of the host crates, their tests and the `chladni` binary, which the docs
# check, the tests and the hardware-in-the-loop step all use (a plain `cargo build --bin
# chladni` resolves other features and would build every dependency again).
step "build (host crates and their tests, debug)"
cargo test --no-run

step "docs check (command examples)"
CHLADNI_BIN=target/debug/chladni scripts/docs-check.sh

# The fuzz crate is its own workspace (fuzz/): formatted and linted with the same stable
# toolchain; without libFuzzer's runtime, so no C++ is compiled for the check.
step "format + clippy (fuzz crate)"
cargo fmt --manifest-path fuzz/Cargo.toml -- --check
cargo clippy --manifest-path fuzz/Cargo.toml --all-targets --no-default-features -- -D warnings

step "firmware: clippy and build of every board (started after the format check)"
finish "$firmware_job" "$background/firmware.log" "the firmware build"

step "tests (host, on-target in QEMU, end-to-end)"
cargo test

# The firmware's board-independent app (link, drive) on the host: its lib is `test = false`
# so that the Cortex-M builds never try a std test harness; asked for by name here.
step "firmware app on the host"
cargo test -p chladni-firmware --lib
# Its host-side code (unit tests, the mock flash) is linted here too: the board builds above
# never compile it.
cargo clippy -p chladni-firmware --lib --tests --features mock-flash -- -D warnings

# Each fuzz target for a short time on the pinned nightly (the long runs are by hand:
# docs/fuzzing.md). Fails on any crash.
step "fuzz smoke run (${CHLADNI_FUZZ_SECONDS:-8} s per target)"
finish "$fuzz_job" "$background/fuzz.log" "the fuzz targets' build"
scripts/fuzz.sh smoke "${CHLADNI_FUZZ_SECONDS:-8}"

# scripts/hitl.sh runs the end-to-end suite against a port instead of its own QEMU; try that
# path here against a standalone `chladni emulator` (no board on CI).
step "hardware-in-the-loop path (scripts/hitl.sh against a standalone emulator)"
hitl_dir=$(mktemp -d)
source scripts/lib/emulator.sh
start_emulator target/debug/chladni "$hitl_dir" --time-limit-s 600 --log "$hitl_dir/firmware.log" \
  --flash-file "$hitl_dir/flash.bin"
CHLADNI_EXPECT_BOARD=qemu scripts/hitl.sh "$port" --no-flash
kill $emu

step "done in $(( $(date +%s) - start )) s"
