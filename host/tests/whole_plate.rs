//! Whole-plate plans on grid (solver) modes (docs/plan.md, "Whole-plate plans on grid modes"):
//! a plan is run from a grid of drop points over the plate, every part and face of it, the
//! drops it does not hold from refine the step maps, and what still fails is named; a plan
//! for both faces from a feed region holds in `chladni simulate` over that region.

use chladni::model::part::Part;
use chladni::model::plate::{Node, PlateModel};
use chladni::motion::sim::Body;
use chladni::planner::whole::{DROP_GRID, DROP_TURNS, DropEnd, check, check_parts, plate_groups};
use chladni::planner::{self, PlanFailure, PlanOptions};

mod support;
use support::cli::{ok_json, tmp, triangle_on_four_lines};
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

/// The four-lines plate with the cantilever's bending mode (a grid mode, no interior node)
/// added: the check runs (a grid mode is there), and the plans use the straight nodes, which
/// hold from anywhere on the plate.
fn four_lines_and_a_grid_mode() -> PlateModel {
    let mut p = plate("four-lines.toml");
    let grid = plate("cantilever-6-modes.toml").modes.swap_remove(0);
    assert!(matches!(grid.node, Node::Grid(_)) && p.size_mm == [300.0, 200.0]);
    p.modes.push(grid);
    p
}

#[test]
fn a_plan_for_both_faces_is_checked_on_every_face_and_a_face_that_fails_is_named() {
    // Each face of a part that flips is one part of the plan, never on the plate with the
    // other: each is dropped alone from the 48 grid drops, against its own prediction.
    let plate = four_lines_and_a_grid_mode();
    let tri = part("triangle.json");
    let faces = [tri.clone(), tri.mirrored()];
    let opt = PlanOptions { sim_starts: 36, refine_rounds: 1, ..Default::default() };
    let syn = planner::plan_parts(&faces, &plate, &opt, &[None, None]).unwrap();
    assert!(syn.steps.iter().all(|s| s.mode < 4), "straight nodes only");
    let w = syn.whole_plate.as_ref().expect("checked");
    let one = DROP_GRID[0] * DROP_GRID[1] * DROP_TURNS;
    assert!(w.checked && !w.together, "{w:?}");
    assert_eq!((w.drops, w.held, w.rounds), (2 * one, 2 * one, 0), "{w:?}");
    let names: Vec<&str> = w.parts.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["triangle", "triangle (flipped)"]);
    let json = chladni::shapes::plan::with_whole_plate(serde_json::json!({}), Some(w));
    assert_eq!(json["whole_plate"]["checked"], true);
    assert_eq!(json["whole_plate"]["parts"][1]["part"], "triangle (flipped)");
    assert_eq!(json["whole_plate"]["parts"][1]["failed"], 0);
    assert!(w.describe().contains("triangle (flipped) 48/48"), "{}", w.describe());

    // The faces are told apart: with the flipped face's prediction turned by 90° every one
    // of its drops fails, and none of the face up's.
    let mut wrong = syn.clone();
    wrong.parts[1].final_orientation_deg += 90.0;
    let refs: Vec<&Part> = faces.iter().collect();
    let bodies: Vec<Body> = faces.iter().map(|p| Body::with_samples(p, 160)).collect();
    let (per, together) = check_parts(&refs, &bodies, &plate, &wrong).unwrap();
    assert!(!together);
    assert_eq!((per[0].drops, per[0].failed.len()), (one, 0));
    assert_eq!((per[1].drops, per[1].failed.len()), (one, one));
    assert!(per[1].failed.iter().all(|d| d.2 == DropEnd::Interior), "{:?}", per[1].failed);

    // On the cantilever's modes the plan of the rectangle's two faces (the library plans
    // them as given; `plan` would plan one, the rectangle being its own mirror turned) fails
    // from the clamp side: the failure names the face that fails most, with its 48 drops.
    let plate = cantilever_two_modes();
    let rect = part("rectangle.json");
    let faces = [rect.clone(), rect.mirrored()];
    let e = planner::plan_parts(&faces, &plate, &opt, &[None, None]).unwrap_err();
    let PlanFailure::NotWholePlate(n) = &e else { panic!("{e}") };
    assert!(n.part == "rectangle" || n.part == "rectangle (flipped)", "{e}");
    assert_eq!(n.drops, one, "{e}");
    assert!(n.failed > 0 && e.to_string().starts_with(&n.part), "{e}");
}

#[test]
fn parts_of_two_files_are_grouped_to_be_dropped_together_and_faces_alone() {
    let (tri, rect) = (part("triangle.json"), part("rectangle.json"));
    let flip = tri.mirrored();
    // One part on both faces: each face alone.
    assert_eq!(plate_groups(&[&tri, &flip]), (vec![vec![0], vec![1]], false));
    // Two files, one of them on both faces: the face-up drop and the flipped one, the other
    // part in both (as `chladni simulate` drops them).
    assert_eq!(plate_groups(&[&tri, &flip, &rect]), (vec![vec![0, 2], vec![1, 2]], true));
    assert_eq!(plate_groups(&[&rect, &tri]), (vec![vec![0, 1]], true));
}

#[test]
fn a_both_face_feed_plan_is_confirmed_by_simulate_over_the_feed_region() {
    // `plan --feed … --both-faces` then `simulate --feed … --both-faces` over the same region:
    // each face holds in at least 95 % of its trials.
    let plan = tmp("whole-plate-feed", "plan.json");
    let plan_s = plan.to_str().unwrap();
    let feed = ["--feed", "40", "40", "120", "120", "--both-faces"];
    let out = triangle_on_four_lines("plan", &[&feed[..], &["--out", plan_s, "--json"]].concat());
    let printed = ok_json(&out);
    assert!(printed.get("whole_plate").is_none(), "a feed plan is not a whole-plate plan");
    let more = [&feed[..], &["--plan", plan_s, "--trials", "200", "--json"]].concat();
    let report = ok_json(&triangle_on_four_lines("simulate", &more));
    let parts = report["parts"].as_array().expect("per face");
    let faces: Vec<&str> = parts.iter().map(|p| p["face"].as_str().unwrap()).collect();
    assert_eq!(faces, ["up", "flipped"]);
    for p in parts {
        assert_eq!(p["trials"], 100, "{p}");
        assert!(p["success_rate"].as_f64().unwrap() >= 0.95, "{p}");
    }
}
