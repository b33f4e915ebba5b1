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

#[test]
fn json_prints_the_port_and_pid_as_one_object() {
    let log =
        std::env::temp_dir().join(format!("chladni-emulator-json-{}.log", std::process::id()));
    let out =
        chladni(&["emulator", "--time-limit-s", "3", "--json", "--log", log.to_str().unwrap()]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(0), "{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let ready: serde_json::Value = serde_json::from_str(stdout.trim())
        .unwrap_or_else(|e| panic!("{e}: stdout is not one JSON object:\n{stdout}"));
    let port = ready["port"].as_str().unwrap_or_else(|| panic!("no port in {ready}"));
    assert!(port.starts_with("tcp://127.0.0.1:"), "{ready}");
    assert!(ready["pid"].as_u64().is_some_and(|pid| pid > 0), "{ready}");
    let _ = std::fs::remove_file(log);
}
