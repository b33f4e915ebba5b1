//! `chladni simulate` of a plan for two parts, one of them on both faces: every trial drops
//! the parts together (contacts between them), the flipping part face up in the first half
//! of the trials and flipped in the other; each face is reported against its own prediction
//! in the plan, and the runs are the library's own drops of exactly those bodies.

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::bulk::{self, Drop};
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo;
use chladni_core::motion::shape::{self, Pieces};
use chladni_core::motion::steps::plan_steps;

use crate::support;
use support::cli::{chladni, ex, json, tmp, write_tmp};
use support::examples;

const TRIALS: usize = 8;

/// A trial's end pose from `simulate --json --poses`.
fn end(e: &serde_json::Value, trial: usize) -> Pose {
    let p = &e["poses"][trial]["end"];
    let v = |k: &str| p[k].as_f64().unwrap();
    Pose { x: v("x_mm"), y: v("y_mm"), theta: v("theta_deg").to_radians() }
}

fn same(a: Pose, b: Pose) -> bool {
    let dt = (a.theta.to_degrees() - b.theta.to_degrees()).rem_euclid(360.0);
    (a.x - b.x).abs() < 1e-9 && (a.y - b.y).abs() < 1e-9 && dt.min(360.0 - dt) < 1e-9
}

#[test]
fn a_part_on_both_faces_is_simulated_together_with_the_other_part_per_face() {
    // The triangle lands on either face ("flips": true); the plate with a hole does not.
    let tri = examples::part("triangle.json");
    let text = serde_json::json!({"name": "triangle", "outline": tri.outline, "flips": true});
    let tri_path = write_tmp("faces-together", "triangle.json", text.to_string());
    let (other, plate_path) = (ex("parts/plate-with-hole.json"), ex("plates/six-lines.toml"));
    let plan = tmp("faces-together", "plan.json");
    let plan_s = plan.to_str().unwrap();
    let out =
        chladni(&["plan", &tri_path, &other, "--plate", &plate_path, "--out", plan_s, "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    // The planner sends both parts to one node crossing: their predicted ends overlap, and
    // the plan says so (the simulation below keeps them apart).
    let printed: serde_json::Value = serde_json::from_slice(&out.stdout).expect("plan --json");
    let overlaps = printed["end_overlaps"].as_array().expect("end_overlaps");
    assert!(
        overlaps.iter().any(|o| o["parts"] == serde_json::json!(["triangle", "plate with hole"])
            && o["depth_mm"].as_f64().is_some_and(|d| d > 1.0)),
        "{printed}"
    );
    assert!(stderr.contains("predicted to end overlapping"), "{stderr}");
    let file = PlanFile::parse(&std::fs::read_to_string(&plan).unwrap()).unwrap();
    let faces: Vec<_> = file.parts.as_ref().unwrap().iter().map(|p| p.face).collect();
    assert_eq!(faces.len(), 3, "triangle up, triangle flipped, plate with hole");
    let trials = TRIALS.to_string();
    let args = ["simulate", &tri_path, &other, "--plate", &plate_path, "--plan", plan_s];
    let out = chladni(&[&args[..], &["--trials", &trials, "--json", "--poses"]].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v = json(&out);
    let r = v["parts"].as_array().unwrap();
    let said = |i: usize, k: &str| r[i][k].clone();
    assert_eq!(r.len(), 3, "{v}");
    assert_eq!(
        [0, 1, 2].map(|i| (said(i, "part"), said(i, "face"))),
        [
            ("triangle".into(), "up".into()),
            ("triangle (flipped)".into(), "flipped".into()),
            ("plate with hole".into(), serde_json::Value::Null)
        ]
    );
    let half = TRIALS.div_ceil(2);
    assert_eq!(
        [0, 1, 2].map(|i| said(i, "trials")),
        [half, TRIALS - half, TRIALS].map(serde_json::Value::from)
    );

    // The same drops from the library: the face up with the plate from --seed, the flipped
    // face with the plate from the flipped face's seed.
    let plate = examples::plate("six-lines.toml");
    let steps = plan_steps(&file, &plate).unwrap();
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let plate_part = Part::load(std::path::Path::new(&other)).unwrap();
    let shapes = [tri.clone(), tri.mirrored(), plate_part].map(|p| Body::new(&p));
    let pieces = shapes.each_ref().map(Pieces::of);
    let group = |face: usize, n: usize, seed: u64| {
        let bodies = [&shapes[face], &shapes[2]];
        let pcs = [&pieces[face], &pieces[2]];
        let d = Drop {
            bodies: &bodies,
            pieces: &pcs,
            plate: &plate,
            fields: &fields,
            steps: &steps,
            feed: None,
        };
        bulk::run_drops(&d, n as u32, seed, &chladni_core::progress::Silent).unwrap()
    };
    let up = group(0, half, said(0, "seed").as_u64().unwrap());
    let flipped = group(1, TRIALS - half, said(1, "seed").as_u64().unwrap());
    for (k, t) in up.per_body[0].finals.iter().enumerate() {
        assert!(same(end(&r[0], k), *t), "face up, trial {}", k + 1);
        assert!(same(end(&r[2], k), up.per_body[1].finals[k]), "plate, trial {}", k + 1);
    }
    for (k, t) in flipped.per_body[0].finals.iter().enumerate() {
        assert!(same(end(&r[1], k), *t), "flipped, trial {}", k + 1);
        assert!(same(end(&r[2], half + k), flipped.per_body[1].finals[k]), "plate {}", half + k);
    }
    // Together: in every drop the two parts on the plate end apart.
    for k in 0..TRIALS {
        let face = if k < half { 0 } else { 1 };
        let (a, b) = (end(&r[face], k % half), end(&r[2], k));
        let depth = shape::overlap(&pieces[face], a, &pieces[2], b);
        assert!(depth < 1e-3, "trial {}: the parts overlap by {depth} mm", k + 1);
    }

    // Each face judged against its own prediction in the plan, as the library judges it.
    let runs = [&up.per_body[0], &flipped.per_body[0]];
    for (i, trials) in runs.iter().enumerate() {
        let view = file.for_part(i).unwrap();
        let stats = montecarlo::statistics(trials, &view, 5.0);
        assert_eq!(said(i, "final_orientation_deg").as_f64(), view.final_orientation_deg);
        let rate = said(i, "success_rate").as_f64().unwrap();
        assert!((rate - stats.success_rate.unwrap()).abs() < 1e-6, "face {i}: {rate} {stats:?}");
        eprintln!(
            "{}: success {rate} (predicted {:?})",
            said(i, "part"),
            view.final_orientation_deg
        );
    }
    // The faces' predictions differ, so a swapped face would be judged against the other's.
    let (p0, p1) = (file.for_part(0).unwrap(), file.for_part(1).unwrap());
    let d = (p0.final_orientation_deg.unwrap() - p1.final_orientation_deg.unwrap()).abs();
    assert!(d > 10.0, "the faces' predictions {p0:?} {p1:?}");
}
