//! `chladni plan` and `chladni simulate` end to end: JSON shape, files, exit codes, plots.

use std::path::Path;

use crate::support;
use support::cli::{chladni, ex, tmp, triangle_on_four_lines};

#[test]
fn plan_json_is_the_documented_object_and_simulates_to_100_percent() {
    let out_file = tmp("plan", "tri.json");
    let out = triangle_on_four_lines("plan", &["--json", "--out", out_file.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let mut keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    keys.sort_unstable();
    assert_eq!(
        keys,
        [
            "final_orientation_deg",
            "final_position_mm",
            "margins",
            "name",
            "period_deg",
            "reachable_deg",
            "repeat",
            "steps"
        ]
    );
    let steps = v["steps"].as_array().unwrap();
    assert_eq!(steps.len(), 2);
    for s in steps {
        let mut k: Vec<&str> = s.as_object().unwrap().keys().map(String::as_str).collect();
        k.sort_unstable();
        assert_eq!(k, ["amplitude", "duration_ms", "freq_hz", "ramp_ms"]);
    }
    assert_eq!(steps[0]["freq_hz"], 100.0);
    assert_eq!(steps[1]["freq_hz"], 60.0);
    assert_eq!(v["period_deg"], 360.0);
    assert!((v["final_orientation_deg"].as_f64().unwrap() - 110.7066).abs() < 1e-3);
    assert_eq!(v["final_position_mm"].as_array().unwrap().len(), 2);
    // The written file is the same object, without the margins each step kept (stdout only).
    let file: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out_file).unwrap()).unwrap();
    let mut plan = v.clone();
    plan.as_object_mut().unwrap().remove("margins");
    assert_eq!(file, plan);
    // Simulate it.
    let plot = tmp("plan", "tri-sim.png");
    let out = simulate_triangle_with(
        &out_file,
        &["--trials", "40", "--seed", "3", "--json", "--plot", plot.to_str().unwrap()],
    );
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(s["success_rate"], 1.0);
    assert_eq!(s["trials"], 40);
    assert!(s["orientation_error_deg"]["max"].as_f64().unwrap() < 0.5);
    assert!(s["position_error_mm"]["max"].as_f64().unwrap() < 1.0);
    for p in [plot.clone(), tmp("plan", "tri-sim-plan.png")] {
        let bytes = std::fs::read(&p).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{}", p.display());
    }
}

#[test]
fn plan_without_solution_exits_1_and_says_why() {
    let out =
        chladni(&["plan", &ex("parts/trapezoid.json"), "--plate", &ex("plates/four-lines.toml")]);
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no plan with these modes") && err.contains("stay apart"), "{err}");
}

#[test]
fn bad_input_exits_2_with_named_errors() {
    let plate = tmp("plan", "bad.toml");
    std::fs::write(
        &plate,
        "[plate]\nname = \"b\"\nsize_mm = [300.0, 200.0]\n[[mode]]\nfreq_hz = 60.0\nfield = \"cosine\"\nnode = { kind = \"line\", angle_deg = 0.0 }\n",
    )
    .unwrap();
    let out = chladni(&["plan", &ex("parts/triangle.json"), "--plate", plate.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("field = \"cosine\"") && err.contains("sign"), "{err}");
    let out = triangle_on_four_lines("plan", &["--margin-deg", "-1"]);
    assert_eq!(out.status.code(), Some(2));
    // A plan whose frequency is not a mode of the plate.
    let plan = tmp("plan", "p.json");
    std::fs::write(
        &plan,
        r#"{"steps": [{"freq_hz": 77.0, "duration_ms": 100, "amplitude": 0.5, "ramp_ms": 0}]}"#,
    )
    .unwrap();
    let out = simulate_triangle(&plan);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("no mode"),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::write(
        &plan,
        r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 100, "amplitude": 1.5}]}"#,
    )
    .unwrap();
    let out = simulate_triangle(&plan);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("amplitude 1.5"));
}

#[test]
fn example_plans_parse_as_device_plans_and_match_the_planner() {
    use chladni_core::model::plan_file::PlanFile;
    use chladni_shared::icd::plan::DeviceLimits;
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/plans");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap() {
        let path = e.unwrap().path();
        if path.extension().and_then(|x| x.to_str()) != Some("json") {
            continue;
        }
        let f = PlanFile::parse(&std::fs::read_to_string(&path).unwrap()).unwrap();
        f.to_plan(&DeviceLimits::DEFAULT).unwrap();
        n += 1;
    }
    assert!(n >= 4, "{n} example plans");
    // The triangle example is exactly what the planner writes today.
    let out = triangle_on_four_lines("plan", &["--json"]);
    let mut v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    v.as_object_mut().unwrap().remove("margins");
    let file: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("triangle-four-lines.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(v, file);
}

/// `chladni simulate` of the triangle on the four-line plate with the plan file `plan`.
fn simulate_triangle(plan: &std::path::Path) -> std::process::Output {
    simulate_triangle_with(plan, &[])
}

/// [`simulate_triangle`] with more arguments.
fn simulate_triangle_with(plan: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let (part, plate) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let mut args = vec!["simulate", &part, "--plate", &plate, "--plan", plan.to_str().unwrap()];
    args.extend_from_slice(extra);
    chladni(&args)
}

// A plan too short for the parts to settle misses; simulate counts the misses and lists
// their start poses (JSON) and their range (text).
#[test]
fn simulate_lists_the_starts_of_missed_trials() {
    let plan = tmp("plan", "short.json");
    std::fs::write(
        &plan,
        r#"{"steps": [{"freq_hz": 60.0, "duration_ms": 100, "amplitude": 0.8, "ramp_ms": 0}],
            "final_orientation_deg": 110.707, "period_deg": 360.0}"#,
    )
    .unwrap();
    let out = simulate_triangle_with(&plan, &["--trials", "30", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let missed = s["missed"].as_u64().unwrap();
    assert!(missed >= 20, "{s}");
    assert_eq!(s["missed_starts"].as_array().unwrap().len() as u64, missed);
    let rate = s["success_rate"].as_f64().unwrap();
    assert!((rate - (1.0 - missed as f64 / 30.0)).abs() < 1e-6, "{s}");
    let first = &s["missed_starts"][0];
    assert!((0.0..=300.0).contains(&first[0].as_f64().unwrap()), "{first}");
    let out = simulate_triangle(&plan);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("misses     ") && text.contains("started in x ∈ ["), "{text}");
}

#[test]
fn bad_feed_regions_exit_2_naming_the_values() {
    let (part, plate) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let plan = |feed: &[&str]| {
        let mut args = vec!["plan", part.as_str(), "--plate", plate.as_str(), "--feed"];
        args.extend_from_slice(feed);
        chladni(&args)
    };
    for (feed, want) in [
        (["10", "20", "5", "40"], "feed region 10 20 5 40 mm is empty"),
        (["10", "20", "50", "20"], "feed region 10 20 50 20 mm is empty"),
        (
            ["250", "150", "320", "190"],
            "feed region 250 150 320 190 mm is not inside the 300 × 200 mm plate",
        ),
        (["-5", "0", "40", "40"], "feed region -5 0 40 40 mm is not inside"),
        (
            ["nan", "0", "40", "40"],
            "feed region NaN 0 40 40 mm: every coordinate must be a finite number",
        ),
    ] {
        let out = plan(&feed);
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{feed:?}: {err}");
        assert!(err.contains("--feed") && err.contains(want), "{feed:?}: {err}");
    }
    // Three numbers, or one that is not a number: clap's own errors, also exit 2.
    for feed in [&["10", "20", "50"][..], &["10", "20", "x", "40"]] {
        let out = plan(feed);
        assert_eq!(out.status.code(), Some(2), "{feed:?}");
    }
    // `chladni simulate --feed` checks the region the same way (before reading the plan).
    let out = chladni(&[
        "simulate",
        &part,
        "--plate",
        &plate,
        "--plan",
        &ex("plans/triangle-four-lines.json"),
        "--feed",
        "0",
        "0",
        "400",
        "40",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("feed region 0 0 400 40 mm is not inside"), "{err}");
}

#[test]
fn static_and_dynamic_maps_give_the_same_example_plan() {
    let run = |maps: &str| {
        let args =
            ["plan", &ex("parts/key.svg"), "--plate", &ex("plates/four-lines.toml"), "--json"];
        let out = chladni(&[&args[..], &["--maps", maps]].concat());
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        out.stdout
    };
    assert_eq!(run("static"), run("dynamic"));
    assert_eq!(run("auto"), run("static"));
    let out = chladni(&[
        "plan",
        &ex("parts/key.svg"),
        "--plate",
        &ex("plates/four-lines.toml"),
        "--maps",
        "exact",
    ]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("static") && err.contains("dynamic") && err.contains("auto"), "{err}");
}

#[test]
fn a_plan_out_of_time_is_one_json_failure_naming_the_limit_and_the_stage() {
    // 1 ns: gone by the first look at the clock (before the first step map).
    let out = triangle_on_four_lines("plan", &["--max-time-s", "1e-9", "--json"]);
    assert!(!out.status.success());
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["error"], "out_of_time", "{v}");
    assert_eq!(v["max_time_s"], 1e-9);
    assert!(v["stage"].as_str().unwrap().contains("step map 1 of 4"), "{v}");
    assert!(v["message"].as_str().unwrap().contains("--max-time-s"), "{v}");
    // Refused before planning: a limit that is no time at all.
    let out = triangle_on_four_lines("plan", &["--max-time-s", "0"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("max-time-s"));
}

#[test]
fn a_plan_over_the_device_hour_is_written_with_a_warning_in_text_and_json() {
    // --safety 100: the triangle's two ~24 s steps last about 40 min each, over the hour.
    let out_file = tmp("plan", "tri-long.json");
    let args = ["--json", "--safety", "100", "--out", out_file.to_str().unwrap()];
    let out = triangle_on_four_lines("plan", &args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let d = &v["device_limit"];
    assert_eq!(d["max_total_ms"], 3_600_000);
    let plan_ms = d["plan_ms"].as_u64().unwrap();
    assert!(plan_ms > 3_600_000, "{d}");
    let w = d["warning"].as_str().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    for needed in [format!("{plan_ms} ms"), "3600000 ms".into(), "plate calibrate-speed".into()] {
        assert!(w.contains(&needed) && stderr.contains(&needed), "{needed}: {w} / {stderr}");
    }
    // The written file is the plan, without the report key.
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out_file).unwrap()).unwrap();
    assert!(written.get("device_limit").is_none());
}
