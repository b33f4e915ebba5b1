//! Feed-region planning (docs/plan.md "Feed-region planning"): on the free plate's solver
//! modes the rest a part reaches depends on where it starts, so the orientation-set planner
//! finds no plan; tracking poses from a known feed region does, and independent simulation
//! from poses inside that region (not the ones the planner tracked) confirms it.

use std::process::Command;

use chladni_core::model::angle::cdist;
use chladni_core::model::feed_region::FeedRegion;
use chladni_core::model::part::Part;
use chladni_core::model::plate::{Node, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::steps::simulate_plan;
use chladni_core::planner::FeedSearch;
use chladni_core::planner::{self, PlanFailure, PlanOptions};

use crate::support;
use support::cli::{chladni, ex, json};
use support::examples::root;

/// The free plate's solver modes 2 and 4 (`chladni plate modes --count 4 --write-modes`).
fn free_plate_modes_2_and_4() -> PlateModel {
    // One file per call: the tests run in parallel in one process.
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let out = std::env::temp_dir().join(format!("chladni-feed-{}-{n}.toml", std::process::id()));
    let st = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .args(["plate", "modes"])
        .arg(root().join("examples/plate-free.toml"))
        .args(["--count", "4", "--write-modes"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
    let mut plate = PlateModel::load(&out).unwrap();
    let _ = std::fs::remove_file(&out);
    assert!(plate.modes.iter().all(|m| matches!(m.node, Node::Grid(_))));
    plate.modes = vec![plate.modes[1].clone(), plate.modes[3].clone()];
    plate
}

#[test]
fn triangle_on_free_plate_modes_plans_only_from_a_feed_region() {
    let plate = free_plate_modes_2_and_4();
    let part = Part::load(&root().join("examples/parts/triangle.json")).unwrap();

    // Without a feed region: the outcome of each mode depends on the start point, which the
    // orientation-set search sees as ambiguity everywhere.
    let opt = PlanOptions { sim_starts: 18, ..Default::default() };
    let err = planner::plan(&part, &plate, &opt).unwrap_err();
    assert!(matches!(err, PlanFailure::NoPlan(_)), "{err}");

    // From a 40 × 40 mm feed region in the lower-left quadrant (coarse: 2 × 2 positions × 6
    // orientations tracked, 3 × 3 × 6 interleaved starts in the confirmation).
    let region = FeedRegion::new([60.0, 40.0, 100.0, 80.0], &plate).unwrap();
    let feed_search = FeedSearch { depth: 3, points: 2, starts: 6, ..Default::default() };
    let opt = PlanOptions { feed: Some(region), feed_search, ..Default::default() };
    let syn = planner::plan(&part, &plate, &opt).unwrap();
    let modes: Vec<usize> = syn.steps.iter().map(|s| s.mode).collect();
    assert_eq!(modes.len(), 3, "the shortest plan here has 3 steps: {modes:?}");

    // The step bound (`plan --max-steps`): at 2 the same search fails, naming the bound as
    // what stopped it (sequences were left to extend).
    let short = PlanOptions { feed_search: FeedSearch { depth: 2, ..feed_search }, ..opt };
    let err = planner::plan(&part, &plate, &short).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, PlanFailure::NoPlan(_)), "{msg}");
    assert!(msg.contains("no sequence of up to 2 modes (--max-steps 2)"), "{msg}");
    assert!(msg.contains("the search stopped at 2 modes (--max-steps 2;"), "{msg}");
    assert_eq!(syn.period_deg, 360.0);
    let check = syn.feed.as_ref().unwrap();
    assert_eq!(check.starts, 24);
    assert!(check.checked >= 54, "{check:?}");
    assert!(check.worst_error_deg < 3.0, "{check:?}");

    // Independent check: poses on a grid inside the feed region that the planner did not
    // track, every 60° from 10°.
    let body = Body::new(&part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let steps = syn.sim_steps();
    let mut worst = 0.0f64;
    for (x, y) in [(65.0, 45.0), (95.0, 50.0), (80.0, 60.0), (70.0, 75.0), (90.0, 78.0)] {
        for k in 0..6 {
            let start = Pose { x, y, theta: (10.0 + 60.0 * k as f64).to_radians() };
            let (poses, _, _) = simulate_plan(&body, &plate, &fields, &steps, start);
            let end = poses.last().unwrap();
            worst = worst.max(cdist(end.theta.to_degrees(), syn.final_orientation_deg, 360.0));
        }
    }
    assert!(worst < 3.0, "worst final orientation error {worst}° (plan {modes:?})");
}

/// Both faces from the feed region (docs/plan.md, "Both faces"): the triangle and its mirror
/// image are tracked through the same sequences. On modes 2 and 4 the face up gets to one
/// orientation (modes 2, 4, 2 as in the test above) but the flipped face from every start
/// ends in a 180° pair, so the search fails, naming the flipped face.
#[test]
fn both_faces_from_a_feed_region_fail_naming_the_face_left_apart() {
    let plate = free_plate_modes_2_and_4();
    let up = Part::load(&root().join("examples/parts/triangle.json")).unwrap();
    let parts = [up.clone(), up.mirrored()];
    let region = FeedRegion::new([60.0, 40.0, 100.0, 80.0], &plate).unwrap();
    let feed_search = FeedSearch { depth: 3, points: 2, starts: 6, ..Default::default() };
    let opt = PlanOptions { feed: Some(region), feed_search, ..Default::default() };
    let bar = chladni_core::progress::Silent;
    let err = planner::feed::plan_parts(&parts, &plate, &opt, &region, &bar).unwrap_err();
    let msg = err.to_string();
    assert!(matches!(err, PlanFailure::NoPlan(_)), "{msg}");
    assert!(msg.contains("every part in the feed region"), "{msg}");
    assert!(msg.contains("triangle (flipped)'s tracked orientations spread"), "{msg}");
    // The face up alone plans from the same region (the test above).
    assert!(planner::feed::plan_parts(&parts[..1], &plate, &opt, &region, &bar).is_ok());
}

/// `plan --max-steps N`: checked before any work (1..=8, and only with `--feed`: the search
/// over orientation sets has no step bound), one JSON failure each with `--json`.
#[test]
fn max_steps_is_refused_out_of_range_or_without_a_feed_region() {
    let (part, plate) = (ex("parts/rectangle.json"), ex("plates/free-6-modes.toml"));
    let feed = ["--feed", "40", "50", "90", "150"];
    for bad in ["0", "9", "four"] {
        let mut args = vec!["plan", &part, "--plate", &plate, "--json", "--max-steps", bad];
        args.extend_from_slice(&feed);
        let out = chladni(&args);
        assert_eq!(out.status.code(), Some(2), "--max-steps {bad}");
        let v = json(&out);
        assert_eq!(v["error"], "usage", "{v}");
        let msg = v["message"].as_str().unwrap();
        assert!(msg.contains(&format!("'{bad}'")) && msg.contains("--max-steps"), "{msg}");
        if bad != "four" {
            assert!(msg.contains("1..=8"), "{msg}");
        }
    }
    let out = chladni(&["plan", &part, "--plate", &plate, "--json", "--max-steps", "5"]);
    assert_eq!(out.status.code(), Some(2));
    let v = json(&out);
    assert_eq!(v["error"], "bad_input", "{v}");
    let msg = v["message"].as_str().unwrap();
    assert!(msg.contains("--max-steps 5") && msg.contains("--feed"), "{msg}");
}

/// `--max-steps` reaches the search through the CLI: the rectangle from the free plate's left
/// side needs 2 steps (docs/plan.md, the ordinary-parts table), so at 1 it gets `no_plan`
/// naming the flag.
#[test]
fn max_steps_one_stops_the_feed_search_and_says_so() {
    let (part, plate) = (ex("parts/rectangle.json"), ex("plates/free-6-modes.toml"));
    let args =
        ["plan", &part, "--plate", &plate, "--feed", "40", "50", "90", "150", "--max-steps", "1"];
    let out = chladni(&[&args[..], &["--json"]].concat());
    assert_eq!(out.status.code(), Some(1));
    let v = json(&out);
    assert_eq!(v["error"], "no_plan", "{v}");
    let msg = v["message"].as_str().unwrap();
    assert!(msg.contains("no sequence of up to 1 mode (--max-steps 1)"), "{msg}");
    assert!(msg.contains("a larger value searches longer sequences"), "{msg}");
}

/// The default step bound is 6: the triangle from the hinged-rod plate's left side gets its
/// 5-step plan (docs/plan.md, "The step bound"; none of up to 4 steps exists) without
/// `--max-steps`; a plan of at most 4 steps (the L-shape's 3) is the one a bound of 4
/// gives, byte for byte, as the first four levels run every start exactly.
#[test]
fn the_default_step_bound_finds_a_5_step_plan_and_keeps_the_shorter_ones() {
    let plate = ex("plates/hinged-rod-6-modes.toml");
    let feed = ["--feed", "40", "50", "90", "150", "--json"];
    let plan = |part: &str, more: &[&str]| {
        let part = ex(part);
        let args = [&["plan", part.as_str(), "--plate", plate.as_str()][..], &feed, more].concat();
        let out = chladni(&args);
        (out.status.code(), json(&out))
    };
    let (code, v) = plan("parts/triangle.json", &[]);
    assert_eq!(code, Some(0), "{v}");
    assert_eq!(v["steps"].as_array().map(Vec::len), Some(5), "{v}");
    let (default, four) =
        (plan("parts/l-shape.json", &[]), plan("parts/l-shape.json", &["--max-steps", "4"]));
    assert_eq!(default.0, Some(0), "{}", default.1);
    assert_eq!(default.1["steps"].as_array().map(Vec::len), Some(3), "{}", default.1);
    assert_eq!(default, four);
}
