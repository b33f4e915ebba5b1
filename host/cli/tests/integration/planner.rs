//! Planner tests: plans checked by independent simulation of every start orientation on a
//! fine grid, rotational symmetry, a case with no plan, fixed-point vs f64 maps, simulated
//! (grid) maps vs the exact line analysis.

use crate::support;

use chladni_core::model::angle::cdist;
use chladni_core::model::grid::Grid;
use chladni_core::model::part::Part;
use chladni_core::model::plate::{Node, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::SimStep;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::{
    self, Backend, MapKind, PlanFailure, PlanOptions, Problem, symmetry_order,
};
use support::examples::{part, plate, plate_text};

fn polygon(n: usize, r: f64) -> Part {
    let pts = (0..n)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / n as f64;
            [50.0 + r * a.cos(), 50.0 + r * a.sin()]
        })
        .collect();
    Part::new(format!("{n}-gon"), pts, vec![]).unwrap()
}

/// Simulates the plan from every start orientation (every `step_deg`) at three start points
/// and returns the worst final orientation error modulo the period, skipping starts within
/// 1° of a first-step basin boundary (metastable: their time is unbounded).
fn verify(p: &Part, plate: &PlateModel, opt: &PlanOptions, step_deg: f64) -> (f64, usize) {
    verify_from(p, plate, opt, step_deg, 0.0)
}

/// [`verify`] with the corner starts `inset` mm further from the rim.
fn verify_from(
    p: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    step_deg: f64,
    inset: f64,
) -> (f64, usize) {
    let problem = Problem::new(p, plate, opt).unwrap();
    let syn = planner::plan_with(p, plate, opt, &problem).unwrap();
    let body = Body::new(p);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps: Vec<SimStep> = syn.sim_steps();
    let first = &problem.maps[syn.steps[0].mode];
    let (mut worst, mut runs) = (0.0f64, 0);
    let [w, h] = plate.size_mm;
    let r = body.radius + inset;
    for start in [[r, r], [w / 2.0, h / 2.0], [w - r, h - r]] {
        let n = (360.0 / step_deg).round() as usize;
        for i in 0..n {
            let th = i as f64 * step_deg;
            if first.boundaries.iter().any(|&b| cdist(b, th, 360.0) < 1.0) {
                continue;
            }
            let (poses, _, _) = simulate_plan(
                &body,
                plate,
                &fields,
                &steps,
                Pose { x: start[0], y: start[1], theta: th.to_radians() },
            );
            let end = poses.last().unwrap().theta.to_degrees();
            let err = cdist(end, syn.final_orientation_deg, syn.period_deg);
            worst = worst.max(err);
            runs += 1;
        }
    }
    (worst, runs)
}

#[test]
fn plans_hold_for_every_start_orientation_in_simulation() {
    let four = plate("four-lines.toml");
    let opt = PlanOptions::default();
    for (name, plate) in [
        ("triangle.json", &four),
        ("key.svg", &four),
        ("plate-with-hole.json", &plate("six-lines.toml")),
    ] {
        let (worst, runs) = verify(&part(name), plate, &opt, 1.0);
        assert!(runs > 1000, "{name}: {runs}");
        assert!(worst < 0.5, "{name}: worst final orientation error {worst}°");
    }
    // Hyperbola plate (simulated first-step map), rectangle: one straight-node step.
    let (worst, _) = verify(&part("rectangle.json"), &plate("hyperbola.toml"), &opt, 2.0);
    assert!(worst < 0.5, "rectangle on hyperbola plate: {worst}°");
}

#[test]
fn triangle_plan_is_two_steps_and_fixes_the_position() {
    let syn =
        planner::plan(&part("triangle.json"), &plate("four-lines.toml"), &PlanOptions::default())
            .unwrap();
    assert_eq!(syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [1, 0]);
    assert!((syn.final_orientation_deg - 110.707).abs() < 0.01, "{}", syn.final_orientation_deg);
    assert_eq!(syn.period_deg, 360.0);
    let p = syn.final_position_mm.unwrap();
    assert!((p[0] - 149.97).abs() < 0.05 && (p[1] - 117.80).abs() < 0.05, "{p:?}");
    assert!(syn.steps.iter().all(|s| s.duration_ms >= 1000 && s.duration_ms < 120_000));
}

#[test]
fn rotational_symmetry_reduces_the_period() {
    assert_eq!(symmetry_order(&polygon(4, 15.0)), 4);
    assert_eq!(symmetry_order(&polygon(6, 15.0)), 6);
    assert_eq!(symmetry_order(&part("rectangle.json")), 2);
    assert_eq!(symmetry_order(&part("triangle.json")), 1);
    // Square, plate with an asymmetric mode: period 90°; sign field rests with a diagonal on
    // the node: one step suffices, and simulation agrees modulo 90°.
    let four = plate("four-lines.toml");
    let sq = polygon(4, 15.0);
    let syn = planner::plan(&sq, &four, &PlanOptions::default()).unwrap();
    assert_eq!(syn.period_deg, 90.0);
    assert_eq!(syn.steps.len(), 1);
    assert!(syn.final_orientation_deg < 90.0);
    let (worst, _) = verify(&sq, &four, &PlanOptions::default(), 3.0);
    assert!(worst < 0.5, "square: {worst}°");
    // Rectangle on a plate of symmetric straight nodes only: period 180°.
    let sym = plate_text(
        "[[mode]]\nfreq_hz = 60.0\nfield = \"sign\"\nnode = { kind = \"line\", angle_deg = 30.0 }\n",
    );
    let syn = planner::plan(&part("rectangle.json"), &sym, &PlanOptions::default()).unwrap();
    assert_eq!(syn.period_deg, 180.0);
    assert!((syn.final_orientation_deg - 30.0).abs() < 1e-3, "{}", syn.final_orientation_deg);
}

#[test]
fn no_plan_says_which_orientations_stay_apart() {
    // One asymmetric mode: the triangle has two stable rests that no sequence can merge.
    let one = plate_text(
        "[[mode]]\nfreq_hz = 60.0\nfield = \"sign\"\ngain_right = 2.5\nnode = { kind = \"line\", angle_deg = 90.0 }\n",
    );
    let err = planner::plan(&part("triangle.json"), &one, &PlanOptions::default()).unwrap_err();
    let PlanFailure::NoPlan(msg) = err else { panic!("{err:?}") };
    assert!(msg.contains("stay apart") && msg.contains("mode 1 keeps them apart"), "{msg}");
    // The margin can be what blocks a plan: trapezoid on the four-line plate.
    let err =
        planner::plan(&part("trapezoid.json"), &plate("four-lines.toml"), &PlanOptions::default())
            .unwrap_err();
    let msg = err.to_string();
    // The blocked mode says how far it keeps, and the rule names the mode it is for.
    assert!(msg.contains("from a basin boundary, under its 3.16°)"), "{msg}");
    assert!(msg.contains("(mode 2: a step keeps every orientation at least 3.16°"), "{msg}");
    assert!(msg.contains("(--margin-deg 3°"), "{msg}");
}

#[test]
fn fixed_point_maps_match_the_f64_reference() {
    let four = plate("four-lines.toml");
    for name in ["triangle.json", "l-shape.json"] {
        let p = part(name);
        // The static maps (the analysis itself); dynamic maps are compared in dynamic_maps.rs.
        let st = PlanOptions { maps: MapKind::Static, ..Default::default() };
        let fixed = Problem::new(&p, &four, &st).unwrap();
        let f64m = Problem::new(&p, &four, &PlanOptions { backend: Backend::F64, ..st }).unwrap();
        for (a, b) in fixed.maps.iter().zip(&f64m.maps) {
            assert_eq!(a.stable.len(), b.stable.len(), "{name}");
            assert_eq!(a.boundaries.len(), b.boundaries.len(), "{name}");
            for x in &a.stable {
                assert!(
                    b.stable.iter().any(|y| cdist(*x, *y, 360.0) < 0.05),
                    "{name}: {x} vs {:?}",
                    b.stable
                );
            }
            for x in &a.boundaries {
                assert!(b.boundaries.iter().any(|y| cdist(*x, *y, 360.0) < 0.05), "{name}: {x}");
            }
        }
        let opt = PlanOptions { durations: false, ..st };
        let pa = fixed.search(&opt).unwrap();
        let pb = f64m.search(&opt).unwrap();
        assert_eq!(
            pa.iter().map(|s| s.0).collect::<Vec<_>>(),
            pb.iter().map(|s| s.0).collect::<Vec<_>>()
        );
        let (fa, fb) = (pa.last().unwrap().1[0], pb.last().unwrap().1[0]);
        assert!(cdist(fa, fb, 360.0) < 0.05, "{name}: {fa} vs {fb}");
    }
}

#[test]
fn simulated_grid_map_matches_the_exact_line_analysis() {
    // φ = sin(π(x − W/2)/W): a straight node at x = W/2, φ ≈ linear near it, so the φ² field
    // is the linear field there: rests must agree with the exact straight-node analysis.
    let (nx, ny) = (61, 41);
    let values = (0..ny)
        .flat_map(|_| {
            (0..nx).map(move |i| (std::f64::consts::PI * (i as f64 / (nx - 1) as f64 - 0.5)).sin())
        })
        .collect();
    let mut model = plate_text(
        "[[mode]]\nfreq_hz = 60.0\nfield = \"linear\"\nspeed_mm_s = 30.0\nnode = { kind = \"line\", angle_deg = 90.0 }\n",
    );
    let mut grid_mode = model.modes[0].clone();
    grid_mode.node = Node::Grid(Grid { nx, ny, size_mm: [300.0, 200.0], values });
    model.modes.push(grid_mode);
    let p = part("triangle.json");
    let opt = PlanOptions { sim_starts: 36, ..Default::default() };
    let problem = Problem::new(&p, &model, &opt).unwrap();
    let (line, grid) = (&problem.maps[0], &problem.maps[1]);
    assert_eq!(line.stable.len(), 2);
    for s in &line.stable {
        assert!(grid.stable.iter().any(|g| cdist(*g, *s, 360.0) < 1.0), "{s} vs {:?}", grid.stable);
    }
}

/// Two `line` entries at one frequency are one mode: the planner cannot plan a step from one
/// to the other ("60 Hz → 60 Hz"), which the plate cannot tell apart.
#[test]
fn two_lines_at_one_frequency_plan_as_one_mode() {
    let plate = plate_text(
        r#"
[[mode]]
name = "60 Hz vertical"
freq_hz = 60.0
node = { kind = "line", angle_deg = 90.0, offset_mm = 50.0 }
[[mode]]
name = "60 Hz horizontal"
freq_hz = 60.0
node = { kind = "line", angle_deg = 0.0, offset_mm = 0.0 }
[[mode]]
name = "80 Hz diagonal"
freq_hz = 80.0
field = "sign"
node = { kind = "line", angle_deg = 45.0, offset_mm = 0.0 }
"#,
    );
    assert_eq!(plate.modes.len(), 2);
    assert!(matches!(&plate.modes[0].node, Node::Lines(l) if l.len() == 2));
    let rect = part("rectangle.json");
    let opt = PlanOptions::default();
    let syn = planner::plan(&rect, &plate, &opt).unwrap();
    let freqs: Vec<f64> = syn.steps.iter().map(|s| plate.modes[s.mode].freq_hz).collect();
    assert!(!freqs.is_empty());
    assert!(freqs.windows(2).all(|w| w[0] != w[1]), "same frequency twice in a row: {freqs:?}");
    // The plan holds in simulation: the merged mode's field is the nearest line's. From the
    // corners themselves the rim turns the rectangle on its way to the nodes (push
    // alignment), which these straight-node maps do not model (44° off with the rim): the
    // corner starts are one radius further in (docs/motion.md, "The plate's rim").
    let r = Body::new(&rect).radius;
    let (worst, _) = verify_from(&rect, &plate, &opt, 30.0, r);
    assert!(worst < 5.0, "worst final error {worst}°");
}

/// A plate whose every mode is centrally symmetric about its centre cannot tell a pose from
/// its twin turned 180° about the centre: the failure names the symmetry and what breaks it.
#[test]
fn a_centrally_symmetric_plate_names_its_symmetry_and_what_breaks_it() {
    let cross = plate_text(
        "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"lines\", lines = [{ angle_deg = 0.0, offset_mm = 0.0 }, { angle_deg = 90.0, offset_mm = 0.0 }] }\n",
    );
    let opt = PlanOptions { sim_starts: 36, durations: false, ..Default::default() };
    let err = planner::plan(&part("triangle.json"), &cross, &opt).unwrap_err();
    let msg = err.to_string();
    for want in ["180° twins", "centrally symmetric about the plate centre", "clamps_mm", "--feed"]
    {
        assert!(msg.contains(want), "{want}: {msg}");
    }
}
