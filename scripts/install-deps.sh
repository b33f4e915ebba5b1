#!/usr/bin/env bash
# Installs everything Chladni needs, from nothing but rustup and Debian's apt:
#   - the Rust toolchain named by rust-toolchain.toml, with its components and the
#     thumbv7em-none-eabihf target (`rustup toolchain install` reads the file; it also adds a
#     missing target or component to a toolchain that is already installed, which a plain
#     `cargo` call does not do)
#   - qemu-system-arm 10 from Debian bookworm-backports (the emulated B-L475E-IOT01A)
#   - binutils-arm-none-eabi (arm-none-eabi-size/nm/objdump: size report, image checks)
#   - python3-pymodbus 3.6 from bookworm-backports: the Modbus client that plays the PLC in
#     host/cli/tests/integration/cli_serve_modbus.rs (tests/cell/modbus_client.py, run by /usr/bin/python3)
#   - defmt-print (decodes the QEMU firmware's defmt log)
#   - chromium, chromium-driver and python3-selenium (the cell dashboard's browser test)
#   - for fuzzing, the pinned nightly toolchain and cargo-fuzz (scripts/fuzz.sh install; the
#     pins are in fuzz/toolchain.env)
# With --board it also installs probe-rs-tools (the `probe-rs` command, for
# `scripts/firmware.sh run stm32l475`: flash the real board and print its defmt log over RTT).
# Idempotent: every step checks first, so running it twice costs seconds.
set -euo pipefail
cd "$(dirname "$0")/.."

board=false
for arg in "$@"; do
  case "$arg" in
    --board) board=true ;;
    *) echo "install-deps: unknown option '$arg' (only --board)" >&2; exit 2 ;;
  esac
done

SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

# 1. Rust, from rust-toolchain.toml, before any cargo call.
if ! command -v rustup >/dev/null; then
  echo "install-deps: rustup not found. Install it (https://rustup.rs, or Debian's 'rustup'" >&2
  echo "package), make sure \$CARGO_HOME/bin is on PATH, and run this again." >&2
  exit 1
fi
rustup toolchain install --no-self-update  # the project never changes the user's rustup
if ! rustup target list --installed | grep -qx thumbv7em-none-eabihf; then
  echo "install-deps: thumbv7em-none-eabihf still missing after 'rustup toolchain install'" >&2
  exit 1
fi
rustc --version

# 2. Debian packages.
need_apt=()
if ! qemu-system-arm --version 2>/dev/null | grep -qE 'version (9|1[0-9])\.'; then
  need_apt+=(qemu-system-arm)
fi
command -v arm-none-eabi-size >/dev/null || need_apt+=(binutils-arm-none-eabi)
# The dashboard's browser test (host/cli/tests/integration/cli_serve_http.rs drives tests/cell/dashboard.py).
command -v chromium >/dev/null || need_apt+=(chromium)
command -v chromedriver >/dev/null || need_apt+=(chromium-driver)
/usr/bin/python3 -c 'import selenium' 2>/dev/null || need_apt+=(python3-selenium)
/usr/bin/python3 -c 'import pymodbus' 2>/dev/null || need_apt+=(python3-pymodbus)

if [ ${#need_apt[@]} -gt 0 ]; then
  if ! grep -rqs 'bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "install-deps: adding Debian bookworm-backports"
    echo 'deb http://deb.debian.org/debian bookworm-backports main' |
      $SUDO tee /etc/apt/sources.list.d/bookworm-backports.list >/dev/null
  fi
  echo "install-deps: apt-get install ${need_apt[*]}"
  $SUDO apt-get update -qq
  for pkg in "${need_apt[@]}"; do
    if [ "$pkg" = qemu-system-arm ] || [ "$pkg" = python3-pymodbus ]; then
      # Backports: QEMU ≥ 9 (checked above); pymodbus 3.6, the version the client script is
      # written and tested against (bookworm's own is 3.0).
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        -t bookworm-backports "$pkg"
    else
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$pkg"
    fi
  done
fi
qemu-system-arm --version | head -n 1
/usr/bin/python3 -c 'import pymodbus; print("pymodbus", pymodbus.__version__)'

# 3. Cargo-installed tools (into $CARGO_HOME/bin).
if ! command -v defmt-print >/dev/null; then
  echo "install-deps: cargo install defmt-print"
  cargo install --locked defmt-print@1.0.0 2>&1 | tail -n 2
fi
if $board && ! command -v probe-rs >/dev/null; then
  echo "install-deps: cargo install probe-rs-tools (a few minutes)"
  cargo install --locked probe-rs-tools@0.32.0 2>&1 | tail -n 2
fi

# 4. Fuzzing: the pinned nightly and cargo-fuzz (about 40 s from nothing; docs/fuzzing.md).
scripts/fuzz.sh install
