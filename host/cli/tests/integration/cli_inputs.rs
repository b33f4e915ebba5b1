//! Bad input refused before any work, with exit code 2 and a message naming what is wrong:
//! outputs that would overwrite an input, figure files of the wrong type, out-of-range options.

use std::process::Output;

use crate::support;
use support::cli::{chladni, ex, tmp};

/// Exit code 2, nothing on stdout (no work done), and `needle` in the message.
fn refused(out: &Output, needle: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(out.stdout.is_empty(), "{}", String::from_utf8_lossy(&out.stdout));
    assert!(err.contains(needle), "{needle:?} not in: {err}");
}

#[test]
fn plan_refuses_to_overwrite_its_part_or_plate() {
    let part = tmp("inputs", "tri.json");
    std::fs::copy(ex("parts/triangle.json"), &part).unwrap();
    let before = std::fs::read(&part).unwrap();
    let plate = ex("plates/four-lines.toml");
    let p = part.to_str().unwrap();
    let out = chladni(&["plan", p, "--plate", &plate, "--out", p]);
    refused(&out, &format!("--out {p} is the part {p}"));
    assert_eq!(std::fs::read(&part).unwrap(), before, "the part was changed");
    // Another spelling of the same file is the same file.
    let dotted = part.parent().unwrap().join(".").join(part.file_name().unwrap());
    let out = chladni(&["plan", p, "--plate", &plate, "--out", dotted.to_str().unwrap()]);
    refused(&out, "is the part");
    let plate_copy = tmp("inputs", "plate.toml");
    std::fs::copy(&plate, &plate_copy).unwrap();
    let q = plate_copy.to_str().unwrap();
    let out = chladni(&["plan", p, "--plate", q, "--plot", q]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(std::fs::read(&part).unwrap(), before);
}

#[test]
fn plan_writes_its_file_whole_and_leaves_no_temporary_file() {
    let dir = tmp("inputs", "atomic");
    std::fs::create_dir_all(&dir).unwrap();
    let out_file = dir.join("plan.json");
    std::fs::write(&out_file, "old").unwrap();
    let out = chladni(&[
        "plan",
        &ex("parts/triangle.json"),
        "--plate",
        &ex("plates/four-lines.toml"),
        "--out",
        out_file.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out_file).unwrap()).unwrap();
    assert_eq!(v["name"], "triangle");
    let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names, ["plan.json"]);
}

#[test]
fn a_figure_of_the_wrong_type_is_refused_before_the_work() {
    let out = chladni(&[
        "analyze",
        &ex("parts/triangle.json"),
        "--field",
        "sign",
        "--plot",
        tmp("inputs", "x.gif").to_str().unwrap(),
    ]);
    refused(&out, "--plot file must end in .png or .svg");
    let (part, plate) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let plan = ex("plans/triangle-four-lines.json");
    let gif = tmp("inputs", "t.gif");
    let g = gif.to_str().unwrap();
    let out = chladni(&["simulate", &part, "--plate", &plate, "--plan", &plan, "--plot", g]);
    refused(&out, "--plot file must end in .png");
    let out = chladni(&["physics", "string", "--e", "0.5", "--plot", g]);
    refused(&out, "--plot file must end in .png");
}

#[test]
fn simulate_refuses_a_figure_over_its_plan_and_bad_ranges() {
    let plan = tmp("inputs", "p.png");
    std::fs::copy(ex("plans/triangle-four-lines.json"), &plan).unwrap();
    let (part, plate) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let p = plan.to_str().unwrap();
    let out = chladni(&["simulate", &part, "--plate", &plate, "--plan", p, "--plot", p]);
    refused(&out, "is the plan");
    let good = ex("plans/triangle-four-lines.json");
    let out = chladni(&["simulate", &part, "--plate", &plate, "--plan", &good, "--trials", "0"]);
    refused(&out, "--trials");
    let out = chladni(&["simulate", &part, "--plate", &plate, "--plan", &good, "--tol-deg", "0"]);
    refused(&out, "--tol-deg must be positive, got 0");
    let out = chladni(&["simulate", &part, "--plate", &plate, "--plan", &good, "--seed", "-1"]);
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn plate_modes_refuses_to_overwrite_its_plate_and_bad_counts() {
    let plate = tmp("inputs", "hinged.toml");
    std::fs::copy(ex("plate-hinged-rod.toml"), &plate).unwrap();
    let before = std::fs::read(&plate).unwrap();
    let p = plate.to_str().unwrap();
    let out = chladni(&["plate", "modes", p, "--count", "2", "--write-modes", p]);
    refused(&out, &format!("--write-modes {p} is the plate {p}"));
    assert_eq!(std::fs::read(&plate).unwrap(), before);
    refused(&chladni(&["plate", "modes", p, "--count", "0"]), "--count must be in 1..=");
    refused(&chladni(&["plate", "modes", p, "--terms", "3"]), "--terms must be in 4..=30, got 3");
    refused(&chladni(&["plate", "modes", p, "--grid", "2"]), "--grid must be in 3..=401, got 2");
}

#[test]
fn emulator_and_drive_ranges_are_checked_before_anything_starts() {
    refused(&chladni(&["emulator", "--time-limit-s", "0"]), "--time-limit-s must be");
    let port = "tcp://127.0.0.1:1";
    let drive = |f: &str, a: &str| {
        chladni(&["device", "drive", "--port", port, "--freq", f, "--amplitude", a])
    };
    refused(&drive("0", "0.5"), "frequency 0 Hz is outside the drive's range 1..=2000 Hz");
    refused(&drive("5e6", "0.5"), "frequency 5000000 Hz is outside the drive's range");
    refused(&drive("nan", "0.5"), "frequency NaN Hz is outside the drive's range");
    refused(&drive("100", "1.5"), "amplitude 1.5 outside 0..=1");
    refused(&chladni(&["device", "ping", "--port", port, "--count", "0"]), "--count");
}

#[test]
fn device_plan_slots_names_and_config_values_are_checked_before_connecting() {
    // Port 1 has no controller: each refusal must come before any connection is tried.
    let port = "tcp://127.0.0.1:1";
    let device = |args: &[&str]| {
        let mut all = vec!["device"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--port", port]);
        chladni(&all)
    };
    refused(&device(&["run", "65"]), "slot 65 does not exist: slots are 0..=64");
    refused(&device(&["delete", "300"]), "slot 300 does not exist");
    refused(&device(&["run", &"n".repeat(33)]), "is 33 bytes, at most 32 fit");
    refused(&device(&["run", "x", "--repeat", "0"]), "--repeat");
    refused(&device(&["upload", "p.json", "--slot", "70"]), "slot 70 does not exist");
    refused(&device(&["monitor", "--rate", "0"]), "--rate");
    refused(&device(&["monitor", "--rate", "101"]), "--rate");
    refused(&device(&["config", "get", "speed"]), "unknown configuration key 'speed'");
    refused(
        &device(&["config", "set", "max_steps", "0"]),
        "max_steps must be a whole number in 1..=256, got '0'",
    );
    refused(
        &device(&["config", "set", "max_freq_hz", "9000"]),
        "max_freq_hz: frequency 9000 Hz is outside",
    );
    let missing = tmp("inputs", "no-such-plan.json");
    refused(&device(&["run-file", missing.to_str().unwrap()]), "cannot read plan");
}

#[test]
fn drive_levels_sweeps_and_control_keys_are_checked_before_connecting() {
    let port = "tcp://127.0.0.1:1";
    let device = |args: &[&str]| {
        let mut all = vec!["device"];
        all.extend_from_slice(args);
        all.extend_from_slice(&["--port", port]);
        chladni(&all)
    };
    // Exactly one of --amplitude and --accel.
    refused(&device(&["drive", "--freq", "100"]), "--amplitude");
    refused(
        &device(&["drive", "--freq", "100", "--amplitude", "0.1", "--accel", "5"]),
        "cannot be used with",
    );
    refused(
        &device(&["drive", "--freq", "100", "--accel", "150"]),
        "acceleration target 150.000 m/s² above the maximum 100.000 m/s²",
    );
    refused(&device(&["drive", "--freq", "100", "--accel=-1"]), "--accel: acceleration -1 m/s²");
    // Sweeps, by the controller's own check, before any connection.
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", "--from", "20", "--to", "400"];
        args.extend_from_slice(extra);
        device(&args)
    };
    refused(
        &device(&["sweep", "--from", "400", "--to", "20"]),
        "sweep from 400.000 Hz to 20.000 Hz: the start must be below the end",
    );
    refused(&device(&["sweep", "--from", "0.5", "--to", "20"]), "--from: frequency 0.5 Hz");
    refused(&sweep(&["--points", "1"]), "1 sweep points: give 2..=200");
    refused(&sweep(&["--points", "500"]), "500 sweep points: give 2..=200");
    refused(&sweep(&["--amplitude", "2"]), "--amplitude: amplitude 2 outside 0..=1");
    refused(&sweep(&["--dwell-ms", "5"]), "dwell 5 ms per point: give 10..=10000 ms");
    refused(&sweep(&["--plot", "bode.gif"]), "--plot file must end in .png");
    let plate = tmp("inputs", "sweep-plate.toml");
    std::fs::write(&plate, "[plate]\nname = \"p\"\n").unwrap();
    let p = plate.to_str().unwrap();
    refused(&sweep(&["--write-modes", p, "--out", p]), "refusing to overwrite an input");
    std::fs::write(&plate, "[plate\n").unwrap();
    refused(&sweep(&["--write-modes", p]), "--write-modes:");
    // Control thresholds in user units.
    refused(
        &device(&["config", "set", "warn_band_db", "loud"]),
        "warn_band_db must be a level in dB",
    );
    refused(
        &device(&["config", "set", "fault_accel_mps2", "1e7"]),
        "fault_accel_mps2: acceleration 10000000",
    );
    refused(&device(&["config", "set", "check_ms", "0.5"]), "check_ms must be whole milliseconds");
}
