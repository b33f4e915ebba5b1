//! `chladni analyze` end to end: output format, exit codes, plots.

use crate::support;
use support::cli::{chladni, ex, floats, ok_json, tmp};

#[test]
fn rectangle_json_is_exactly_the_documented_object() {
    let v =
        ok_json(&chladni(&["analyze", &ex("parts/rectangle.json"), "--field", "sign", "--json"]));
    let keys: Vec<&str> = v.as_object().unwrap().keys().map(String::as_str).collect();
    assert_eq!(keys.len(), 6);
    for k in ["part", "field", "stable_deg", "unstable_deg", "neutral", "period_deg"] {
        assert!(keys.contains(&k), "{k} missing");
    }
    assert_eq!(v["part"], "rectangle");
    assert_eq!(v["field"], "sign");
    assert_eq!(floats(&v["stable_deg"]), [90.0, 270.0]);
    assert_eq!(floats(&v["unstable_deg"]), [0.0, 180.0]);
    assert_eq!(v["neutral"], false);
    assert_eq!(v["period_deg"], 180.0);
}

#[test]
fn square_is_neutral_in_a_linear_field_and_diagonal_in_a_sign_field() {
    let sq = tmp("analyze", "square.json");
    std::fs::write(&sq, r#"{"name": "square", "outline": [[0,0],[20,0],[20,20],[0,20]]}"#).unwrap();
    let sq = sq.display().to_string();
    let v = ok_json(&chladni(&["analyze", &sq, "--field", "linear", "--json"]));
    assert_eq!(v["neutral"], true);
    assert!(v["stable_deg"].as_array().unwrap().is_empty());
    assert!(v["unstable_deg"].as_array().unwrap().is_empty());
    let v = ok_json(&chladni(&["analyze", &sq, "--field", "sign", "--json"]));
    assert_eq!(floats(&v["stable_deg"]), [45.0, 135.0, 225.0, 315.0]);
    assert_eq!(v["period_deg"], 90.0);
}

#[test]
fn rotated_input_file_shifts_the_orientations() {
    let base =
        ok_json(&chladni(&["analyze", &ex("parts/triangle.json"), "--field", "sign", "--json"]));
    // The same triangle turned by 30° and moved: rests shift by −30°.
    let (s, c) = 30f64.to_radians().sin_cos();
    let pts: Vec<[f64; 2]> = [[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]]
        .iter()
        .map(|p: &[f64; 2]| [c * p[0] - s * p[1] + 55.0, s * p[0] + c * p[1] - 7.0])
        .collect();
    let f = tmp("analyze", "turned.json");
    std::fs::write(&f, serde_json::json!({"name": "turned", "outline": pts}).to_string()).unwrap();
    let v = ok_json(&chladni(&["analyze", f.to_str().unwrap(), "--field", "sign", "--json"]));
    let mut want: Vec<f64> =
        floats(&base["stable_deg"]).iter().map(|d| (d - 30.0).rem_euclid(360.0)).collect();
    want.sort_by(f64::total_cmp);
    for (g, w) in floats(&v["stable_deg"]).iter().zip(&want) {
        assert!((g - w).abs() < 1e-4, "{g} vs {w}");
    }
}

#[test]
fn every_example_part_analyses_and_the_table_is_readable() {
    for name in [
        "rectangle.json",
        "triangle.json",
        "trapezoid.json",
        "l-shape.json",
        "plate-with-hole.json",
        "key.svg",
    ] {
        let out = chladni(&["analyze", &ex(&format!("parts/{name}")), "--field", "linear"]);
        assert!(out.status.success(), "{name}: {}", String::from_utf8_lossy(&out.stderr));
        let text = String::from_utf8(out.stdout).unwrap();
        assert!(text.contains("stable") && text.contains("period"), "{text}");
    }
}

#[test]
fn bad_input_exits_with_code_2_and_names_the_problem() {
    let bow = tmp("analyze", "bowtie.json");
    std::fs::write(&bow, r#"{"outline": [[0,0],[2,2],[2,0],[0,2]]}"#).unwrap();
    let out = chladni(&["analyze", bow.to_str().unwrap(), "--field", "sign"]);
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("self-intersection") && err.contains("vertex 0") && err.lines().count() == 1,
        "{err}"
    );
    let rect = ex("parts/rectangle.json");
    for args in [
        vec!["analyze", &rect, "--field", "sine"],
        vec!["analyze", &rect, "--field", "sine", "--wavelength", "10"],
        vec!["analyze", &rect, "--field", "sign", "--wavelength", "10"],
        vec!["analyze", &rect, "--field", "sign", "--gain-left", "-1"],
        vec!["analyze", "/nonexistent/part.json", "--field", "sign"],
    ] {
        let out = chladni(&args);
        assert_eq!(
            out.status.code(),
            Some(2),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let out = chladni(&["analyze", &rect, "--field", "sine", "--wavelength", "10"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("too short"));
}

#[test]
fn plots_are_written_as_png_and_svg() {
    let png = tmp("analyze", "l.png");
    let svg = tmp("analyze", "l.svg");
    for p in [&png, &svg] {
        let out = chladni(&[
            "analyze",
            &ex("parts/l-shape.json"),
            "--field",
            "sign",
            "--plot",
            p.to_str().unwrap(),
        ]);
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    }
    let bytes = std::fs::read(&png).unwrap();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert!(bytes.len() > 10_000);
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg") && text.contains("turn function"));
}
