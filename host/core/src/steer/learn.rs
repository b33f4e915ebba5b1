//! Learning a plate from recorded bursts: per mode, the [`Correction`] that best predicts
//! them, with held-out bursts to say how much better the learned plate predicts than the given
//! one; and the bursts to record (which mode, how long, when to bring the parts home first).
//!
//! The fit ([`crate::steer::fit`]) minimises the squared prediction error (mm, and degrees ×
//! [`crate::steer::cost::MM_PER_DEG`]) of the used bursts with a weak prior (spreads 30 mm and
//! ×10: it only conditions a mode whose bursts barely moved its parts), from the best of
//! the speed factor alone first (a scan of ×0.4–×2.5 at shift 0), refined with the shift;
//! when that fit is poor (RMS above 1.5 mm), also from that factor with ±5 mm along each axis,
//! the better of the two fits kept. Held-out bursts are scored under the given and the learned
//! plate, leaving out of both the one held-out part the learned plate finds an outlier (a
//! bounce no model predicts).

use crate::model::plate::PlateModel;
use crate::model::plate_file::LearnedMode;
use crate::steer::SteerError;
use crate::steer::correct::check_burst;
use crate::steer::cost::Piece;
use crate::steer::fit::{Burst, Prior, Problem, correction_of, outlier, params_of};
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
    /// Held-out parts left out of the scores as outliers (at most one per mode).
    pub held_out_outliers: usize,
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

impl Learned {
    /// The `[learned]` table's rows ([`LearnedMode`]) of the modes the fit used bursts of:
    /// the shift is the mode's whole `shift_mm` (the given file's, if it had one, plus the
    /// learned one), as a plate file's entry takes it; errors are 0 where none was held out
    /// (`held_out` = 0 says so).
    pub fn rows(&self) -> Vec<LearnedMode> {
        let given = self.model.given();
        self.reports
            .iter()
            .filter(|r| r.bursts_used > 0)
            .filter_map(|r| {
                let mode = given.modes.get(r.mode)?;
                let s = r.correction.shift_mm;
                Some(LearnedMode {
                    freq_hz: mode.freq_hz,
                    bursts: u32::try_from(r.bursts_used).unwrap_or(u32::MAX),
                    held_out: u32::try_from(r.held_out).unwrap_or(u32::MAX),
                    speed_factor: r.correction.speed_factor,
                    shift_mm: [mode.shift_mm[0] + s[0], mode.shift_mm[1] + s[1]],
                    before_mm: r.before_mm.unwrap_or(0.0),
                    after_mm: r.after_mm.unwrap_or(0.0),
                    before_deg: r.before_deg.unwrap_or(0.0),
                    after_deg: r.after_deg.unwrap_or(0.0),
                })
            })
            .collect()
    }
}

/// The learning fit's weak prior.
const LEARN_PRIOR: Prior = Prior {
    centre: Correction { shift_mm: [0.0, 0.0], speed_factor: 1.0 },
    shift_mm: 30.0,
    ln_factor: 2.3,
};

/// Fits every mode of `plate` to `bursts` (parts by index into `pieces`), holding out every
/// `hold_out_every`-th burst of each mode to score the given and the learned plate.
pub fn learn(
    plate: &PlateModel,
    pieces: &[Piece],
    bursts: &[Burst],
    opt: LearnOptions,
) -> Result<Learned, SteerError> {
    let mut model = Model::new(plate.clone());
    for b in bursts {
        check_burst(&model, pieces, b)?;
    }
    let mut reports = Vec::with_capacity(plate.modes.len());
    for mode in 0..plate.modes.len() {
        let report = learn_mode(plate, pieces, bursts, mode, opt);
        model.set_correction(mode, report.correction)?;
        reports.push(report);
    }
    Ok(Learned { model, reports })
}

/// One mode's fit and scores.
fn learn_mode(
    plate: &PlateModel,
    pieces: &[Piece],
    bursts: &[Burst],
    mode: usize,
    opt: LearnOptions,
) -> ModeReport {
    let mine = bursts.iter().filter(|b| b.mode == mode).enumerate();
    let (mut used, mut held) = (Vec::new(), Vec::new());
    for (k, b) in mine {
        let hold = opt.hold_out_every > 0 && (k + 1) % opt.hold_out_every == 0;
        if hold { held.push(b) } else { used.push(b) }
    }
    let (used_n, held_n) = (used.len(), held.len());
    let fit = Problem::new(plate, mode, pieces, used, Some(LEARN_PRIOR));
    let (correction, keep) = if used_n == 0 {
        (Correction::default(), Vec::new())
    } else {
        fit_from_starts(&fit, opt.iterations)
    };
    let scored = Problem::new(plate, mode, pieces, held, None);
    let scored_keep = scored_items(&scored, correction);
    let before = rms(&scored, Correction::default(), &scored_keep);
    let after = rms(&scored, correction, &scored_keep);
    ModeReport {
        mode,
        name: plate.modes.get(mode).map_or_else(String::new, |m| m.name.clone()),
        bursts_used: used_n,
        held_out: held_n,
        outliers: keep.iter().filter(|k| !**k).count(),
        held_out_outliers: scored_keep.iter().filter(|k| !**k).count(),
        before_mm: before.map(|r| r.0),
        before_deg: before.map(|r| r.1),
        after_mm: after.map(|r| r.0),
        after_deg: after.map(|r| r.1),
        correction,
    }
}

/// The fit from the best of the starts the module doc names.
fn fit_from_starts(problem: &Problem, iterations: usize) -> (Correction, Vec<bool>) {
    let at = |dx: f64, dy: f64, k: f64| Correction { shift_mm: [dx, dy], speed_factor: k };
    let factor = [0.4, 0.6, 0.9, 1.3, 1.8, 2.5]
        .into_iter()
        .map(|k| (k, problem.cost(at(0.0, 0.0, k))))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map_or(1.0, |(k, _)| k);
    let first = problem.fit(at(0.0, 0.0, factor), iterations);
    let keep = &first.1;
    let rms_of = |c: Correction| rms(problem, c, keep).map_or(0.0, |r| r.0);
    if rms_of(first.0) <= GOOD_FIT_MM {
        return first;
    }
    // A poor fit may be a local minimum: try the shifted starts, refine the best.
    let all = vec![true; problem.items()];
    let best = [(5.0, 0.0), (-5.0, 0.0), (0.0, 5.0), (0.0, -5.0)]
        .into_iter()
        .map(|(dx, dy)| {
            let p = problem.lm(params_of(at(dx, dy, factor)), &all, 2);
            let c = correction_of(p);
            (c, problem.cost(c))
        })
        .min_by(|a, b| a.1.total_cmp(&b.1));
    match best {
        Some((c, cost)) if cost < problem.cost(first.0) => {
            let other = problem.fit(c, iterations);
            if rms_of(other.0) < rms_of(first.0) { other } else { first }
        }
        _ => first,
    }
}

/// An RMS position residual (mm) of the fitted bursts below which a fit from the first start
/// is taken as it is: a few times the noise of a located part after a burst.
const GOOD_FIT_MM: f64 = 1.5;

/// RMS position (mm) and orientation (deg) error of `problem`'s items in `keep` under `c`;
/// `None` when there are none.
fn rms(problem: &Problem, c: Correction, keep: &[bool]) -> Option<(f64, f64)> {
    let r = problem.item_residuals(&problem.predictions(c));
    let kept: Vec<&[f64; 3]> = r.iter().zip(keep).filter(|(_, k)| **k).map(|(v, _)| v).collect();
    if kept.is_empty() {
        return None;
    }
    let n = kept.len() as f64;
    let mm = kept.iter().map(|v| v[0] * v[0] + v[1] * v[1]).sum::<f64>() / n;
    let deg = kept.iter().map(|v| (v[2] / crate::steer::cost::MM_PER_DEG).powi(2)).sum::<f64>() / n;
    Some((mm.sqrt(), deg.sqrt()))
}

/// Which held-out items to score: all but the one outlier under the learned correction
/// ([`crate::steer::fit`]'s rule), left out of both the given plate's and the learned one's
/// error (no model predicts a bounce).
fn scored_items(problem: &Problem, c: Correction) -> Vec<bool> {
    let norms: Vec<f64> = problem
        .item_residuals(&problem.predictions(c))
        .iter()
        .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt())
        .collect();
    let mut keep = vec![true; norms.len()];
    if let Some(k) = outlier(&norms) {
        keep[k] = false;
    }
    keep
}
