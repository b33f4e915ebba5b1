#!/usr/bin/env bash
# Fuzzing with cargo-fuzz (libFuzzer) on the pinned nightly; docs/fuzzing.md.
#
#   scripts/fuzz.sh install              the pinned nightly and cargo-fuzz (fuzz/toolchain.env);
#                                        idempotent, offline when both are there
#   scripts/fuzz.sh seeds                (re)writes the seed corpora, fuzz/corpus/<target>/seed-*
#   scripts/fuzz.sh build                writes the seeds and builds every target (what smoke
#                                        does first)
#   scripts/fuzz.sh smoke [SECONDS]      every target for SECONDS each (default 20): fails on a
#                                        crash, prints executions and coverage per target
#   scripts/fuzz.sh run TARGET [-- ARGS] one target until libFuzzer's ARGS stop it
#                                        (e.g. -- -runs=10000000 or -max_total_time=3600), or ^C
#   scripts/fuzz.sh list                 the targets
#
# Targets build with debug assertions (integer overflow panics) and AddressSanitizer, into
# fuzz/target. Corpus: fuzz/corpus/<target>/ (generated seeds and what libFuzzer adds), plus
# the committed crash inputs of fuzz/regressions/<target>/, replayed at every start. A crash
# lands in fuzz/artifacts/<target>/; the log of the last run in fuzz/target/logs/<target>.log.
# Builds: `build` and `smoke` use AddressSanitizer with compare tracing (memory errors in the
# dependencies' unsafe code show at once); `run` leaves both out (the long runs: 3.5-6 times
# as fast, docs/fuzzing.md). FUZZ_SANITIZER=none|address|... and FUZZ_BUILD_FLAGS (cargo-fuzz
# build options, e.g. --no-trace-compares) override either default.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck source=../fuzz/toolchain.env
source fuzz/toolchain.env

die() { echo "fuzz: $*" >&2; exit 2; }

targets() {
  local f
  for f in fuzz/fuzz_targets/*.rs; do basename "$f" .rs; done
}

nightly_installed() {
  rustup toolchain list | grep -q "^$FUZZ_NIGHTLY-"
}

cargo_fuzz_installed() {
  [ "$(cargo "+$FUZZ_NIGHTLY" fuzz --version 2>/dev/null)" = "cargo-fuzz $CARGO_FUZZ_VERSION" ]
}

install() {
  if ! nightly_installed; then
    echo "fuzz: rustup toolchain install $FUZZ_NIGHTLY"
    rustup toolchain install --no-self-update --profile minimal "$FUZZ_NIGHTLY"
  fi
  if ! cargo_fuzz_installed; then
    echo "fuzz: cargo install cargo-fuzz@$CARGO_FUZZ_VERSION (about a minute)"
    cargo "+$FUZZ_NIGHTLY" install --locked "cargo-fuzz@$CARGO_FUZZ_VERSION" 2>&1 | tail -n 2
  fi
  cargo "+$FUZZ_NIGHTLY" fuzz --version
  rustup run "$FUZZ_NIGHTLY" rustc --version
}

require() {
  nightly_installed && cargo_fuzz_installed ||
    die "$FUZZ_NIGHTLY and cargo-fuzz $CARGO_FUZZ_VERSION are needed: run scripts/fuzz.sh install"
}

seeds() {
  cargo "+$FUZZ_NIGHTLY" run --quiet --manifest-path fuzz/Cargo.toml --no-default-features \
    --example seeds -- fuzz/corpus
}

# No `--cfg fuzzing`: sequential-storage 8 prints its page-state cache to stderr under it,
# which floods the log and slows the store's targets several times over.
# No defmt logging either (the workspace's .cargo/config.toml asks for `info`): on the host it
# encodes every line into a buffer that nothing reads, a cost on every refused request.
export DEFMT_LOG=off
# `cargo fuzz build` options for a command: its defaults (above), unless overridden.
set_build_args() {
  local sanitizer=address flags=""
  if [ "$1" = run ]; then sanitizer=none flags=--no-trace-compares; fi
  build_args=(--debug-assertions --no-cfg-fuzzing --sanitizer "${FUZZ_SANITIZER:-$sanitizer}")
  local extra
  read -r -a extra <<<"${FUZZ_BUILD_FLAGS-$flags}"
  build_args+=("${extra[@]}")
}

# libFuzzer's input cap per target, bytes: longer inputs only repeat what shorter ones do, at
# a cost that grows with their length (each harness also reads at most so many steps; its doc
# comment says how many). A -max_len given to `run` overrides it.
max_len() {
  case $1 in
    request_handler) echo 1024 ;;
    plan_store) echo 256 ;;
    part_analysis) echo 256 ;;
    *) echo 4096 ;;
  esac
}

build() {
  cargo "+$FUZZ_NIGHTLY" fuzz build "${build_args[@]}" "$@"
}

# A target's binary as `build` leaves it (cargo-fuzz builds for the host, release profile).
# The runs start it directly: `cargo fuzz run` would call cargo twice more per target.
binary() {
  local host
  host=$(rustup run "$FUZZ_NIGHTLY" rustc -vV | sed -n 's/^host: //p')
  echo "fuzz/target/$host/release/$1"
}

# One target; libFuzzer's output to the terminal (or not, with quiet=1) and to its log.
# Defaults first, so the caller's libFuzzer arguments override them.
fuzz_one() {
  local target=$1 quiet=$2
  shift 2
  mkdir -p fuzz/target/logs
  local log=fuzz/target/logs/$target.log t0=$SECONDS rc=0
  # The working corpus (new inputs go there), then the committed crash regressions, which
  # libFuzzer replays first: a crash that came back fails at once.
  mkdir -p "fuzz/corpus/$target"
  local corpora=("fuzz/corpus/$target")
  if [ -d "fuzz/regressions/$target" ]; then corpora+=("fuzz/regressions/$target"); fi
  mkdir -p "fuzz/artifacts/$target"
  # (ASAN_OPTIONS with what `cargo fuzz run` adds to it.)
  local run=(env ASAN_OPTIONS="${ASAN_OPTIONS:+$ASAN_OPTIONS:}detect_odr_violation=0"
    "$(binary "$target")" -artifact_prefix="fuzz/artifacts/$target/" "${corpora[@]}"
    -print_final_stats=1 -timeout=10 -max_len="$(max_len "$target")" "$@")
  if [ "$quiet" = 1 ]; then
    "${run[@]}" >"$log" 2>&1 || rc=$?
  else
    # ^C stops libFuzzer (which prints its final stats), not this script: the summary follows.
    local interrupted=0
    trap 'interrupted=1' INT
    "${run[@]}" 2>&1 | tee -i "$log" || rc=$?
    trap - INT
    # (72: libFuzzer's exit code when a signal stopped it, e.g. SIGINT sent to it alone.)
    if [ $interrupted = 1 ] || [ "$rc" = 72 ]; then
      summary "$target" "$log" $((SECONDS - t0))
      echo "fuzz: $target interrupted"
      return 130
    fi
  fi
  summary "$target" "$log" $((SECONDS - t0))
  if [ $rc != 0 ]; then
    echo "fuzz: $target FAILED (exit $rc); the end of $log:" >&2
    tail -n 40 "$log" >&2
    ls -1 fuzz/artifacts/"$target"/ 2>/dev/null | sed "s|^|fuzz: artifact fuzz/artifacts/$target/|" >&2
  fi
  return $rc
}

# Executions, speed and coverage from libFuzzer's last status line and final stats.
summary() {
  local target=$1 log=$2 secs=$3 status runs speed
  status=$(grep -E '^#[0-9]+.*cov: ' "$log" | tail -n 1 || true)
  runs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
  speed=$(sed -n 's/^stat::average_exec_per_sec: *//p' "$log" | tail -n 1)
  printf 'fuzz: %-16s %12s execs  %8s exec/s  %5d s  cov: %s  ft: %s  corp: %s\n' "$target" \
    "${runs:-?}" "${speed:-?}" "$secs" \
    "$(sed -n 's/.* cov: \([0-9]*\).*/\1/p' <<<"$status")" \
    "$(sed -n 's/.* ft: \([0-9]*\).*/\1/p' <<<"$status")" \
    "$(sed -n 's/.* corp: \([^ ]*\).*/\1/p' <<<"$status")"
}

cmd=${1:-}
[ $# -gt 0 ] && shift
set_build_args "$cmd"
case "$cmd" in
  install) install ;;
  list) targets ;;
  seeds) require; seeds ;;
  build) require; seeds; build ;;
  smoke)
    secs=${1:-20}
    [[ "$secs" =~ ^[0-9]+$ ]] || die "smoke takes a number of seconds, not '$secs'"
    require
    seeds
    build
    failed=()
    for t in $(targets); do
      fuzz_one "$t" 1 -max_total_time="$secs" || failed+=("$t")
    done
    if [ ${#failed[@]} -gt 0 ]; then
      die "crash or failure in: ${failed[*]} (see above; docs/fuzzing.md: reproduce and minimise)"
    fi
    ;;
  run)
    target=${1:-}
    [ -n "$target" ] || die "usage: scripts/fuzz.sh run TARGET [-- libFuzzer args]"
    shift
    targets | grep -x "$target" >/dev/null || die "no target '$target' (scripts/fuzz.sh list)"
    [ "${1:-}" = "--" ] && shift
    require
    seeds
    build "$target"
    fuzz_one "$target" 0 "$@"
    ;;
  *)
    awk 'NR > 1 && !/^#/ { exit } NR > 1 { sub(/^# ?/, ""); print }' "$0"
    [ -z "$cmd" ] || [ "$cmd" = help ] || [ "$cmd" = -h ] || exit 2
    ;;
esac
