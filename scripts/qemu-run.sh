#!/usr/bin/env bash
# Cargo runner for thumbv7em-none-eabihf: boots an ELF on QEMU's B-L475E-IOT01A and decodes its
# defmt log (semihosting on stdout) with defmt-print. Exits with the firmware's semihosting exit
# code; QEMU always runs under a timeout (QEMU_TIMEOUT seconds, default 120).
# Flash bank 2 is a fresh erased temporary file. USART1 goes nowhere unless QEMU_SERIAL
# names a chardev spec (e.g. socket,...).
# QEMU_EXTRA adds options (e.g. "-icount shift=0" for the instruction-counting benchmark).
set -uo pipefail
elf=${1:?usage: qemu-run.sh ELF}

# The board an image was built for, from its CHLADNI_BOARD symbol (NUL-padded name); empty if
# the image has none (not a Chladni firmware image).
board_of() {
  local addr hex
  addr=$(arm-none-eabi-nm "$1" 2>/dev/null | awk '$3 == "CHLADNI_BOARD" {print $1; exit}')
  [ -n "$addr" ] || return 0
  hex=$(arm-none-eabi-objdump -s --start-address=0x"$addr" \
          --stop-address="$(printf '0x%x' $((0x$addr + 16)))" "$1" |
        awk '/^ [0-9a-f]+ / {for (i = 2; i <= 5 && $i ~ /^[0-9a-f]+$/; i++) printf "%s", $i}')
  printf '%b' "$(printf '%s' "$hex" | fold -w2 | grep -v '^00$' | sed 's/^/\\x/' | tr -d '\n')"
}
# One runner serves the whole target, so `cargo run --features board-stm32l475` lands here too:
# refuse an image QEMU cannot run instead of booting it into a hang.
board=$(board_of "$elf")
if [ "$board" != qemu ]; then
  if [ -n "$board" ]; then
    echo "qemu-run: $elf is a '$board' image, not a QEMU-board image." >&2
  else
    echo "qemu-run: $elf is not a QEMU-board image (no CHLADNI_BOARD symbol)." >&2
  fi
  if [ "$board" = stm32l475 ]; then
    echo "qemu-run: it runs on the B-L475E-IOT01A: scripts/firmware.sh run stm32l475, or chladni flash --elf $elf" >&2
  else
    echo "qemu-run: build the QEMU image with --features board-qemu (scripts/firmware.sh run qemu)" >&2
  fi
  exit 2
fi
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
