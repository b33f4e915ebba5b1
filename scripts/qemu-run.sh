#!/usr/bin/env bash
# Cargo runner for thumbv7em-none-eabihf: boots an ELF on QEMU's B-L475E-IOT01A and decodes its
# defmt log (semihosting on stdout) with defmt-print. Exits with the firmware's semihosting exit
# code; QEMU always runs under a timeout (QEMU_TIMEOUT seconds, default 120).
# Flash bank 2 is a fresh erased temporary file. USART1 goes nowhere unless QEMU_SERIAL
# names a chardev spec (e.g. socket,...).
# QEMU_EXTRA adds options (e.g. "-icount shift=0" for the instruction-counting benchmark).
set -uo pipefail
elf=${1:?usage: qemu-run.sh ELF}
serial=(-serial null)
if [ -n "${QEMU_SERIAL:-}" ]; then serial=(-chardev "$QEMU_SERIAL,id=s0" -serial chardev:s0); fi
# Flash bank 2 lives in a fresh erased file for each run (see firmware/src/board/qemu/flash.rs).
flash=$(mktemp --suffix=.flash)
trap 'rm -f "$flash"' EXIT
head -c 524288 /dev/zero | tr '\0' '\377' >"$flash"
timeout --kill-after=5 "${QEMU_TIMEOUT:-120}" \
  qemu-system-arm -M b-l475e-iot01a -display none -monitor none "${serial[@]}" \
    -semihosting-config "enable=on,target=native,arg=$(basename "$elf"),arg=flash=$flash" ${QEMU_EXTRA:-} -kernel "$elf" |
  defmt-print --show-skipped-frames -e "$elf" stdin
status=${PIPESTATUS[0]}
if [ "$status" = 124 ] || [ "$status" = 137 ]; then
  echo "qemu-run: timed out after ${QEMU_TIMEOUT:-120} s: $elf" >&2
fi
exit "$status"
