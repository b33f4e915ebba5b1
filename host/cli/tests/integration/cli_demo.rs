//! `chladni demo` through the built binary, non-interactively: the whole job against the QEMU
//! controller it starts (`--fast --json`: the summary's timing, fault, success rate and pose
//! against `chladni plan`), a controller given with `--port` whose shaker is disconnected (the
//! fault named, then refused while latched), and the errors that name their fix.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use chladni_shared::icd::link::TestFault;

use crate::support;
use support::cli::json as json_of;

const PART: &str = "../../examples/parts/triangle.json";
const PLATE: &str = "../../examples/plates/four-lines.toml";

fn out_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("chladni-cli-demo-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// `chladni ARGS`, with `PATH` replaced by `path_env` if given.
fn chladni(args: &[&str], path_env: Option<&Path>) -> Output {
    let mut command = support::cli::command();
    command.args(args);
    if let Some(path) = path_env {
        command.env("PATH", path);
    }
    command.output().unwrap()
}

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn fast_json_demo_runs_the_plan_sample_exact_on_qemu() {
    let out = out_dir("qemu");
    let out_s = out.to_str().unwrap();
    let run = chladni(&["demo", "--fast", "--json", "--out", out_s], None);
    let stderr = String::from_utf8_lossy(&run.stderr);
    let s = json_of(&run);
    assert_eq!(run.status.code(), Some(0), "{s}\n{stderr}");
    let r = &s["run"];
    assert_eq!((r["outcome"].as_str(), s["fault"].is_null()), (Some("done"), true), "{s}");
    assert_eq!(s["controller"]["emulated"], true);
    assert_eq!(s["stored"]["name"], "demo");

    // The plan as run: time-scaled by the stated factor, each step holding amplitude × accel.
    let scale = s["time_scale"].as_u64().unwrap();
    assert!(scale > 1, "--fast scales a 70 s plan");
    let steps = s["steps"].as_array().unwrap();
    let mut scaled_ms = 0.0;
    for step in steps {
        let nominal = f(&step["nominal_ms"]);
        let ms = f(&step["duration_ms"]);
        assert!((ms - nominal / scale as f64).abs() <= 0.5, "{step}");
        assert!(
            (f(&step["accel_mps2"]) - f(&step["amplitude"]) * f(&s["accel_mps2"])).abs() < 1e-3
        );
        scaled_ms += ms;
    }
    assert!(scaled_ms <= 25_000.0, "the fast run takes at most 25 s: {scaled_ms} ms");

    // Sample-exact: the steps ran exactly the scaled plan's samples, by the controller's clock.
    let rate = f(&r["sample_rate"]);
    assert_eq!(f(&r["planned_ms"]), scaled_ms);
    assert_eq!(r["planned_samples"].as_u64(), Some((scaled_ms * rate / 1000.0) as u64));
    assert_eq!(r["executed_samples"], r["planned_samples"], "{r}");
    assert_eq!(
        (r["difference_samples"].as_i64(), r["clock_disagreements"].as_u64()),
        (Some(0), Some(0))
    );
    let (start, end) = (r["start_clock"].as_u64().unwrap(), r["end_clock"].as_u64().unwrap());
    let ran = r["executed_samples"].as_u64().unwrap() + r["final_ramp_samples"].as_u64().unwrap();
    assert_eq!(end - start, ran, "{r}");
    assert_eq!(r["steps_seen"].as_u64(), Some(steps.len() as u64));

    // The Monte Carlo check meets the plan's claim.
    let sim = &s["simulation"];
    assert!(f(&sim["success_rate"]) >= f(&sim["claimed_success_rate"]), "{sim}");

    // The predicted pose is `chladni plan`'s.
    let plan = json_of(&chladni(&["plan", PART, "--plate", PLATE, "--json"], None));
    let predicted = &s["predicted"];
    assert!((f(&predicted["orientation_deg"]) - f(&plan["final_orientation_deg"])).abs() < 1e-3);
    assert_eq!(predicted["period_deg"], plan["period_deg"]);
    for i in 0..2 {
        let (a, b) = (&predicted["position_mm"][i], &plan["final_position_mm"][i]);
        assert!((f(a) - f(b)).abs() < 0.01, "{predicted} vs {plan}");
    }
    // Not a terminal: plain telemetry lines (on stderr with --json), the summary for people;
    // the second step seen (numbered from 1, as `plan` prints steps).
    assert!(stderr.contains("plan 'demo' step 2"), "{stderr}");
    assert!(stderr.contains("time scale  1/"), "{stderr}");
    for file in ["plan.json", "device-plan.json", "plan.png", "traces.png", "firmware.log"] {
        assert!(out.join(file).is_file(), "{file}");
    }
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn a_disconnected_shaker_faults_the_run_and_a_latched_fault_is_refused() {
    let out = out_dir("fault");
    std::fs::create_dir_all(&out).unwrap();
    let emu = support::emu::emulator_for("cli-demo-fault", Duration::from_secs(120));
    emu.connect("cli_demo test").unwrap().inject_fault(TestFault::ShakerDisconnected).unwrap();
    let port = emu.address();
    let args = ["demo", "--fast", "--json", "--port", &port, "--out", out.to_str().unwrap()];
    let run = chladni(&args, None);
    let s = json_of(&run);
    assert_eq!(run.status.code(), Some(1), "{s}");
    assert_eq!(s["run"]["outcome"], "faulted", "{s}");
    assert_eq!(s["fault"]["cause"], "loop_check", "{s}");
    assert_eq!(s["controller"]["emulated"], false);
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("error: the drive faulted") && stderr.contains("clear-fault"),
        "{stderr}"
    );

    // The fault stays latched: the next demo is refused before it runs anything.
    let again = chladni(&args, None);
    let e = json_of(&again);
    assert_eq!((again.status.code(), e["error"].as_str()), (Some(1), Some("fault_latched")), "{e}");
    assert!(e["message"].as_str().unwrap().contains("chladni device clear-fault --port"), "{e}");
    drop(emu);
    std::fs::remove_dir_all(&out).unwrap();
}

#[test]
fn errors_name_their_fix() {
    let out = out_dir("errors");
    let out_s = out.to_str().unwrap();
    // No QEMU on PATH: refused before any work.
    let empty = out.join("empty-path");
    std::fs::create_dir_all(&empty).unwrap();
    let run = chladni(&["demo", "--json", "--out", out_s], Some(&empty));
    let e = json_of(&run);
    assert_eq!((run.status.code(), e["error"].as_str()), (Some(1), Some("qemu_missing")), "{e}");
    assert!(e["message"].as_str().unwrap().contains("scripts/install-deps.sh"), "{e}");
    assert!(!out.join("plan.json").exists(), "nothing planned before the check");
    let run = chladni(&["demo", "--steer", "--json", "--out", out_s], Some(&empty));
    let e = json_of(&run);
    assert_eq!((run.status.code(), e["error"].as_str()), (Some(1), Some("qemu_missing")), "{e}");
    assert!(!out.join("true-plate.toml").exists(), "--steer: no rig before the check");
    // --steer brings its own controller, part and plate.
    let run = chladni(&["demo", "--steer", "--port", "tcp://127.0.0.1:1", "--out", out_s], None);
    assert_eq!(run.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&run.stderr).contains("cannot be used with"));
    // A port where no controller listens.
    let run = chladni(&["demo", "--json", "--port", "tcp://127.0.0.1:1", "--out", out_s], None);
    let e = json_of(&run);
    assert_eq!((run.status.code(), e["error"].as_str()), (Some(1), Some("port_unreachable")));
    // Bad input: exit 2.
    let run = chladni(&["demo", "--accel", "0", "--out", out_s], None);
    assert_eq!(run.status.code(), Some(2));
    let run = chladni(&["demo", "--json", "--part", "nope.json", "--out", out_s], None);
    let e = json_of(&run);
    assert_eq!((run.status.code(), e["error"].as_str()), (Some(2), Some("bad_input")), "{e}");
    std::fs::remove_dir_all(&out).unwrap();
}
