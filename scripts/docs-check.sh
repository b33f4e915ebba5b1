#!/usr/bin/env bash
# The README's and docs' command examples still run and print what they show (the blocks after
# a `<!-- docs-check -->` line; scripts/lib/docs_check.py says how they are read). QEMU-free, on
# the debug build. `--update` rewrites the outputs that changed (review the diff).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --quiet --bin chladni
exec python3 scripts/lib/docs_check.py target/debug/chladni "$@"
