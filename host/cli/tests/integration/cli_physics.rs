//! `chladni physics string`: input errors, the bouncing threshold in text and JSON.

use std::process::{Command, Output};

/// Runs `chladni physics string` for `secs` simulated seconds (force profile: 1 s a point).
fn string(secs: &str, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["physics", "string", "--duration", secs, "--average", "1"])
        .args(args)
        .output()
        .unwrap()
}

#[test]
fn bad_restitution_and_start_are_named_with_their_value() {
    let out = string("40", &["--e", "1.5"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--e must be in [0, 1], got 1.5"));
    let out = string("40", &["--e", "0.5", "--x0", "4"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--x0 must be in (0, π), got 4"));
}

#[test]
fn low_restitution_at_the_default_drive_is_told_it_cannot_bounce_and_what_would_help() {
    let out = string("40", &["--e", "0.1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("x: 1.200 → 1.200"), "{text}");
    assert!(text.contains("= 2.570 > Γ: the particle locks onto the string everywhere"), "{text}");
    assert!(text.contains("it needs --freq-hz > 5.85"), "{text}");
}

#[test]
fn json_reports_the_threshold_and_the_stop_position() {
    let out = string("150", &["--e", "0.9", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let b = &v["bouncing"];
    assert!((b["threshold_gamma_sin_x"].as_f64().unwrap() - 0.1653).abs() < 1e-3, "{b}");
    assert!((b["stop_x"].as_f64().unwrap() - 0.1355).abs() < 1e-3, "{b}");
    // Chaotic near the antinode, then periodic bouncing to the node: 0.386 after 120 s.
    assert!(v["trajectory"]["x_end"].as_f64().unwrap() < 0.6, "{}", v["trajectory"]["x_end"]);
    let out = string("40", &["--e", "0.1", "--json"]);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["bouncing"]["stop_x"].is_null(), "{}", v["bouncing"]);
}

#[test]
fn json_samples_are_as_many_as_asked_and_agree_with_the_text() {
    let args = ["--e", "0.9", "--json", "--samples", "7"];
    let out = string("60", &args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let tr = &v["trajectory"];
    let s = tr["samples"].as_array().unwrap();
    assert_eq!(s.len(), 7, "{tr}");
    assert_eq!(s[0][0].as_f64(), Some(0.0));
    assert_eq!(s[0][1].as_f64(), tr["x0"].as_f64());
    assert_eq!(s[6][0].as_f64(), Some(60.0));
    assert_eq!(s[6][1].as_f64(), tr["x_end"].as_f64());
    assert!(s.windows(2).all(|w| w[0][0].as_f64() < w[1][0].as_f64()), "{tr}");
    // The drift profile and its fit: the paper's sign (c > 0, towards the nodes), and the same
    // c as the text report prints.
    assert_eq!(v["drift"].as_array().unwrap().len(), 16);
    let c = v["fit"]["c"].as_f64().unwrap();
    assert!(c > 0.0, "{}", v["fit"]);
    let text = String::from_utf8_lossy(&string("60", &["--e", "0.9"]).stdout).to_string();
    assert!(text.contains(&format!("c = {c:.2e} m/s")), "{c:.2e} in {text}");
    let bad = string("10", &["--e", "0.9", "--samples", "1"]);
    assert_eq!(bad.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&bad.stderr).contains("--samples must be in 2..=100000, got 1")
    );
}

#[test]
fn the_figure_is_also_written_as_svg() {
    let dir = std::env::temp_dir().join(format!("chladni-physics-svg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let svg = dir.join("string.svg");
    let out = string("20", &["--e", "0.9", "--plot", svg.to_str().unwrap()]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let text = std::fs::read_to_string(&svg).unwrap();
    let doc = roxmltree::Document::parse(&text).unwrap();
    assert_eq!(doc.root_element().tag_name().name(), "svg");
    let texts: Vec<String> = doc
        .descendants()
        .filter(|n| n.has_tag_name("text"))
        .filter_map(|n| n.text().map(|t| t.trim().to_string()))
        .collect();
    for want in ["time (s)", "drift v (mm/s)", "x(t)", "fit −c sin 2x"] {
        assert!(texts.iter().any(|t| t == want), "{want} not in {texts:?}");
    }
    assert!(doc.descendants().any(|n| n.has_tag_name("polyline")), "no curves");
    std::fs::remove_dir_all(&dir).unwrap();
}
