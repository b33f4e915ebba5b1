//! The rim as an orienting feature (docs/plan.md, "The rim in the step maps"): a plan that
//! needs the wall. On `host/cli/tests/integration/data/rim-push.toml` the two straight nodes have equal gains,
//! so each maps θ and θ + 180° alike and the triangle's 180° twins stay apart; the third mode
//! pushes the part into the left wall, whose reaction turns it onto a stable edge and so
//! tells the twins apart. With `edge = "open"` the same field pushes the part off the plate:
//! no plan.

use crate::support;

use chladni_core::model::angle::cdist;
use chladni_core::model::plate::{Edge, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::{self, PlanFailure, PlanOptions, Problem, rim_line};
use support::examples::{part, root};

fn rim_plate(edge: Edge) -> PlateModel {
    let mut plate =
        PlateModel::load(&root().join("host/cli/tests/integration/data/rim-push.toml")).unwrap();
    plate.edge = edge;
    plate
}

/// Runs the plan from a grid of drops over the whole plate (4 × 3 positions, inset by the
/// part's radius as `simulate` draws them, × 8 orientations): (worst orientation error mod
/// the period, drops that fell off the plate).
fn drops(plate: &PlateModel, syn: &planner::Synthesis, body: &Body) -> (f64, usize) {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps = syn.sim_steps();
    let [w, h] = plate.size_mm;
    let r = body.radius;
    let (mut worst, mut lost) = (0.0f64, 0);
    for i in 0..4 {
        for j in 0..3 {
            let (x, y) = (r + (w - 2.0 * r) * i as f64 / 3.0, r + (h - 2.0 * r) * j as f64 / 2.0);
            for k in 0..8 {
                let theta = (k as f64 * 45.0 + 7.0).to_radians();
                let (poses, _, _) =
                    simulate_plan(body, plate, &fields, &steps, Pose { x, y, theta });
                let end = *poses.last().unwrap();
                if !(0.0..=w).contains(&end.x) || !(0.0..=h).contains(&end.y) {
                    lost += 1;
                }
                let err = cdist(end.theta.to_degrees(), syn.final_orientation_deg, syn.period_deg);
                worst = worst.max(err);
            }
        }
    }
    (worst, lost)
}

#[test]
fn a_plan_needs_the_rim_and_the_open_edge_has_none() {
    let p = part("triangle.json");
    let body = Body::new(&p);
    let opt = PlanOptions::default();

    let wall = rim_plate(Edge::Wall);
    assert!(
        rim_line(body.radius, &wall.modes[2], &wall),
        "the push mode's node is beyond the edge"
    );
    assert!(!rim_line(body.radius, &wall.modes[0], &wall));
    let syn = planner::plan(&p, &wall, &opt).unwrap();
    let modes: Vec<usize> = syn.steps.iter().map(|s| s.mode).collect();
    assert!(modes.contains(&2), "the plan uses the wall: {modes:?}");
    assert_eq!(syn.period_deg, 360.0);
    // Without the push mode the two nodes cannot tell θ from θ + 180°: at best a plan modulo
    // 180°, which leaves the triangle in one of two orientations.
    let mut nodes_only = wall.clone();
    nodes_only.modes.truncate(2);
    if let Ok(half) = planner::plan(&p, &nodes_only, &opt) {
        assert_eq!(half.period_deg, 180.0);
    }
    let (worst, lost) = drops(&wall, &syn, &body);
    assert_eq!(lost, 0);
    assert!(worst < 3.0, "every drop over the plate ends at the prediction: worst {worst:.2}°");

    // The open edge: the push mode's parts fall off, its map has no rest, no plan.
    let open = rim_plate(Edge::Open);
    let problem = Problem::new(&p, &open, &opt).unwrap();
    assert!(problem.maps[2].stable.is_empty(), "{:?}", problem.maps[2].stable);
    assert!(matches!(planner::plan(&p, &open, &opt), Err(PlanFailure::NoPlan(_))));
    let (_, lost) = drops(&open, &syn, &body);
    assert_eq!(lost, 96, "the wall's plan pushes every part off an open edge");
}
