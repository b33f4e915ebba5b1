#!/usr/bin/env bash
# The README's and docs' command examples still run and print what they show (the blocks after
# a `<!-- docs-check -->` line; scripts/lib/docs_check.py says how they are read). QEMU-free, on
# the debug build. `--update` rewrites the outputs that changed (review the diff).
set -euo pipefail
cd "$(dirname "$0")/.."
# CHLADNI_BIN: a binary built already (scripts/test-all.sh passes the one its test build made,
# so the debug build is not made twice with other features).
bin=${CHLADNI_BIN:-}
if [ -z "$bin" ]; then
  cargo build --quiet --bin chladni
  bin=target/debug/chladni
fi
exec python3 scripts/lib/docs_check.py "$bin" "$@"
