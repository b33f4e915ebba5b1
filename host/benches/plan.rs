//! Plan synthesis for a 64-vertex part on a plate with 12 straight-node modes: step maps
//! (shared fixed-point analysis), breadth-first search, dynamic confirmation and simulated
//! step durations (`plan`), and maps + search alone (`search`); the dynamic straight-node
//! maps computed from scratch (`planner::dynamic`, 72 orientations, uncached) for one mode and
//! for all twelve. The plan and search benches reuse the process-wide map cache after their
//! first run (as a second `plan` call in one process would).
//!
//! `cargo bench -p chladni-host --bench plan -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use chladni::model::part::Part;
use chladni::model::plate::PlateModel;
use chladni::model::plate_file::PlateFile;
use chladni::planner::{self, Backend, DynSettings, MapKind, PlanOptions, Problem, plan_period};
use criterion::{Criterion, criterion_group, criterion_main};

/// An irregular 64-gon (an ellipse with a few harmonics): no symmetry.
fn part() -> Part {
    let n = 64;
    let outline = (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let r = 1.0 + 0.15 * (3.0 * a).cos() + 0.05 * (2.0 * a + 0.4).sin();
            [30.0 * r * a.cos() + 5.0, 18.0 * r * a.sin() - 3.0]
        })
        .collect();
    Part::new("64-gon".into(), outline, vec![]).unwrap()
}

/// Twelve straight nodes every 15°, laws and gains varied.
fn plate() -> PlateModel {
    let mut text = String::from("[plate]\nname = \"bench\"\nsize_mm = [300.0, 200.0]\n");
    for i in 0..12 {
        let law = if i % 3 == 2 { "linear" } else { "sign" };
        let gains = if i % 2 == 1 { "gain_left = 1.0\ngain_right = 2.0\n" } else { "" };
        text += &format!(
            "[[mode]]\nfreq_hz = {}.0\nfield = \"{law}\"\n{gains}node = {{ kind = \"line\", angle_deg = {}.0, offset_mm = {}.0 }}\n",
            40 + 10 * i,
            15 * i,
            (i - 6) * 5
        );
    }
    PlateModel::from_file(&PlateFile::parse(&text, "bench").unwrap()).unwrap()
}

fn bench(c: &mut Criterion) {
    let (p, pl) = (part(), plate());
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
