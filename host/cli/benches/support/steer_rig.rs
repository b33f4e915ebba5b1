//! The rig the steering benches (`steer`, `present`, `learned_plans`) share: the given plate,
//! the way a true plate departs from it, and the bursts learning records on it (compiled into
//! each through `#[path]`).
#![allow(dead_code)]

use std::path::Path;

use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::rng::Rng;
use chladni_core::steer::cost::Piece;
use chladni_core::steer::policy::{LearnStep, Rules, next_learning_step};
use chladni_core::steer::sim::Truth;
use chladni_core::steer::{Burst, Correction, Corrector, Menu, Model};

/// The given plate's settle speed (mm/s). With the true factors of ×0.4–×2.5, parts cross
/// 100 mm in the 3–10 s of the rig (measured by the steer bench's `speed` section).
pub const SPEED_MM_S: f64 = 120.0;

/// The free plate's first 12 solver modes (`examples/plates/free-12-modes.toml`), at
/// [`SPEED_MM_S`].
pub fn twelve_modes(root: &Path) -> PlateModel {
    let mut plate = PlateModel::load(&root.join("examples/plates/free-12-modes.toml"))
        .expect("the example plate loads");
    assert_eq!(plate.modes.len(), 12, "12 modes");
    for m in &mut plate.modes {
        m.speed_mm_s = SPEED_MM_S;
    }
    plate
}

/// A true correction per mode: a shift of 4–8 mm in a random direction, a factor
/// log-uniform in ×0.4–×2.5.
pub fn true_corrections(rng: &mut Rng, n: usize) -> Vec<Correction> {
    true_corrections_in(rng, n, (0.4, 2.5))
}

/// [`true_corrections`] with the factor log-uniform in `factors` (low, high).
pub fn true_corrections_in(rng: &mut Rng, n: usize, factors: (f64, f64)) -> Vec<Correction> {
    (0..n)
        .map(|_| {
            let (r, a) = (rng.range(4.0, 8.0), rng.range(0.0, std::f64::consts::TAU));
            let speed_factor = rng.range(factors.0.ln(), factors.1.ln()).exp();
            Correction { shift_mm: [r * a.cos(), r * a.sin()], speed_factor }
        })
        .collect()
}

/// Bursts recorded by the learning policy until each mode has `per_mode`.
/// The policy's predictions come from a model corrected online from the recorded bursts (as
/// the steering loop corrects its own), so later bursts and recoveries are chosen on a
/// plate closer to the true one; the fit itself starts from the given plate.
pub fn record(
    truth: &mut Truth,
    model: &mut Model,
    pieces: &[Piece],
    per_mode: usize,
) -> (Vec<Burst>, f64, usize) {
    let menu = Menu {
        bursts_s: vec![0.05, 0.1, 0.2, 0.4, 0.7, 1.0, 1.5],
        lookahead: 0,
        to_go_mm_per_s: None,
    };
    let mut corrector = Corrector::new(model.mode_count());
    let rules = Rules::default();
    let mut poses: Vec<Pose> = pieces.iter().map(|p| truth.random_pose(&p.body, 10.0)).collect();
    let mut counts = vec![0usize; model.mode_count()];
    let (mut bursts, mut drive_s, mut recovers) = (Vec::new(), 0.0, 0);
    while counts.iter().any(|c| *c < per_mode) && drive_s < 3600.0 {
        let parts: Vec<(&Piece, Pose)> = pieces.iter().zip(&poses).map(|(p, q)| (p, *q)).collect();
        let bodies: Vec<(&Body, Pose)> = parts.iter().map(|(p, q)| (&p.body, *q)).collect();
        let (mode, burst_s, recorded) =
            match next_learning_step(model, &parts, &counts, &menu, &rules).unwrap() {
                LearnStep::Burst { mode, burst_s } => (mode, burst_s, true),
                LearnStep::Recover(cmd) => (cmd.mode, cmd.burst_s, false),
            };
        let after = truth.burst(&bodies, mode, burst_s).unwrap();
        if recorded {
            counts[mode] += 1;
            let seen =
                poses.iter().zip(&after).enumerate().map(|(i, (b, a))| (i, *b, *a)).collect();
            let burst = Burst { mode, burst_s, parts: seen };
            corrector.observe(model, pieces, burst.clone()).unwrap();
            bursts.push(burst);
        } else {
            recovers += 1;
        }
        drive_s += burst_s;
        poses = after;
    }
    (bursts, drive_s, recovers)
}
