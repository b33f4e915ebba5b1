//! Bad inputs a careless user gives `chladni analyze`, `plan` and `simulate`: each exits with
//! code 2 and a message naming the offending value and the fix.

use crate::support;
use support::cli::{chladni, ex, write_tmp};

/// Writes `text` to this file's scratch file `name`; its path.
fn file(name: &str, text: &str) -> String {
    write_tmp("model-inputs", name, text)
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
    let p = file("nan.json", r#"{"name": "t", "outline": [[0, 0], [NaN, 1], [1, 1]]}"#);
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("`NaN`") && e.contains("column") && e.contains("\"outline\""), "{e}");
    let p = file(
        "nan.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg"><polygon points="0,0 10,NaN 5,8"/></svg>"#,
    );
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("`NaN`") && e.contains("not a finite number"), "{e}");
    let p = file(
        "two.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg"><path d="M0 0 L10 0 L10 10 Z"/><path d="M20 0 L40 0 L40 10 Z"/></svg>"#,
    );
    let e = refused(&["analyze", &p, "--field", "sign"]);
    assert!(e.contains("2 separate outlines") && e.contains("one outline plus holes"), "{e}");
}

#[test]
fn plate_size_with_three_numbers_is_refused() {
    let p = file(
        "three.toml",
        "[plate]\nsize_mm = [300.0, 200.0, 5.0]\n[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    );
    let e = refused(&["plan", &ex("parts/triangle.json"), "--plate", &p]);
    assert!(e.contains("size_mm") && e.contains("exactly two"), "{e}");
}

/// A plate past any rig, and absurd numbers in a plate, plan or region: refused naming the
/// value as the user wrote it (`1e308`), not as hundreds of digits.
#[test]
fn absurd_numbers_are_refused_and_named_readably() {
    let mode = "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";
    let p = file("huge.toml", &format!("[plate]\nsize_mm = [1e308, 200.0]\n{mode}"));
    let e = refused(&["plan", &ex("parts/triangle.json"), "--plate", &p]);
    assert!(e.contains("size_mm[0] = 1e308 mm is absurdly large (limit 100000 mm)"), "{e}");
    let plan = file(
        "thz.json",
        r#"{"steps": [{"freq_hz": 1e300, "duration_ms": 100, "amplitude": 0.5}]}"#,
    );
    let four = ex("plates/four-lines.toml");
    let e = refused(&["simulate", &ex("parts/triangle.json"), "--plate", &four, "--plan", &plan]);
    assert!(e.contains("frequency 1e300 Hz is outside the drive's range"), "{e}");
    let e = refused(&[
        "plan",
        &ex("parts/triangle.json"),
        "--plate",
        &four,
        "--feed",
        "0",
        "0",
        "1e308",
        "10",
    ]);
    assert!(e.contains("feed region 0 0 1e308 10 mm is not inside"), "{e}");
}

/// A plan given as its list of steps, and a part as its outline alone: refused naming the top
/// level (serde's own message was "invalid type: map, expected a string").
#[test]
fn a_bare_list_is_named_as_what_it_is() {
    let steps = file("steps.json", r#"[{"freq_hz": 60, "duration_ms": 100, "amplitude": 0.5}]"#);
    let four = ex("plates/four-lines.toml");
    let e = refused(&["simulate", &ex("parts/triangle.json"), "--plate", &four, "--plan", &steps]);
    assert!(e.contains("the file is an array; a plan file is one JSON object"), "{e}");
    let outline = file("outline.json", "[[0, 0], [10, 0], [0, 10]]");
    let e = refused(&["analyze", &outline, "--field", "sign"]);
    assert!(e.contains("the file is an array; a part file is one JSON object"), "{e}");
}

#[test]
fn frequencies_name_the_drive_range_in_plate_and_plan_files() {
    let p = file(
        "fast.toml",
        "[plate]\nsize_mm = [300.0, 200.0]\n[[mode]]\nfreq_hz = 5000.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    );
    let e = refused(&["plan", &ex("parts/triangle.json"), "--plate", &p]);
    assert!(
        e.contains("freq_hz = 5000") && e.contains("outside the drive's range 1..=2000 Hz"),
        "{e}"
    );
    let plan =
        file("mhz.json", r#"{"steps": [{"freq_hz": 5e6, "duration_ms": 100, "amplitude": 0.5}]}"#);
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
    let big = file("big.json", r#"{"name": "big", "outline": [[0, 0], [3000, 0], [1500, 2000]]}"#);
    let many = file("many.json", &circle(chladni_core::planner::MAX_PLAN_VERTICES + 1, 20.0));
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
    let part = file(
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

#[test]
fn a_part_that_fits_the_plate_in_no_orientation_is_refused() {
    // 400 × 30 mm: narrower than the 300 × 200 mm plate, longer than its diagonal (361 mm).
    let long = file(
        "fits-nowhere.json",
        r#"{"name": "long", "outline": [[0,0],[400,0],[400,30],[0,30]]}"#,
    );
    // 320 × 20 mm fits only turned (about 30°): simulated, not refused.
    let turned =
        file("turned.json", r#"{"name": "turned", "outline": [[0,0],[320,0],[320,20],[0,20]]}"#);
    let (plate, plan) = (ex("plates/four-lines.toml"), ex("plans/triangle-four-lines.json"));
    let err = refused(&["plan", &long, "--plate", &plate]);
    assert!(err.contains("part long fits the 300 × 200 mm plate in no orientation"), "{err}");
    let sim = |part: &str| {
        ["simulate", part, "--plate", &plate, "--plan", &plan, "--trials", "2"].map(String::from)
    };
    let err = refused(&sim(&long).each_ref().map(String::as_str));
    assert!(err.contains("even turned by"), "{err}");
    let out = chladni(&sim(&turned).each_ref().map(String::as_str));
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}
