//! Dynamic straight-node step maps (`planner::dynamic`): a plate where the static maps'
//! plan fails the dynamic check and the dynamic maps find another one that simulation
//! confirms; agreement with the static maps where the part does not turn while crossing; the
//! map cache.

use crate::support;

use chladni_core::model::angle::cdist;
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::{
    self, Backend, DynSettings, MapCache, MapKind, PlanOptions, Problem, plan_period,
};
use support::examples::{part, plate_text};

fn line(law: &str, gain_right: f64, angle: f64, offset: f64) -> String {
    // Distinct frequencies (modes at one frequency must be one node).
    let freq = 40.0 + angle + 10.0 * gain_right + offset;
    format!(
        "[[mode]]\nfreq_hz = {freq}\nfield = \"{law}\"\ngain_right = {gain_right}\n\
         node = {{ kind = \"line\", angle_deg = {angle}, offset_mm = {offset} }}\n"
    )
}

/// Four straight nodes on which the L-shape turns while crossing the node of mode 2.
fn crossing_plate() -> PlateModel {
    plate_text(
        &[
            line("linear", 2.5, 135.0, 0.0),
            line("sign", 2.5, 45.0, 0.0),
            line("linear", 1.0, 75.0, 0.0),
            line("linear", 1.0, 135.0, -20.0),
        ]
        .concat(),
    )
}

/// The plan run from 5 × 4 positions over the plate × 24 orientations: the worst final
/// orientation error (deg, modulo the plan's period) of the runs that never touch the plate's
/// rim (bounding circle within 1 mm of an edge), and how many runs touched it. The rim turns
/// a part pressed against it (push alignment), which this plate's straight-node maps do not
/// model: near the top-right corner mode 2's node runs into the top edge, and parts pulled
/// onto it there are turned by the wall (docs/motion.md, "The plate's rim").
fn worst_error(p: &Part, plate: &PlateModel, syn: &planner::Synthesis) -> (f64, usize) {
    let body = Body::new(p);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps = syn.sim_steps();
    let (r, [w, h]) = (body.radius, plate.size_mm);
    let near = |q: &Pose| q.x < r + 1.0 || q.y < r + 1.0 || q.x > w - r - 1.0 || q.y > h - r - 1.0;
    let (mut worst, mut touched) = (0.0f64, 0);
    for i in 0..5 {
        for j in 0..4 {
            for k in 0..24 {
                // Starts 1 mm further in than the rim-touching band.
                let (r1, d) = (r + 1.5, 2.0 * (r + 1.5));
                let x = r1 + (w - d) * f64::from(i) / 4.0;
                let y = r1 + (h - d) * f64::from(j) / 3.0;
                let theta = (f64::from(k) * 15.0 + 1.7).to_radians();
                let (poses, trace, _) =
                    simulate_plan(&body, plate, &fields, &steps, Pose { x, y, theta });
                if trace.iter().any(|(_, q)| near(q)) {
                    touched += 1;
                    continue;
                }
                let end = poses.last().unwrap().theta.to_degrees();
                worst = worst.max(cdist(end, syn.final_orientation_deg, syn.period_deg));
            }
        }
    }
    (worst, touched)
}

#[test]
fn dynamic_maps_find_a_plan_where_the_static_plan_fails_the_dynamic_check() {
    let (p, plate) = (part("l-shape.json"), crossing_plate());
    let st = PlanOptions { maps: MapKind::Static, durations: false, ..Default::default() };
    let statics = Problem::new(&p, &plate, &st).unwrap();
    let path = statics.search(&st).unwrap();
    // The static maps' shortest plan: mode 1, then mode 2; the part turns while crossing
    // mode 2's node and some transition is not confirmed.
    assert_eq!(path.iter().map(|s| s.0).collect::<Vec<_>>(), [0, 1]);
    let body = Body::with_samples(&p, chladni_core::motion::body::PLANNER_BODY_SAMPLES);
    let rejected = path[0].1.iter().any(|&u| {
        let v = statics.maps[1].apply(u, st.margin_deg).unwrap();
        !planner::confirm(&body, &plate.modes[1], &plate, u, v, statics.period)
    });
    assert!(rejected, "the static plan was expected to fail the dynamic check");
    // The dynamic maps' own search (no transition ruled out) finds another sequence ...
    let dy = PlanOptions { maps: MapKind::Dynamic, ..st };
    let dynamic = Problem::new(&p, &plate, &dy).unwrap();
    let dpath = dynamic.search(&dy).unwrap();
    assert_ne!(dpath.iter().map(|s| s.0).collect::<Vec<_>>(), [0, 1]);
    // ... which the planner keeps (its dynamic check passes) and simulation confirms from
    // starts all over the plate.
    let syn =
        planner::plan_with(&p, &plate, &PlanOptions { durations: true, ..dy }, &dynamic).unwrap();
    assert_eq!(
        syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>(),
        dpath.iter().map(|s| s.0).collect::<Vec<_>>()
    );
    let (worst, touched) = worst_error(&p, &plate, &syn);
    eprintln!("dynamic plan: {touched} of 480 runs touched the rim");
    assert!(touched < 480 / 4, "{touched} of 480 runs touched the rim");
    assert!(worst < 1.0, "dynamic plan: worst final orientation error {worst}°");
}

#[test]
fn static_and_dynamic_maps_agree_where_the_part_does_not_turn_while_crossing() {
    // The rectangle on sign-law nodes (equal gains and not): a uniform pull away from the
    // node has no moment, so the rest is decided on the node, as the static analysis assumes.
    let p = part("rectangle.json");
    for modes in [line("sign", 1.0, 30.0, 0.0), line("sign", 2.0, 100.0, 15.0)] {
        let plate = plate_text(&modes);
        let period = plan_period(&p, &plate);
        let st = planner::line_map(&p, &plate.modes[0], Backend::Fixed).unwrap();
        let dy = planner::dynamic::dynamic_line_map(
            &p,
            &plate.modes[0],
            &plate,
            period,
            Backend::Fixed,
            DynSettings::default(),
        )
        .unwrap();
        let mut reached = dy.stable.clone();
        reached.sort_by(f64::total_cmp);
        for t in (0..72).map(|i| f64::from(i) * 5.0 + 0.7) {
            let (a, b) = (st.apply(t, 3.0), dy.apply_all(t, 3.0));
            match (a, b) {
                (Ok(a), Ok(b)) => {
                    assert_eq!(b.len(), 1, "{modes}: {t}° ambiguous: {b:?}");
                    assert!(
                        cdist(a, b[0], period) < 1e-6,
                        "{modes}: {t}°: static {a}, dynamic {b:?}"
                    );
                }
                (Err(_), Err(_)) => {}
                (a, b) => panic!("{modes}: {t}°: static {a:?}, dynamic {b:?}"),
            }
        }
        // Every static rest is reached dynamically, and nothing else.
        for s in &st.stable {
            assert!(reached.iter().any(|r| cdist(*r, *s, period) < 1e-6), "{s} vs {reached:?}");
        }
        assert!(reached.iter().all(|r| st.stable.iter().any(|s| cdist(*r, *s, period) < 1e-6)));
    }
}

#[test]
fn the_cache_serves_the_second_use() {
    let (p, plate) = (part("triangle.json"), plate_text(&line("sign", 1.8, 0.0, 20.0)));
    let cache = MapCache::new();
    let set = DynSettings { orientations: 24, refine: 2 };
    let first = cache.line_map(&p, &plate.modes[0], &plate, 360.0, Backend::Fixed, set).unwrap();
    assert_eq!((cache.hits(), cache.misses()), (0, 1));
    let second = cache.line_map(&p, &plate.modes[0], &plate, 360.0, Backend::Fixed, set).unwrap();
    assert_eq!((cache.hits(), cache.misses()), (1, 1));
    assert_eq!(first.stable, second.stable);
    assert_eq!(first.boundaries, second.boundaries);
    // Another mode (other gains) is another key.
    let other = plate_text(&line("sign", 1.2, 0.0, 20.0));
    cache.line_map(&p, &other.modes[0], &other, 360.0, Backend::Fixed, set).unwrap();
    assert_eq!((cache.hits(), cache.misses()), (1, 2));
}
