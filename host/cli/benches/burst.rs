//! Predicting a burst: where each part is after each mode driven for each burst length, the
//! question a closed-loop controller asks every camera cycle (issue budget: 12 modes × 8 burst
//! lengths × 3 parts within 20 ms, one camera cycle). One iteration is all 288 runs, from one
//! pose per part near the plate's middle, inside the plate's rim, by the fast grid wrench and by
//! the reference rule.
//!
//! The modes: the free plate's first 12 solver modes (`examples/plates/free-12-modes.toml`).
//! `cargo bench -p chladni --bench burst -- --warm-up-time 1 --measurement-time 5`.

use std::path::Path;

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::{Body, PLANNER_BODY_SAMPLES};
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::{SimParams, run};
use criterion::{Criterion, criterion_group, criterion_main};

/// Burst lengths (s): at the plate file's 10 mm/s a part crosses 100 mm in about 10 s.
const BURSTS: [f64; 8] = [0.1, 0.2, 0.35, 0.5, 0.75, 1.0, 1.5, 2.0];

/// The parts, each with its start pose.
const PARTS: [(&str, Pose); 3] = [
    ("examples/parts/ordinary/tee-plate.json", Pose { x: 120.0, y: 90.0, theta: 0.4 }),
    ("examples/parts/ordinary/hex-key.json", Pose { x: 170.0, y: 110.0, theta: 1.3 }),
    ("examples/parts/ordinary/keyed-gear.json", Pose { x: 150.0, y: 70.0, theta: 2.2 }),
];

/// The free plate's first 12 solver modes (`examples/plates/free-12-modes.toml`, written by
/// `chladni plate modes`) at 10 mm/s, the speed this bench's numbers were first measured at.
fn twelve_modes(root: &Path) -> PlateModel {
    let mut plate = PlateModel::load(&root.join("examples/plates/free-12-modes.toml"))
        .expect("the example plate loads");
    assert_eq!(plate.modes.len(), 12, "12 modes");
    for m in &mut plate.modes {
        m.speed_mm_s = 10.0;
    }
    plate
}

/// Every (part, mode, burst) prediction; the sum of the end orientations (kept alive).
fn predict(plate: &PlateModel, fields: &[FieldModel], bodies: &[(Body, Pose)]) -> f64 {
    let mut sum = 0.0;
    for (body, start) in bodies {
        for (mode, field) in plate.modes.iter().zip(fields) {
            for burst in BURSTS {
                sum += run(body, field, SimParams::under(mode, plate, burst), *start).pose.theta;
            }
        }
    }
    sum
}

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let plate = twelve_modes(&root);
    let fast: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
    let reference: Vec<FieldModel> = fast.iter().map(|f| f.clone().reference()).collect();
    let bodies: Vec<(Body, Pose)> = PARTS
        .iter()
        .map(|(path, start)| {
            let part = Part::load(&root.join(path)).expect("the part loads");
            (Body::with_samples(&part, PLANNER_BODY_SAMPLES), *start)
        })
        .collect();
    let mut group = c.benchmark_group("burst prediction");
    group.sample_size(20);
    for (rule, fields) in [("fast", &fast), ("reference", &reference)] {
        let name = format!("3 parts x 12 modes x 8 bursts, {rule}");
        group.bench_function(name, |b| b.iter(|| predict(&plate, fields, &bodies)));
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
