//! Learning a plate from recorded bursts: per mode, the [`Correction`] that best predicts
//! them, with held-out bursts to say how much better the learned plate predicts than the given
//! one; and the bursts to record (which mode, how long, when to bring the parts home first).
//!
//! The fit ([`crate::steer::fit`]) minimises the squared prediction error (mm, and degrees ×
//! [`crate::steer::cost::MM_PER_DEG`]) of the used bursts with a weak prior (spreads 30 mm and
//! ×10: it only conditions a mode whose bursts barely moved its parts), from the best of
//! several starts: the speed factor alone first (a scan of ×0.4–×2.5 at shift 0), then that
//! factor with shift 0 and ±5 mm along each axis; the start of least cost is refined.

use crate::model::plate::PlateModel;
use crate::steer::SteerError;
use crate::steer::correct::check_burst;
use crate::steer::cost::Piece;
use crate::steer::fit::{Burst, Prior, Problem};
use crate::steer::model::{Correction, Model};

/// How to learn.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LearnOptions {
    /// Every `hold_out_every`-th burst of each mode (the 4th, 8th, …) is held out of the fit
    /// and only scored; 0: none held out.
    pub hold_out_every: usize,
    /// Levenberg–Marquardt iterations per start.
    pub iterations: usize,
}

impl Default for LearnOptions {
    fn default() -> Self {
        LearnOptions { hold_out_every: 4, iterations: 12 }
    }
}

/// What was learned about one mode.
#[derive(Debug, Clone, PartialEq)]
pub struct ModeReport {
    /// Mode index.
    pub mode: usize,
    /// Its name.
    pub name: String,
    /// Bursts the fit used.
    pub bursts_used: usize,
    /// Bursts held out.
    pub held_out: usize,
    /// Parts dropped from the fit as outliers.
    pub outliers: usize,
    /// RMS position error (mm) on held-out bursts under the given plate (`None`: none held out).
    pub before_mm: Option<f64>,
    /// RMS orientation error (deg) on held-out bursts under the given plate.
    pub before_deg: Option<f64>,
    /// RMS position error (mm) on held-out bursts under the learned correction.
    pub after_mm: Option<f64>,
    /// RMS orientation error (deg) on held-out bursts under the learned correction.
    pub after_deg: Option<f64>,
    /// The learned correction (the given plate's when no burst was used).
    pub correction: Correction,
}

/// A learned plate: the model and a report per mode.
#[derive(Debug, Clone)]
pub struct Learned {
    /// The given plate with the learned corrections.
    pub model: Model,
    /// One report per mode, in mode order.
    pub reports: Vec<ModeReport>,
}

/// The learning fit's weak prior.
const LEARN_PRIOR: Prior = Prior {
    centre: Correction { shift_mm: [0.0, 0.0], speed_factor: 1.0 },
    shift_mm: 30.0,
    ln_factor: 2.3,
};

/// Fits every mode of `plate` to `bursts` (parts by index into `pieces`), holding out every
/// `hold_out_every`-th burst of each mode to score the given and the learned plate.
pub fn learn<'a>(
    plate: &'a PlateModel,
    pieces: &'a [Piece],
    bursts: &'a [Burst],
    opt: LearnOptions,
) -> Result<Learned, SteerError> {
    let mut model = Model::new(plate.clone());
    for b in bursts {
        check_burst(&model, pieces, b)?;
    }
    let mut reports = Vec::with_capacity(plate.modes.len());
    for mode in 0..plate.modes.len() {
        let (used, held): (Vec<(usize, &Burst)>, Vec<(usize, &Burst)>) = bursts
            .iter()
            .filter(|b| b.mode == mode)
            .enumerate()
            .partition(|(k, _)| opt.hold_out_every == 0 || (k + 1) % opt.hold_out_every != 0);
        let problem = |set: &[(usize, &'a Burst)], prior| Problem {
            given: plate,
            mode,
            pieces,
            bursts: set.iter().map(|(_, b)| *b).collect(),
            prior,
        };
        let fit_problem = problem(&used, Some(LEARN_PRIOR));
        let (correction, keep) = if used.is_empty() {
            (Correction::default(), Vec::new())
        } else {
            fit_from_starts(&fit_problem, opt.iterations)
        };
        model.set_correction(mode, correction)?;
        let scored = problem(&held, None);
        let before = rms(&scored, Correction::default());
        let after = rms(&scored, correction);
        reports.push(ModeReport {
            mode,
            name: plate.modes[mode].name.clone(),
            bursts_used: used.len(),
            held_out: held.len(),
            outliers: keep.iter().filter(|k| !**k).count(),
            before_mm: before.map(|r| r.0),
            before_deg: before.map(|r| r.1),
            after_mm: after.map(|r| r.0),
            after_deg: after.map(|r| r.1),
            correction,
        });
    }
    Ok(Learned { model, reports })
}

/// The fit from the best of the starts the module doc names.
fn fit_from_starts(problem: &Problem, iterations: usize) -> (Correction, Vec<bool>) {
    let at = |dx: f64, dy: f64, k: f64| Correction { shift_mm: [dx, dy], speed_factor: k };
    let factor = [0.4, 0.6, 0.9, 1.3, 1.8, 2.5]
        .into_iter()
        .map(|k| (k, problem.cost(at(0.0, 0.0, k))))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(1.0, |(k, _)| k);
    let starts = [(0.0, 0.0), (5.0, 0.0), (-5.0, 0.0), (0.0, 5.0), (0.0, -5.0)];
    let start = starts
        .into_iter()
        .map(|(dx, dy)| {
            let p = problem.lm(
                crate::steer::fit::params_of(at(dx, dy, factor)),
                &vec![true; problem.items()],
                2,
            );
            let c = crate::steer::fit::correction_of(p);
            (c, problem.cost(c))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(at(0.0, 0.0, factor), |(c, _)| c);
    problem.fit(start, iterations)
}

/// RMS position (mm) and orientation (deg) error of `problem`'s bursts under `c`; `None`
/// when it has none.
fn rms(problem: &Problem, c: Correction) -> Option<(f64, f64)> {
    let n = problem.items();
    if n == 0 {
        return None;
    }
    let r = problem.item_residuals(&problem.predictions(c));
    let mm = r.iter().map(|v| v[0] * v[0] + v[1] * v[1]).sum::<f64>() / n as f64;
    let deg =
        r.iter().map(|v| (v[2] / crate::steer::cost::MM_PER_DEG).powi(2)).sum::<f64>() / n as f64;
    Some((mm.sqrt(), deg.sqrt()))
}
