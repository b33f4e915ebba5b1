//! Planning time on solver-made modes: every row of the feed-region table in docs/plan.md,
//! plus orientation-set plans on hyperbola and grid modes.
//!
//! The plates in `benches/data/` were written by `chladni plate modes examples/plate-free.toml
//! --count 4|6 --write-modes` and `chladni plate modes examples/plate-hinged-rod.toml --count 4
//! --write-modes` with the forced rocking mode removed (elastic modes only).
//!
//! `cargo bench -p chladni --bench feed -- --warm-up-time 1 --measurement-time 3`
//! (a few minutes; one row: add its name as a filter, e.g. `-- "free 6, L-shape"`).

use std::hint::black_box;
use std::path::{Path, PathBuf};

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::planner::feed::FeedRegion;
use chladni_core::planner::{self, PlanOptions};
use criterion::{Criterion, criterion_group, criterion_main};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn plate(name: &str) -> PlateModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/data").join(name);
    PlateModel::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn part(name: &str) -> Part {
    let path = root().join("examples/parts").join(name);
    Part::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The docs/plan.md feed-region table: (plate file, part, region, plan expected).
const ROWS: &[(&str, &str, [f64; 4], bool)] = &[
    ("free-4-modes.toml", "rectangle.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-4-modes.toml", "triangle.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-4-modes.toml", "trapezoid.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-4-modes.toml", "l-shape.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-4-modes.toml", "triangle.json", [200.0, 120.0, 240.0, 160.0], true),
    ("free-4-modes.toml", "triangle.json", [130.0, 80.0, 170.0, 120.0], false),
    ("free-4-modes.toml", "trapezoid.json", [130.0, 80.0, 170.0, 120.0], false),
    ("free-4-modes.toml", "l-shape.json", [130.0, 80.0, 170.0, 120.0], false),
    ("free-6-modes.toml", "triangle.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-6-modes.toml", "trapezoid.json", [60.0, 40.0, 100.0, 80.0], true),
    ("free-6-modes.toml", "l-shape.json", [60.0, 40.0, 100.0, 80.0], true),
    ("hinged-rod-4-elastic.toml", "rectangle.json", [60.0, 40.0, 100.0, 80.0], true),
    ("hinged-rod-4-elastic.toml", "triangle.json", [60.0, 40.0, 100.0, 80.0], false),
    ("hinged-rod-4-elastic.toml", "trapezoid.json", [60.0, 40.0, 100.0, 80.0], false),
    ("hinged-rod-4-elastic.toml", "l-shape.json", [60.0, 40.0, 100.0, 80.0], false),
];

fn feed(c: &mut Criterion) {
    let mut group = c.benchmark_group("feed plan");
    group.sample_size(10);
    for &(plate_file, part_file, r, expect) in ROWS {
        let (pl, p) = (plate(plate_file), part(part_file));
        let region = FeedRegion::new(r, &pl).unwrap();
        let opt = PlanOptions { feed: Some(region), ..Default::default() };
        let got = planner::plan(&p, &pl, &opt);
        assert_eq!(got.is_ok(), expect, "{plate_file} {part_file} {r:?}: {got:?}");
        let name = format!(
            "{}, {}, {} {} {} {}",
            plate_file.trim_end_matches(".toml"),
            part_file.split('.').next().unwrap_or(part_file),
            r[0],
            r[1],
            r[2],
            r[3]
        );
        group.bench_function(name, |b| b.iter(|| planner::plan(black_box(&p), &pl, &opt)));
    }
    group.finish();
}

/// Orientation-set plans on curved and grid nodes (simulated maps, settle times).
fn orientation_sets(c: &mut Criterion) {
    let mut group = c.benchmark_group("orientation-set plan");
    group.sample_size(10);
    let cases = [
        ("hyperbola.toml", "triangle.json"),
        ("hyperbola.toml", "rectangle.json"),
        ("cantilever-solver.toml", "rectangle.json"),
        ("hinged-rod-solver.toml", "rectangle.json"),
    ];
    for (plate_file, part_file) in cases {
        let path = root().join("examples/plates").join(plate_file);
        let pl = PlateModel::load(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let p = part(part_file);
        let opt = PlanOptions::default();
        planner::plan(&p, &pl, &opt).unwrap_or_else(|e| panic!("{plate_file} {part_file}: {e}"));
        let name = format!("{}, {}", plate_file.trim_end_matches(".toml"), part_file);
        group.bench_function(name, |b| b.iter(|| planner::plan(black_box(&p), &pl, &opt)));
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF plots need a system font.
    config = Criterion::default().without_plots();
    targets = feed, orientation_sets
}
criterion_main!(benches);
