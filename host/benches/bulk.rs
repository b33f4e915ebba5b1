//! Parts in contact (docs/motion.md, "Bulk feeding"): the cost of one plan run for one part
//! alone (the single-part path) and for 10 copies dropped together with contacts, and the
//! bulk numbers of 10 copies over 5 drops (oriented fraction, parts per minute), printed once
//! before the timings. Two cases:
//! - the triangle's example plan on the four-lines plate (examples/plans/triangle-four-lines.json);
//! - an ordinary part on a solver plate: the rectangle on examples/plates/hinged-rod-solver.toml,
//!   planned here by the planner with its default options (no example plan file exists for it).
//!
//! `cargo bench -p chladni-host --bench bulk -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;

use chladni::model::part::Part;
use chladni::model::plan_file::PlanFile;
use chladni::model::plate::PlateModel;
use chladni::motion::body::Body;
use chladni::motion::bulk::{BulkReport, Drop, run_drops};
use chladni::motion::field::FieldModel;
use chladni::motion::shape::Pieces;
use chladni::motion::sim::{SimStep, plan_steps};
use chladni::planner::{self, PlanOptions};
use criterion::{Criterion, criterion_group, criterion_main};

#[path = "../tests/support/examples.rs"]
mod examples;

/// Drops per bulk number.
const DROPS: u32 = 5;

/// One case: a part, its plate and plan, and what a drop needs.
struct Case {
    name: &'static str,
    plate: PlateModel,
    plan: PlanFile,
    steps: Vec<SimStep>,
    fields: Vec<FieldModel>,
    body: Body,
    pieces: Pieces,
}

impl Case {
    fn new(name: &'static str, part: Part, plate: PlateModel, plan: PlanFile) -> Case {
        let steps = plan_steps(&plan, &plate).expect("the plan runs on its plate");
        let fields = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
        let body = Body::new(&part);
        let pieces = Pieces::of(&body);
        Case { name, plate, plan, steps, fields, body, pieces }
    }

    /// Prints the bulk numbers of `n` copies over [`DROPS`] drops, seed 1.
    fn report(&self, n: usize) {
        let (b, p) = (vec![&self.body; n], vec![&self.pieces; n]);
        let d = self.drop(&b, &p);
        let t = std::time::Instant::now();
        let drops = run_drops(&d, DROPS, 1, || ()).expect("the copies fit");
        let wall = t.elapsed().as_secs_f64();
        let r = BulkReport::new(&drops, &self.plan, &self.steps, 1, 5.0);
        eprintln!(
            "bulk: {n} × {}, {DROPS} drops (plan {:.2} s): oriented {:?}, {:?} parts/min, lost {}, \
             deepest overlap {} mm, {:.2} s wall per drop",
            self.name,
            r.plan_s,
            r.oriented,
            r.parts_per_min,
            r.lost,
            r.max_overlap_mm,
            wall / f64::from(DROPS)
        );
    }

    fn drop<'a>(&'a self, b: &'a [&'a Body], p: &'a [&'a Pieces]) -> Drop<'a> {
        Drop {
            bodies: b,
            pieces: p,
            plate: &self.plate,
            fields: &self.fields,
            steps: &self.steps,
            feed: None,
        }
    }
}

/// The rectangle planned on the hinged-rod solver plate.
fn solver_case() -> Case {
    let part = examples::part("rectangle.json");
    let plate = examples::plate("hinged-rod-solver.toml");
    let syn = planner::plan(&part, &plate, &PlanOptions::default())
        .unwrap_or_else(|e| panic!("the rectangle gets no plan on hinged-rod-solver: {e}"));
    let plan = syn.to_file(&plate, &part.name);
    Case::new("rectangle on hinged-rod-solver", part, plate, plan)
}

fn four_lines_case() -> Case {
    let path = examples::root().join("examples/plans/triangle-four-lines.json");
    let text = std::fs::read_to_string(path).expect("example plan");
    let plan = PlanFile::parse(&text).expect("example plan");
    let (part, plate) = (examples::part("triangle.json"), examples::plate("four-lines.toml"));
    Case::new("triangle on four-lines", part, plate, plan)
}

fn bench(c: &mut Criterion) {
    let cases = [four_lines_case(), solver_case()];
    for case in &cases {
        case.report(10);
    }
    let mut group = c.benchmark_group("bulk");
    group.sample_size(10);
    for case in &cases {
        for n in [1, 10] {
            let (b, p) = (vec![&case.body; n], vec![&case.pieces; n]);
            let d = case.drop(&b, &p);
            group.bench_function(format!("{}, {n} copies, one plan run", case.name), |bch| {
                bch.iter(|| run_drops(black_box(&d), 1, 1, || ()).map(|d| d.max_overlap_mm))
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
