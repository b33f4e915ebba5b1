//! Goal plans (docs/plan.md): a goal orientation, a fixed or goal position, least time, and
//! several parts at once, each plan checked by simulating it (`motion`) from spread starts.

use crate::support;

use chladni_core::model::angle::cdist;
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::SimStep;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::position::{self, diameter, reachable_region};
use chladni_core::planner::{self, Minimize, PlanFailure, PlanOptions, Synthesis};
use support::examples::{part, plate, plate_text};

/// A straight-node mode entry.
fn line(freq: f64, angle: f64, offset: f64, extra: &str) -> String {
    format!(
        "[[mode]]\nfreq_hz = {freq}\nfield = \"sign\"\n{extra}\n\
         node = {{ kind = \"line\", angle_deg = {angle}, offset_mm = {offset} }}\n"
    )
}

/// Final poses of the plan's steps (as `chladni simulate` runs them) from the inset corners
/// and the centre, four orientations each.
fn run(p: &Part, plate: &PlateModel, steps: &[SimStep]) -> Vec<Pose> {
    let body = Body::new(p);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let [w, h] = plate.size_mm;
    let r = body.radius;
    let mut ends = Vec::new();
    for s in [[r, r], [w - r, r], [w - r, h - r], [r, h - r], [w / 2.0, h / 2.0]] {
        for j in 0..4 {
            let start = Pose { x: s[0], y: s[1], theta: (j as f64 * 90.0 + 17.0).to_radians() };
            let (poses, _, _) = simulate_plan(&body, plate, &fields, steps, start);
            ends.push(*poses.last().unwrap());
        }
    }
    ends
}

/// The largest orientation error (deg, mod period) of simulated runs of a plan.
fn worst_error(p: &Part, plate: &PlateModel, syn: &Synthesis, theta: f64, period: f64) -> f64 {
    run(p, plate, &syn.sim_steps())
        .iter()
        .map(|q| cdist(q.theta.to_degrees(), theta, period))
        .fold(0.0, f64::max)
}

#[test]
fn a_goal_orientation_gets_a_plan_that_ends_there_in_simulation() {
    let (tri, four) = (part("triangle.json"), plate("four-lines.toml"));
    let opt = PlanOptions::default();
    let default = planner::plan(&tri, &four, &opt).unwrap();
    let theta1 = default.final_orientation_deg;
    assert!(default.reachable_deg.len() >= 2, "{:?}", default.reachable_deg);
    assert!(default.reachable_deg.iter().any(|&t| cdist(t, theta1, 360.0) < 1e-3));
    // Another reachable orientation, not the default one.
    let theta2 = default
        .reachable_deg
        .iter()
        .copied()
        .find(|&t| cdist(t, theta1, 360.0) > 10.0)
        .expect("a second reachable orientation");
    let syn = planner::plan(&tri, &four, &PlanOptions { goal_deg: Some(theta2), ..opt }).unwrap();
    assert!(cdist(syn.final_orientation_deg, theta2, 360.0) < 1e-3);
    assert!(syn.steps.len() <= default.steps.len() + 1);
    assert_eq!(syn.goal_deg, Some(theta2));
    let err = worst_error(&tri, &four, &syn, theta2, syn.period_deg);
    assert!(err < 1.0, "simulated runs end up to {err}° from the goal {theta2}°");
    // A goal given off by 2° (inside the 3° margin) and modulo the period is the same plan.
    let near = PlanOptions { goal_deg: Some(theta2 + 360.0 - 2.0), ..opt };
    let again = planner::plan(&tri, &four, &near).unwrap();
    assert!(cdist(again.final_orientation_deg, theta2, 360.0) < 1e-3);
}

#[test]
fn an_unreachable_goal_is_answered_with_the_reachable_orientations() {
    let (tri, four) = (part("triangle.json"), plate("four-lines.toml"));
    let reachable = planner::plan(&tri, &four, &PlanOptions::default()).unwrap().reachable_deg;
    // The point of the circle farthest from every reachable orientation.
    let goal = (0..360)
        .map(f64::from)
        .max_by(|a, b| {
            let d = |g: f64| reachable.iter().map(|&t| cdist(t, g, 360.0)).fold(360.0, f64::min);
            d(*a).total_cmp(&d(*b))
        })
        .unwrap();
    let opt = PlanOptions { goal_deg: Some(goal), ..Default::default() };
    match planner::plan(&tri, &four, &opt) {
        Err(PlanFailure::GoalUnreachable {
            part, reachable_deg, nearest_deg, goal_deg, ..
        }) => {
            assert_eq!(part, "triangle");
            assert_eq!(goal_deg, goal);
            assert_eq!(reachable_deg, reachable);
            let nearest = nearest_deg.unwrap();
            for t in &reachable_deg {
                assert!(cdist(nearest, goal, 360.0) <= cdist(*t, goal, 360.0));
            }
        }
        other => panic!("expected GoalUnreachable, got {other:?}"),
    }
}

#[test]
fn two_non_parallel_nodes_do_not_fix_the_position_and_perpendicular_ones_do() {
    let rect = part("rectangle.json");
    let gains0 = "gain_left = 1.0\ngain_right = 2.2";
    let gains60 = "gain_left = 2.0\ngain_right = 1.0";
    let z60 = plate_text(&(line(40.0, 0.0, 0.0, gains0) + &line(70.0, 60.0, 0.0, gains60)));
    // Nodes at 0° then 60°: the second node moves the part along its normal only, so its
    // place along the first node survives, shrunk by cos 60°.
    let path = vec![(0, vec![0.0]), (1, vec![60.0])];
    let predicted = diameter(&reachable_region(&rect, &z60, 180.0, &path));
    assert!(predicted > 50.0, "{predicted}");
    let steps = [SimStep::new(0, 120_000, 1.0), SimStep::new(1, 120_000, 1.0)];
    let ends = run(&rect, &z60, &steps);
    let spread = diameter(&ends.iter().map(|q| [q.x, q.y]).collect::<Vec<_>>());
    assert!(
        spread > 0.5 * predicted && spread < predicted + 2.0,
        "simulated spread {spread} mm, predicted {predicted} mm"
    );
    let opt = PlanOptions { fix_position: true, ..Default::default() };
    assert!(matches!(planner::plan(&rect, &z60, &opt), Err(PlanFailure::PositionNotFixed { .. })));
    // Perpendicular nodes (0° then 90° on the six-line plate, for the triangle) fix it, and
    // the simulation puts every start there. (The rectangle cannot use a perpendicular pair:
    // at rest along one node it lies on the other's unstable rest.)
    let (tri, six) = (part("triangle.json"), plate("six-lines.toml"));
    let syn = planner::plan(&tri, &six, &opt).unwrap();
    let p = syn.final_position_mm.expect("a fixed position");
    let check = syn.position_check_mm.unwrap();
    assert!(check < position::POSITION_TOL_MM * 2.0, "{check}");
    for q in run(&tri, &six, &syn.sim_steps()) {
        assert!((q.x - p[0]).hypot(q.y - p[1]) < 2.0, "{q:?} vs {p:?}");
    }
}

#[test]
fn a_goal_position_picks_the_nearest_fixed_crossing() {
    let (tri, four) = (part("triangle.json"), plate("four-lines.toml"));
    let default = planner::plan(&tri, &four, &PlanOptions::default()).unwrap();
    let p0 = default.final_position_mm.unwrap();
    // Far from the default plan's position: a longer plan that ends nearer wins.
    let goal = [p0[0] - 10.0, p0[1] - 16.0];
    let opt = PlanOptions { goal_pos_mm: Some(goal), ..Default::default() };
    let syn = planner::plan(&tri, &four, &opt).unwrap();
    let p = syn.final_position_mm.unwrap();
    let d = |q: [f64; 2]| (q[0] - goal[0]).hypot(q[1] - goal[1]);
    assert!(d(p) < d(p0), "{p:?} is not nearer to {goal:?} than {p0:?}");
    assert!(syn.position_check_mm.unwrap() < 2.0);
    for q in run(&tri, &four, &syn.sim_steps()) {
        assert!((q.x - p[0]).hypot(q.y - p[1]) < 2.0, "{q:?} vs {p:?}");
    }
}

#[test]
fn minimizing_time_chooses_the_faster_plan() {
    // Two vertical nodes, the first slow (1 mm/s per unit pull), the second fast: both orient
    // the rectangle in one step; fewest steps takes the first found, least time the fast one.
    let rect = part("rectangle.json");
    let slow = line(60.0, 90.0, 0.0, "speed_mm_s = 1.0");
    let fast = line(90.0, 90.0, 30.0, "speed_mm_s = 20.0");
    let pl = plate_text(&(slow + &fast));
    let total = |s: &Synthesis| s.steps.iter().map(|s| u64::from(s.duration_ms)).sum::<u64>();
    let steps = planner::plan(&rect, &pl, &PlanOptions::default()).unwrap();
    let time =
        planner::plan(&rect, &pl, &PlanOptions { minimize: Minimize::Time, ..Default::default() })
            .unwrap();
    assert_eq!(steps.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [0]);
    assert_eq!(time.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [1]);
    assert!(total(&time) * 5 < total(&steps), "{} vs {}", total(&time), total(&steps));
    let err = worst_error(&rect, &pl, &time, time.final_orientation_deg, time.period_deg);
    assert!(err < 1.0, "{err}");
}

#[test]
fn one_sequence_orients_two_parts_each_to_its_own_orientation() {
    let six = plate("six-lines.toml");
    let parts = [part("triangle.json"), part("plate-with-hole.json")];
    let syn = planner::plan_parts(&parts, &six, &PlanOptions::default(), &[None, None]).unwrap();
    assert_eq!(syn.parts.len(), 2);
    for (p, pred) in parts.iter().zip(&syn.parts) {
        assert_eq!(p.name, pred.name);
        let err = worst_error(p, &six, &syn, pred.final_orientation_deg, pred.period_deg);
        assert!(err < 1.0, "{}: simulated runs end up to {err}° off", p.name);
    }
    // The plan file carries one prediction per part.
    let file = syn.to_file(&six, "two");
    let per = file.parts.as_ref().unwrap();
    assert_eq!(per.len(), 2);
    assert!(file.final_orientation_deg.is_none());
    assert_eq!(file.for_part(1).unwrap().final_orientation_deg, per[1].final_orientation_deg);
    // The triangle and the rectangle: every sequence that brings the triangle together puts
    // the rectangle on a perpendicular node's unstable rest.
    let apart = [part("triangle.json"), part("rectangle.json")];
    match planner::plan_parts(&apart, &six, &PlanOptions::default(), &[None, None]) {
        Err(PlanFailure::PartsApart { apart, .. }) => {
            assert!(apart.iter().any(|(n, d, _)| n == "triangle" && d.len() == 2), "{apart:?}");
        }
        other => panic!("expected PartsApart, got {other:?}"),
    }
}
