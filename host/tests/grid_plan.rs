//! The planner on solver-made modes (issue 6): `chladni plate modes --write-modes` on the
//! cantilever plate, the modes read back as `grid` nodes, a plan for the rectangle that uses
//! the torsion mode (node line along the plate's mid-line y = 100 mm), verified by independent
//! simulation from many start poses in the mode's feed region (x ≥ 150 mm within the planned duration: nearer the clamp
//! the pull vanishes like x³ and parts drift onto the clamp instead of the node).

use std::path::Path;
use std::process::Command;

use chladni::part::Part;
use chladni::planner::{self, PlanOptions, Problem, cdist};
use chladni::plate::model::{Node, PlateModel};
use chladni::sim::{Body, FieldModel, Pose, run_plan};

fn root() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

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
    // Mode 2 (torsion): the two corners at the clamp lie outside the feed region; from the
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

    // Independent check: start poses on a grid over the feed region, every 30°.
    let body = Body::new(&part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let steps = syn.sim_steps();
    let (mut worst, mut runs) = (0.0f64, 0);
    for x in [150.0, 190.0, 230.0, 275.0] {
        for y in [25.0, 60.0, 140.0, 175.0] {
            for k in 0..6 {
                let th = 15.0 + 30.0 * k as f64;
                let start = Pose { x, y, theta: th.to_radians() };
                let (poses, _, _) = run_plan(&body, &plate, &fields, &steps, start);
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
