#!/usr/bin/env bash
# Builds, checks or tests the firmware for one board, always in target/firmware so that the
# host-side `cargo test` (which may build the QEMU image itself) never waits on its lock.
#   scripts/firmware.sh build  qemu|stm32l475   -> prints the ELF path (one per board) on stdout
#                                                  and the image's sizes on stderr
#   scripts/firmware.sh clippy qemu|stm32l475
#   scripts/firmware.sh test   qemu             -> on-target tests in QEMU
#   scripts/firmware.sh size   qemu|stm32l475
#   scripts/firmware.sh sizes  all             -> the size table of docs/firmware.md for every
#                                                  board; `sizes doc` writes it into the doc
#   scripts/firmware.sh run    qemu             -> boot in QEMU, defmt log on stdout (Ctrl-C ends;
#                                                  `chladni emulator` is the one with a link)
#   scripts/firmware.sh run    stm32l475        -> flash the board with probe-rs, then its defmt
#                                                  log over RTT (installs probe-rs-tools if missing);
#                                                  the probe does not catch HardFault or reset, so
#                                                  the firmware's own handlers run (fail-safe, watchdog)
#   scripts/firmware.sh bench  qemu             -> per-sample cost of the drive (QEMU -icount)
#   scripts/firmware.sh bench-link qemu         -> instructions of UploadChunk and RunPlan (-icount)
#   scripts/firmware.sh build-bin qemu NAME     -> builds firmware/src/bin/NAME, prints its ELF path
#   scripts/firmware.sh frames qemu|stm32l475   -> the largest stack frames of the image (bytes a
#                                                  function reserves at entry: pushes + sub sp)
# BOARD stm32l475-pwm is the B-L475E-IOT01A with the PWM drive (features board-stm32l475 +
# drive-pwm: TIM3 ch3 on PB0 instead of the DAC; docs/pwm.md); build, clippy, size and run
# take it like stm32l475.
set -euo pipefail
cd "$(dirname "$0")/.."
cmd=${1:?usage: firmware.sh build|clippy|test|size|sizes|run|bench BOARD}
board=${2:?usage: firmware.sh build|clippy|test|size|sizes|run|bench BOARD}
# The size table of docs/firmware.md, one row per board (a markdown table on stdout).
size_table() {
  echo "| image | flash | static RAM | stack (SRAM2) |"
  echo "|-------|------:|-----------:|--------------:|"
  for b in qemu stm32l475 stm32l475-pwm; do
    "$0" size "$b" | awk -v b="$b" '{printf "| %s | %d B | %d B | 32768 B |\n", b, $4, $8}'
  done
}
if [ "$cmd" = sizes ]; then
  case "$board" in
    all) size_table; exit ;;
    doc) table=$(size_table) || exit 1
         # Between the markers in docs/firmware.md, nothing else touched.
         awk -v table="$table" '/<!-- sizes:begin/ {print; print table; skip=1; next}
              /<!-- sizes:end/ {skip=0} !skip {print}' docs/firmware.md >docs/firmware.md.new &&
         mv docs/firmware.md.new docs/firmware.md && printf '%s\n' "$table"; exit ;;
    *) echo "usage: firmware.sh sizes all|doc" >&2; exit 2 ;;
  esac
fi
case "$board" in
  qemu|stm32l475) features="board-$board" ;;
  stm32l475-pwm) features="board-stm32l475,drive-pwm" ;;
  *) echo "unknown board '$board' (qemu, stm32l475 or stm32l475-pwm)" >&2; exit 2 ;;
esac
args=(-p chladni-firmware --target thumbv7em-none-eabihf --profile firmware
      --features "$features" --target-dir target/firmware)
elf=target/firmware/thumbv7em-none-eabihf/firmware/chladni-firmware
# One line of an image's sizes: flash = vector table + text + rodata + data, static RAM =
# data + bss + uninit (the stack has SRAM2 to itself). `sizes` reads fields 4 and 8.
image_size() {
  arm-none-eabi-size -A "$1" | awk -v b="$2" '
    $1 ~ /^\.(vector_table|text|rodata)$/ {flash += $2}
    $1 ~ /^\.data$/ {flash += $2; ram += $2}
    $1 ~ /^\.(bss|uninit)$/ {ram += $2}
    END {printf "firmware %s: flash %d B, static RAM %d B\n", b, flash, ram}'
}
case "$cmd" in
  build)
    # Both boards link to the same path; keep one copy per board. Build and copy under one
    # lock, so that two builds for different boards at once cannot swap their images.
    mkdir -p target/firmware
    (
      flock 9
      cargo build "${args[@]}" --bin chladni-firmware >&2
      cp "$elf" "target/firmware/chladni-firmware-$board.elf"
    ) 9>target/firmware/.build.lock
    [ -n "${FIRMWARE_SIZE_QUIET:-}" ] || image_size "target/firmware/chladni-firmware-$board.elf" "$board" >&2
    echo "target/firmware/chladni-firmware-$board.elf" ;;
  clippy) cargo clippy "${args[@]}" --all-targets -- -D warnings ;;
  test) cargo test "${args[@]}" ;;
  size) elf=$(FIRMWARE_SIZE_QUIET=1 "$0" build "$board") && image_size "$elf" "$board" ;;
  run)
    elf=$("$0" build "$board")
    if [ "$board" = qemu ]; then
      QEMU_TIMEOUT=${QEMU_TIMEOUT:-86400} exec scripts/qemu-run.sh "$elf"
    fi
    scripts/install-deps.sh --board
    # probe-rs 0.32 halts the core at the HardFault and reset vectors by default (vector
    # catch), before the fail-safe parks the output and with TIM6 frozen by the debug freeze;
    # --no-catch-hardfault/--no-catch-reset let the firmware's handlers and the watchdog's
    # reset run as they do without a probe.
    exec probe-rs run --chip "${CHLADNI_CHIP:-STM32L475VGTx}" ${CHLADNI_PROBE:+--probe "$CHLADNI_PROBE"} \
      --no-catch-hardfault --no-catch-reset "$elf" ;;
  bench) [ "$board" = qemu ] || { echo "bench runs on the qemu board only" >&2; exit 2; }
         elf=$("$0" build-bin qemu bench_drive) &&
         QEMU_EXTRA="-icount shift=0" scripts/qemu-run.sh "$elf" ;;
  bench-link) [ "$board" = qemu ] || { echo "bench-link runs on the qemu board only" >&2; exit 2; }
         elf=$("$0" build-bin qemu bench_link) &&
         QEMU_EXTRA="-icount shift=0" scripts/qemu-run.sh "$elf" ;;
  frames) elf=$("$0" build "$board") &&
    # Per function: the registers pushed (push/stmdb/vpush) and the `sub sp` before the first
    # use, i.e. the frame it reserves at entry. Async poll functions show their temporaries.
    arm-none-eabi-objdump -d --no-show-raw-insn -C "$elf" | awk '
      /^[0-9a-f]+ <.*>:$/ { fn = $0; sub(/^[0-9a-f]+ </, "", fn); sub(/>:$/, "", fn); push = 0; seen = 0; next }
      seen { next }
      /\t(push|stmdb)(\.w)?\t/ { s = $0; n = gsub(/,/, ",", s) + 1; if ($0 ~ /stmdb/) n--; push += 4 * n; next }
      /\tvpush\t/ { s = $0; if (match(s, /d[0-9]+-d[0-9]+/)) { split(substr(s, RSTART, RLENGTH), a, "-");
                       push += 8 * (substr(a[2], 2) - substr(a[1], 2) + 1) } else push += 8; next }
      /\t(sub|subw|sub\.w)\tsp, / { s = $0; sub(/.*#/, "", s); sub(/[^0-9].*/, "", s)
                       printf "%8d B  %s\n", s + push, substr(fn, 1, 150); seen = 1 }' |
      sort -rn | head -n "${FRAMES_TOP:-15}" ;;
  build-bin) name=${3:?usage: firmware.sh build-bin BOARD NAME}
    cargo build "${args[@]}" --bin "$name" >&2
    echo "target/firmware/thumbv7em-none-eabihf/firmware/$name" ;;
  *) echo "unknown command '$cmd'" >&2; exit 2 ;;
esac
