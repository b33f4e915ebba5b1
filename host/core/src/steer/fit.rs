//! The one fit of a mode's [`Correction`] to observed bursts, shared by the offline learning
//! ([`learn`](mod@crate::steer::learn)) and the online correction ([`crate::steer::correct`]).
//!
//! Parameters p = (dx mm, dy mm, ln factor). Residuals: for every part of every burst of the
//! mode, the predicted pose after the burst minus the observed one, (Δx, Δy) in mm and the
//! orientation difference (modulo the part's symmetry period) in degrees times
//! [`MM_PER_DEG`]; with a prior, three more residuals pull p towards the prior's centre,
//! (p − c)/σ · [`PRIOR_NOISE_MM`] (the prior counts as one observation of that noise).
//! Levenberg–Marquardt on forward differences (the runs are deterministic, so a difference
//! step well above the integrator's tolerance, 0.5 mm and 0.05 in ln factor, is smooth
//! enough). Robust to one outlier: after a fit, the part whose residual is largest is dropped
//! and the fit rerun from there when that residual exceeds both 3 × the median of the others'
//! and [`OUTLIER_MM`] (a part that bounced or was mislocated).

use std::cell::RefCell;

use nalgebra::{Matrix3, Vector3};

use crate::model::angle::signed_diff;
use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::field::FieldModel;
use crate::motion::integrate::{SimParams, run};
use crate::steer::cost::{MM_PER_DEG, Piece};
use crate::steer::model::{Correction, corrected_mode};

/// One recorded burst: a mode driven for `burst_s`, and each part located before and after.
#[derive(Debug, Clone, PartialEq)]
pub struct Burst {
    /// Mode index.
    pub mode: usize,
    /// Burst length (s).
    pub burst_s: f64,
    /// (index of the part's body, pose before, pose after) per part located both times.
    pub parts: Vec<(usize, Pose, Pose)>,
}

/// A residual (mm) above which, and above 3 × the median of the others, one part's burst is
/// an outlier: 5 mm, several times a good prediction's error but well under a bounce.
pub const OUTLIER_MM: f64 = 5.0;

/// The noise (mm) one prior residual counts as.
pub const PRIOR_NOISE_MM: f64 = 1.0;

/// A prior on the correction: its centre and spreads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// Centre.
    pub centre: Correction,
    /// Spread of the shift (mm).
    pub shift_mm: f64,
    /// Spread of ln factor.
    pub ln_factor: f64,
}

/// A mode's bursts and what it takes to predict them.
pub(crate) struct Problem<'a> {
    pub given: &'a PlateModel,
    pub mode: usize,
    pub pieces: &'a [Piece],
    pub bursts: Vec<&'a Burst>,
    pub prior: Option<Prior>,
    /// The last shift's field: a field is rebuilt only when the shift changes (a change of
    /// speed alone reuses it).
    cache: RefCell<Option<([f64; 2], FieldModel)>>,
}

pub(crate) type Params = [f64; 3];

pub(crate) fn params_of(c: Correction) -> Params {
    [c.shift_mm[0], c.shift_mm[1], c.speed_factor.max(1e-9).ln()]
}

pub(crate) fn correction_of(p: Params) -> Correction {
    Correction { shift_mm: [p[0], p[1]], speed_factor: p[2].exp() }
}

/// The fit's bounds: shifts within ±40 mm, factors within ×0.05–×20.
fn clamp(p: Params) -> Params {
    [p[0].clamp(-40.0, 40.0), p[1].clamp(-40.0, 40.0), p[2].clamp(0.05f64.ln(), 20f64.ln())]
}

impl<'a> Problem<'a> {
    /// A mode's bursts to fit or score.
    pub fn new(
        given: &'a PlateModel,
        mode: usize,
        pieces: &'a [Piece],
        bursts: Vec<&'a Burst>,
        prior: Option<Prior>,
    ) -> Problem<'a> {
        Problem { given, mode, pieces, bursts, prior, cache: RefCell::new(None) }
    }

    /// Number of (burst, part) items.
    pub fn items(&self) -> usize {
        self.bursts.iter().map(|b| b.parts.len()).sum()
    }

    /// Each item's predicted pose after its burst under correction `c`.
    pub fn predictions(&self, c: Correction) -> Vec<Pose> {
        let Some(given_mode) = self.given.modes.get(self.mode) else { return Vec::new() };
        let mode = corrected_mode(given_mode, c);
        let mut cache = self.cache.borrow_mut();
        let field = match &*cache {
            Some((shift, field)) if *shift == c.shift_mm => field,
            _ => &cache.insert((c.shift_mm, FieldModel::new(&mode, self.given))).1,
        };
        let mut out = Vec::with_capacity(self.items());
        for b in &self.bursts {
            let p = SimParams::under(&mode, self.given, b.burst_s);
            for (i, before, _) in &b.parts {
                out.push(
                    self.pieces.get(*i).map_or(*before, |q| run(&q.body, field, p, *before).pose),
                );
            }
        }
        out
    }

    /// Each item's residual (Δx, Δy, Δθ·[`MM_PER_DEG`]) of `predicted` against the observed.
    pub fn item_residuals(&self, predicted: &[Pose]) -> Vec<[f64; 3]> {
        let observed = self.bursts.iter().flat_map(|b| b.parts.iter());
        predicted
            .iter()
            .zip(observed)
            .map(|(p, (i, _, after))| {
                let period = self.pieces.get(*i).map_or(360.0, |q| q.period_deg);
                let dth = signed_diff(p.theta.to_degrees(), after.theta.to_degrees(), period);
                [p.x - after.x, p.y - after.y, MM_PER_DEG * dth]
            })
            .collect()
    }

    /// The residual vector at `p`, items not in `keep` left out, prior appended.
    fn residuals(&self, p: Params, keep: &[bool]) -> Vec<f64> {
        let items = self.item_residuals(&self.predictions(correction_of(p)));
        let mut r: Vec<f64> =
            items.iter().zip(keep).filter(|(_, k)| **k).flat_map(|(v, _)| *v).collect();
        if let Some(prior) = self.prior {
            let c = params_of(prior.centre);
            let s = [prior.shift_mm, prior.shift_mm, prior.ln_factor];
            r.extend((0..3).map(|k| (p[k] - c[k]) / s[k].max(1e-9) * PRIOR_NOISE_MM));
        }
        r
    }

    /// The robust fit from `start`: [`lm`], then once more without the one outlier if there
    /// is one. Returns the correction and which items were kept.
    pub fn fit(&self, start: Correction, iterations: usize) -> (Correction, Vec<bool>) {
        let mut keep = vec![true; self.items()];
        let p = self.lm(params_of(start), &keep, iterations);
        let norms: Vec<f64> = self
            .item_residuals(&self.predictions(correction_of(p)))
            .iter()
            .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt())
            .collect();
        let Some(worst) = outlier(&norms) else {
            return (correction_of(p), keep);
        };
        keep[worst] = false;
        let p = self.lm(p, &keep, iterations);
        (correction_of(p), keep)
    }

    /// Levenberg–Marquardt from `p0` (forward differences), at most `iterations` Jacobians.
    pub fn lm(&self, p0: Params, keep: &[bool], iterations: usize) -> Params {
        const H: Params = [0.5, 0.5, 0.05];
        let sq = |r: &[f64]| r.iter().map(|v| v * v).sum::<f64>();
        let mut p = clamp(p0);
        let mut r = self.residuals(p, keep);
        let mut cost = sq(&r);
        let mut lambda = 1e-2;
        for _ in 0..iterations {
            // The factor's column first: it reuses the field at p (same shift, cached).
            let mut cols: Vec<Vec<f64>> = vec![Vec::new(); 3];
            for k in [2, 0, 1] {
                let mut q = p;
                q[k] += H[k];
                let rq = self.residuals(q, keep);
                cols[k] = rq.iter().zip(&r).map(|(a, b)| (a - b) / H[k]).collect();
            }
            let a = Matrix3::from_fn(|i, j| cols[i].iter().zip(&cols[j]).map(|(x, y)| x * y).sum());
            let g = Vector3::from_fn(|i, _| cols[i].iter().zip(&r).map(|(x, y)| x * y).sum());
            let mut improved = false;
            for _ in 0..6 {
                let damped = a
                    + Matrix3::from_diagonal(&(a.diagonal() * lambda))
                    + Matrix3::identity() * 1e-9;
                let Some(step) = damped.lu().solve(&(-g)) else { break };
                let q = clamp([p[0] + step[0], p[1] + step[1], p[2] + step[2]]);
                let rq = self.residuals(q, keep);
                let cq = sq(&rq);
                if cq < cost {
                    let small =
                        step[0].abs() < 0.01 && step[1].abs() < 0.01 && step[2].abs() < 1e-3;
                    (p, r, cost, lambda) = (q, rq, cq, (lambda / 3.0).max(1e-6));
                    improved = !small;
                    break;
                }
                lambda *= 4.0;
            }
            if !improved {
                break;
            }
        }
        p
    }

    /// The cost (sum of squares, prior included) at correction `c`.
    pub fn cost(&self, c: Correction) -> f64 {
        self.residuals(params_of(c), &vec![true; self.items()]).iter().map(|v| v * v).sum()
    }
}

/// The index of the one outlier among residual norms, if any ([`OUTLIER_MM`]; needs 3).
pub(crate) fn outlier(norms: &[f64]) -> Option<usize> {
    if norms.len() < 3 {
        return None;
    }
    let (worst, &max) = norms.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    let mut others: Vec<f64> =
        norms.iter().enumerate().filter(|(i, _)| *i != worst).map(|(_, v)| *v).collect();
    others.sort_by(f64::total_cmp);
    let median = others[others.len() / 2];
    (max > OUTLIER_MM && max > 3.0 * median).then_some(worst)
}
