//! The field wrench of a grid mode, the motion model's inner loop (about two per Heun step;
//! docs/plan.md, "Planning time"): criterion's time per call for parts of growing outline
//! length on the free plate's first solver mode (`examples/plates/free-6-modes.toml`), over
//! 64 poses spread across the plate (one iteration is all 64; the names give the edges), by
//! the motion model's fast rule and by the reference rule it is tested against.

use chladni_core::model::pose::Pose;
use chladni_core::model::{part::Part, plate::PlateModel};
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use criterion::{Criterion, criterion_group, criterion_main};

/// Parts from the smallest outline to the longest (paths from the host crate's folder).
const PARTS: [&str; 4] = [
    "../../examples/parts/rectangle.json",
    "../../examples/parts/ordinary/u-channel.json",
    "../../examples/parts/ordinary/tee-plate.json",
    "../../examples/parts/ordinary/keyed-gear.json",
];

fn bench(c: &mut Criterion) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let plate = PlateModel::load(&dir.join("../../examples/plates/free-6-modes.toml"))
        .expect("the free plate's solver modes load");
    let fast = FieldModel::new(&plate.modes[0], &plate);
    let reference = fast.clone().reference();
    // 64 poses on a golden-ratio spiral over the plate's interior, each turned differently.
    let poses: Vec<Pose> = (0..64)
        .map(|i| {
            let f = i as f64;
            Pose {
                x: 40.0 + (f * 0.618_034 % 1.0) * 220.0,
                y: 40.0 + (f * 0.414_214 % 1.0) * 120.0,
                theta: f * 0.77,
            }
        })
        .collect();
    let mut group = c.benchmark_group("grid wrench");
    for path in PARTS {
        let part = Part::load(&dir.join(path)).expect("the part loads");
        let body = Body::with_samples(&part, chladni_core::motion::body::PLANNER_BODY_SAMPLES);
        let edges: usize = body.rings.iter().map(Vec::len).sum();
        for (rule, field) in [("fast", &fast), ("reference", &reference)] {
            let name = format!("{} ({edges} edges), {rule}", part.name);
            group.bench_function(name, |b| {
                b.iter(|| poses.iter().map(|q| field.wrench(&body, *q).fx).sum::<f64>())
            });
        }
    }
    group.finish();
}

criterion_group! {
    name = benches;
    // No plots: criterion's PDF backend needs a system font this machine may lack.
    config = Criterion::default().without_plots();
    targets = bench
}
criterion_main!(benches);
