# Sourced by scripts that need a controller: starts `chladni emulator` in the background and
# waits until it prints its link address.
#   start_emulator CHLADNI DIR [emulator options...]
# Sets `emu` (its pid) and `port` (tcp://127.0.0.1:N); its stdout and stderr go to
# DIR/emulator.out and DIR/emulator.err. The caller stops it (kill "$emu").
start_emulator() {
  local chladni=$1 dir=$2
  shift 2
  "$chladni" emulator "$@" >"$dir/emulator.out" 2>"$dir/emulator.err" &
  emu=$!
  port=""
  # Up to 5 min: the first start may build the QEMU firmware.
  for _ in $(seq 1 1500); do
    port=$(grep -o 'tcp://[0-9.:]*' "$dir/emulator.out" | head -n 1 || true)
    [ -n "$port" ] && return 0
    kill -0 "$emu" 2>/dev/null || { echo "the emulator exited:"; cat "$dir/emulator.err"; return 1; }
    sleep 0.2
  done
  echo "the emulator did not come up"
  cat "$dir/emulator.err"
  return 1
}
