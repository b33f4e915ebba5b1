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
