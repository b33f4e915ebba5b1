//! Parts on the plate together, end to end: `chladni simulate --copies N` (bulk feeding: the
//! JSON keys, no two copies overlapping at the end, seeded drops, the named error for an N
//! that cannot be placed) and a plan for two parts simulated with both on the plate.
//!
//! Overlaps are checked here with plain geometry, not the simulator's (parry) contacts:
//! points sampled along each part's boundary must not lie deeper than a tolerance inside
//! the other part's area.

use std::process::Output;

use chladni_core::model::geometry::inside;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::bulk::{self, Drop};
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::shape::Pieces;
use chladni_core::motion::steps::plan_steps;

use crate::support;
use support::cli::{chladni, ex};
use support::examples;

/// Overlap allowed at the end (mm): the contact solve's separation leaves less.
const TOL_MM: f64 = 0.05;

fn copies(n: &str, seed: &str, extra: &[&str]) -> Output {
    let (part, plate, plan) = (
        ex("parts/triangle.json"),
        ex("plates/four-lines.toml"),
        ex("plans/triangle-four-lines.json"),
    );
    let mut args = vec!["simulate", &part, "--plate", &plate, "--plan", &plan];
    args.extend(["--copies", n, "--seed", seed, "--trials", "1", "--json"]);
    args.extend(extra);
    chladni(&args)
}

fn seg_dist(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let t = (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0);
    (p[0] - a[0] - t * dx).hypot(p[1] - a[1] - t * dy)
}

/// How deep points on `a`'s boundary lie inside `b`'s area (outline minus holes), mm.
fn depth_in(a: &[Vec<[f64; 2]>], b: &[Vec<[f64; 2]>]) -> f64 {
    let mut worst = 0.0f64;
    for ring in a {
        for k in 0..ring.len() {
            let (p, q) = (ring[k], ring[(k + 1) % ring.len()]);
            for s in 0..=40 {
                let t = s as f64 / 40.0;
                let x = [p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])];
                if inside(x, &b[0]) && !b[1..].iter().any(|h| inside(x, h)) {
                    let d = (b.iter())
                        .flat_map(|r| {
                            (0..r.len()).map(move |i| seg_dist(x, r[i], r[(i + 1) % r.len()]))
                        })
                        .fold(f64::INFINITY, f64::min);
                    worst = worst.max(d);
                }
            }
        }
    }
    worst
}

fn overlap(a: &[Vec<[f64; 2]>], b: &[Vec<[f64; 2]>]) -> f64 {
    depth_in(a, b).max(depth_in(b, a))
}

#[test]
fn copies_report_the_documented_keys_and_end_apart_reproducibly() {
    let out = copies("4", "7", &[]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    for key in ["copies", "oriented", "lost", "parts_per_min"] {
        assert!(v.get(key).is_some(), "{key} missing: {v}");
    }
    assert_eq!(v["copies"], 4);
    assert_eq!(v["lost"], 0);
    let f = v["oriented"].as_f64().unwrap();
    assert!((0.0..=1.0).contains(&f), "{v}");
    let ppm = v["parts_per_min"].as_f64().unwrap();
    let plan_s = v["plan_s"].as_f64().unwrap();
    assert!((ppm - f * 4.0 * 60.0 / plan_s).abs() < 1e-5, "{v}");
    // No two copies overlap at the end (plain geometry).
    let body = Body::new(&examples::part("triangle.json"));
    let placed: Vec<Vec<Vec<[f64; 2]>>> = (v["final_poses"].as_array().unwrap().iter())
        .map(|p| {
            let p: Vec<f64> = p.as_array().unwrap().iter().map(|x| x.as_f64().unwrap()).collect();
            body.placed(Pose { x: p[0], y: p[1], theta: p[2].to_radians() })
        })
        .collect();
    assert_eq!(placed.len(), 4);
    for i in 0..4 {
        for j in i + 1..4 {
            let d = overlap(&placed[i], &placed[j]);
            assert!(d <= TOL_MM, "copies {i} and {j} overlap by {d} mm: {v}");
        }
    }
    // Same seed, same drop; another seed, another.
    assert_eq!(copies("4", "7", &[]).stdout, out.stdout);
    assert_ne!(copies("4", "8", &[]).stdout, out.stdout);
}

#[test]
fn copies_that_cannot_be_placed_are_refused_by_name() {
    let out = copies("1000", "1", &[]);
    assert_eq!(out.status.code(), Some(2), "{}", String::from_utf8_lossy(&out.stderr));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("cannot place 1000 parts without overlap"), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["error"], "cannot_place");
    assert_eq!(v["parts"], 1000);
    // And copies of two parts are refused (copies are of one part).
    let (a, b) = (ex("parts/triangle.json"), ex("parts/plate-with-hole.json"));
    let (plate, plan) =
        (ex("plates/six-lines.toml"), ex("plans/triangle-and-plate-with-hole-six-lines.json"));
    let out = chladni(&["simulate", &a, &b, "--plate", &plate, "--plan", &plan, "--copies", "2"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--copies drops copies of one part"));
}

#[test]
fn the_two_part_plan_runs_both_parts_together_and_they_end_apart() {
    // The example plan for a triangle and a plate with a hole predicts both at nearly the
    // same spot; simulated together they cannot both be there, and never overlap.
    let (tri, holed) = (examples::part("triangle.json"), examples::part("plate-with-hole.json"));
    let plate = examples::plate("six-lines.toml");
    let text =
        std::fs::read_to_string(ex("plans/triangle-and-plate-with-hole-six-lines.json")).unwrap();
    let file = chladni_core::model::plan_file::PlanFile::parse(&text).unwrap();
    let steps = plan_steps(&file, &plate).unwrap();
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let bodies = [Body::new(&tri), Body::new(&holed)];
    let pieces = [Pieces::of(&bodies[0]), Pieces::of(&bodies[1])];
    let (b, p) = ([&bodies[0], &bodies[1]], [&pieces[0], &pieces[1]]);
    let d =
        Drop { bodies: &b, pieces: &p, plate: &plate, fields: &fields, steps: &steps, feed: None };
    let drops = bulk::run_drops(&d, 3, 11, &chladni_core::progress::Silent).unwrap();
    for k in 0..3 {
        let (qa, qb) = (drops.per_body[0].finals[k], drops.per_body[1].finals[k]);
        let d = overlap(&bodies[0].placed(qa), &bodies[1].placed(qb));
        assert!(d <= TOL_MM, "drop {k}: overlap {d} mm at {qa:?} {qb:?}");
    }
    // The command reports each part, as before.
    let args = [
        "simulate",
        &ex("parts/triangle.json"),
        &ex("parts/plate-with-hole.json"),
        "--plate",
        &ex("plates/six-lines.toml"),
        "--plan",
        &ex("plans/triangle-and-plate-with-hole-six-lines.json"),
        "--trials",
        "2",
        "--json",
    ];
    let out = chladni(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let parts = v["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 2);
    assert_eq!(
        (parts[0]["part"].as_str(), parts[1]["part"].as_str()),
        (Some("triangle"), Some("plate with hole"))
    );
    assert_eq!(parts[0]["trials"], 2);
}

#[test]
fn plan_copies_reports_the_chosen_candidate_and_refuses_several_parts() {
    let (part, plate) = (ex("parts/rectangle.json"), ex("plates/four-lines.toml"));
    let out = chladni(&["plan", &part, "--plate", &plate, "--copies", "3", "--json"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["copies"], 3);
    assert!(v["oriented"].is_f64() && v["lost"].is_u64(), "{v}");
    let best = v["parts_per_min"].as_f64().unwrap();
    let cands = v["candidates"].as_array().unwrap();
    assert!(cands.len() >= 2, "{v}");
    for c in cands {
        assert!(c["parts_per_min"].as_f64().unwrap() <= best, "{c} beats the chosen {best}");
    }
    // The plan printed is the chosen one: its prediction is a candidate's with that throughput.
    let chosen = cands.iter().find(|c| c["parts_per_min"].as_f64() == Some(best)).unwrap();
    assert_eq!(chosen["final_orientation_deg"], v["final_orientation_deg"]);
    let tri = ex("parts/triangle.json");
    let out = chladni(&["plan", &part, &tri, "--plate", &plate, "--copies", "3"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&out.stderr)
            .contains("--copies ranks plans for copies of one part")
    );
}
