//! The measurement behind the planner's margins from evidence (docs/plan.md, "Margins from
//! evidence"): per plate × part × mode, how far the step map's basin boundaries move
//!
//! - grid modes: with the grid resampled to half its resolution ([`margin::coarse_grid`]; the
//!   whole map made again, and the windowed runs that `--margin-deg auto` makes,
//!   [`margin::windowed_spread`]) and to twice it, and without the rim (`edge = "open"`);
//! - straight-node modes: the dynamic map (approach from both sides simulated) against the
//!   static one;
//! - curved nodes and straight nodes along an edge (simulated maps): without the rim;
//!
//! as the spread ([`margin::boundary_spread`]: the farthest boundary of either map from the
//! other's nearest; `appears` when one map has boundaries and the other none), with the margin
//! `auto` sets and the time of the mode's map and of the resampled one.
//!
//! `cargo bench -p chladni --bench margin_evidence` (release; prints a markdown table).
//! Filters, comma-separated substrings: `CHLADNI_MARGIN_PLATES=cantilever`,
//! `CHLADNI_MARGIN_PARTS=rectangle,gear`; `CHLADNI_MARGIN_STARTS=90` (start orientations per
//! simulated map, the planner's default). A debug run (`cargo test -p chladni --bench
//! margin_evidence`) takes minutes per plate and part.

use std::path::{Path, PathBuf};
use std::time::Instant;

use chladni_core::model::part::Part;
use chladni_core::model::plate::{Edge, Mode, Node, PlateModel};
use chladni_core::motion::body::Body;
use chladni_core::planner::margin::{self, boundary_spread};
use chladni_core::planner::mode_margin::MarginSource;
use chladni_core::planner::{self, Backend, DynSettings, MapCache, StepMap, sampled_map};

/// The plates measured: the solver's own modes of the three example plates and the hand-made
/// example plates.
const PLATES: [&str; 7] = [
    "examples/plates/cantilever-6-modes.toml",
    "examples/plates/free-6-modes.toml",
    "examples/plates/hinged-rod-6-modes.toml",
    "examples/plates/four-lines.toml",
    "examples/plates/six-lines.toml",
    "examples/plates/hyperbola.toml",
    "examples/plates/cantilever-solver.toml",
];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The comma-separated substrings of `var` (empty: everything).
fn filter(var: &str) -> Vec<String> {
    std::env::var(var)
        .map(|v| v.split(',').map(str::trim).filter(|s| !s.is_empty()).map(String::from).collect())
        .unwrap_or_default()
}

fn wanted(name: &str, f: &[String]) -> bool {
    f.is_empty() || f.iter().any(|s| name.contains(s.as_str()))
}

/// The example parts and the ordinary parts.
fn parts() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["examples/parts", "examples/parts/ordinary"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(root().join(dir))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "json"))
            .collect();
        files.sort();
        v.extend(files);
    }
    v
}

/// `12.34°`, or `appears` for an infinite spread.
fn deg(x: f64) -> String {
    if x.is_finite() { format!("{x:.2}°") } else { "appears".into() }
}

/// The map of `mode` simulated with `n` start orientations, and its time (s).
fn timed(body: &Body, mode: &Mode, plate: &PlateModel, n: usize, period: f64) -> (StepMap, f64) {
    let t = Instant::now();
    let map = sampled_map(body, mode, plate, n, period);
    (map, t.elapsed().as_secs_f64())
}

/// One grid mode's row: the spreads with resampling and without the rim, the margin.
fn grid_row(body: &Body, mode: &Mode, plate: &PlateModel, n: usize, period: f64) -> String {
    let Node::Grid(g) = &mode.node else { unreachable!() };
    let (base, t_base) = timed(body, mode, plate, n, period);
    let with = |g| Mode { node: Node::Grid(g), ..mode.clone() };
    let coarse = margin::coarse_grid(g);
    let dims = [coarse.nx, coarse.ny];
    let coarse_mode = with(coarse);
    let (c, _) = timed(body, &coarse_mode, plate, n, period);
    let t = Instant::now();
    let m = margin::grid_margin(body, mode, plate, n, period, &base).unwrap();
    let t_evidence = t.elapsed().as_secs_f64();
    let fine = margin::resample(g, 2 * g.nx - 1, 2 * g.ny - 1);
    let (f, _) = timed(body, &with(fine), plate, n, period);
    let open = PlateModel { edge: Edge::Open, ..plate.clone() };
    let (o, _) = timed(body, mode, &open, n, period);
    let s = boundary_spread(&base.boundaries, &c.boundaries);
    let windowed = match m.source {
        MarginSource::Resampled { spread_deg, .. } => deg(spread_deg),
        _ => "—".into(),
    };
    format!(
        "grid {}×{} {}×{} | {} | {} / {windowed} | {} | {} | — | {:.2}° | {:.1} s + {:.1} s",
        g.nx,
        g.ny,
        dims[0],
        dims[1],
        base.boundaries.len(),
        deg(s),
        deg(boundary_spread(&base.boundaries, &f.boundaries)),
        deg(boundary_spread(&base.boundaries, &o.boundaries)),
        m.deg,
        t_base,
        t_evidence
    )
}

/// One straight-node mode's row: static against dynamic boundaries (or, for a node the part
/// cannot rest across, the simulated map with and without the rim).
fn line_row(part: &Part, body: &Body, mode: &Mode, plate: &PlateModel, n: usize, p: f64) -> String {
    if planner::rim_line(body.radius, mode, plate) {
        return simulated_row("line on the rim", body, mode, plate, n, p);
    }
    let t = Instant::now();
    let Ok(st) = planner::line_map(part, mode, Backend::Fixed) else {
        return "line | refused | | | | | | | ".into();
    };
    let t_static = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let dynamic =
        MapCache::global().line_map(part, mode, plate, p, Backend::Fixed, DynSettings::default());
    let t_dyn = t.elapsed().as_secs_f64();
    let spread = dynamic.map_or(f64::NAN, |d| boundary_spread(&st.boundaries, &d.boundaries));
    format!(
        "line | {} | — | — | — | {} | 3° (default) | {t_static:.2} s + {t_dyn:.1} s",
        st.boundaries.len(),
        deg(spread)
    )
}

/// A simulated map without a grid: with and without the rim.
fn simulated_row(
    kind: &str,
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    n: usize,
    p: f64,
) -> String {
    let (base, t_base) = timed(body, mode, plate, n, p);
    let open = PlateModel { edge: Edge::Open, ..plate.clone() };
    let (o, _) = timed(body, mode, &open, n, p);
    format!(
        "{kind} | {} | — | — | {} | — | 3° (default) | {t_base:.1} s",
        base.boundaries.len(),
        deg(boundary_spread(&base.boundaries, &o.boundaries))
    )
}

fn main() {
    let (plates, parts_f) = (filter("CHLADNI_MARGIN_PLATES"), filter("CHLADNI_MARGIN_PARTS"));
    let n: usize =
        std::env::var("CHLADNI_MARGIN_STARTS").ok().and_then(|v| v.parse().ok()).unwrap_or(90);
    println!(
        "| plate | part | mode | node (grid, resampled) | boundaries | spread, grid / 2 (map / \
         windowed) | spread, grid × 2 | spread, no rim | spread, dynamic | margin (auto) | map \
         time + evidence time |"
    );
    println!("|---|---|---|---|---:|---:|---:|---:|---:|---:|---|");
    for plate_path in PLATES.iter().filter(|p| wanted(p, &plates)) {
        let plate = PlateModel::load(&root().join(plate_path)).unwrap();
        let short = Path::new(plate_path).file_stem().unwrap().to_string_lossy().to_string();
        for part_path in parts().iter().filter(|p| wanted(&p.to_string_lossy(), &parts_f)) {
            let part = Part::load(part_path).unwrap();
            let body = Body::with_samples(&part, chladni_core::motion::body::PLANNER_BODY_SAMPLES);
            let period = planner::plan_period(&part, &plate);
            for (k, mode) in plate.modes.iter().enumerate() {
                let row = match mode.node {
                    Node::Grid(_) => grid_row(&body, mode, &plate, n, period),
                    Node::Line { .. } => line_row(&part, &body, mode, &plate, n, period),
                    _ => simulated_row(mode.node.kind(), &body, mode, &plate, n, period),
                };
                println!("| {short} | {} | {} | {row} |", part.name, k + 1);
            }
        }
    }
}
