//! The rig the steering benches (`steer`, `present`, `learned_plans`) share: the given plate
//! and the way a true plate departs from it (compiled into each through `#[path]`).
#![allow(dead_code)]

use std::path::Path;

use chladni_core::model::plate::PlateModel;
use chladni_core::rng::Rng;
use chladni_core::steer::Correction;

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
