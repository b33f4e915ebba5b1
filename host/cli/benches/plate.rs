//! Plate physics (issue 6): the Rayleigh–Ritz mode solver, the photo pipeline on a straight
//! and a curved synthetic photo, the signed-distance grid from photo nodes, and one point of
//! the string model's averaged force.
//!
//! `cargo bench -p chladni --bench plate -- --warm-up-time 1 --measurement-time 3`

use std::hint::black_box;

use chladni_core::model::plate_file::PlateFile;
use chladni_core::motion::string::{self, StringParams};
use chladni_core::plate::contour::node_lines;
use chladni_core::plate::photo::synth::{Scene, render};
use chladni_core::plate::photo::{self, DEFAULT_SNAP, PhotoParams};
use chladni_core::plate::{node_field, solver};
use criterion::{Criterion, criterion_group, criterion_main};

fn plate(text: &str) -> chladni_core::model::plate_file::Plate {
    PlateFile::parse(text, "bench").unwrap().plate.mechanics().unwrap()
}

fn bench(c: &mut Criterion) {
    let cantilever = plate(include_str!("../../../examples/plate-cantilever.toml"));
    let free = plate(include_str!("../../../examples/plate-free.toml"));
    c.bench_function("solve cantilever, 14² terms, 6 modes", |b| {
        b.iter(|| solver::solve(black_box(&cantilever), 6, solver::DEFAULT_TERMS))
    });
    c.bench_function("solve free, 14² terms, 6 modes", |b| {
        b.iter(|| solver::solve(black_box(&free), 6, solver::DEFAULT_TERMS))
    });

    let straight = render(&Scene::standard(vec![(90.0, 40.0), (20.0, -30.0)], vec![], 7));
    let curves = node_lines(&solver::solve(&free, 5, 10).sample(4, 121, 81));
    let curved = render(&Scene::standard(vec![], curves, 7));
    let big = render(&Scene {
        px: (1200, 800),
        ..Scene::standard(vec![(90.0, 40.0), (20.0, -30.0)], vec![], 7)
    });
    let size = [300.0, 200.0];
    let p = PhotoParams::default();
    c.bench_function("photo 360×240, two lines", |b| {
        b.iter(|| photo::find_lines(black_box(&straight), size, &p))
    });
    c.bench_function("photo 360×240, free mode 5 (curves)", |b| {
        b.iter(|| photo::find_lines(black_box(&curved), size, &p))
    });
    c.bench_function("photo 1200×800, two lines", |b| {
        b.iter(|| photo::find_lines(black_box(&big), size, &p))
    });
    let nodes = photo::find_lines(&curved, size, &p).nodes(DEFAULT_SNAP);
    c.bench_function("signed-distance grid 121×81 from photo nodes", |b| {
        b.iter(|| node_field::node_field(black_box(&nodes), size, 121, 81))
    });

    let sp = StringParams::default();
    c.bench_function("string: averaged drift at one x (8 particles × 10 s)", |b| {
        b.iter(|| string::average_drift(black_box(&sp), 1.2, 10.0, 8))
    });
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF plots need a system font.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
