//! Whole-plate plans on grid (solver) modes (docs/plan.md, "Whole-plate plans on grid modes"):
//! a plan is run from a grid of drop points over the plate, the drops it does not hold from
//! refine the step maps, and what still fails is named.

use chladni::model::plate::{Node, PlateModel};
use chladni::motion::sim::Body;
use chladni::planner::whole::{DROP_GRID, DROP_TURNS, check};
use chladni::planner::{self, PlanFailure, PlanOptions};

mod support;
use support::examples::{part, plate};

/// The cantilever's solver-made bending and torsion modes (the first two of the committed
/// six-mode file): the torsion mode's node runs along y = 100 mm, and near the clamp (x = 0)
/// the pull falls off like x³.
fn cantilever_two_modes() -> PlateModel {
    let mut p = plate("cantilever-6-modes.toml");
    p.modes.truncate(2);
    assert!(p.modes.iter().all(|m| matches!(m.node, Node::Grid(_))));
    p
}

#[test]
fn the_cantilever_rectangle_plan_holds_from_the_far_side_only_and_the_failure_names_the_clamp_side()
{
    let plate = cantilever_two_modes();
    let rect = part("rectangle.json");
    let base = PlanOptions { sim_starts: 36, ..Default::default() };

    // Without the whole-plate check the planner gives the torsion-mode plan of the mode's
    // reach, which the drops over the plate do not all confirm.
    let syn = planner::plan(&rect, &plate, &base).unwrap();
    assert_eq!(syn.steps.iter().map(|s| s.mode).collect::<Vec<_>>(), [1]);
    assert!(syn.whole_plate.is_none());
    let body = Body::with_samples(&rect, 160);
    let (drops, failed) = check(&body, &plate, &syn);
    assert_eq!(drops, DROP_GRID[0] * DROP_GRID[1] * DROP_TURNS);
    assert!(!failed.is_empty());
    // Every drop it fails from lies on the clamp side (x < 100 mm).
    assert!(failed.iter().all(|d| d.0[0] < 100.0), "{failed:?}");

    // With it, no plan holds over the whole plate: the failure says from where, how the
    // parts end, and a feed region away from the clamp where the plan held.
    let opt = PlanOptions { refine_rounds: 2, ..base };
    let e = planner::plan(&rect, &plate, &opt).unwrap_err();
    let PlanFailure::NotWholePlate(n) = &e else { panic!("{e}") };
    let (drops, failed, region_mm, ends, max_rounds, feed_mm) =
        (&n.drops, &n.failed, &n.region_mm, &n.ends, &n.max_rounds, &n.feed_mm);
    assert_eq!((*drops, *max_rounds), (48, 2));
    assert!(*failed > 0 && *failed < *drops, "{e}");
    assert!(region_mm[2] < 100.0, "{e}");
    assert!(ends.contains("left (x = 0) edge") || ends.contains("inside"), "{e}");
    let feed = feed_mm.expect("a feed region where the plan held");
    assert!(feed[0] >= 75.0 && feed[2] > feed[0] && feed[3] > feed[1], "{feed:?}");
    let msg = e.to_string();
    assert!(msg.contains("--refine-rounds") && msg.contains("try --feed"), "{msg}");
    let json = chladni::shapes::plan_failure_json(&e);
    assert_eq!(json["error"], "not_whole_plate");
    assert!(json["held_share"].as_f64().unwrap() < 1.0, "{json}");
    assert_eq!(json["feed_mm"].as_array().unwrap().len(), 4, "{json}");
}

#[test]
fn a_plan_of_two_parts_says_its_whole_plate_hold_is_not_checked() {
    // The check runs one part on one face: a plan of several (or of both faces of a part
    // that flips) is marked unchecked, in the result and in `plan --json`, not passed.
    let plate = cantilever_two_modes();
    let rect = part("rectangle.json");
    let opt = PlanOptions { sim_starts: 36, refine_rounds: 2, ..Default::default() };
    let syn = planner::plan_parts(&[rect.clone(), rect], &plate, &opt, &[None, None]).unwrap();
    let w = syn.whole_plate.as_ref().expect("marked");
    assert!(!w.checked && w.drops == 0, "{w:?}");
    let json = chladni::shapes::plan::with_whole_plate(serde_json::json!({}), Some(w));
    assert_eq!(json["whole_plate"]["checked"], false);
    assert!(json["whole_plate"]["why"].as_str().unwrap().contains("chladni simulate"));
}
