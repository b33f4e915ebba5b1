//! `chladni emulator` through the built binary, with the real QEMU controller: the exit codes
//! a user sees when the time limit ends the run, and when `--flash-file` cannot be a flash.

use crate::support;
use support::cli::chladni;

#[test]
fn the_time_limit_ends_the_emulator_with_success_and_says_so() {
    let log = std::env::temp_dir().join(format!("chladni-emulator-{}.log", std::process::id()));
    let out = chladni(&["emulator", "--time-limit-s", "3", "--log", log.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stdout.contains("controller ready on tcp://127.0.0.1:"), "{stdout}");
    assert!(stderr.contains("time limit of 3 s reached: the emulator stopped"), "{stderr}");
    let _ = std::fs::remove_file(log);
}

#[test]
fn a_directory_as_flash_file_is_bad_input_named_as_a_directory() {
    let dir = std::env::temp_dir();
    let out = chladni(&["emulator", "--time-limit-s", "3", "--flash-file", dir.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("is a directory"), "{stderr}");
    assert!(!stderr.contains("bytes"), "the old size message came back: {stderr}");
}

#[test]
fn an_emulator_on_a_busy_port_says_so_and_never_claims_ready() {
    // Something already listens there (here: a bare socket; in issue 11, another emulator,
    // which answered the new one's start-up ping, so it printed "controller ready").
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let out = chladni(&["emulator", "--tcp", &port, "--time-limit-s", "3"]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "stdout:\n{stdout}\nstderr:\n{stderr}");
    assert!(stderr.contains(&format!("port {port} is in use")), "{stderr}");
    assert!(!stdout.contains("controller ready"), "{stdout}");
}

/// `--json` prints one object; without `--flash-file` the controller still keeps the plans it
/// is sent (in a flash file of the emulator's own, named in the ready line and removed at the
/// end), where it used to refuse every store request.
#[test]
fn json_prints_one_object_and_plans_are_kept_without_a_flash_file() {
    use std::io::BufRead;
    let log =
        std::env::temp_dir().join(format!("chladni-emulator-json-{}.log", std::process::id()));
    let mut emulator = support::cli::command()
        .args(["emulator", "--time-limit-s", "60", "--json", "--log", log.to_str().unwrap()])
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    let stdout = emulator.stdout.take().unwrap();
    std::io::BufReader::new(stdout).read_line(&mut line).unwrap();
    let ready: serde_json::Value = serde_json::from_str(line.trim())
        .unwrap_or_else(|e| panic!("{e}: the ready line is not one JSON object:\n{line}"));
    let port = ready["port"].as_str().unwrap_or_else(|| panic!("no port in {ready}"));
    assert!(port.starts_with("tcp://127.0.0.1:"), "{ready}");
    assert!(ready["pid"].as_u64().is_some_and(|pid| pid > 0), "{ready}");
    assert_eq!(ready["flash_kept"], false, "{ready}");
    let flash = std::path::PathBuf::from(ready["flash_file"].as_str().unwrap());
    assert!(flash.is_file(), "{ready}");

    let plan = support::cli::ex("plans/triangle-four-lines.json");
    let upload = chladni(&["device", "upload", "--port", port, &plan]);
    assert!(upload.status.success(), "{}", String::from_utf8_lossy(&upload.stderr));
    let plans = support::cli::ok_json(&chladni(&["device", "plans", "--port", port, "--json"]));
    assert_eq!(plans["plans"].as_array().map(Vec::len), Some(1), "{plans}");

    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(emulator.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    assert!(emulator.wait().unwrap().success());
    assert!(!flash.exists(), "the emulator's own flash file is removed at the end");
    let _ = std::fs::remove_file(log);
}
