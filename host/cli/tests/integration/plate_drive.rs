//! The drive point, clamps and `plate suggest` (docs/plate.md): a square plate's solver file is
//! one the planner takes, a drive point on a node does not excite that mode, a clamped point
//! is a node, and every plan `suggest` lists for a drive point and clamps is one `chladni plan`
//! gives on the plate file written from them.

use std::process::Output;

use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_file::PlateFile;
use chladni_core::plate::contour::node_lines;
use chladni_core::plate::solver;

use crate::support;
use support::cli::{chladni, repo, tmp};
use support::examples::root;

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into(), String::from_utf8_lossy(&o.stderr).into())
}

#[test]
fn a_square_plates_solver_file_is_one_the_planner_takes_and_plans() {
    let square = repo("examples/plate-square.toml");
    let out = tmp("plate-drive", "square.toml");
    let o = chladni(&[
        "plate",
        "modes",
        &square,
        "--count",
        "3",
        "--grid",
        "31",
        "--write-modes",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let model = PlateModel::load(&out).expect("the planner loads the solver's own file");
    assert_eq!(model.modes.len(), 3);
    // With the pair in: six modes, pairs 4+5 and 6+7 one resonance each (five).
    let all = tmp("plate-drive", "square6.toml");
    let o = chladni(&[
        "plate",
        "modes",
        &square,
        "--count",
        "6",
        "--write-modes",
        all.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let model = PlateModel::load(&all).expect("no SameFrequency");
    let names: Vec<&str> = model.modes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["mode 1", "mode 2", "mode 3", "modes 4+5", "modes 6+7"]);
    // The clamped variant (`plate suggest`'s first candidate on the square) is a file the
    // planner takes.
    let clamped = tmp("plate-drive", "square-clamped.toml");
    let text_of = std::fs::read_to_string(&square).unwrap();
    std::fs::write(&clamped, row_plate(&text_of, [60.0, 74.0], &[[20.0, 24.0]])).unwrap();
    let file = tmp("plate-drive", "square-clamped-modes.toml");
    let o = chladni(&[
        "plate",
        "modes",
        clamped.to_str().unwrap(),
        "--count",
        "3",
        "--write-modes",
        file.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let part = repo("examples/parts/rectangle.json");
    // Without the whole-plate check (`--refine-rounds 0`): with it, the plan holds from 12 of
    // the 48 drops over the plate, `plan` refuses it (docs/plan.md, "Whole-plate plans on grid
    // modes") and `plate suggest` lists the row as `not_whole_plate`; this test is about the
    // file being one the planner takes.
    let file = file.to_str().unwrap();
    let o = chladni(&["plan", &part, "--plate", file, "--maps", "static", "--refine-rounds", "0"]);
    assert!(o.status.success(), "{:?}", text(&o));
}

#[test]
fn without_a_drive_point_a_degenerate_pair_refuses_write_modes_naming_it() {
    let square = std::fs::read_to_string(root().join("examples/plate-square.toml")).unwrap();
    let plain = tmp("plate-drive", "square-nodrive.toml");
    std::fs::write(&plain, square.replace("drive_mm = [70.0, 45.0]\n", "")).unwrap();
    let out = tmp("plate-drive", "never.toml");
    let o = chladni(&[
        "plate",
        "modes",
        plain.to_str().unwrap(),
        "--write-modes",
        out.to_str().unwrap(),
    ]);
    let (_, err) = text(&o);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("modes 4+5") && err.contains("drive_mm"), "{err}");
    assert!(!out.exists());
    // The table alone is fine.
    assert!(chladni(&["plate", "modes", plain.to_str().unwrap()]).status.success());
}

#[test]
fn a_drive_point_on_a_nodal_line_does_not_excite_that_mode() {
    let square = std::fs::read_to_string(root().join("examples/plate-square.toml")).unwrap();
    // Mode 1 of the free square twists about both mid-lines: x = 100 mm is on its node.
    let on_node = tmp("plate-drive", "square-on-node.toml");
    std::fs::write(&on_node, square.replace("[70.0, 45.0]", "[100.0, 37.0]")).unwrap();
    let o = chladni(&["plate", "modes", on_node.to_str().unwrap(), "--count", "3", "--json"]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}");
    assert!(err.contains("warning: mode 1 ") && err.contains("not excited"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let names: Vec<&str> =
        v["modes"].as_array().unwrap().iter().map(|m| m["name"].as_str().unwrap()).collect();
    assert!(!names.contains(&"mode 1"), "{names:?}");
    assert!(
        v["modes"].as_array().unwrap().iter().all(|m| m["excitation"].as_f64().unwrap() >= 0.05)
    );
    // Off the node (the example's drive point) mode 1 is there.
    let o =
        chladni(&["plate", "modes", &repo("examples/plate-square.toml"), "--count", "3", "--json"]);
    assert!(text(&o).0.contains("\"name\":\"mode 1\""), "{:?}", text(&o));
    // A drive point off the plate is refused, naming the key and value.
    let off = tmp("plate-drive", "square-off.toml");
    std::fs::write(&off, square.replace("[70.0, 45.0]", "[70.0, 245.0]")).unwrap();
    let o = chladni(&["plate", "modes", off.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o).1.contains("drive_mm = [70.0, 245.0]"), "{:?}", text(&o));
}

#[test]
fn clamps_move_the_nodes_and_a_clamped_point_is_a_node() {
    let square = std::fs::read_to_string(root().join("examples/plate-square.toml")).unwrap();
    let free = PlateFile::parse(&square, "sq").unwrap().plate.mechanics().unwrap();
    let clamped = PlateFile::parse(&(square + "clamps_mm = [[40.0, 30.0]]\n"), "sq")
        .unwrap()
        .plate
        .mechanics()
        .unwrap();
    let (a, b) = (solver::solve(&free, 4, 12), solver::solve(&clamped, 4, 12));
    // A 41×41 grid over 200 mm has a point at (40, 30) mm: i = 8, j = 6.
    let (ga, gb) = (a.sample(1, 41, 41), b.sample(1, 41, 41));
    assert_eq!(gb.point(8, 6), [40.0, 30.0]);
    for k in 0..4 {
        assert_eq!(b.sample(k, 41, 41).at(8, 6), 0.0, "clamped mode {} moves at the clamp", k + 1);
    }
    assert!(ga.at(8, 6).abs() > 0.05, "the free mode moves there: {}", ga.at(8, 6));
    // The node lines differ: the clamped mode's pass through the clamp.
    let near = |g: &chladni_core::model::grid::Grid| {
        node_lines(g)
            .iter()
            .flat_map(|l| l.iter())
            .map(|p| (p[0] - 40.0).hypot(p[1] - 30.0))
            .fold(f64::INFINITY, f64::min)
    };
    assert!(near(&gb) < 1.0 && near(&ga) > 5.0, "{} {}", near(&gb), near(&ga));
}

/// The plate file of a `plate suggest` row: the source file with the row's `drive_mm` and
/// `clamps_mm` in place of its own (the `[plate]` table is the source's only table).
fn row_plate(source: &str, drive: [f64; 2], clamps: &[[f64; 2]]) -> String {
    let keep = |l: &&str| !l.starts_with("drive_mm") && !l.starts_with("clamps_mm");
    let mut text: String = source.lines().filter(keep).map(|l| format!("{l}\n")).collect();
    text += &format!("drive_mm = [{:.1}, {:.1}]\n", drive[0], drive[1]);
    if !clamps.is_empty() {
        let c: Vec<String> = clamps.iter().map(|c| format!("[{:.1}, {:.1}]", c[0], c[1])).collect();
        text += &format!("clamps_mm = [{}]\n", c.join(", "));
    }
    text
}

/// A JSON `[x, y]` (mm).
fn pt(v: &serde_json::Value) -> [f64; 2] {
    [v[0].as_f64().unwrap(), v[1].as_f64().unwrap()]
}

#[test]
fn every_plan_suggest_lists_is_one_chladni_plan_gives_on_that_rows_plate_file() {
    // The hinged-rod plate: the rectangle aligns on the forced rocking's node (the hinge) from
    // anywhere on the plate, so suggest's whole-plate check holds from every drop. (On the
    // free square the first candidate's plan holds from 12 of 48 drops: a `not_whole_plate`
    // row, docs/plate.md.)
    let source = repo("examples/plate-hinged-rod.toml");
    let part = repo("examples/parts/rectangle.json");
    let o =
        chladni(&["plate", "suggest", &source, &part, "--count", "2", "--budget-s", "1", "--json"]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "{err}\n{out}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 21);
    // The budget lets the first candidate run (one clamp near a corner, drive off centre); a
    // later row on its clamps either has its plate file (same_as row 0, its outcome) or is not
    // tried, and every other clamp set is not tried: the budget names those rows.
    assert_eq!(rows[0]["outcome"], "plan", "{out}");
    assert!(rows[0]["wall_s"].as_f64().unwrap() > 0.0);
    let whole = &rows[0]["whole_plate"];
    assert_eq!(
        (&whole["checked"], &whole["drops"], &whole["held"]),
        (&true.into(), &48.into(), &48.into()),
        "{out}"
    );
    for r in &rows[1..] {
        if r["clamps_mm"] == rows[0]["clamps_mm"] && r["same_as"] == 0 {
            assert_eq!((&r["outcome"], &r["whole_plate"]), (&rows[0]["outcome"], whole), "{r}");
        } else {
            assert_eq!(r["outcome"], "not_tried", "{r}");
            assert_eq!(r["modes"], 0, "{r}");
        }
    }
    // Every plan row is a plan `chladni plan` (default flags) gives on its row's plate file.
    let source_text = std::fs::read_to_string(&source).unwrap();
    let plans: Vec<&serde_json::Value> = rows.iter().filter(|r| r["outcome"] == "plan").collect();
    assert!(plans.len() >= 2, "row 0 and its twin at another drive point: {out}");
    for (k, r) in plans.iter().enumerate() {
        let clamps: Vec<[f64; 2]> = r["clamps_mm"].as_array().unwrap().iter().map(pt).collect();
        let plate = tmp("plate-drive", &format!("suggested-{k}.toml"));
        std::fs::write(&plate, row_plate(&source_text, pt(&r["drive_mm"]), &clamps)).unwrap();
        let modes = tmp("plate-drive", &format!("suggested-{k}-modes.toml"));
        let (p, m) = (plate.to_str().unwrap(), modes.to_str().unwrap());
        let o = chladni(&["plate", "modes", p, "--count", "2", "--write-modes", m]);
        assert!(o.status.success(), "{:?}", text(&o));
        let o = chladni(&["plan", &part, "--plate", m]);
        let (plan, err) = text(&o);
        assert!(o.status.success(), "row {r}: {err}\n{plan}");
        assert!(plan.contains("whole plate  held from 48 of 48 drops"), "row {r}: {plan}");
        let steps = plan.lines().filter(|l| l.starts_with("step ")).count();
        assert_eq!(steps as u64, r["steps"].as_u64().unwrap(), "row {r}: {plan}");
    }
}
