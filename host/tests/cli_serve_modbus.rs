//! `chladni serve --modbus` end to end: the built binary serves the QEMU controller, and a
//! Modbus client nobody here wrote (pymodbus, through tests/cell/modbus_client.py) reads the
//! register map, is refused a bad slot, runs a stored plan and follows it to `done`; then QEMU
//! is killed and the state must read `error` with the link-lost fault code.
//!
//! Needs Debian's python3-pymodbus (scripts/install-deps.sh installs it); without it the test
//! fails naming that script, it never skips.

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use chladni::cell::modbus::{CommandResult, FAULT_LINK_DOWN};
use chladni::controller::emulator::{Emulator, EmulatorConfig};
use chladni_shared::icd::plan::{Level, Plan, Step};
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

const PYTHON: &str = "/usr/bin/python3";
const SLOT: u8 = 3;

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../tests/cell/modbus_client.py")
}

fn require_pymodbus() {
    let found = Command::new(PYTHON)
        .args(["-c", "import pymodbus"])
        .output()
        .is_ok_and(|out| out.status.success());
    assert!(
        found,
        "{PYTHON} cannot import pymodbus: run scripts/install-deps.sh (it installs Debian's \
         python3-pymodbus from bookworm-backports)"
    );
}

fn emulator() -> Emulator {
    let base =
        std::env::temp_dir().join(format!("chladni-cli-serve-modbus-{}", std::process::id()));
    let flash = base.with_extension("flash");
    let _ = std::fs::remove_file(&flash);
    let config = EmulatorConfig {
        time_limit: Some(Duration::from_secs(120)),
        log_file: Some(base.with_extension("log")),
        flash_file: Some(flash),
        ..Default::default()
    };
    Emulator::start(&config).expect("start the emulator")
}

/// Two steps of 1.5 s each, open loop, stored in [`SLOT`].
fn upload_plan(emu: &Emulator) {
    let step =
        |freq_mhz| Step { freq_mhz, level: Level::Drive(8_000), duration_ms: 1_500, ramp_ms: 50 };
    let plan = Plan {
        name: heapless::String::try_from("modbus").unwrap(),
        repeat: 1,
        steps: heapless::Vec::from_slice(&[step(120_000), step(150_000)]).unwrap(),
    };
    let mut client = emu.connect("cli_serve_modbus upload").expect("connect");
    client.upload(&plan, Some(SLOT), |_, _| {}).expect("upload");
    // Dropping the client releases ownership, so the cell's session may run the plan.
}

/// The `chladni serve` process, killed if the test ends early (a panic), so that it never
/// outlives the test holding its stderr.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `chladni serve` on a free port; its address from the first line it prints.
fn serve(emu: &Emulator) -> (Served, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["serve", "--port", &emu.address(), "--modbus", "127.0.0.1:0", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start chladni serve");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).expect("read stdout");
    let printed: Value =
        serde_json::from_str(line.trim()).unwrap_or_else(|e| panic!("{e}: {line}"));
    let address = printed["modbus"].as_str().unwrap_or_else(|| panic!("no address in {line}"));
    (Served(child), address.parse().expect("a socket address"))
}

/// Runs the client script; its transcript and the JSON object it printed last.
fn client(address: SocketAddr, args: &[&str]) -> (String, Value) {
    let out = Command::new(PYTHON)
        .arg(script())
        .args([address.ip().to_string(), address.port().to_string()])
        .args(args)
        .output()
        .expect("run the client script");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "client {args:?} failed: {stderr}\n{stdout}");
    let last = stdout.lines().last().unwrap_or_default();
    let json = serde_json::from_str(last).unwrap_or_else(|e| panic!("{e}: {stdout}"));
    (stdout, json)
}

fn readings(seen: &Value, key: &str) -> Vec<u64> {
    seen.as_array().unwrap().iter().map(|r| r[key].as_u64().unwrap()).collect()
}

/// The run seen by the client: busy first, remaining time falling to 0, done at the end.
fn check_run(out: &Value) {
    assert_eq!(out["bad_slot_exception"], 3, "a bad slot is IllegalDataValue");
    assert_eq!(out["bad_slot_result"], CommandResult::BadSlot.code());
    assert_eq!(out["unknown_command_exception"], 3);
    assert_eq!(out["past_the_map"], 2, "past the map is IllegalDataAddress");
    assert_eq!((&out["setup_exception"], &out["run_exception"]), (&Value::Null, &Value::Null));
    assert_eq!(out["holding_after_run"], serde_json::json!([SLOT, 0, 1]));
    let seen = &out["seen"];
    let states = readings(seen, "state");
    assert_eq!(states.first(), Some(&1), "the first reading after the run is busy: {states:?}");
    assert_eq!(states.last(), Some(&2), "the run ended done: {states:?}");
    // Until the controller reports the run (device run = command run), the registers still
    // describe the command before it: the time left is checked from then on.
    let ours: Vec<Value> = seen
        .as_array()
        .unwrap()
        .iter()
        .filter(|r| r["device_run"] == r["command_run"])
        .cloned()
        .collect();
    assert!(ours.len() >= 5, "the run was seen {} times", ours.len());
    let remaining = readings(&Value::Array(ours), "remaining_ms");
    assert!(remaining[0] > 1_000, "{remaining:?}");
    assert!(remaining.windows(2).all(|w| w[1] <= w[0]), "remaining time rose: {remaining:?}");
    assert_eq!(remaining.last(), Some(&0));
    let steps = readings(seen, "step");
    assert!(steps.contains(&0) && steps.contains(&1), "both steps seen: {steps:?}");
    let beats = readings(seen, "heartbeat");
    let first = out["before"]["heartbeat"].as_u64().unwrap();
    assert!(beats.last().unwrap().wrapping_sub(first) % 65_536 > 5, "{first} → {beats:?}");
    let last = seen.as_array().unwrap().last().unwrap();
    assert_eq!((last["slot"].as_u64(), last["fault"].as_u64()), (Some(u64::from(SLOT)), Some(0)));
    assert_eq!(last["command_run"], last["device_run"], "done is this client's run");
}

#[test]
fn a_plc_runs_a_plan_through_modbus_and_sees_the_link_lost() {
    require_pymodbus();
    let mut emu = emulator();
    upload_plan(&emu);
    let (mut serve, address) = serve(&emu);
    let (transcript, out) = client(address, &["run", &SLOT.to_string()]);
    let saved = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("modbus_transcript.txt");
    std::fs::write(&saved, &transcript).expect("save the transcript");
    eprintln!("transcript: {}", saved.display());
    check_run(&out);

    emu.kill();
    let killed = Instant::now();
    let (lost, out) = client(address, &["wait-link-lost"]);
    let took = killed.elapsed();
    let last = out["seen"].as_array().unwrap().last().unwrap().clone();
    assert_eq!(
        (last["state"].as_u64(), last["fault"].as_u64()),
        (Some(3), Some(u64::from(FAULT_LINK_DOWN))),
        "{lost}"
    );
    assert_eq!(last["link_up"], 0);
    eprintln!("link lost read as error after {:.1} s", took.as_secs_f64());
    let both =
        format!("{transcript}\n--- QEMU killed; polling until the link-lost error ---\n{lost}");
    std::fs::write(&saved, both).expect("save the transcript");
    assert!(took < Duration::from_secs(8), "took {took:?}:\n{lost}");

    kill(Pid::from_raw(serve.0.id() as i32), Signal::SIGTERM).unwrap();
    let status = serve.0.wait().unwrap();
    assert!(status.success(), "chladni serve ended with {status} on SIGTERM");
}
