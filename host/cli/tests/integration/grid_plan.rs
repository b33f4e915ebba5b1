//! The planner on solver-made modes (issue 6): `chladni plate modes --write-modes` on the
//! cantilever plate, the modes read back as `grid` nodes, a plan for the rectangle that uses
//! the torsion mode (node line along the plate's mid-line y = 100 mm), verified by independent
//! simulation from many start poses in the mode's reach (x ≥ 150 mm within the planned duration: nearer the clamp
//! the pull vanishes like x³ and parts drift onto the clamp instead of the node).

use std::process::Command;

use chladni_core::model::angle::cdist;
use chladni_core::model::part::Part;
use chladni_core::model::plate::{Node, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::{self, PlanOptions, Problem};

use crate::support;
use support::examples::root;

#[test]
fn rectangle_plan_on_solver_made_cantilever_modes_holds_in_simulation() {
    let out = std::env::temp_dir().join(format!("chladni-grid-plan-{}.toml", std::process::id()));
    let st = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["plate", "modes"])
        .arg(root().join("examples/plate-cantilever.toml"))
        .args(["--count", "2", "--write-modes"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
    let plate = PlateModel::load(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert_eq!(plate.modes.len(), 2);
    assert!(plate.modes.iter().all(|m| matches!(m.node, Node::Grid(_))));

    let part = Part::load(&root().join("examples/parts/rectangle.json")).unwrap();
    let opt = PlanOptions { sim_starts: 36, ..Default::default() };
    let problem = Problem::new(&part, &plate, &opt).unwrap();
    // Mode 1 (bending, no interior node): every start drifts onto the clamp or never settles.
    assert!(problem.maps[0].dead_starts >= 3, "{}", problem.maps[0].dead_starts);
    // Mode 2 (torsion): the two corners at the clamp lie outside the mode's reach; from the
    // centre and the two far corners the rectangle lies along the node line; the only basin
    // boundary is its unstable rest across the node (90°, sampled exactly from the centre,
    // which lies on the node).
    let m2 = &problem.maps[1];
    assert_eq!(m2.dead_starts, 2);
    assert!(m2.boundaries.iter().all(|&b| cdist(b, 90.0, 180.0) < 10.0), "{:?}", m2.boundaries);
    let syn = planner::plan_with(&part, &plate, &opt, &problem).unwrap();
    assert_eq!(syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [1]);
    assert_eq!(syn.period_deg, 180.0);
    assert!(cdist(syn.final_orientation_deg, 0.0, 180.0) < 0.5, "{}", syn.final_orientation_deg);
    assert!(syn.steps[0].duration_ms < 3_600_000);
    // `chladni plan` reports the mode's reach: from the two clamp-side corners of the 9
    // settle start points the part ends on the clamp edge.
    let settle = &syn.steps[0].settle;
    assert_eq!(settle.points, 9);
    assert_eq!(settle.ends_on_edge.len(), 2, "{settle:?}");
    assert!(settle.ends_on_edge.iter().all(|p| p[0] < 50.0), "{settle:?}");

    // Independent check: start poses on a grid over the mode's reach, every 30°.
    let body = Body::new(&part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let steps = syn.sim_steps();
    let (mut worst, mut runs) = (0.0f64, 0);
    for x in [150.0, 190.0, 230.0, 275.0] {
        for y in [25.0, 60.0, 140.0, 175.0] {
            for k in 0..6 {
                let th = 15.0 + 30.0 * k as f64;
                let start = Pose { x, y, theta: th.to_radians() };
                let (poses, _, _) = simulate_plan(&body, &plate, &fields, &steps, start);
                let end = poses.last().unwrap();
                let err = cdist(end.theta.to_degrees(), syn.final_orientation_deg, 180.0);
                assert!((end.y - 100.0).abs() < 2.0, "start {start:?} ended at {end:?}");
                worst = worst.max(err);
                runs += 1;
            }
        }
    }
    assert_eq!(runs, 96);
    assert!(worst < 1.0, "worst final orientation error {worst}°");
}

/// Runs `chladni plate modes` with `args` on the hinged-rod example.
fn hinged_rod_modes(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["plate", "modes"])
        .arg(root().join("examples/plate-hinged-rod.toml"))
        .args(args)
        .output()
        .unwrap()
}

// The paper's setup 2: below the first elastic mode the rod rocks the plate rigidly about the
// hinge. `--write-modes` puts that forced rocking first, as a straight linear-field node on
// the hinge line, and the rectangle gets a one-step plan on it that holds from anywhere.
#[test]
fn hinged_rod_plate_plans_on_its_forced_rocking_about_the_hinge() {
    let out = std::env::temp_dir().join(format!("chladni-hinged-{}.toml", std::process::id()));
    let st = hinged_rod_modes(&[
        "--count",
        "1",
        "--rocking-hz",
        "12",
        "--write-modes",
        out.to_str().unwrap(),
    ]);
    assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
    assert!(String::from_utf8_lossy(&st.stdout).contains("rigid rocking about the hinge at 12 Hz"));
    let plate = PlateModel::load(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert_eq!(plate.modes.len(), 2);
    let rocking = &plate.modes[0];
    assert_eq!(
        (rocking.name.as_str(), rocking.freq_hz, rocking.law.name()),
        ("rocking (forced)", 12.0, "linear")
    );
    match rocking.node {
        Node::Line { angle_deg, offset_mm } => assert_eq!((angle_deg, offset_mm), (90.0, 0.0)),
        ref n => panic!("rocking node should be the hinge line, got {n:?}"),
    }
    assert!(matches!(plate.modes[1].node, Node::Grid(_)));

    let part = Part::load(&root().join("examples/parts/rectangle.json")).unwrap();
    let opt = PlanOptions { sim_starts: 36, ..Default::default() };
    let syn = planner::plan(&part, &plate, &opt).unwrap();
    assert_eq!(syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [0]);
    assert!(cdist(syn.final_orientation_deg, 90.0, 180.0) < 0.5, "{}", syn.final_orientation_deg);

    // Independent check over the whole plate (both sides of the hinge), every 30°.
    let body = Body::new(&part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let steps = syn.sim_steps();
    let mut worst = 0.0f64;
    for x in [40.0, 100.0, 200.0, 260.0] {
        for y in [40.0, 100.0, 160.0] {
            for k in 0..6 {
                let start = Pose { x, y, theta: (15.0 + 30.0 * k as f64).to_radians() };
                let (poses, _, _) = simulate_plan(&body, &plate, &fields, &steps, start);
                let end = poses.last().unwrap();
                assert!((end.x - 150.0).abs() < 2.0, "start {start:?} ended at {end:?}");
                worst = worst.max(cdist(end.theta.to_degrees(), syn.final_orientation_deg, 180.0));
            }
        }
    }
    assert!(worst < 1.0, "worst final orientation error {worst}°");
}

#[test]
fn rocking_frequency_must_stay_below_the_first_elastic_mode() {
    let st = hinged_rod_modes(&["--count", "1", "--rocking-hz", "40"]);
    assert_eq!(st.status.code(), Some(2));
    let err = String::from_utf8_lossy(&st.stderr);
    assert!(
        err.contains("--rocking-hz must be in [1, 29.2] Hz") && err.contains("got 40"),
        "{err}"
    );
}

/// `simulate --reference-wrench` runs the grid modes by the reference rule: the crank lever
/// (its ⌀5 bore enters the fast rule by its moment rule) under the free plate's first solver
/// mode ends, from the same seeded starts, at poses that differ from the fast rule's (the flag
/// took effect) by no more than the two rules' agreement allows.
#[test]
fn simulate_by_the_reference_wrench_ends_where_the_fast_rule_does() {
    use support::cli::{ex, ok_json, tmp};
    let plan = tmp("reference-wrench", "plan.json");
    let text = r#"{"name": "crank lever", "period_deg": 360.0, "final_orientation_deg": 0.0,
        "steps": [{"freq_hz": 108.419, "duration_ms": 30000, "amplitude": 1.0, "ramp_ms": 20}]}"#;
    std::fs::write(&plan, text).unwrap();
    let (part, plate) = (ex("parts/ordinary/crank-lever.json"), ex("plates/free-6-modes.toml"));
    let plan_s = plan.to_string_lossy().into_owned();
    let ends = |extra: &[&str]| {
        let mut args = vec!["simulate", &part, "--plate", &plate, "--plan", &plan_s];
        args.extend(["--trials", "6", "--json", "--poses"]);
        args.extend(extra);
        let v = ok_json(&support::cli::chladni(&args));
        let poses = v["poses"].as_array().unwrap().clone();
        poses.iter().map(|p| p["end"].clone()).collect::<Vec<_>>()
    };
    let (fast, reference) = (ends(&[]), ends(&["--reference-wrench"]));
    assert_eq!(fast.len(), reference.len());
    assert_ne!(fast, reference, "the flag changes nothing");
    for (a, b) in fast.iter().zip(&reference) {
        let d = |k: &str| (a[k].as_f64().unwrap() - b[k].as_f64().unwrap()).abs();
        let deg = d("theta_deg").min(360.0 - d("theta_deg"));
        assert!(d("x_mm").hypot(d("y_mm")) < 0.05 && deg < 0.05, "{a} vs {b}");
    }
}
