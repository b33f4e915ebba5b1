//! Data out for research: `analyze --json --samples N` and `--csv`, `simulate --json --poses`
//! and `--traces`, figures as SVG. Each check compares the data with the numbers the command
//! prints otherwise.

use std::path::PathBuf;
use std::process::{Command, Output};

fn chladni(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chladni")).args(args).output().unwrap()
}

fn repo(path: &str) -> String {
    format!("{}/../{path}", env!("CARGO_MANIFEST_DIR"))
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("chladni-data-out-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn json(out: &Output) -> serde_json::Value {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

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
    let csv = tmp("triangle.csv");
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
    let svg = tmp("triangle.svg");
    let out = chladni(&["analyze", &part, "--field", "sign", "--plot", svg.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&svg).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let polylines = doc.descendants().filter(|n| n.has_tag_name("polyline")).count();
    assert!(polylines >= 2, "t(θ) and a(θ) curves: {polylines}");
}
