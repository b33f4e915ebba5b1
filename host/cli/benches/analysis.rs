//! Full rest analysis (`Analyzer::new` + `analyze`) versus vertex count, sign and linear
//! fields. Parts: smooth non-symmetric "blobs" (an ellipse with a few harmonics), so the
//! rest count does not change with n and the timing shows the per-vertex cost.
//!
//! `cargo bench -p chladni --bench analysis -- --warm-up-time 1 --measurement-time 2`

use std::hint::black_box;

use chladni_shared::analysis::field::{Field, FieldKind};
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::Analyzer;
use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};

fn blob(n: usize) -> Vec<Pt> {
    (0..n)
        .map(|i| {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let r = 1.0 + 0.15 * (3.0 * a).cos() + 0.05 * (2.0 * a + 0.4).sin();
            let (x, y) = (30.0 * r * a.cos() + 5.0, 18.0 * r * a.sin() - 3.0);
            Pt::new(Fx::from_f64(x), Fx::from_f64(y))
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("analysis");
    group.sample_size(10);
    for n in [8usize, 100, 1_000, 10_000] {
        let ring = blob(n);
        let rings: [&[Pt]; 1] = [&ring];
        for (name, kind) in [("sign", FieldKind::Sign), ("linear", FieldKind::Linear)] {
            group.bench_with_input(BenchmarkId::new(name, n), &rings, |b, rings| {
                b.iter(|| {
                    let an = Analyzer::new(black_box(rings), Field::symmetric(kind)).unwrap();
                    black_box(an.analyze().unwrap())
                })
            });
        }
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // Criterion's own charts would need system fonts; the numbers are what we want.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
