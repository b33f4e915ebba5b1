//! Plan steps as the simulator runs them: a plan file's steps mapped to the plate's modes, and
//! a whole plan run from one start pose.

use crate::model::plan_file::{PlanFile, PlanFileError, StepLevel};
use crate::model::plate::{PlateModel, SAME_FREQ_HZ};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::integrate::{SimParams, run};
use chladni_shared::icd::units::s_from_ms;

/// One step of a plan to simulate: the mode, how long, and the drive amplitude relative to
/// the mode's own (speed scales with the square of the amplitude, K ∝ e·A²·ω: docs/motion.md).
#[derive(Debug, Clone, Copy)]
pub struct SimStep {
    /// Index into the plate's modes.
    pub mode: usize,
    /// Duration (s).
    pub duration_s: f64,
    /// Amplitude / the mode's amplitude.
    pub amplitude_ratio: f64,
}

impl SimStep {
    /// A plan step as the simulator runs it: mode `mode` for `duration_ms`, driven at
    /// `amplitude_ratio` times the mode's own amplitude.
    pub fn new(mode: usize, duration_ms: u32, amplitude_ratio: f64) -> Self {
        SimStep { mode, duration_s: s_from_ms(u64::from(duration_ms)), amplitude_ratio }
    }
}

/// A plan step whose frequency no mode of the plate has.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("plan step {step}: no mode at {freq_hz} Hz (modes: {modes})")]
pub struct NoModeAt {
    /// Step number, 1-based (as `chladni plan` prints steps).
    pub step: usize,
    /// The step's frequency.
    pub freq_hz: f64,
    /// The plate's mode frequencies, listed.
    pub modes: String,
}

/// Why a plan file's steps cannot be simulated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanStepsError {
    /// A step at a frequency the plate has no mode at.
    #[error(transparent)]
    NoMode(#[from] NoModeAt),
    /// A step without exactly one level.
    #[error(transparent)]
    Level(#[from] PlanFileError),
    /// A closed-loop step: the motion model is driven by amplitude, and the plate file does
    /// not say which amplitude holds an acceleration.
    #[error(
        "plan step {step}: closed loop (accel_mps2 = {accel_mps2} m/s²): the simulation needs \
         an open-loop \"amplitude\" (0..1) for this step"
    )]
    ClosedLoop {
        /// Step number, 1-based (as `chladni plan` prints steps).
        step: usize,
        /// The step's acceleration target, m/s².
        accel_mps2: f64,
    },
}

/// The steps of a plan file as the simulator runs them, `repeat` times over: each step on the
/// plate's first mode at its frequency (within 1 mHz), at its amplitude relative to the mode's.
/// Open-loop steps only ([`PlanStepsError::ClosedLoop`]).
pub fn plan_steps(file: &PlanFile, plate: &PlateModel) -> Result<Vec<SimStep>, PlanStepsError> {
    let mut steps = Vec::with_capacity(file.steps.len());
    for (i, s) in file.steps.iter().enumerate() {
        let amplitude = match s.level(i)? {
            StepLevel::Amplitude(a) => a,
            StepLevel::AccelMps2(accel_mps2) => {
                return Err(PlanStepsError::ClosedLoop { step: i + 1, accel_mps2 });
            }
        };
        let k = plate
            .modes
            .iter()
            .position(|m| (m.freq_hz - s.freq_hz).abs() < SAME_FREQ_HZ)
            .ok_or_else(|| NoModeAt {
                step: i + 1,
                freq_hz: s.freq_hz,
                modes: plate
                    .modes
                    .iter()
                    .map(|m| format!("{} Hz", m.freq_hz))
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        steps.push(SimStep::new(k, s.duration_ms, amplitude / plate.modes[k].amplitude));
    }
    Ok((0..file.repeat).flat_map(|_| steps.iter().copied()).collect())
}

/// Runs a whole plan from `start`: the pose before each step and at the end, the full trace
/// (times continue across steps) and each step's end time.
pub fn simulate_plan(
    body: &Body,
    plate: &PlateModel,
    fields: &[FieldModel],
    steps: &[SimStep],
    start: Pose,
) -> (Vec<Pose>, Vec<(f64, Pose)>, Vec<f64>) {
    let mut poses = vec![start];
    let mut trace = vec![(0.0, start)];
    let mut ends = Vec::new();
    let (mut t0, mut pose) = (0.0, start);
    for s in steps {
        let mode = &plate.modes[s.mode];
        let p = SimParams {
            speed: mode.speed_mm_s * s.amplitude_ratio * s.amplitude_ratio,
            t_limit: s.duration_s,
            run_to_limit: true,
            rim: Some(Rim::of(plate)),
        };
        let r = run(body, &fields[s.mode], p, pose);
        trace.extend(r.trace.iter().skip(1).map(|&(t, q)| (t0 + t, q)));
        t0 += s.duration_s;
        pose = r.pose;
        poses.push(pose);
        ends.push(t0);
    }
    (poses, trace, ends)
}
