//! `chladni plan --goal-deg/--fix-position/--goal-pos/--minimize` and several parts with
//! `plan` and `simulate`: exit codes and JSON keys.

use std::process::Output;

use crate::support;
use support::cli::{chladni, ex, json, tmp};

fn triangle_plan(extra: &[&str]) -> Output {
    let (tri, four) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let mut args = vec!["plan", tri.as_str(), "--plate", four.as_str(), "--json"];
    args.extend(extra);
    chladni(&args)
}

#[test]
fn goal_deg_reachable_and_unreachable() {
    let out = triangle_plan(&[]);
    assert!(out.status.success());
    let v = json(&out);
    let reachable: Vec<f64> =
        v["reachable_deg"].as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
    assert!(reachable.len() >= 2 && v.get("goal_deg").is_none(), "{v}");
    let other = reachable
        .iter()
        .find(|&&t| (t - v["final_orientation_deg"].as_f64().unwrap()).abs() > 10.0)
        .unwrap()
        .to_string();
    let out = triangle_plan(&["--goal-deg", &other]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let g = json(&out);
    assert!(
        (g["final_orientation_deg"].as_f64().unwrap() - other.parse::<f64>().unwrap()).abs() < 1e-3
    );
    assert_eq!(g["goal_deg"].as_f64().unwrap(), other.parse::<f64>().unwrap());
    // 30° is not reachable: exit 1, the reachable set and the nearest, in JSON and text.
    let out = triangle_plan(&["--goal-deg", "30"]);
    assert_eq!(out.status.code(), Some(1));
    let e = json(&out);
    assert_eq!(e["error"], "goal_unreachable");
    assert_eq!(e["reachable_deg"].as_array().unwrap().len(), reachable.len());
    assert!(e["nearest_deg"].is_number() && e["message"].is_string(), "{e}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("reachable final orientations") && err.contains("nearest"), "{err}");
    // One angle per part.
    let out = triangle_plan(&["--goal-deg", "30", "40"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("one angle per part"));
}

#[test]
fn position_and_minimize_flags() {
    let out = triangle_plan(&["--fix-position", "--minimize", "time"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(json(&out)["final_position_mm"].as_array().unwrap().len(), 2);
    let out = triangle_plan(&["--goal-pos", "140", "100"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let p = json(&out)["final_position_mm"].clone();
    assert!((p[0].as_f64().unwrap() - 140.0).abs() < 5.0, "{p}");
    let out = triangle_plan(&["--minimize", "fast"]);
    assert_eq!(out.status.code(), Some(2));
    // The rectangle on the six-line plate: no plan of at most two steps fixes it.
    let (rect, six) = (ex("parts/rectangle.json"), ex("plates/six-lines.toml"));
    let out = chladni(&["plan", &rect, "--plate", &six, "--fix-position", "--json"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(json(&out)["error"], "position_not_fixed");
}

#[test]
fn two_parts_plan_and_simulate_per_part() {
    let (tri, hole, six) =
        (ex("parts/triangle.json"), ex("parts/plate-with-hole.json"), ex("plates/six-lines.toml"));
    let file = tmp("goal", "two.json");
    let f = file.to_str().unwrap();
    let out = chladni(&["plan", &tri, &hole, "--plate", &six, "--json", "--out", f]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(&out);
    assert!(v["final_orientation_deg"].is_null());
    let parts = v["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 2);
    assert_eq!(parts[0]["name"], "triangle");
    for p in parts {
        assert!(p["final_orientation_deg"].is_number() && p["reachable_deg"].is_array(), "{p}");
    }
    let out = chladni(&[
        "simulate", &tri, &hole, "--plate", &six, "--plan", f, "--trials", "4", "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let s = json(&out);
    let entries = s["parts"].as_array().unwrap();
    assert_eq!(entries.len(), 2);
    // Both parts are dropped together and touch (docs/motion.md, "Contacts between parts"):
    // the plan brings them to nearly one spot, so both cannot end where it predicts; each
    // part's report is still there (host/cli/tests/integration/bulk.rs checks that they end apart).
    for e in entries {
        let s = e["success_rate"].as_f64().unwrap();
        assert!((0.0..=1.0).contains(&s) && e["trials"] == 4, "{e}");
    }
    assert_eq!(entries[1]["part"], "plate with hole");
    // The plan is for two parts: one part is refused (bad input).
    let out = chladni(&["simulate", &tri, "--plate", &six, "--plan", f, "--trials", "2"]);
    assert_eq!(out.status.code(), Some(2));
    // The triangle and the rectangle cannot share a plan here: exit 1, named.
    let rect = ex("parts/rectangle.json");
    let out = chladni(&["plan", &tri, &rect, "--plate", &six, "--json"]);
    assert_eq!(out.status.code(), Some(1));
    let e = json(&out);
    assert_eq!(e["error"], "parts_apart");
    assert_eq!(e["apart"][0]["part"], "triangle");
}
