//! Calibrating a mode's settle speed μ (`speed_mm_s`) from observations of real parts
//! (`chladni plate calibrate-speed`, docs/plate.md "Calibrating the settle speed").
//!
//! **The structure used.** In the motion model (docs/motion.md) the velocity is μ times a
//! function of the pose alone, so a run at speed μ is the run at μ = 1 with time divided by
//! μ: pose(t; μ) = pose(μ·t; 1). The integrator keeps this exactly (its step, rest and
//! settle tolerances are all in units of T₀ = R/(μ·gain)). Each observation is therefore
//! simulated once, at μ = 1:
//!
//! - a **time to the node** t_obs is modelled as τ/μ, τ the model's time at μ = 1, and least
//!   squares over Σ (t_obs − τ/μ)² has the closed form 1/μ = Σ t_obs·τ / Σ τ²;
//! - a **pose after a time** t is modelled as the μ = 1 trace read at μ·t, so its residual
//!   d(μ) (centroid distance, plus R·Δθ when the orientation was observed) costs a trace
//!   look-up per μ: the fit is a 1-D minimisation of Σ d² (+ the time terms, 1 s weighing as
//!   1 mm) over log μ, a grid over [`SPEED_RANGE`] refined by golden section.
//!
//! "Reaches the node" is defined on the model's own run: the first time the centroid comes
//! within `within_mm` of the place where the part comes to rest (the stopwatch stops when
//! the part arrives on the line; a slow turn afterwards does not count).

use serde::Serialize;

pub use crate::model::observations::{Measured, Observation};
use crate::model::part::Part;
use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::integrate::SimParams;

/// The speeds (mm/s) a fit may return: a value outside says the observations do not fit the
/// model (or its units), not a plate.
pub const SPEED_RANGE: std::ops::RangeInclusive<f64> = 1e-3..=1e5;

/// Default of `within_mm`: how close to its rest the centroid counts as on the node (mm).
pub const DEFAULT_WITHIN_MM: f64 = 1.0;

/// A part to calibrate with: prepared once, its symmetry period for orientation residuals.
#[derive(Debug, Clone)]
pub struct CalPart {
    /// Name.
    pub name: String,
    /// Prepared for simulation.
    pub body: Body,
    /// Orientations equal modulo this (deg): the part's rotational symmetry.
    pub period_deg: f64,
}

impl CalPart {
    /// Prepares a part.
    pub fn new(part: &Part) -> CalPart {
        let m = crate::planner::symmetry_order(part);
        CalPart { name: part.name.clone(), body: Body::new(part), period_deg: 360.0 / m as f64 }
    }
}

/// One observation against the fitted model.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Residual {
    /// CSV line.
    pub line: usize,
    /// Part name.
    pub part: String,
    /// `"time"` (seconds) or `"pose"` (mm).
    pub kind: &'static str,
    /// Observed time (s), for time observations.
    pub observed_s: Option<f64>,
    /// Model time at the fitted speed (s), for time observations.
    pub model_s: Option<f64>,
    /// Model pose at the observed time `[x_mm, y_mm, θ_deg]`, for pose observations.
    pub model_pose: Option<[f64; 3]>,
    /// Observed minus model (s), or distance from the model pose (mm, R·Δθ included).
    pub residual: f64,
}

/// The fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fit {
    /// The fitted speed μ (mm/s), rounded to 6 significant digits.
    pub speed_mm_s: f64,
    /// `"closed form"` (time observations only) or `"1-D search"`.
    pub method: &'static str,
    /// RMS of the time residuals (s), when there are time observations.
    pub rms_time_s: Option<f64>,
    /// RMS of the pose residuals (mm), when there are pose observations.
    pub rms_pose_mm: Option<f64>,
    /// Every observation.
    pub residuals: Vec<Residual>,
}

/// Why no speed was fitted.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FitError {
    /// No observations.
    #[error("no observations: add rows to the CSV (docs/plate.md)")]
    Empty,
    /// Nothing in the observations depends on μ.
    #[error(
        "the speed is not determined: {0}. Start the parts away from the node (at least a few \
         mm), and observe poses before the part comes to rest"
    )]
    Undetermined(String),
    /// The model's part never reaches the node from this start.
    #[error(
        "line {line}: in the model, {part} does not come to rest from this start (it creeps \
         along the node or leaves the plate): start it elsewhere, or observe its pose after a time"
    )]
    NoRest {
        /// CSV line.
        line: usize,
        /// Part name.
        part: String,
    },
    /// The best fit lies at the end of the range searched.
    #[error(
        "the best fit lies at the end of the speeds searched ({speed} mm/s, range {lo}..={hi} \
         mm/s): check the observations' units (mm, s, degrees) and the mode"
    )]
    AtBound {
        /// The speed found.
        speed: f64,
        /// Range start.
        lo: f64,
        /// Range end.
        hi: f64,
    },
}

/// One observation simulated at μ = 1.
enum Model {
    /// τ: the model's time to the node at μ = 1.
    Time { t_obs: f64, tau: f64 },
    /// The μ = 1 trace and the observation.
    Pose { t_obs: f64, at: [f64; 2], theta: Option<f64>, trace: Vec<(f64, Pose)> },
}

/// The first time (interpolated) at which the centroid is within `within` of `end`.
fn time_within(trace: &[(f64, Pose)], end: Pose, within: f64) -> f64 {
    let d = |q: &Pose| (q.x - end.x).hypot(q.y - end.y);
    for k in 0..trace.len() {
        let (tb, b) = trace[k];
        if d(&b) > within {
            continue;
        }
        let Some(&(ta, a)) = k.checked_sub(1).and_then(|i| trace.get(i)) else { return tb };
        let (da, db) = (d(&a), d(&b));
        let f = if da > db { (da - within) / (da - db) } else { 1.0 };
        return ta + f * (tb - ta);
    }
    trace.last().map_or(0.0, |t| t.0)
}

/// The pose at time `t` on a trace (linear between samples; the last pose after its end).
fn pose_at(trace: &[(f64, Pose)], t: f64) -> Pose {
    let k = trace.partition_point(|s| s.0 <= t);
    match (k.checked_sub(1).and_then(|i| trace.get(i)), trace.get(k)) {
        (Some(&(ta, a)), Some(&(tb, b))) if tb > ta => {
            let f = (t - ta) / (tb - ta);
            Pose {
                x: a.x + f * (b.x - a.x),
                y: a.y + f * (b.y - a.y),
                theta: a.theta + f * (b.theta - a.theta),
            }
        }
        (Some(&(_, a)), _) => a,
        (None, Some(&(_, b))) => b,
        (None, None) => Pose::default(),
    }
}

/// Signed difference a − b (deg) wrapped to (−p/2, p/2].
fn wrap(a: f64, b: f64, p: f64) -> f64 {
    crate::model::angle::signed_diff(a, b, p)
}

/// Simulates every observation once at μ = 1 (see the module docs).
fn models(
    parts: &[CalPart],
    field: &FieldModel,
    rim: Rim,
    obs: &[Observation],
    within: f64,
) -> Result<Vec<Model>, FitError> {
    // The rim's contacts are quasi-static too (constraint forces scale with the field's), so
    // a run against the wall keeps the same 1/μ time scaling.
    let p = SimParams { speed: 1.0, t_limit: 1e12, run_to_limit: false, rim: Some(rim) };
    let runs: Vec<crate::motion::integrate::Run> = {
        use rayon::prelude::*;
        obs.par_iter()
            .map(|o| crate::motion::integrate::run(&parts[o.part].body, field, p, o.start))
            .collect()
    };
    obs.iter()
        .zip(runs)
        .map(|(o, r)| match o.measured {
            Measured::TimeToNode { t_s } => {
                if !r.rested {
                    return Err(FitError::NoRest {
                        line: o.line,
                        part: parts[o.part].name.clone(),
                    });
                }
                Ok(Model::Time { t_obs: t_s, tau: time_within(&r.trace, r.pose, within) })
            }
            Measured::PoseAfter { t_s, x_mm, y_mm, theta_deg } => {
                Ok(Model::Pose { t_obs: t_s, at: [x_mm, y_mm], theta: theta_deg, trace: r.trace })
            }
        })
        .collect()
}

impl Model {
    /// Residual at speed μ: seconds (time) or mm (pose; R·Δθ at the part's radius).
    fn residual(&self, mu: f64, part: &CalPart) -> f64 {
        match self {
            Model::Time { t_obs, tau } => t_obs - tau / mu,
            Model::Pose { t_obs, at, theta, trace } => {
                let q = pose_at(trace, mu * t_obs);
                let dth = theta.map_or(0.0, |th| {
                    wrap(q.theta.to_degrees(), th, part.period_deg).to_radians() * part.body.radius
                });
                (q.x - at[0]).hypot(q.y - at[1]).hypot(dth)
            }
        }
    }

    /// Does the observation depend on μ at all (the model part moves)?
    fn moves(&self) -> bool {
        match self {
            Model::Time { tau, .. } => *tau > 0.0,
            Model::Pose { trace, .. } => {
                let (a, b) = (trace[0].1, trace[trace.len() - 1].1);
                (a.x - b.x).hypot(a.y - b.y) > 1e-9 || (a.theta - b.theta).abs() > 1e-12
            }
        }
    }
}

/// Fits μ of `plate.modes[mode]` to the observations (see the module docs).
pub fn fit(
    parts: &[CalPart],
    plate: &PlateModel,
    mode: usize,
    obs: &[Observation],
    within_mm: f64,
) -> Result<Fit, FitError> {
    if obs.is_empty() {
        return Err(FitError::Empty);
    }
    let field = FieldModel::new(&plate.modes[mode], plate);
    let models = models(parts, &field, Rim::of(plate), obs, within_mm)?;
    if !models.iter().any(Model::moves) {
        return Err(FitError::Undetermined(format!(
            "in the model no observed part moves (every start is already within {within_mm} mm \
             of its rest)"
        )));
    }
    let cost = |mu: f64| -> f64 {
        (models.iter().zip(obs)).map(|(m, o)| m.residual(mu, &parts[o.part]).powi(2)).sum()
    };
    let times_only = models.iter().all(|m| matches!(m, Model::Time { .. }));
    let (lo, hi) = (*SPEED_RANGE.start(), *SPEED_RANGE.end());
    let (mu, method) = if times_only {
        let (num, den) = models.iter().fold((0.0, 0.0), |(n, d), m| match m {
            Model::Time { t_obs, tau } => (n + t_obs * tau, d + tau * tau),
            Model::Pose { .. } => (n, d),
        });
        if num <= 0.0 {
            return Err(FitError::Undetermined("every observed time is 0".into()));
        }
        (den / num, "closed form")
    } else {
        (search(&cost, lo, hi)?, "1-D search")
    };
    if !(lo..=hi).contains(&mu) {
        return Err(FitError::AtBound { speed: mu, lo, hi });
    }
    let mu = round_sig(mu, 6);
    Ok(report(parts, &models, obs, mu, method))
}

/// The minimum of `cost` over log μ in [lo, hi]: a grid of 30 points per decade, then golden
/// section between the best point's neighbours; refused at the range's ends or where the
/// cost does not change with μ.
fn search(cost: &dyn Fn(f64) -> f64, lo: f64, hi: f64) -> Result<f64, FitError> {
    let (a, b) = (lo.ln(), hi.ln());
    let n = (30.0 * (hi / lo).log10()).ceil() as usize;
    let grid: Vec<f64> = (0..=n).map(|i| a + (b - a) * i as f64 / n as f64).collect();
    let values: Vec<f64> = grid.iter().map(|&u| cost(u.exp())).collect();
    let best = (0..values.len()).min_by(|&i, &j| values[i].total_cmp(&values[j])).unwrap_or(0);
    if best == 0 || best == n {
        return Err(FitError::AtBound { speed: grid[best].exp(), lo, hi });
    }
    let (mut x0, mut x1) = (grid[best - 1], grid[best + 1]);
    let g = (5f64.sqrt() - 1.0) / 2.0;
    let (mut c, mut d) = (x1 - g * (x1 - x0), x0 + g * (x1 - x0));
    let (mut fc, mut fd) = (cost(c.exp()), cost(d.exp()));
    while x1 - x0 > 1e-10 {
        if fc < fd {
            (x1, d, fd) = (d, c, fc);
            c = x1 - g * (x1 - x0);
            fc = cost(c.exp());
        } else {
            (x0, c, fc) = (c, d, fd);
            d = x0 + g * (x1 - x0);
            fd = cost(d.exp());
        }
    }
    let u = 0.5 * (x0 + x1);
    let (f, near) = (cost(u.exp()), cost((u + 0.2).exp()).min(cost((u - 0.2).exp())));
    if near - f <= 1e-9 * (1.0 + f) {
        return Err(FitError::Undetermined(format!(
            "the residuals hardly change with the speed near {:.4} mm/s (the parts observed \
             are at rest, or have not moved, at the observed times)",
            u.exp()
        )));
    }
    Ok(u.exp())
}

/// `v` rounded to `digits` significant digits.
fn round_sig(v: f64, digits: i32) -> f64 {
    let scale = 10f64.powi(digits - 1 - v.abs().log10().floor() as i32);
    (v * scale).round() / scale
}

/// The fit's report at μ: per-observation residuals and the RMS of each kind.
fn report(
    parts: &[CalPart],
    models: &[Model],
    obs: &[Observation],
    mu: f64,
    method: &'static str,
) -> Fit {
    let mut residuals = Vec::new();
    let (mut time, mut pose) = (Vec::new(), Vec::new());
    for (m, o) in models.iter().zip(obs) {
        let part = &parts[o.part];
        let r = m.residual(mu, part);
        let (kind, observed_s, model_s, model_pose) = match m {
            Model::Time { t_obs, tau } => {
                time.push(r);
                ("time", Some(*t_obs), Some(tau / mu), None)
            }
            Model::Pose { t_obs, trace, .. } => {
                pose.push(r);
                let q = pose_at(trace, mu * t_obs);
                ("pose", None, None, Some([q.x, q.y, q.theta.to_degrees()]))
            }
        };
        let name = part.name.clone();
        residuals.push(Residual {
            line: o.line,
            part: name,
            kind,
            observed_s,
            model_s,
            model_pose,
            residual: r,
        });
    }
    let rms = |v: &[f64]| {
        (!v.is_empty()).then(|| (v.iter().map(|r| r * r).sum::<f64>() / v.len() as f64).sqrt())
    };
    Fit { speed_mm_s: mu, method, rms_time_s: rms(&time), rms_pose_mm: rms(&pose), residuals }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_within_interpolates_the_crossing() {
        let q = |x: f64| Pose { x, y: 0.0, theta: 0.0 };
        let trace = vec![(0.0, q(10.0)), (1.0, q(4.0)), (2.0, q(0.5)), (3.0, q(0.0))];
        // 1 mm from the end at x = 1: between t = 1 (4 mm) and t = 2 (0.5 mm), 3/3.5 of it.
        let t = time_within(&trace, q(0.0), 1.0);
        assert!((t - (1.0 + 3.0 / 3.5)).abs() < 1e-12, "{t}");
        assert_eq!(time_within(&trace, q(0.0), 20.0), 0.0);
        let p = pose_at(&trace, 2.5);
        assert!((p.x - 0.25).abs() < 1e-12);
        assert_eq!(pose_at(&trace, 9.0).x, 0.0);
        assert_eq!(pose_at(&trace, -1.0).x, 10.0);
    }

    #[test]
    fn rounding_and_wrapping() {
        assert_eq!(round_sig(12.345_678_9, 6), 12.3457);
        assert_eq!(round_sig(0.000_123_456_78, 3), 0.000_123);
        assert!((wrap(359.0, 1.0, 360.0) + 2.0).abs() < 1e-12);
        assert!((wrap(95.0, 1.0, 90.0) - 4.0).abs() < 1e-12);
    }
}
