//! `chladni serve --modbus` end to end: the built binary serves the QEMU controller, and a
//! Modbus client nobody here wrote (pymodbus, through tests/cell/modbus_client.py) reads the
//! register map, is refused a bad slot, runs a stored plan and follows it to `done`; then QEMU
//! is killed and the state must read `error` with the link-lost fault code. The same process
//! serves HTTP meanwhile, and a second client polls `/api/status` all through the run: both
//! front ends share the one link owner, so both must see the same run, in order.
//!
//! After the run a photo of the plate is posted to the same process's `POST /api/verify`, and
//! the PLC reads the check's result in input registers 16–20.
//!
//! Needs Debian's python3-pymodbus (scripts/install-deps.sh installs it); without it the test
//! fails naming that script, it never skips.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use chladni_cell::modbus::{CommandResult, FAULT_LINK_DOWN};
use chladni_device::emulator::Emulator;
use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use serde_json::Value;

use crate::support;
use support::emu;

const PYTHON: &str = "/usr/bin/python3";
const SLOT: u8 = 3;

fn script() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/cell/modbus_client.py")
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

/// The `chladni serve` process, killed if the test ends early (a panic), so that it never
/// outlives the test holding its stderr.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `chladni serve` on free ports, Modbus and HTTP; their addresses from the lines it prints.
fn serve(emu: &Emulator) -> (Served, SocketAddr, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["serve", "--port", &emu.address(), "--json"])
        .args(["--modbus", "127.0.0.1:0", "--http", "127.0.0.1:0"])
        .args(support::photos::serve_args())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .spawn()
        .expect("start chladni serve");
    let mut stdout = BufReader::new(child.stdout.take().unwrap());
    let mut printed = serde_json::Map::new();
    for _ in 0..2 {
        let mut line = String::new();
        stdout.read_line(&mut line).expect("read stdout");
        let object: Value =
            serde_json::from_str(line.trim()).unwrap_or_else(|e| panic!("{e}: {line}"));
        printed.extend(object.as_object().cloned().unwrap_or_default());
    }
    let modbus = printed["modbus"].as_str().expect("the modbus address").parse().unwrap();
    let url = printed["http"].as_str().expect("the http URL");
    let http = url.trim_start_matches("http://").trim_end_matches('/').parse().unwrap();
    (Served(child), modbus, http)
}

/// `GET /api/status` over a plain socket: the status code and the JSON body.
fn http_status(address: SocketAddr) -> (u16, Value) {
    let mut stream = TcpStream::connect(address).expect("connect to the HTTP front end");
    stream.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(stream, "GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n")
        .unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("read the HTTP response");
    let (head, body) = response.split_once("\r\n\r\n").unwrap_or_else(|| panic!("{response}"));
    let code = head.split(' ').nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, serde_json::from_str(body).unwrap_or_else(|e| panic!("{e}: {body}")))
}

/// The camera: a photo of two keys (one as planned, one off) posted to `POST /api/verify`.
fn post_photo(address: SocketAddr) {
    let mut png = Vec::new();
    support::photos::one_good_one_off()
        .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
        .unwrap();
    let mut stream = TcpStream::connect(address).expect("connect to the HTTP front end");
    stream.set_read_timeout(Some(Duration::from_secs(30))).unwrap();
    write!(
        stream,
        "POST /api/verify HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\nContent-Type: \
         image/png\r\nContent-Length: {}\r\n\r\n",
        png.len()
    )
    .unwrap();
    stream.write_all(&png).unwrap();
    let mut response = String::new();
    stream.read_to_string(&mut response).expect("read the HTTP response");
    assert!(response.starts_with("HTTP/1.1 200"), "{response}");
}

/// Polls `/api/status` every 50 ms until `stop`, and after `stop` until the cell no longer says
/// busy (the PLC may see done a poll before HTTP does; 5 s at most): every answer's (state,
/// last_run, device run).
fn poll_http(address: SocketAddr, stop: Arc<AtomicBool>) -> Vec<(String, u64, u64)> {
    let mut seen: Vec<(String, u64, u64)> = Vec::new();
    let mut stopped_at = None;
    loop {
        if stopped_at.is_none() && stop.load(Ordering::Relaxed) {
            stopped_at = Some(Instant::now());
        }
        if let Some(at) = stopped_at {
            let settled = seen.last().is_some_and(|s| s.0 != "busy");
            if settled || at.elapsed() > Duration::from_secs(5) {
                return seen;
            }
        }
        let (code, status) = http_status(address);
        assert_eq!(code, 200, "{status}");
        let state = status["state"].as_str().unwrap_or_default().to_owned();
        let last_run = status["last_run"].as_u64().unwrap_or(0);
        let device_run = status["device"]["run"].as_u64().unwrap_or(0);
        seen.push((state, last_run, device_run));
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// What the HTTP client saw while the PLC ran the plan: the same run, busy then done, and the
/// controller's run number never going back (answers of one session, in order).
fn check_http_alongside(seen: &[(String, u64, u64)], plc: &Value) {
    let run = plc["seen"].as_array().unwrap().last().unwrap()["command_run"].as_u64().unwrap();
    let ours: Vec<&(String, u64, u64)> = seen.iter().filter(|s| s.1 == run).collect();
    assert!(ours.iter().any(|s| s.0 == "busy"), "HTTP never saw run {run} busy: {seen:?}");
    assert_eq!(ours.last().map(|s| s.0.as_str()), Some("done"), "{seen:?}");
    assert!(seen.windows(2).all(|w| w[1].2 >= w[0].2), "device run went back: {seen:?}");
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
fn a_plc_runs_a_plan_through_modbus_while_http_watches_and_both_see_the_link_lost() {
    require_pymodbus();
    let mut emu = emu::emulator_for("cli-serve-modbus", Duration::from_secs(120));
    // Two steps of 1.5 s each, open loop; the upload's session is gone when it returns, so
    // the cell's session may run the plan.
    emu::upload(&emu, &emu::open_loop_plan("modbus", &[120_000, 150_000], 8_000, 1_500), SLOT);
    let (mut serve, address, http) = serve(&emu);
    let stop = Arc::new(AtomicBool::new(false));
    let poller = std::thread::spawn({
        let stop = stop.clone();
        move || poll_http(http, stop)
    });
    let (transcript, out) = client(address, &["run", &SLOT.to_string()]);
    stop.store(true, Ordering::Relaxed);
    let by_http = poller.join().expect("the HTTP poller");
    eprintln!("HTTP polled the status {} times during the Modbus run", by_http.len());
    let saved = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("modbus_transcript.txt");
    std::fs::write(&saved, &transcript).expect("save the transcript");
    eprintln!("transcript: {}", saved.display());
    check_run(&out);
    check_http_alongside(&by_http, &out);
    // No photo checked yet: sequence 0, result 0, rate "none".
    assert_eq!(out["before"]["verify"], serde_json::json!([0, 0, 0, 0, 0xFFFF]));
    post_photo(http);
    let (checked, out) = client(address, &["verify"]);
    // Photo 1: off (2), 2 parts found, 1 as planned, 50.0 %.
    assert_eq!(out["verify"], serde_json::json!([1, 2, 2, 1, 500]), "{checked}");

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
    let (code, status) = http_status(http);
    assert_eq!(code, 200);
    assert_eq!(
        (&status["state"], &status["link_up"]),
        (&Value::from("error"), &Value::from(false))
    );
    eprintln!("link lost read as error after {:.1} s", took.as_secs_f64());
    let both =
        format!("{transcript}\n--- QEMU killed; polling until the link-lost error ---\n{lost}");
    std::fs::write(&saved, both).expect("save the transcript");
    assert!(took < Duration::from_secs(8), "took {took:?}:\n{lost}");

    kill(Pid::from_raw(serve.0.id() as i32), Signal::SIGTERM).unwrap();
    let status = serve.0.wait().unwrap();
    assert!(status.success(), "chladni serve ended with {status} on SIGTERM");
}
