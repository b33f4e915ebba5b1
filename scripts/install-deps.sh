#!/usr/bin/env bash
# Installs what Chladni needs beyond the Rust toolchain (rust-toolchain.toml brings that):
#   - qemu-system-arm 10 from Debian bookworm-backports (the emulated B-L475E-IOT01A)
#   - binutils-arm-none-eabi (arm-none-eabi-size for the size report)
#   - defmt-print (decodes the QEMU firmware's defmt log)
# Idempotent: every step checks first, so running it twice costs seconds.
set -euo pipefail

SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi

need_apt=()
if ! qemu-system-arm --version 2>/dev/null | grep -qE 'version (9|1[0-9])\.'; then
  need_apt+=(qemu-system-arm)
fi
command -v arm-none-eabi-size >/dev/null || need_apt+=(binutils-arm-none-eabi)

if [ ${#need_apt[@]} -gt 0 ]; then
  if ! grep -rqs 'bookworm-backports' /etc/apt/sources.list /etc/apt/sources.list.d/; then
    echo "install-deps: adding Debian bookworm-backports"
    echo 'deb http://deb.debian.org/debian bookworm-backports main' |
      $SUDO tee /etc/apt/sources.list.d/bookworm-backports.list >/dev/null
  fi
  echo "install-deps: apt-get install ${need_apt[*]}"
  $SUDO apt-get update -qq
  for pkg in "${need_apt[@]}"; do
    if [ "$pkg" = qemu-system-arm ]; then
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
        -t bookworm-backports qemu-system-arm
    else
      $SUDO env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "$pkg"
    fi
  done
fi
qemu-system-arm --version | head -n 1

if ! command -v defmt-print >/dev/null; then
  echo "install-deps: cargo install defmt-print"
  cargo install --locked defmt-print@1.0.0 2>&1 | tail -n 2
fi
