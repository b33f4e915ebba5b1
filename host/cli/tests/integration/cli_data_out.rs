//! Data out for research: `analyze --json --samples N` and `--csv`, `simulate --json --poses`
//! and `--traces`, figures as SVG. Each check compares the data with the numbers the command
//! prints otherwise.

use crate::support;
use support::cli::{chladni, ok_json as json, repo, tmp};

#[test]
fn analyze_samples_agree_with_the_rests_and_the_csv() {
    let part = repo("examples/parts/triangle.json");
    let v = json(&chladni(&["analyze", &part, "--field", "sign", "--json", "--samples", "361"]));
    let samples = v["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 361);
    let stable: Vec<f64> =
        v["stable_deg"].as_array().unwrap().iter().map(|s| s.as_f64().unwrap()).collect();
    assert!(!stable.is_empty());
    // Every alignment value is a stable rest; t goes from + to − across each stable rest.
    let near = |a: f64, b: f64| ((a - b + 540.0).rem_euclid(360.0) - 180.0).abs() < 1e-3;
    for s in samples {
        let a = s["alignment_deg"].as_f64().unwrap();
        assert!(stable.iter().any(|&r| near(r, a)), "a = {a} not in {stable:?}");
        assert!(s["turn"].as_f64().unwrap().abs() <= 1.0 + 1e-12);
    }
    for &r in &stable {
        let at = |d: f64| {
            let k = (d.rem_euclid(360.0)).round() as usize;
            samples[k]["turn"].as_f64().unwrap()
        };
        assert!(
            at(r - 2.0) > 0.0 && at(r + 2.0) < 0.0,
            "t around {r}: {} {}",
            at(r - 2.0),
            at(r + 2.0)
        );
    }
    // The CSV holds the same samples.
    let csv = tmp("data-out", "triangle.csv");
    let out = chladni(&[
        "analyze",
        &part,
        "--field",
        "sign",
        "--csv",
        csv.to_str().unwrap(),
        "--samples",
        "361",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let mut r = csv::Reader::from_path(&csv).unwrap();
    assert_eq!(r.headers().unwrap(), vec!["theta_deg", "turn", "alignment_deg"]);
    let rows: Vec<Vec<f64>> =
        r.records().map(|rec| rec.unwrap().iter().map(|f| f.parse().unwrap()).collect()).collect();
    assert_eq!(rows.len(), 361);
    for (row, s) in rows.iter().zip(samples) {
        for (k, key) in ["theta_deg", "turn", "alignment_deg"].iter().enumerate() {
            assert!((row[k] - s[key].as_f64().unwrap()).abs() < 1e-12, "{key}: {row:?} {s}");
        }
    }
    // Without --json or --csv, --samples is refused rather than ignored.
    let out = chladni(&["analyze", &part, "--field", "sign", "--samples", "9"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--samples goes with --json or --csv"));
    // Without --samples the JSON has no samples key (as before).
    let v = json(&chladni(&["analyze", &part, "--field", "sign", "--json"]));
    assert!(v.get("samples").is_none());
}

#[test]
fn analyze_plot_as_svg_is_xml_with_its_three_panels() {
    let part = repo("examples/parts/triangle.json");
    let svg = tmp("data-out", "triangle.svg");
    let out = chladni(&["analyze", &part, "--field", "sign", "--plot", svg.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&svg).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let polylines = doc.descendants().filter(|n| n.has_tag_name("polyline")).count();
    assert!(polylines >= 2, "t(θ) and a(θ) curves: {polylines}");
}

#[test]
fn simulate_poses_and_traces_agree_with_the_statistics() {
    let traces = tmp("data-out", "traces.jsonl");
    let args = [
        "simulate",
        &repo("examples/parts/triangle.json"),
        "--plate",
        &repo("examples/plates/four-lines.toml"),
        "--plan",
        &repo("examples/plans/triangle-four-lines.json"),
        "--trials",
        "12",
        "--json",
        "--poses",
        "--traces",
        traces.to_str().unwrap(),
    ];
    let v = json(&chladni(&args));
    let poses = v["poses"].as_array().unwrap();
    assert_eq!(poses.len(), 12, "every trial, not the first few");
    let target = v["final_orientation_deg"].as_f64().unwrap();
    let tol = v["tolerance_deg"].as_f64().unwrap();
    let within = |a: f64| ((a - target + 540.0).rem_euclid(360.0) - 180.0).abs() <= tol;
    let hits = poses.iter().filter(|p| within(p["end"]["theta_deg"].as_f64().unwrap())).count();
    assert_eq!(hits as f64 / 12.0, v["success_rate"].as_f64().unwrap());
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&traces)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(lines.len(), 12);
    for (k, (p, line)) in poses.iter().zip(&lines).enumerate() {
        assert_eq!(p["trial"].as_u64(), Some(k as u64 + 1));
        assert_eq!(line["trial"].as_u64(), Some(k as u64 + 1));
        assert_eq!(p["steps"].as_array().unwrap().len(), 2, "two steps in the plan");
        assert_eq!(p["steps"][1], p["end"]);
        let s = line["samples"].as_array().unwrap();
        let (first, last) = (&s[0], &s[s.len() - 1]);
        assert_eq!(first[1].as_f64(), Some(1.0), "steps numbered from 1");
        assert_eq!(last[1].as_f64(), Some(2.0));
        assert!((first[2].as_f64().unwrap() - p["start"]["x_mm"].as_f64().unwrap()).abs() < 1e-9);
        assert!((last[2].as_f64().unwrap() - p["end"]["x_mm"].as_f64().unwrap()).abs() < 1e-9);
        assert!((last[3].as_f64().unwrap() - p["end"]["y_mm"].as_f64().unwrap()).abs() < 1e-9);
        let th = last[4].as_f64().unwrap().rem_euclid(360.0);
        let end = p["end"]["theta_deg"].as_f64().unwrap();
        assert!(((th - end + 540.0).rem_euclid(360.0) - 180.0).abs() < 1e-6, "{th} vs {end}");
        // θ unwrapped: no jump larger than a turn step between samples.
        for w in s.windows(2) {
            assert!((w[1][4].as_f64().unwrap() - w[0][4].as_f64().unwrap()).abs() < 180.0);
        }
    }
    // --poses needs --json.
    let out = chladni(&args[..args.len() - 3]);
    assert!(out.status.success());
    let out = chladni(&[&args[..8], &["--poses"]].concat());
    assert_eq!(out.status.code(), Some(2));
}
