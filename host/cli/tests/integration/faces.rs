//! Both faces of a part: the mirror image rests differently, a plan for both faces holds per
//! face in simulation (library and `chladni plan/simulate --both-faces`), a part with a mirror
//! axis needs one face.

use chladni_core::model::angle::cdist;
use chladni_core::model::part::Part;
use chladni_core::model::part::mirror;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::{self, Setup};
use chladni_core::motion::steps::plan_steps;
use chladni_core::planner::{self, Backend, PlanOptions};

use crate::support;
use support::cli::{chladni, tmp};
use support::examples;

fn sorted_mod(v: &[f64], p: f64) -> Vec<f64> {
    let mut v: Vec<f64> = v.iter().map(|x| x.rem_euclid(p)).collect();
    v.sort_by(f64::total_cmp);
    v
}

#[test]
fn the_mirror_of_an_asymmetric_part_has_other_rests_the_reflected_ones() {
    // A vertical node with equal gains is symmetric under x → −x across it, so the flipped
    // face at −θ is the reflection of the face up at θ: its rests are the negated rests.
    let plate = examples::plate_text(
        "[[mode]]\nfreq_hz = 60.0\nfield = \"sign\"\nnode = { kind = \"line\", angle_deg = 90.0 }\n",
    );
    let tri = examples::part("triangle.json");
    let flipped = tri.mirrored();
    let mode = &plate.modes[0];
    let up = planner::line_map(&tri, mode, Backend::F64).unwrap();
    let down = planner::line_map(&flipped, mode, Backend::F64).unwrap();
    let p = 180.0; // symmetric field: orientations modulo 180°
    let (a, b) = (sorted_mod(&up.stable, p), sorted_mod(&down.stable, p));
    let negated = sorted_mod(&up.stable.iter().map(|t| -t).collect::<Vec<_>>(), p);
    assert_eq!(a.len(), b.len());
    for (x, y) in negated.iter().zip(&b) {
        assert!(cdist(*x, *y, p) < 0.05, "flipped rests {b:?}, negated face-up rests {negated:?}");
    }
    // And they are another set than the face up's.
    let differ = a.iter().any(|x| b.iter().all(|y| cdist(*x, *y, p) > 1.0));
    assert!(differ, "face up {a:?}, flipped {b:?}");
}

#[test]
fn a_part_with_a_mirror_axis_is_detected_and_planned_once() {
    let iso = Part {
        flips: true,
        ..Part::new("iso".into(), vec![[0.0, 0.0], [30.0, 0.0], [15.0, 20.0]], vec![]).unwrap()
    };
    let f = mirror::faces(&[iso], false);
    assert_eq!(f.parts.len(), 1);
    assert_eq!(f.self_mirrored, vec![("iso".to_string(), 0.0)]);
    // The example L-shape has arms of 40 and 30 mm: no mirror axis; the rectangle has two.
    let l = examples::part("l-shape.json");
    assert_eq!(mirror::flip_turn_deg(&l), None);
    let rect = examples::part("rectangle.json");
    assert_eq!(mirror::flip_turn_deg(&rect), Some(0.0));
}

#[test]
fn a_plan_for_both_faces_holds_for_each_face_in_simulation() {
    let plate = examples::plate("four-lines.toml");
    let tri = examples::part("triangle.json");
    let faces = mirror::faces(&[tri], true);
    assert_eq!(faces.parts.len(), 2);
    let opt = PlanOptions::default();
    let syn = planner::plan_parts(&faces.parts, &plate, &opt, &[None, None]).unwrap();
    assert_eq!(syn.parts.len(), 2);
    let file = syn.to_file(&plate, "triangle");
    let steps = plan_steps(&file, &plate).unwrap();
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    for (i, part) in faces.parts.iter().enumerate() {
        let body = Body::new(part);
        let setup =
            Setup { body: &body, plate: &plate, fields: &fields, steps: &steps, feed: None };
        let trials =
            montecarlo::run_trials(&setup, 60, 7 + i as u64, &chladni_core::progress::Silent);
        let view = file.for_part(i).unwrap();
        let stats = montecarlo::statistics(&trials, &view, 5.0);
        eprintln!(
            "{}: predicted {:?}, success {:?}",
            part.name, view.final_orientation_deg, stats.success_rate
        );
        assert!(stats.success_rate.unwrap() >= 0.95, "{}: {stats:?}", part.name);
    }
}

#[test]
fn cli_plans_and_simulates_both_faces_and_reports_each() {
    let plan = tmp("faces", "both.json");
    let part = examples::root().join("examples/parts/triangle.json");
    let plate = examples::root().join("examples/plates/four-lines.toml");
    let (part, plate) = (part.to_str().unwrap(), plate.to_str().unwrap());
    let out = chladni(&[
        "plan",
        part,
        "--plate",
        plate,
        "--both-faces",
        "--json",
        "--out",
        plan.to_str().unwrap(),
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let parts = v["parts"].as_array().unwrap();
    assert_eq!(parts.len(), 2);
    assert_eq!(
        (parts[0]["face"].as_str(), parts[1]["face"].as_str()),
        (Some("up"), Some("flipped"))
    );
    assert_eq!(parts[1]["name"], "triangle (flipped)");
    assert_eq!(v["name"], "triangle");
    // Text: each face's final pose.
    let out = chladni(&["plan", part, "--plate", plate, "--both-faces"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("--         triangle (flipped)"), "{text}");
    // Simulate: half the trials per face, each against its own prediction.
    let sim = |extra: &[&str]| {
        let mut args = vec![
            "simulate",
            part,
            "--plate",
            plate,
            "--plan",
            plan.to_str().unwrap(),
            "--trials",
            "41",
            "--json",
        ];
        args.extend_from_slice(extra);
        chladni(&args)
    };
    let out = sim(&["--both-faces"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let r = v["parts"].as_array().unwrap();
    assert_eq!((r[0]["face"].as_str(), r[1]["face"].as_str()), (Some("up"), Some("flipped")));
    assert_eq!((r[0]["trials"].as_u64(), r[1]["trials"].as_u64()), (Some(21), Some(20)));
    assert_ne!(r[0]["seed"], r[1]["seed"]);
    for e in r {
        assert!(e["success_rate"].as_f64().unwrap() >= 0.9, "{e}");
    }
    // Without --both-faces the plan's flipped face is missing: bad input naming the fix.
    let out = sim(&[]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("give --both-faces"));
    // A part with a mirror axis: one face, and it says so.
    let out = chladni(&[
        "plan",
        examples::root().join("examples/parts/rectangle.json").to_str().unwrap(),
        "--plate",
        plate,
        "--both-faces",
        "--json",
    ]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(v["parts"].is_null() && v["final_orientation_deg"].is_number(), "{v}");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("rectangle is its own mirror image turned by 0.00°"), "{err}");
}
