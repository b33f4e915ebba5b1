//! The plate as the loop believes it: the given plate with a [`Correction`] per mode (where
//! its nodes really are, how fast it really moves parts), and the predictions of a burst.

use crate::model::plate::{Mode, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;
use crate::motion::integrate::{Run, SimParams, run};
use crate::steer::SteerError;

/// What one mode really does, relative to the given plate: its field translated by
/// `shift_mm` and its settle speed multiplied by `speed_factor`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Correction {
    /// Translation of the mode's field, nodes included (mm).
    pub shift_mm: [f64; 2],
    /// True speed over the plate file's `speed_mm_s` (> 0).
    pub speed_factor: f64,
}

impl Default for Correction {
    fn default() -> Self {
        Correction { shift_mm: [0.0, 0.0], speed_factor: 1.0 }
    }
}

impl Correction {
    /// The correction is usable: a finite shift and a finite factor > 0.
    pub fn check(&self, mode: usize) -> Result<(), SteerError> {
        let ok = self.shift_mm.iter().all(|v| v.is_finite())
            && self.speed_factor.is_finite()
            && self.speed_factor > 0.0;
        if ok {
            Ok(())
        } else {
            Err(SteerError::BadCorrection {
                mode,
                shift_mm: self.shift_mm,
                speed_factor: self.speed_factor,
            })
        }
    }
}

/// The given plate, corrected mode by mode, with each corrected mode's field built once.
#[derive(Debug, Clone)]
pub struct Model {
    given: PlateModel,
    corrections: Vec<Correction>,
    /// The given modes with their corrections applied.
    modes: Vec<Mode>,
    fields: Vec<FieldModel>,
}

impl Model {
    /// The given plate, uncorrected.
    pub fn new(given: PlateModel) -> Model {
        let corrections = vec![Correction::default(); given.modes.len()];
        let modes = given.modes.clone();
        let fields = modes.iter().map(|m| FieldModel::new(m, &given)).collect();
        Model { given, corrections, modes, fields }
    }

    /// The given plate with `corrections` (one per mode).
    pub fn with_corrections(
        given: PlateModel,
        corrections: &[Correction],
    ) -> Result<Model, SteerError> {
        if corrections.len() != given.modes.len() {
            return Err(SteerError::CorrectionCount {
                given: corrections.len(),
                modes: given.modes.len(),
            });
        }
        let mut model = Model::new(given);
        for (i, c) in corrections.iter().enumerate() {
            model.set_correction(i, *c)?;
        }
        Ok(model)
    }

    /// The plate as given.
    pub fn given(&self) -> &PlateModel {
        &self.given
    }

    /// Number of modes.
    pub fn mode_count(&self) -> usize {
        self.modes.len()
    }

    /// The correction of mode `mode`.
    pub fn correction(&self, mode: usize) -> Result<Correction, SteerError> {
        self.check_mode(mode)?;
        Ok(self.corrections[mode])
    }

    /// Every mode's correction, in mode order.
    pub fn corrections(&self) -> &[Correction] {
        &self.corrections
    }

    /// The corrected mode `mode` (as a plate file holding what was learned would give it).
    pub fn mode(&self, mode: usize) -> Result<&Mode, SteerError> {
        self.check_mode(mode)?;
        Ok(&self.modes[mode])
    }

    /// The corrected plate: every mode with its correction applied.
    pub fn plate(&self) -> PlateModel {
        PlateModel { modes: self.modes.clone(), ..self.given.clone() }
    }

    /// Sets mode `mode`'s correction and rebuilds its field (only when it changed).
    pub fn set_correction(&mut self, mode: usize, c: Correction) -> Result<(), SteerError> {
        self.check_mode(mode)?;
        c.check(mode)?;
        if self.corrections[mode] == c {
            return Ok(());
        }
        let corrected = corrected_mode(&self.given.modes[mode], c);
        self.fields[mode] = FieldModel::new(&corrected, &self.given);
        self.modes[mode] = corrected;
        self.corrections[mode] = c;
        Ok(())
    }

    /// An error unless `mode` is one of the plate's.
    pub(crate) fn check_mode(&self, mode: usize) -> Result<(), SteerError> {
        if mode < self.modes.len() {
            Ok(())
        } else {
            Err(SteerError::NoMode { index: mode, count: self.modes.len() })
        }
    }

    /// The run of `body` from `pose` under mode `mode` for `t_limit` s (or to rest).
    pub(crate) fn run(&self, body: &Body, pose: Pose, mode: usize, t_limit: f64) -> Run {
        let p = SimParams::under(&self.modes[mode], &self.given, t_limit);
        run(body, &self.fields[mode], p, pose)
    }

    /// The run of `body` from `pose` under mode `mode` to rest ([`SimParams::to_rest`]).
    pub(crate) fn run_to_rest(&self, body: &Body, pose: Pose, mode: usize) -> Run {
        let (m, f) = (&self.modes[mode], &self.fields[mode]);
        run(body, f, SimParams::to_rest(body, m, f, &self.given), pose)
    }

    /// The pose of `body` after mode `mode` driven for `burst_s` s from `pose`.
    pub fn predict(
        &self,
        body: &Body,
        pose: Pose,
        mode: usize,
        burst_s: f64,
    ) -> Result<Pose, SteerError> {
        self.check_mode(mode)?;
        check_bursts(&[burst_s])?;
        Ok(self.run(body, pose, mode, burst_s).pose)
    }

    /// For each part (body, pose), its pose after mode `mode` driven for each of `bursts`
    /// (s): `[part][burst]`. One run per part to the longest burst, read at each length
    /// ([`pose_at`]). Parts are predicted independently: the motion model of one part in the
    /// field, no part–part contact (parts closer than their radii are the caller's to keep
    /// apart, see [`crate::steer::policy::needs_recover`]).
    pub fn predict_all(
        &self,
        parts: &[(&Body, Pose)],
        mode: usize,
        bursts: &[f64],
    ) -> Result<Vec<Vec<Pose>>, SteerError> {
        self.check_mode(mode)?;
        check_bursts(bursts)?;
        let longest = bursts.iter().copied().fold(0.0, f64::max);
        Ok(parts
            .iter()
            .map(|(body, pose)| {
                let r = self.run(body, *pose, mode, longest);
                bursts.iter().map(|&t| pose_at(&r, t)).collect()
            })
            .collect())
    }

    /// [`Model::predict_all`] without the checks (the callers checked once).
    pub(crate) fn predict_unchecked(
        &self,
        body: &Body,
        pose: Pose,
        mode: usize,
        bursts: &[f64],
        out: &mut Vec<Pose>,
    ) {
        let longest = bursts.iter().copied().fold(0.0, f64::max);
        let r = self.run(body, pose, mode, longest);
        out.clear();
        out.extend(bursts.iter().map(|&t| pose_at(&r, t)));
    }
}

/// Every burst length is finite and > 0, and there is at least one.
pub(crate) fn check_bursts(bursts: &[f64]) -> Result<(), SteerError> {
    if bursts.is_empty() {
        return Err(SteerError::NoBursts);
    }
    match bursts.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        Some(&t) => Err(SteerError::BadBurst { burst_s: t }),
        None => Ok(()),
    }
}

/// The pose of a run at time `t` (s): linear between the integrator's accepted steps (each
/// within its error tolerance of 10⁻³ of the part's radius), the end pose after the run
/// ended (at rest or at its limit).
pub fn pose_at(r: &Run, t: f64) -> Pose {
    let k = r.trace.partition_point(|(ts, _)| *ts <= t);
    if k == 0 {
        return r.trace.first().map_or(r.pose, |s| s.1);
    }
    if k >= r.trace.len() {
        return r.pose;
    }
    let ((ta, a), (tb, b)) = (r.trace[k - 1], r.trace[k]);
    let u = if tb > ta { (t - ta) / (tb - ta) } else { 1.0 };
    Pose {
        x: a.x + u * (b.x - a.x),
        y: a.y + u * (b.y - a.y),
        theta: a.theta + u * (b.theta - a.theta),
    }
}

/// `mode` with correction `c` on top of it: its nodes moved by the correction's shift
/// ([`crate::model::plate::Node::shifted`]; the mode's own `shift_mm`, if the plate file had one, grows by it) and
/// its speed scaled.
pub fn corrected_mode(mode: &Mode, c: Correction) -> Mode {
    let s = c.shift_mm;
    Mode {
        node: mode.node.clone().shifted(s),
        shift_mm: [mode.shift_mm[0] + s[0], mode.shift_mm[1] + s[1]],
        speed_mm_s: mode.speed_mm_s * c.speed_factor,
        ..mode.clone()
    }
}
