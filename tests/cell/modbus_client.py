#!/usr/bin/python3
"""A PLC's side of `chladni serve --modbus`, played by pymodbus (a Modbus client nobody here
wrote): it reads the register map of docs/cell.md, refuses a bad slot, runs a plan and follows
it to the end, or waits for the link-lost error.

Prints a transcript for people (each request and the registers it read, decoded) and, as its
last line, one JSON object with what it saw, for host/cli/tests/integration/cli_serve_modbus.rs to check.

    modbus_client.py HOST PORT run SLOT          # map, bad slot, run SLOT, poll until done
    modbus_client.py HOST PORT wait-link-lost    # poll until state 3 with fault 100
    modbus_client.py HOST PORT verify            # the last photo check's registers

Exit status: 0 when the conversation ran (the checks are the caller's), 1 when a request failed
in a way a PLC could not go on from (no connection, no answer), 2 for bad arguments.
"""

import json
import sys
import time

try:
    from pymodbus.client import ModbusTcpClient
    from pymodbus.pdu import ExceptionResponse
except ImportError:
    print("pymodbus is missing: run scripts/install-deps.sh (python3-pymodbus from "
          "bookworm-backports)", file=sys.stderr)
    sys.exit(3)

UNIT = 1
INPUT_NAMES = [
    "state", "link_up", "slot", "step", "repetition", "remaining_ms_hi", "remaining_ms_lo",
    "accel_0.01mps2", "freq_0.1hz", "fault", "result", "heartbeat", "command_run_hi",
    "command_run_lo", "device_run_hi", "device_run_lo",
    "verify_seq", "verify_result", "verify_found", "verify_oriented", "verify_rate_0.1%",
]
VERIFY_RESULTS = {0: "none", 1: "ok", 2: "off", 3: "empty", 4: "refused"}
HOLDING_NAMES = ["slot", "repeat", "command"]
STATES = {0: "idle", 1: "busy", 2: "done", 3: "error"}
EXCEPTIONS = {1: "IllegalFunction", 2: "IllegalDataAddress", 3: "IllegalDataValue",
              4: "ServerDeviceFailure", 11: "GatewayTargetDevice"}
START = time.monotonic()


def say(text):
    print(f"[{time.monotonic() - START:6.2f} s] {text}", flush=True)


class Failed(Exception):
    """A request got no usable answer."""


def exception_of(reply):
    """The exception code of a reply, or None for a normal answer."""
    if isinstance(reply, ExceptionResponse):
        return reply.exception_code
    if reply.isError():
        raise Failed(f"no answer: {reply}")
    return None


def read(client, kind, address, count):
    """Reads registers (kind "input": FC04, "holding": FC03); prints and returns them."""
    if kind == "input":
        reply, names, fc = client.read_input_registers(address, count, slave=UNIT), INPUT_NAMES, 4
    else:
        reply, names, fc = client.read_holding_registers(address, count, slave=UNIT), HOLDING_NAMES, 3
    code = exception_of(reply)
    if code is not None:
        say(f"FC{fc:02d} read {kind} {address}..{address + count - 1} -> exception {code} "
            f"({EXCEPTIONS.get(code, '?')})")
        return None
    regs = list(reply.registers)
    shown = ", ".join(f"{names[address + i]}={v}" for i, v in enumerate(regs))
    say(f"FC{fc:02d} read {kind} {address}..{address + count - 1} -> {shown}")
    return regs


def write(client, address, values):
    """Writes holding registers (FC06 for one, FC16 for several); the exception code or None."""
    if len(values) == 1:
        reply, fc = client.write_register(address, values[0], slave=UNIT), 6
    else:
        reply, fc = client.write_registers(address, values, slave=UNIT), 16
    code = exception_of(reply)
    names = ", ".join(f"{HOLDING_NAMES[address + i]}={v}" for i, v in enumerate(values))
    outcome = "ok" if code is None else f"exception {code} ({EXCEPTIONS.get(code, '?')})"
    say(f"FC{fc:02d} write {names} -> {outcome}")
    return code


def decode(regs):
    """The input registers as named values (32-bit ones joined, high word first)."""
    return {
        "state": regs[0], "link_up": regs[1], "slot": regs[2], "step": regs[3],
        "repetition": regs[4], "remaining_ms": regs[5] << 16 | regs[6],
        "accel_mps2": regs[7] / 100, "freq_hz": regs[8] / 10, "fault": regs[9],
        "result": regs[10], "heartbeat": regs[11], "command_run": regs[12] << 16 | regs[13],
        "device_run": regs[14] << 16 | regs[15], "verify": regs[16:21],
    }


def poll(client, until, limit_s):
    """Reads the whole input map every 100 ms until `until(values)`; every reading."""
    seen = []
    deadline = time.monotonic() + limit_s
    while time.monotonic() < deadline:
        regs = read(client, "input", 0, len(INPUT_NAMES))
        if regs is None:
            raise Failed("reading the input registers was refused")
        values = decode(regs)
        values["t_s"] = round(time.monotonic() - START, 3)
        seen.append(values)
        say(f"  = {STATES.get(values['state'], '?')}, step {values['step']}, "
            f"{values['remaining_ms']} ms left, {values['freq_hz']} Hz, "
            f"{values['accel_mps2']} m/s², fault {values['fault']}")
        if until(values):
            break
        time.sleep(0.1)
    return seen


def run(client, slot):
    """Reads the map, tries a bad slot, runs `slot` and follows it until done (or error)."""
    out = {}
    read(client, "holding", 0, len(HOLDING_NAMES))
    before = read(client, "input", 0, len(INPUT_NAMES))
    out["before"] = decode(before)
    out["past_the_map"] = exception_of(client.read_input_registers(len(INPUT_NAMES), 1, slave=UNIT))
    say(f"FC04 read input {len(INPUT_NAMES)} (past the map) -> exception {out['past_the_map']}")
    out["bad_slot_exception"] = write(client, 0, [200])
    out["bad_slot_result"] = read(client, "input", 10, 1)[0]
    out["unknown_command_exception"] = write(client, 2, [7])
    out["setup_exception"] = write(client, 0, [slot, 0])
    out["run_exception"] = write(client, 2, [1])
    out["holding_after_run"] = read(client, "holding", 0, len(HOLDING_NAMES))
    seen = poll(client, lambda v: v["state"] in (2, 3), 30)
    out["seen"] = seen
    return out


def wait_link_lost(client):
    """Polls until the state reads error with the link-lost fault code."""
    seen = poll(client, lambda v: v["state"] == 3 and v["fault"] == 100, 20)
    return {"seen": seen}


def verify(client):
    """Reads the last photo check's registers (16..20) and decodes them."""
    regs = read(client, "input", 16, 5)
    if regs is None:
        raise Failed("reading the verification registers was refused")
    seq, result, found, oriented, rate = regs
    shown = "none" if rate == 0xFFFF else f"{rate / 10} %"
    say(f"  = photo check {seq}: {VERIFY_RESULTS.get(result, '?')}, {oriented} of {found} parts "
        f"as planned ({shown})")
    return {"verify": regs}


def main(argv):
    modes = ("run", "wait-link-lost", "verify")
    if len(argv) < 4 or argv[3] not in modes or (argv[3] == "run") != (len(argv) == 5):
        print(__doc__, file=sys.stderr)
        return 2
    host, port, mode = argv[1], int(argv[2]), argv[3]
    client = ModbusTcpClient(host, port=port, timeout=5, retries=0)
    if not client.connect():
        print(f"cannot connect to {host}:{port}", file=sys.stderr)
        return 1
    say(f"connected to {host}:{port} (pymodbus)")
    try:
        if mode == "run":
            out = run(client, int(argv[4]))
        elif mode == "verify":
            out = verify(client)
        else:
            out = wait_link_lost(client)
    except Failed as e:
        print(f"modbus_client: {e}", file=sys.stderr)
        return 1
    finally:
        client.close()
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
