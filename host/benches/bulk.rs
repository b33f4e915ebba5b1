//! Parts in contact (docs/motion.md, "Bulk feeding"): the cost of one run of the triangle's
//! example plan on the four-lines plate for one part alone (the single-part path) and for 10
//! copies dropped together with contacts, and the bulk numbers of 10 copies over 5 drops
//! (oriented fraction, parts per minute), printed once before the timings.
//!
//! `cargo bench -p chladni-host --bench bulk -- --warm-up-time 1 --measurement-time 5`

use std::hint::black_box;
use std::path::Path;

use chladni::model::part::Part;
use chladni::model::plan_file::PlanFile;
use chladni::model::plate::PlateModel;
use chladni::motion::body::Body;
use chladni::motion::bulk::{BulkReport, Drop, run_drops};
use chladni::motion::field::FieldModel;
use chladni::motion::shape::Pieces;
use chladni::motion::sim::plan_steps;
use criterion::{Criterion, criterion_group, criterion_main};

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let part = Part::load(&root.join("examples/parts/triangle.json")).expect("example part");
    let plate = PlateModel::load(&root.join("examples/plates/four-lines.toml")).unwrap();
    let text =
        std::fs::read_to_string(root.join("examples/plans/triangle-four-lines.json")).unwrap();
    let plan = PlanFile::parse(&text).expect("example plan");
    let steps = plan_steps(&plan, &plate).expect("the example plan runs on its plate");
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let body = Body::new(&part);
    let pieces = Pieces::of(&body);
    let drop = |n: usize| (vec![&body; n], vec![&pieces; n]);
    let (b10, p10) = drop(10);
    let d10 = Drop {
        bodies: &b10,
        pieces: &p10,
        plate: &plate,
        fields: &fields,
        steps: &steps,
        feed: None,
    };
    let drops = run_drops(&d10, 5, 1, || ()).expect("10 triangles fit");
    let r = BulkReport::new(&drops, &plan, &steps, 1, 5.0);
    eprintln!(
        "bulk: 10 triangles on four-lines, 5 drops: oriented {:?}, {:?} parts/min, lost {}, overlap {} mm",
        r.oriented, r.parts_per_min, r.lost, r.max_overlap_mm
    );
    let (b1, p1) = drop(1);
    let d1 = Drop { bodies: &b1, pieces: &p1, ..d10 };
    let mut group = c.benchmark_group("bulk");
    group.sample_size(10);
    group.bench_function("triangle four-lines, 1 part, one plan run", |b| {
        b.iter(|| run_drops(black_box(&d1), 1, 1, || ()).map(|d| d.max_overlap_mm))
    });
    group.bench_function("triangle four-lines, 10 copies, one plan run", |b| {
        b.iter(|| run_drops(black_box(&d10), 1, 1, || ()).map(|d| d.max_overlap_mm))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
