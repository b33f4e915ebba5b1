//! Bad inputs a careless user gives `chladni analyze`, `plan` and `simulate`: each exits with
//! code 2 and a message naming the offending value and the fix.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn chladni(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chladni")).args(args).output().unwrap()
}

fn ex(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples").join(rel).display().to_string()
}

fn tmp(name: &str, text: &str) -> String {
    let dir = std::env::temp_dir().join(format!("chladni-inputs-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p: PathBuf = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// Runs and expects exit code 2; returns stderr.
fn refused(args: &[&str]) -> String {
    let out = chladni(args);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
    err
}

#[test]
fn part_files_with_nan_or_two_outlines() {
    let p = tmp("nan.json", r#"{"name": "t", "outline": [[0, 0], [NaN, 1], [1, 1]]}"#);
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("`NaN`") && e.contains("column") && e.contains("\"outline\""), "{e}");
    let p = tmp(
        "nan.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg"><polygon points="0,0 10,NaN 5,8"/></svg>"#,
    );
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("`NaN`") && e.contains("not a finite number"), "{e}");
    let p = tmp(
        "two.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 L10 0 L10 10 Z"/><path d="M20 0 L40 0 L40 10 Z"/></svg>"#,
    );
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("2 separate outlines") && e.contains("one outline plus holes"), "{e}");
}

#[test]
fn plate_size_with_three_numbers_is_refused() {
    let p = tmp(
        "three.toml",
        "[plate]\nsize_mm = [300.0, 200.0, 5.0]\n[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    );
    let e = refused(&["plan", &ex("parts/triangle.json"), "--plate", &p]);
    assert!(e.contains("size_mm") && e.contains("exactly two"), "{e}");
}

#[test]
fn frequencies_name_the_drive_range_in_plate_and_plan_files() {
    let p = tmp(
        "fast.toml",
        "[plate]\nsize_mm = [300.0, 200.0]\n[[mode]]\nfreq_hz = 5000.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    );
    let e = refused(&["plan", &ex("parts/triangle.json"), "--plate", &p]);
    assert!(
        e.contains("freq_hz = 5000") && e.contains("outside the drive's range 1..=2000 Hz"),
        "{e}"
    );
    let plan =
        tmp("mhz.json", r#"{"steps": [{"freq_hz": 5e6, "duration_ms": 100, "amplitude": 0.5}]}"#);
    let e = refused(&[
        "simulate",
        &ex("parts/triangle.json"),
        "--plate",
        &ex("plates/four-lines.toml"),
        "--plan",
        &plan,
    ]);
    assert!(e.contains("frequency 5000000 Hz is outside the drive's range 1..=2000 Hz"), "{e}");
}

fn circle(n: usize, r: f64) -> String {
    let pts: Vec<String> = (0..n)
        .map(|k| {
            let a = k as f64 * std::f64::consts::TAU / n as f64;
            format!("[{:.6}, {:.6}]", r * a.cos(), r * a.sin())
        })
        .collect();
    format!("{{\"outline\": [{}]}}", pts.join(", "))
}

#[test]
fn parts_too_large_for_the_plate_or_the_planner_are_refused_in_plan_and_simulate() {
    let big = tmp("big.json", r#"{"name": "big", "outline": [[0, 0], [3000, 0], [1500, 2000]]}"#);
    let many = tmp("many.json", &circle(chladni::planner::MAX_PLAN_VERTICES + 1, 20.0));
    let plan = ex("plans/triangle-four-lines.json");
    for part in [&big, &many] {
        let e = refused(&["plan", part, "--plate", &ex("plates/four-lines.toml")]);
        let s =
            refused(&["simulate", part, "--plate", &ex("plates/four-lines.toml"), "--plan", &plan]);
        assert_eq!(e, s);
        if part == &big {
            assert!(e.contains("cannot lie on the plate") && e.contains("300×200 mm"), "{e}");
        } else {
            assert!(e.contains("vertices, more than the planner's limit"), "{e}");
        }
    }
}

#[test]
fn a_long_part_name_is_cut_with_a_warning() {
    let name = "n".repeat(100_000);
    let part = tmp(
        "long.json",
        &format!(r#"{{"name": "{name}", "outline": [[0, 0], [60, 0], [20, 40]]}}"#),
    );
    let out = chladni(&["plan", &part, "--plate", &ex("plates/four-lines.toml"), "--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning:") && err.contains("100000 bytes") && err.contains("at most 32"),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["name"].as_str().unwrap(), "n".repeat(32));
}
