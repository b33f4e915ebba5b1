//! Plan synthesis for a 64-vertex part on a plate with 12 straight-node modes
//! (`benches/data/`): step maps (shared fixed-point analysis), breadth-first search, dynamic
//! confirmation and simulated step durations (`plan`, the default static maps first; and with
//! the dynamic maps first), and maps + search alone (`search`); the dynamic straight-node
//! maps computed from scratch (`planner::dynamic`, 72 orientations, uncached) for one mode and
//! for all twelve. The plan and search benches reuse the process-wide map cache after their
//! first run (as a second `plan` call in one process would).
//!
//! `cargo bench -p chladni --bench plan -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::planner::{
    self, Backend, DynSettings, MapKind, PlanOptions, Problem, plan_period,
};
use criterion::{Criterion, criterion_group, criterion_main};

/// The bench's data (also timed as a whole command, docs/plan.md): an irregular 64-gon (an
/// ellipse with a few harmonics, no symmetry) and twelve straight nodes every 15°, laws and
/// gains varied.
fn data() -> (Part, PlateModel) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("benches/data");
    let part = Part::load(&dir.join("64-gon.json")).expect("benches/data/64-gon.json");
    let plate = PlateModel::load(&dir.join("twelve-lines.toml")).expect("twelve-lines.toml");
    (part, plate)
}

fn bench(c: &mut Criterion) {
    let (p, pl) = data();
    let opt = PlanOptions::default();
    let syn = planner::plan(&p, &pl, &opt).expect("the bench plate has a plan");
    eprintln!(
        "64-gon, 12 modes: {} steps, final {:.3}° (mod {}°)",
        syn.steps.len(),
        syn.final_orientation_deg,
        syn.period_deg
    );
    let mut group = c.benchmark_group("plan");
    group.sample_size(10);
    group.bench_function("64-gon, 12 modes: plan (maps, search, durations)", |b| {
        b.iter(|| planner::plan(black_box(&p), black_box(&pl), &opt).unwrap())
    });
    let dynamic_first = PlanOptions { maps: MapKind::Dynamic, ..opt };
    group.bench_function("64-gon, 12 modes: plan, dynamic maps first (--maps dynamic)", |b| {
        b.iter(|| planner::plan(black_box(&p), black_box(&pl), &dynamic_first).unwrap())
    });
    let quick = PlanOptions { durations: false, ..opt };
    group.bench_function("64-gon, 12 modes: maps + search", |b| {
        b.iter(|| {
            Problem::new(black_box(&p), black_box(&pl), &quick).unwrap().search(&quick).unwrap()
        })
    });
    let st = PlanOptions { maps: MapKind::Static, ..quick };
    group.bench_function("64-gon, 12 modes: static maps + search", |b| {
        b.iter(|| Problem::new(black_box(&p), black_box(&pl), &st).unwrap().search(&st).unwrap())
    });
    let period = plan_period(&p, &pl);
    let dynamic = |k: usize| {
        planner::dynamic::dynamic_line_map(
            black_box(&p),
            &pl.modes[k],
            &pl,
            period,
            Backend::Fixed,
            DynSettings::default(),
        )
        .unwrap()
    };
    group.bench_function("64-gon: one dynamic map (sign law, uncached)", |b| b.iter(|| dynamic(0)));
    group.bench_function("64-gon: one dynamic map (linear law, uncached)", |b| {
        b.iter(|| dynamic(2))
    });
    group.bench_function("64-gon, 12 modes: dynamic maps (uncached)", |b| {
        b.iter(|| (0..pl.modes.len()).map(dynamic).collect::<Vec<_>>())
    });
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF plots need a system font.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
