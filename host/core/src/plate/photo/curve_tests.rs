//! Curved nodes from synthetic photos: recovery accuracy against the drawn curves, and the
//! grid node built from them.

use super::curves::douglas_peucker;
use super::synth::{Scene, arc, hyperbola, render};
use super::*;
use crate::model::modes_file;
use crate::model::plate::PlateModel;
use crate::model::plate_file::PlateFile;
use crate::plate::contour::{distance_to, node_lines};
use crate::plate::node_field::node_field;
use crate::plate::solver;

const SIZE: [f64; 2] = [300.0, 200.0];
/// Accuracy bounds as fractions of the plate's short side (200 mm).
const MEAN_BOUND: f64 = 0.01;
const MAX_BOUND: f64 = 0.03;

fn scene(curves: Vec<Polyline>, lines: Vec<(f64, f64)>, seed: u64) -> Scene {
    Scene::standard(lines, curves, seed)
}

/// Points every `step` mm along a polyline, kept only inside the plate.
fn dense(l: &Polyline, step: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::new();
    for w in l.windows(2) {
        let len = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        let n = ((len / step).ceil() as usize).max(1);
        for k in 0..n {
            let t = k as f64 / n as f64;
            out.push([w[0][0] + t * (w[1][0] - w[0][0]), w[0][1] + t * (w[1][1] - w[0][1])]);
        }
    }
    out.extend(l.last());
    out.retain(|p| (0.0..=SIZE[0]).contains(&p[0]) && (0.0..=SIZE[1]).contains(&p[1]));
    out
}

/// (mean, max) distance from the points of `a` to the polylines `b`, in mm.
fn spread(a: &[Polyline], b: &[Polyline]) -> (f64, f64) {
    let d: Vec<([f64; 2], f64)> =
        a.iter().flat_map(|l| dense(l, 1.0)).map(|p| (p, distance_to(p, b))).collect();
    let mean = d.iter().map(|v| v.1).sum::<f64>() / d.len().max(1) as f64;
    let worst = d.iter().copied().fold(([0.0, 0.0], 0.0), |a, v| if v.1 > a.1 { v } else { a });
    (mean, worst.1)
}

/// Finds the nodes of a photo drawn from `truth` and checks both directions: every true curve
/// is close to what was found (mean and max), and everything found is close to the truth.
/// Returns the found result for further checks.
fn recover(name: &str, truth: &[Polyline], s: &Scene) -> Found {
    let img = render(s);
    let found = find_lines(&img, s.size_mm, &PhotoParams::default());
    assert_eq!(found.check_confidence(), Ok(()), "{name}");
    let got = found.nodes(DEFAULT_SNAP);
    debug_image(name, &img, &got);
    let short = SIZE[0].min(SIZE[1]);
    for (k, t) in truth.iter().enumerate() {
        let (mean, max) = spread(std::slice::from_ref(t), &got);
        println!(
            "{name} curve {k}: truth→found mean {mean:.2} mm ({:.2} %), max {max:.2} mm ({:.2} %)",
            100.0 * mean / short,
            100.0 * max / short
        );
        assert!(mean < MEAN_BOUND * short && max < MAX_BOUND * short, "{name} curve {k}");
    }
    let (mean, max) = spread(&got, truth);
    println!(
        "{name}: found→truth mean {mean:.2} mm, max {max:.2} mm; {} lines, {} curves {:?}, \
         {} unexplained px",
        found.lines.len(),
        found.curves.len(),
        found
            .curves
            .iter()
            .map(|c| (
                c.points.len(),
                c.length_mm.round(),
                c.rms_mm,
                turning(&c.points) / c.length_mm
            ))
            .collect::<Vec<_>>(),
        found.unexplained_pixels
    );
    assert!(mean < MEAN_BOUND * short && max < MAX_BOUND * short, "{name}: spurious nodes");
    found
}

/// Builds the grid node of `found` and checks that its zero set lies near `truth` and covers
/// it; returns the worst zero-set distance (mm).
fn grid_zero_set(name: &str, truth: &[Polyline], found: &Found, expect_signed: bool) -> f64 {
    let field = node_field(&found.nodes(DEFAULT_SNAP), SIZE, 121, 81).unwrap();
    assert_eq!(field.signed, expect_signed, "{name}: {:?}", field.note);
    let zero = node_lines(&field.grid);
    let (mean, max) = spread(&zero, truth);
    let (cover_mean, cover_max) = spread(truth, &zero);
    println!(
        "{name} grid: {} regions, zero set→truth mean {mean:.2} mm max {max:.2} mm; \
         truth→zero set mean {cover_mean:.2} mm max {cover_max:.2} mm",
        field.regions
    );
    let short = SIZE[0].min(SIZE[1]);
    assert!(max < MAX_BOUND * short && cover_max < MAX_BOUND * short, "{name} grid zero set");
    max
}

/// With CHLADNI_DEBUG_DIR set, writes the photo with the found nodes over it there.
fn debug_image(name: &str, img: &image::GrayImage, nodes: &[Polyline]) {
    if let Ok(dir) = std::env::var("CHLADNI_DEBUG_DIR") {
        let path = std::path::Path::new(&dir).join(format!("{}.png", name.replace(' ', "-")));
        overlay(img, nodes, SIZE).save(path).ok();
    }
}

#[test]
fn recovers_a_quarter_circle_from_edge_to_edge() {
    let truth = vec![arc([0.0, 0.0], 130.0, 0.0, 90.0, 180)];
    let found = recover("quarter circle", &truth, &scene(truth.clone(), vec![], 11));
    assert!(found.lines.is_empty(), "{:?}", found.lines);
    grid_zero_set("quarter circle", &truth, &found, true);
}

#[test]
fn recovers_a_closed_circle_and_a_hyperbola_branch() {
    let truth = vec![
        arc([90.0, 100.0], 45.0, 0.0, 360.0, 180),
        hyperbola([170.0, 100.0], 0.0, [40.0, 30.0], 2.0, 200),
    ];
    let found = recover("circle + hyperbola", &truth, &scene(truth.clone(), vec![], 12));
    grid_zero_set("circle + hyperbola", &truth, &found, true);
}

#[test]
fn recovers_a_curve_crossed_by_a_straight_line() {
    let curve = arc([150.0, -60.0], 200.0, 30.0, 150.0, 240);
    // Vertical line x = 200 mm: angle 90°, offset n̂·(p − c) = −(200 − 150).
    let line = [[200.0, 0.0], [200.0, 200.0]];
    let truth = vec![curve.clone(), line.to_vec()];
    let found = recover("arc × line", &truth, &scene(vec![curve], vec![(90.0, -50.0)], 13));
    assert_eq!(found.lines.len(), 1, "{:?}", found.lines);
    grid_zero_set("arc × line", &truth, &found, true);
}

#[test]
fn recovers_the_nodes_of_a_solver_mode() {
    let file =
        PlateFile::parse(include_str!("../../../../../examples/plate-free.toml"), "t").unwrap();
    let plate = file.plate.mechanics().unwrap();
    let sol = solver::solve(&plate, 5, 10);
    // Mode 5 of the free plate: two hyperbola-like arcs from corner to corner and a straight
    // line x = W/2 between them.
    let truth: Vec<Polyline> = node_lines(&sol.sample(4, 121, 81))
        .into_iter()
        .map(|l| douglas_peucker(&l, 0.05).into_iter().map(|k| l[k]).collect())
        .collect();
    let found = recover("free mode 5", &truth, &scene(truth.clone(), vec![], 14));
    assert_eq!((found.lines.len(), found.curves.len()), (1, 2), "{found:?}");
    grid_zero_set("free mode 5", &truth, &found, true);
    // The grid entry, appended to the plate file, is a mode the planner's model accepts.
    let field = node_field(&found.nodes(DEFAULT_SNAP), SIZE, 61, 41).unwrap();
    let entry = modes_file::sampled_mode("photo nodes", Some(250.0), &field.grid);
    let text = modes_file::render(&file.plate, vec![entry]).unwrap();
    let model = PlateModel::from_file(&PlateFile::parse(&text, "out").unwrap()).unwrap();
    assert_eq!(model.modes[0].node.kind(), "grid");
}

#[test]
fn blank_plates_have_no_curves() {
    for seed in [21, 22, 23] {
        let mut s = scene(vec![], vec![], seed);
        s.density = 0.0;
        let img = render(&s);
        let found = find_lines(&img, SIZE, &PhotoParams::default());
        debug_image(&format!("blank {seed}"), &img, &found.nodes(DEFAULT_SNAP));
        let turn: Vec<f64> =
            found.curves.iter().map(|c| turning(&c.points) / c.length_mm).collect();
        assert!(found.curves.is_empty() && found.lines.is_empty(), "{turn:?} {found:?}");
    }
}

#[test]
fn straight_photo_has_no_curves_and_its_grid_follows_the_lines() {
    let s = scene(vec![], vec![(0.0, 12.0), (120.0, -25.0)], 3);
    let truth = vec![vec![[0.0, 112.0], [300.0, 112.0]], line_truth(120.0, -25.0)];
    let found = recover("two lines", &truth, &s);
    assert!(found.curves.is_empty(), "{:?}", found.curves);
    grid_zero_set("two lines", &truth, &found, true);
}

/// A node line (angle, offset) of the Line convention, clipped generously (dense() clips).
fn line_truth(angle_deg: f64, offset_mm: f64) -> Polyline {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let p = [SIZE[0] / 2.0 - s * offset_mm, SIZE[1] / 2.0 + c * offset_mm];
    let l = SIZE[0] + SIZE[1];
    vec![[p[0] - l * c, p[1] - l * s], [p[0] + l * c, p[1] + l * s]]
}

/// A 720×480 photo of lentils (4 mm disks, 10 px) in bands (σ = 5 mm) on the given nodes.
fn lentils(
    lines: Vec<(f64, f64)>,
    curves: Vec<Polyline>,
    seed: u64,
) -> (image::GrayImage, PhotoParams) {
    let s = Scene::lentils(lines, curves, seed);
    (render(&s), PhotoParams { grain_px: 4.0 * 720.0 / 300.0, ..PhotoParams::default() })
}

/// The seeds a lentil test runs: `default`, or all of `LENTIL_SEEDS=first-last` (to re-measure
/// the docs' numbers over more photos).
fn seeds(default: std::ops::RangeInclusive<u64>) -> std::ops::RangeInclusive<u64> {
    std::env::var("LENTIL_SEEDS")
        .ok()
        .and_then(|v| {
            let (a, b) = v.split_once('-')?;
            Some(a.parse().ok()?..=b.parse().ok()?)
        })
        .unwrap_or(default)
}

/// Worst (angle °, offset mm) error of `found` against `truth`, one found line per true line.
fn line_errors(found: &[Line], truth: &[(f64, f64)]) -> (f64, f64) {
    truth.iter().fold((0.0f64, 0.0f64), |(wa, wo), &t| {
        let (da, dof) = found
            .iter()
            .map(|l| l.difference(t.0, t.1))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap_or((f64::INFINITY, f64::INFINITY));
        (wa.max(da), wo.max(dof))
    })
}

// The paper's lentils: two straight bands of 4 mm lentils. Measured over seeds 1–6: worst
// 1.9° and 1.0 mm (four run here, to keep the debug test short).
#[test]
fn lentil_lines_are_found_as_drawn() {
    let truth = [(90.0, 40.0), (20.0, -30.0)];
    for seed in seeds(1..=4) {
        let (img, p) = lentils(truth.to_vec(), vec![], seed);
        let found = find_lines(&img, SIZE, &p);
        let (da, dof) = line_errors(&found.lines, &truth);
        println!("seed {seed}: worst {da:.2}°, {dof:.2} mm; {} curves", found.curves.len());
        assert_eq!(found.lines.len(), 2, "seed {seed}: {:?}", found.lines);
        assert!(found.curves.is_empty(), "seed {seed}: {:?}", found.curves);
        assert!(da < 2.5 && dof < 2.0, "seed {seed}: {da}° {dof} mm");
    }
}

// A quarter circle of lentils is traced as one curve (seeds 1–6: 5 of 6; seed 4 splits it in
// two pieces), close to the drawn arc (mean ≤ 2.0 mm, max ≤ 9.6 mm at a traced end); a
// plate with only stray lentils has no node.
#[test]
fn lentil_arc_is_one_curve_and_a_blank_plate_has_none() {
    let arc_nodes = vec![arc([0.0, 0.0], 130.0, 0.0, 90.0, 90)];
    let mut whole = 0;
    let runs = seeds(1..=4);
    let n = runs.clone().count();
    for seed in runs {
        let (img, p) = lentils(vec![], arc_nodes.clone(), seed);
        let found = find_lines(&img, SIZE, &p);
        assert!(found.lines.is_empty(), "seed {seed}: {:?}", found.lines);
        let got: Vec<Polyline> = found.curves.iter().map(|c| c.points.clone()).collect();
        let (mean, max) = spread(&got, &arc_nodes);
        println!("seed {seed}: {} curves, found→arc mean {mean:.2} mm max {max:.2} mm", got.len());
        assert!(!got.is_empty() && mean < 3.0 && max < 12.0, "seed {seed}: {mean} {max}");
        whole += usize::from(got.len() == 1 && found.curves[0].length_mm > 180.0);
        if seed <= 2 {
            let (blank, p) = lentils(vec![], vec![], seed);
            let none = find_lines(&blank, SIZE, &p);
            assert!(none.lines.is_empty() && none.curves.is_empty(), "seed {seed}: blank plate");
        }
    }
    assert!(whole + 1 >= n, "the arc was one whole curve in {whole} of {n} photos");
}

// The hard case: the arc crosses the vertical band at 32°, where its lentils pull that line.
// Seeds 1–6: worst 2.3° and 2.1 mm (seed 5); a piece of the arc is found (the lines cut it),
// mean ≤ 2.2 mm and max ≤ 7.6 mm from it. Seeds 3–5 run here.
#[test]
fn lentil_lines_crossed_by_an_arc() {
    let truth = [(90.0, 40.0), (20.0, -30.0)];
    let arc_nodes = vec![arc([0.0, 0.0], 130.0, 0.0, 90.0, 90)];
    for seed in seeds(3..=5) {
        let (img, p) = lentils(truth.to_vec(), arc_nodes.clone(), seed);
        let found = find_lines(&img, SIZE, &p);
        let (da, dof) = line_errors(&found.lines, &truth);
        let got: Vec<Polyline> = found.curves.iter().map(|c| c.points.clone()).collect();
        let (mean, max) = spread(&got, &arc_nodes);
        println!(
            "seed {seed}: worst {da:.2}°, {dof:.2} mm; arc pieces mean {mean:.2} max {max:.2} mm"
        );
        assert_eq!(found.lines.len(), 2, "seed {seed}: {:?}", found.lines);
        assert!(da < 3.0 && dof < 3.0, "seed {seed}: {da}° {dof} mm");
        assert!(!got.is_empty() && mean < 3.0 && max < 10.0, "seed {seed}: {mean} {max}");
    }
}
