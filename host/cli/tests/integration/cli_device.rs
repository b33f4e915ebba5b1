//! `chladni device …` through the built binary against the real QEMU controller (behind the
//! emulator's link proxy): the JSON shapes, a busy controller named at once, the telemetry
//! monitor, and Ctrl-C.

use std::io::{BufRead, BufReader};
use std::process::Stdio;
use std::time::{Duration, Instant};

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;

use crate::support;
use support::cli::{chladni, keys, ok_json as json_of};

/// This file's controller for test `name`.
fn emulator(name: &str) -> chladni_device::emulator::Emulator {
    support::emu::emulator(&format!("cli-device-{name}"))
}

#[test]
fn status_info_ping_config_and_list_print_their_json_shapes() {
    let emu = emulator("json");
    let port = emu.address();
    let status = json_of(&chladni(&["device", "status", "--port", &port, "--json"]));
    assert_eq!(keys(&status), chladni_device::json::STATUS_KEYS);
    assert_eq!(status["state"], "idle");
    let info = json_of(&chladni(&["device", "info", "--port", &port, "--json"]));
    // The board's value is checked end to end (tests/e2e.rs); here, the shape.
    assert_eq!(keys(&info), ["board", "build_id", "firmware_version", "protocol_version"]);
    assert_eq!(info["protocol_version"], chladni_shared::icd::link::PROTOCOL_VERSION);
    let ping = json_of(&chladni(&["device", "ping", "--port", &port, "--count", "3", "--json"]));
    assert_eq!(ping["count"], 3);
    let config = json_of(&chladni(&["device", "config", "get", "--port", &port, "--json"]));
    assert_eq!(
        keys(&config),
        [
            "abort_band_db",
            "band_ms",
            "check_effort",
            "check_min_mps2",
            "check_ms",
            "fault_accel_mps2",
            "max_accel_mps2",
            "max_amplitude",
            "max_freq_hz",
            "max_steps",
            "max_total_ms",
            "min_freq_hz",
            "no_data_ms",
            "open_loop_effort",
            "open_loop_mps2",
            "open_loop_ms",
            "saturation_ms",
            "warn_band_db"
        ]
    );
    assert_eq!(
        (config["max_steps"].as_u64(), config["max_freq_hz"].as_f64()),
        (Some(256), Some(2000.0))
    );
    let one = chladni(&["device", "config", "get", "min_freq_hz", "--port", &port]);
    assert_eq!(String::from_utf8_lossy(&one.stdout).trim(), "1");
    let list = json_of(&chladni(&["device", "list", "--json"]));
    assert!(list["ports"].is_array(), "{list}");

    let drive = json_of(&chladni(&[
        "device",
        "drive",
        "--port",
        &port,
        "--freq",
        "120",
        "--amplitude",
        "0.25",
        "--json",
    ]));
    assert_eq!(keys(&drive), ["accel_mps2", "amplitude", "freq_hz", "run"]);
    let stop = json_of(&chladni(&["device", "stop", "--port", &port, "--json"]));
    assert!(stop["run"].as_u64() > drive["run"].as_u64(), "{stop} after {drive}");
}

#[test]
fn a_second_program_is_told_at_once_who_holds_the_controller() {
    let emu = emulator("busy");
    let mut owner = emu.connect("the owner in a test").expect("connect");
    let run = owner.drive(100_000, chladni_shared::icd::plan::Level::Drive(2_000)).expect("drive");
    let started = Instant::now();
    let out = chladni(&[
        "device",
        "drive",
        "--port",
        &emu.address(),
        "--freq",
        "123",
        "--amplitude",
        "0.1",
    ]);
    let took = started.elapsed();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("the controller is busy: the owner in a test holds it"), "{stderr}");
    assert!(took < Duration::from_secs(2), "took {took:?}");
    // Anyone may stop the shaker, even while another program owns the controller.
    let stop = json_of(&chladni(&["device", "stop", "--port", &emu.address(), "--json"]));
    assert!(stop["run"].as_u64() > Some(u64::from(run.0)), "{stop}");
}

/// Starts `chladni device ARGS…` with stdout piped; returns it and a reader of its lines.
fn spawn(args: &[&str]) -> (std::process::Child, BufReader<std::process::ChildStdout>) {
    let mut child = support::cli::command()
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let stdout = BufReader::new(child.stdout.take().unwrap());
    (child, stdout)
}

#[test]
fn monitor_prints_one_json_object_per_sample_and_stops_at_count() {
    let emu = emulator("monitor");
    let port = emu.address();
    let out =
        chladni(&["device", "monitor", "--port", &port, "--rate", "50", "--count", "5", "--json"]);
    assert_eq!(out.status.code(), Some(0), "{}", String::from_utf8_lossy(&out.stderr));
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let seqs: Vec<u64> = lines.iter().map(|v| v["seq"].as_u64().unwrap()).collect();
    assert_eq!(seqs, [0, 1, 2, 3, 4]);
    assert_eq!(lines[4]["left"], 0);
    assert_eq!(lines[0]["state"], "idle");
    // The status's keys (`device status --json`) and the stream's `seq` and `left`.
    assert_eq!(lines[0].as_object().unwrap().len(), 20, "{}", lines[0]);
}

#[test]
fn monitor_runs_until_ctrl_c_and_says_it_stopped() {
    let emu = emulator("monitor-ctrl-c");
    let port = emu.address();
    let mut owner = emu.connect("driving while monitored").unwrap();
    owner.drive(90_000, chladni_shared::icd::plan::Level::Drive(3_000)).unwrap();
    let (child, mut stdout) = spawn(&["device", "monitor", "--port", &port, "--rate", "20"]);
    // Past the first batch (2 s of samples): the monitor renews its subscription.
    let mut lines = Vec::new();
    for _ in 0..60 {
        let mut line = String::new();
        stdout.read_line(&mut line).unwrap();
        lines.push(line);
    }
    assert!(lines.iter().all(|l| l.starts_with('#')), "{lines:?}");
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    // "monitor stopped; the controller goes on: …" while the drive runs (firmware permitting).
    assert!(stderr.contains("monitor stopped"), "{stderr}");
}

#[test]
fn ctrl_c_during_run_file_wait_stops_the_plan_and_exits_130() {
    let emu = emulator("run-file-ctrl-c");
    let port = emu.address();
    let plan = std::env::temp_dir().join(format!("chladni-ctrl-c-{}.json", std::process::id()));
    let steps = r#"{"freq_hz": 80.0, "duration_ms": 20000, "amplitude": 0.3, "ramp_ms": 50}"#;
    std::fs::write(&plan, format!(r#"{{"name": "long", "repeat": 1, "steps": [{steps}]}}"#))
        .unwrap();
    let (child, mut stdout) =
        spawn(&["device", "run-file", "--port", &port, plan.to_str().unwrap(), "--wait"]);
    let mut line = String::new();
    while !line.contains("Ctrl-C stops it") {
        line.clear();
        assert!(stdout.read_line(&mut line).unwrap() > 0, "run-file ended before running");
    }
    // No wait needed: the CLI installs its Ctrl-C handler and has the run accepted before it
    // prints that line.
    kill(Pid::from_raw(child.id() as i32), Signal::SIGINT).unwrap();
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("interrupted: stopped plan 'long' (slot 64)"), "{stderr}");
    let mut client = emu.connect("after ctrl-c").unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while client.status().unwrap().state.name() != "idle" {
        assert!(Instant::now() < deadline, "the plan still runs after Ctrl-C");
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn sweep_finds_the_plate_writes_its_files_and_appends_the_mode() {
    let emu = emulator("sweep");
    let port = emu.address();
    let dir = std::env::temp_dir().join(format!("chladni-cli-sweep-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (csv, png, plate) = (dir.join("sweep.csv"), dir.join("sweep.png"), dir.join("plate.toml"));
    std::fs::copy("../../examples/plates/four-lines.toml", &plate).unwrap();
    let path = |p: &std::path::Path| p.to_str().unwrap().to_string();
    let out = chladni(&[
        "device",
        "sweep",
        "--port",
        &port,
        "--from",
        "120",
        "--to",
        "260",
        "--points",
        "29",
        "--dwell-ms",
        "120",
        "--amplitude",
        "0.1",
        "--out",
        &path(&csv),
        "--plot",
        &path(&png),
        "--write-modes",
        &path(&plate),
        "--json",
    ]);
    let v = json_of(&out);
    assert_eq!(keys(&v), ["points", "resonances"]);
    let points = v["points"].as_array().unwrap();
    assert_eq!(points.len(), 29);
    assert_eq!(keys(&points[0]), ["accel_mps2", "freq_hz", "phase_deg"]);
    let resonances = v["resonances"].as_array().unwrap();
    assert_eq!(resonances.len(), 1, "{v}");
    let f0 = resonances[0]["freq_hz"].as_f64().unwrap();
    assert!((f0 - 180.0).abs() < 1.8, "the simulated plate resonates at 180 Hz, found {f0}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap().lines().count(), 30, "header + points");
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000, "a Bode plot was drawn");
    let toml = std::fs::read_to_string(&plate).unwrap();
    assert_eq!(toml.matches("[[mode]]").count(), 5, "the resonance appended as a fifth mode");
    // The appended mode has no node yet: planning with it is refused by name.
    let plan = chladni(&["plan", "../../examples/parts/rectangle.json", "--plate", &path(&plate)]);
    assert_eq!(plan.status.code(), Some(2), "{}", String::from_utf8_lossy(&plan.stderr));
}

#[test]
fn closed_loop_drive_shows_its_measurement_and_a_fault_needs_clearing() {
    let emu = emulator("accel");
    let port = emu.address();
    let drive = json_of(&chladni(&[
        "device", "drive", "--port", &port, "--freq", "180", "--accel", "12", "--json",
    ]));
    assert!(drive["run"].as_u64().is_some(), "{drive}");
    // Settled well within a second of the drive's start (QEMU time may slip: poll).
    let deadline = Instant::now() + Duration::from_secs(20);
    let status = loop {
        let s = json_of(&chladni(&["device", "status", "--port", &port, "--json"]));
        let settled = s["accel_mps2"].as_f64().is_some_and(|a| (a - 12.0).abs() < 0.24);
        if settled && s["elapsed_ms"].as_f64().unwrap() > 1000.0 {
            break s;
        }
        assert!(Instant::now() < deadline, "never settled: {s}");
        std::thread::sleep(Duration::from_millis(200));
    };
    assert_eq!(status["target_accel_mps2"], 12.0);
    assert!(status["effort"].as_f64().unwrap() > 0.0 && status["fault"].is_null());
    // Human output names the measurement too.
    let text = chladni(&["device", "status", "--port", &port]);
    assert!(String::from_utf8_lossy(&text.stdout).contains("m/s²"));
    let clear = chladni(&["device", "clear-fault", "--port", &port, "--json"]);
    assert_eq!(clear.status.code(), Some(0), "{}", String::from_utf8_lossy(&clear.stderr));
    chladni(&["device", "stop", "--port", &port]);
}
