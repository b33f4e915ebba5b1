//! Whole-plate plans on grid (solver) modes (docs/plan.md, "Whole-plate plans on grid modes"):
//! a plan is run from a grid of drop points over the plate, every part and face of it, the
//! drops it does not hold from refine the step maps, and what still fails is named; a plan
//! for both faces from a feed region holds in `chladni simulate` over that region.

use chladni_core::model::part::Part;
use chladni_core::model::part::mirror::{self, FLIPPED_SUFFIX};
use chladni_core::model::plate::{Node, PlateModel};
use chladni_core::motion::body::Body;
use chladni_core::planner::whole::{
    DROP_GRID, DROP_TURNS, DropEnd, OnPlate, check, check_parts, plate_groups,
};
use chladni_core::planner::{self, PlanFailure, PlanOptions};

use crate::support;
use support::cli::{chladni, ex, floats, json, ok_json, tmp, triangle_on_four_lines, write_tmp};
use support::examples::{part, plate, plate_entries};

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
    let body = Body::with_samples(&rect, chladni_core::motion::body::PLANNER_BODY_SAMPLES);
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
    let json = chladni_media::shapes::plan_failure_json(&e);
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
    let json = chladni_media::shapes::plan::with_whole_plate(serde_json::json!({}), Some(w));
    assert_eq!(json["whole_plate"]["checked"], true);
    assert_eq!(json["whole_plate"]["parts"][1]["part"], "triangle (flipped)");
    assert_eq!(json["whole_plate"]["parts"][1]["failed"], 0);
    assert!(w.describe().contains("triangle (flipped) 48/48"), "{}", w.describe());

    // The faces are told apart: with the flipped face's prediction turned by 90° every one
    // of its drops fails, and none of the face up's.
    let mut wrong = syn.clone();
    wrong.parts[1].final_orientation_deg += 90.0;
    let bodies: Vec<Body> = faces
        .iter()
        .map(|p| Body::with_samples(p, chladni_core::motion::body::PLANNER_BODY_SAMPLES))
        .collect();
    let (per, together) = check_parts(&bodies, OnPlate::Alone, &plate, &wrong).unwrap();
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
    let groups = |given: &[Part], both: bool| {
        let f = mirror::faces(given, both);
        plate_groups(f.parts.len(), OnPlate::Faces(&f.of))
    };
    // One part on both faces: each face alone.
    assert_eq!(groups(std::slice::from_ref(&tri), true), (vec![vec![0], vec![1]], false));
    // Two files, one of them on both faces (the rectangle has a mirror axis: one face): the
    // face-up drop and the flipped one, the other part in both (as `chladni simulate` drops
    // them).
    assert_eq!(groups(&[tri.clone(), rect.clone()], true), (vec![vec![0, 2], vec![1, 2]], true));
    assert_eq!(groups(&[rect.clone(), tri.clone()], false), (vec![vec![0, 1]], true));
    // The grouping is where the parts come from, not their names: a part file the user named
    // `triangle (flipped)` holding the triangle's mirror image is a second part on the plate
    // with the triangle, and a library caller that says nothing drops each part alone.
    let m = tri.mirrored();
    let named = Part::new(format!("{}{FLIPPED_SUFFIX}", tri.name), m.outline, m.holes).unwrap();
    assert_eq!(named.name, "triangle (flipped)");
    assert_eq!(groups(&[tri.clone(), named], false), (vec![vec![0, 1]], true));
    assert_eq!(plate_groups(2, OnPlate::Alone), (vec![vec![0], vec![1]], false));
    // An `of` that does not match the parts says nothing either.
    let f = mirror::faces(&[tri, rect], false);
    assert_eq!(plate_groups(3, OnPlate::Faces(&f.of)), (vec![vec![0], vec![1], vec![2]], false));
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

/// The cantilever's bending mode (the first of the committed six-mode file), a grid mode with
/// no interior node: added to a plate of straight nodes, it makes the whole-plate check run
/// while the plans use the straight nodes.
fn cantilever_bending_entry() -> String {
    plate_entries("cantilever-6-modes.toml").1.swap_remove(0)
}

/// A part file for the CLI: `part` as JSON (name and outline).
fn part_file(tag: &str, p: &Part) -> String {
    let text = serde_json::json!({"name": p.name, "outline": p.outline}).to_string();
    write_tmp(tag, &format!("{}.json", p.name.replace(' ', "-")), text)
}

#[test]
fn a_part_file_the_user_named_flipped_is_a_part_of_its_own_on_the_plate_with_the_other() {
    // The triangle and a part file of its mirror image that the user named "triangle
    // (flipped)": two part files, so the check drops them together, whatever their names. The
    // plan brings both to the same node crossing, where they block each other. (Planned as the
    // two faces of the triangle, `--both-faces`, each face is dropped alone and the same plan
    // holds from all 96 drops:
    // `a_plan_for_both_faces_is_checked_on_every_face_and_a_face_that_fails_is_named`.)
    let (head, mut modes) = plate_entries("four-lines.toml");
    modes.push(cantilever_bending_entry());
    let plate = write_tmp("whole-named", "plate.toml", head + &modes.concat());
    let named = part_file("whole-named", &part("triangle.json").mirrored());
    let tri = ex("parts/triangle.json");
    let out = chladni(&["plan", &tri, &named, "--plate", &plate, "--refine-rounds", "1", "--json"]);
    let j = together_failure(&out);
    assert!(j["message"].as_str().unwrap().contains("of 48 random drops"), "{j}");
}

/// The `--json` failure of a `plan` whose parts of several files block each other on the
/// plate: `not_whole_plate` of the together drops, exit 1.
fn together_failure(out: &std::process::Output) -> serde_json::Value {
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    let j = json(out);
    assert_eq!(
        (j["error"].as_str(), j["together"].as_bool()),
        (Some("not_whole_plate"), Some(true))
    );
    let msg = j["message"].as_str().unwrap();
    assert!(msg.contains("random drops of the parts together"), "{msg}");
    j
}

/// One horizontal straight node across the middle of a `width` × 200 mm plate, and the
/// cantilever's bending mode stretched over it (there for the check to run).
fn line_plate_text(width: f64) -> String {
    let head =
        format!("[plate]\nname = \"one line, {width} mm\"\nsize_mm = [{width:.1}, 200.0]\n\n");
    let line = "[[mode]]\nname = \"horizontal\"\nfreq_hz = 60.0\namplitude = 0.8\nfield = \"sign\"\n\
                node = { kind = \"line\", angle_deg = 0.0, offset_mm = 0.0 }\n\n";
    head + line + &cantilever_bending_entry()
}

#[test]
fn parts_that_hold_alone_can_block_each_other_together_and_hold_where_they_do_not_meet() {
    // A 12 × 3 mm pin and a 3 × 9 mm peg: one step on the horizontal node lays both along it
    // (the pin at 0°, the peg at 90°, mod 180°), from anywhere, each alone. Dropped together
    // (48 random drops, seed 1) on a 300 mm plate, a part reaching the node where the other
    // already lies stops against it at its drop orientation; on a 1200 mm plate the same drops
    // spread them far enough apart that none meets the other.
    let pin =
        Part::new("pin".into(), vec![[0.0, 0.0], [12.0, 0.0], [12.0, 3.0], [0.0, 3.0]], Vec::new())
            .unwrap();
    let peg =
        Part::new("peg".into(), vec![[0.0, 0.0], [3.0, 0.0], [3.0, 9.0], [0.0, 9.0]], Vec::new())
            .unwrap();
    let text = line_plate_text(300.0);
    let model = PlateModel::parse(&text, "one line").unwrap();
    let opt = PlanOptions { refine_rounds: 1, ..Default::default() };
    // The library, told nothing about where the parts come from, drops each alone.
    let syn =
        planner::plan_parts(&[pin.clone(), peg.clone()], &model, &opt, &[None, None]).unwrap();
    let w = syn.whole_plate.as_ref().expect("checked");
    assert!(!w.together && w.held == w.drops && w.drops == 96, "{w:?}");
    assert_eq!(syn.steps.len(), 1);
    let (pin_f, peg_f) = (part_file("whole-pins", &pin), part_file("whole-pins", &peg));
    let plan = |width: f64| {
        let plate = write_tmp("whole-pins", &format!("plate-{width}.toml"), line_plate_text(width));
        chladni(&["plan", &pin_f, &peg_f, "--plate", &plate, "--json"])
    };
    // Two part files through the CLI: together, and on 300 mm they block each other.
    let j = together_failure(&plan(300.0));
    let failed = j["failed"].as_u64().unwrap();
    assert!(failed > 0 && failed < 48, "{j}");
    assert!(j["ends"].as_str().unwrap().contains("inside the plate"), "{j}");
    // On 1200 mm they hold together.
    let j = ok_json(&plan(1200.0));
    let w = &j["whole_plate"];
    assert_eq!(
        (w["together"].as_bool(), w["drops"].as_u64(), w["held"].as_u64()),
        (Some(true), Some(96), Some(96)),
        "{w}"
    );
}

#[test]
fn the_clamp_capture_zone_is_said_up_front_and_its_outside_box_lies_beyond_it() {
    // The cantilever's bending mode alone (the cheapest plate with a clamp): `plan` warns
    // before planning, and the JSON (here of the failure: one mode gives no plan) names the
    // zone and the plate outside it as a `--feed` box.
    let (head, modes) = plate_entries("cantilever-6-modes.toml");
    let plate = write_tmp("whole-capture", "plate.toml", head + &modes[0]);
    let out = chladni(&["plan", &ex("parts/rectangle.json"), "--plate", &plate, "--json"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let j = json(&out);
    let z = &j["capture_zone"];
    let warning =
        stderr.lines().find(|l| l.starts_with("warning: ")).unwrap_or_else(|| panic!("{stderr}"));
    assert!(warning.contains("(clamped edge x = 0) is the clamp's capture zone"), "{warning}");
    assert!(warning.contains("drop points of the whole-plate check lie in it"), "{warning}");
    assert_eq!(z["bands"][0]["edge"], "x = 0", "{z}");
    let width = z["bands"][0]["width_mm"].as_f64().unwrap();
    let b = floats(&z["outside_mm"]);
    // The box lies inside the 300 × 200 mm plate, beyond the band: a part dropped in it is not
    // in the zone, and the warning's --feed is that box.
    assert!(
        b[0] >= width
            && b[0] < b[2]
            && b[2] <= 300.0
            && b[1] >= 0.0
            && b[1] < b[3]
            && b[3] <= 200.0,
        "{z}"
    );
    // One mode, which takes every part to the clamp in every column: the clear line is the
    // zone's edge, so the warning's --feed is the box outside the zone.
    assert_eq!(z["clear_box_mm"], z["outside_mm"], "{z}");
    let feed = format!("try --feed {:.0} {:.0} {:.0} {:.0}", b[0], b[1], b[2], b[3]);
    assert!(warning.ends_with(&feed), "{warning}");
    let drops_in = z["drops_in"].as_u64().unwrap();
    assert!(drops_in > 0 && drops_in <= z["drops"].as_u64().unwrap(), "{z}");
    assert!(warning.contains(&format!(": {drops_in} of the")), "{warning}");
}

#[test]
fn the_rectangle_plans_from_the_feed_box_outside_the_clamp_capture_zone() {
    // The cantilever's six solver modes: the whole-plate plan fails in the clamp's capture
    // zone and names the plate beyond it; a feed region there plans. The zone ends half a
    // column past the first column some mode keeps off the clamp: the earlier rule's 86 mm,
    // or that column itself (90.6 mm), left starts in the box that every mode takes to the
    // clamp, and the feed search found no plan.
    let plate = ex("plates/cantilever-6-modes.toml");
    let rect = ex("parts/rectangle.json");
    let whole = json(&chladni(&["plan", &rect, "--plate", &plate, "--json"]));
    assert_eq!(whole["error"], "not_whole_plate", "{whole}");
    let b = floats(&whole["capture_zone"]["outside_mm"]);
    assert!(b[0] > 90.7, "{whole}");
    let feed: Vec<String> = b.iter().map(|v| format!("{v}")).collect();
    let mut args = vec!["plan", &rect, "--plate", &plate, "--json", "--feed"];
    args.extend(feed.iter().map(String::as_str));
    let plan = ok_json(&chladni(&args));
    assert!(!plan["steps"].as_array().unwrap().is_empty(), "{plan}");
}

#[test]
fn the_l_shape_plans_from_the_clear_box_the_warning_offers() {
    // The cantilever's six solver modes: past the L-shape's capture zone (x < 92 mm) every
    // mode still takes some sampled drop to the clamp up to x = 142 mm, and from the box
    // outside the zone the feed search finds no plan (docs/plan.md, the ordinary-parts
    // table). The warning offers the box past the clear line instead, and from there it plans.
    let plate = ex("plates/cantilever-6-modes.toml");
    let l = ex("parts/l-shape.json");
    let out = chladni(&["plan", &l, "--plate", &plate, "--json"]);
    let (stderr, whole) = (String::from_utf8_lossy(&out.stderr), json(&out));
    let z = &whole["capture_zone"];
    let (outside, clear) = (floats(&z["outside_mm"]), floats(&z["clear_box_mm"]));
    assert!(clear[0] > outside[0] + 10.0, "{z}");
    let warning =
        stderr.lines().find(|l| l.starts_with("warning: ")).unwrap_or_else(|| panic!("{stderr}"));
    let hint =
        format!("try --feed {:.0} {:.0} {:.0} {:.0}", clear[0], clear[1], clear[2], clear[3]);
    assert!(warning.ends_with(&hint), "{warning}");
    assert!(warning.contains("one mode takes none of the zone's sampled drops"), "{warning}");
    let feed: Vec<String> = clear.iter().map(|v| format!("{v}")).collect();
    let mut args = vec!["plan", &l, "--plate", &plate, "--json", "--feed"];
    args.extend(feed.iter().map(String::as_str));
    let plan = ok_json(&chladni(&args));
    assert!(!plan["steps"].as_array().unwrap().is_empty(), "{plan}");
}
