//! Parts in contact (docs/motion.md, "Bulk feeding"): the cost of one plan run for one part
//! alone (the single-part path) and for 10 copies dropped together with contacts, and the
//! bulk numbers of 10 copies over 5 drops (oriented fraction, parts per minute), printed once
//! before the timings. Two cases:
//! - the triangle's example plan on the four-lines plate (examples/plans/triangle-four-lines.json);
//! - an ordinary part on a solver plate: the rectangle on examples/plates/hinged-rod-solver.toml,
//!   planned here by the planner with its default options (no example plan file exists for it).
//!
//! `cargo bench -p chladni --bench bulk -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use chladni_core::motion::bulk::{BulkReport, run_drops};
use chladni_core::planner::{self, PlanOptions};
use criterion::{Criterion, criterion_group, criterion_main};

#[path = "support/drop_case.rs"]
mod drop_case;
#[path = "../tests/integration/support/examples.rs"]
mod examples;

use drop_case::DropCase;

/// Drops per bulk number.
const DROPS: u32 = 5;

/// Prints the bulk numbers of `n` copies of `case` over [`DROPS`] drops, seed 1.
fn report(case: &DropCase, n: usize) {
    let (b, p) = (vec![&case.body; n], vec![&case.pieces; n]);
    let d = case.drop(&b, &p);
    let t = std::time::Instant::now();
    let drops = run_drops(&d, DROPS, 1, &chladni_core::progress::Silent).expect("the copies fit");
    let wall = t.elapsed().as_secs_f64();
    let r = BulkReport::new(&drops, &case.plan, &case.steps, 1, 5.0);
    eprintln!(
        "bulk: {n} × {}, {DROPS} drops (plan {:.2} s): oriented {:?}, {:?} parts/min, lost {}, \
         deepest overlap {} mm, {:.2} s wall per drop",
        case.name,
        r.plan_s,
        r.oriented,
        r.parts_per_min,
        r.lost,
        r.max_overlap_mm,
        wall / f64::from(DROPS)
    );
}

/// The rectangle planned on the hinged-rod solver plate.
fn solver_case() -> DropCase {
    let part = examples::part("rectangle.json");
    let plate = examples::plate("hinged-rod-solver.toml");
    let syn = planner::plan(&part, &plate, &PlanOptions::default())
        .unwrap_or_else(|e| panic!("the rectangle gets no plan on hinged-rod-solver: {e}"));
    let plan = syn.to_file(&plate, &part.name);
    DropCase::new("rectangle on hinged-rod-solver", part, plate, plan)
}

fn bench(c: &mut Criterion) {
    let cases = [DropCase::triangle_four_lines(), solver_case()];
    for case in &cases {
        report(case, 10);
    }
    let mut group = c.benchmark_group("bulk");
    group.sample_size(10);
    for case in &cases {
        for n in [1, 10] {
            let (b, p) = (vec![&case.body; n], vec![&case.pieces; n]);
            let d = case.drop(&b, &p);
            group.bench_function(format!("{}, {n} copies, one plan run", case.name), |bch| {
                bch.iter(|| {
                    run_drops(black_box(&d), 1, 1, &chladni_core::progress::Silent)
                        .map(|d| d.max_overlap_mm)
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
