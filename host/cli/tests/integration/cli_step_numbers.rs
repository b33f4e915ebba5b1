//! One step numbering for people: a plan file's errors name steps from 1, as `plan` prints its
//! steps and `simulate` its messages (the wire's `PlanError.step` stays a 0-based index; its
//! message is tested in the shared crate).

use crate::support;

use support::cli::{tmp, triangle_on_four_lines};

/// `simulate` of the triangle on the four-line plate with a plan file of `steps`.
fn simulate_steps(name: &str, steps: &str) -> std::process::Output {
    let plan = tmp("steps", name);
    std::fs::write(&plan, format!(r#"{{"name": "n", "steps": [{steps}]}}"#)).unwrap();
    let out =
        triangle_on_four_lines("simulate", &["--plan", plan.to_str().unwrap(), "--trials", "2"]);
    std::fs::remove_file(plan).unwrap();
    out
}

fn refused_with(out: &std::process::Output, want: &str) {
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains(want), "{want:?} not in {err}");
}

const GOOD: &str = r#"{"freq_hz": 100.0, "duration_ms": 500, "amplitude": 0.5}"#;

#[test]
fn the_second_step_is_step_2_in_every_message() {
    let both = r#"{"freq_hz": 100.0, "duration_ms": 5, "amplitude": 0.5, "accel_mps2": 2.0}"#;
    refused_with(
        &simulate_steps("both.json", &format!("{GOOD}, {both}")),
        "step 2: both amplitude and accel_mps2",
    );
    let no_mode = r#"{"freq_hz": 77.0, "duration_ms": 5, "amplitude": 0.5}"#;
    refused_with(
        &simulate_steps("mode.json", &format!("{GOOD}, {no_mode}")),
        "plan step 2: no mode of ",
    );
    let loud = r#"{"freq_hz": 100.0, "duration_ms": 5, "amplitude": 1.5}"#;
    refused_with(
        &simulate_steps("loud.json", &format!("{GOOD}, {GOOD}, {loud}")),
        "step 3: amplitude 1.5 outside 0..=1",
    );
}
