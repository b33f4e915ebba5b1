//! The plate's rim in the Monte Carlo check: 1000 trials of the triangle's example plan on the
//! four-lines plate (examples/plans/triangle-four-lines.json), with the rim (`edge = "wall"`,
//! the default) and without one (the unbounded plane of the model before the rim), same
//! starts. docs/motion.md records the numbers.
//!
//! `cargo bench -p chladni --bench montecarlo -- --warm-up-time 1 --measurement-time 5`
//! on an idle machine; the ratio "with the rim" / "without the rim" of the two cases' times is
//! the rim's cost (the target: at most 2×).

use std::hint::black_box;
use std::path::Path;

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::{DEFAULT_FRICTION, PlateModel};
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::contact::Rim;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::{SimParams, run};
use chladni_core::motion::montecarlo::random_pose;
use chladni_core::motion::steps::plan_steps;
use chladni_core::rng::Rng;
use criterion::{Criterion, criterion_group, criterion_main};

/// Runs `n` trials of the plan's steps from seeded random starts; `rim` as given.
fn trials(body: &Body, plate: &PlateModel, plan: &PlanFile, n: usize, rim: Option<Rim>) -> f64 {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps = plan_steps(plan, plate).expect("the example plan runs on its plate");
    let mut rng = Rng::seeded(1);
    let mut sum = 0.0;
    for _ in 0..n {
        let mut pose: Pose = random_pose(&mut rng, body, plate, None);
        for s in &steps {
            let mode = &plate.modes[s.mode];
            let p = SimParams {
                speed: mode.speed_mm_s * s.amplitude_ratio * s.amplitude_ratio,
                t_limit: s.duration_s,
                run_to_limit: true,
                rim,
            };
            pose = run(body, &fields[s.mode], p, pose).pose;
        }
        sum += pose.theta;
    }
    sum
}

fn bench(c: &mut Criterion) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let part = Part::load(&root.join("examples/parts/triangle.json")).expect("example part");
    let plate = PlateModel::load(&root.join("examples/plates/four-lines.toml")).unwrap();
    let text =
        std::fs::read_to_string(root.join("examples/plans/triangle-four-lines.json")).unwrap();
    let plan = PlanFile::parse(&text).expect("example plan");
    let body = Body::new(&part);
    let wall = Rim::of(&plate);
    assert_eq!(wall.friction, DEFAULT_FRICTION);
    let mut group = c.benchmark_group("montecarlo");
    group.sample_size(10);
    group.bench_function("triangle four-lines, 1000 trials, without the rim", |b| {
        b.iter(|| trials(black_box(&body), &plate, &plan, 1000, None))
    });
    group.bench_function("triangle four-lines, 1000 trials, with the rim (wall)", |b| {
        b.iter(|| trials(black_box(&body), &plate, &plan, 1000, Some(wall)))
    });
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
