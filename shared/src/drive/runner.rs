//! The plan runner: a state machine that fills blocks of DAC samples and advances plan steps
//! by counting samples, so every step boundary falls on an exact sample index.
//!
//! The board calls [`Runner::fill`] with each free half of its sample buffer; commands
//! ([`Runner::start_plan`], [`Runner::drive`], [`Runner::stop`], [`Runner::fault`]) take effect
//! at the next sample filled. Stopping always ramps the amplitude to zero, never cuts it. A
//! fault latches with its cause until [`Runner::clear_fault`]; a stop or a new run does not
//! clear it.
//!
//! Closed loop: a setpoint whose level is an acceleration ([`Level::Accel`]) does not set the
//! amplitude itself: [`Runner::setpoint`] gives the target and its ramp to the closed loop
//! (which ramps it), and the runner takes the amplitude from the controller
//! ([`Runner::set_effort`], once per block, ramped over the next block). Every frequency
//! change leaves a [`PhaseMark`]: the DDS phase at a sample of the runner's sample clock, the
//! reference the lock-in needs.
//!
//! The plan is held by whatever `P` the caller picks ([`Runner<P>`]): the plan itself on the
//! host, a lock guard on one of two plan buffers in the firmware, so a new plan starts by
//! handing over which buffer to read, never by copying a plan. The run's totals are cached when
//! it starts, so [`Runner::status`] is O(1) whatever the plan's length.
//!
//! A block is split into segments in which nothing changes but the phase (and, in a ramp, the
//! gain); each segment is one call of the DDS's tight loop ([`Dds::fill_steady`] /
//! [`Dds::fill_ramp`]), so the per-sample cost carries no state-machine branches.

use core::ops::Deref;

use crate::drive::dds::{self, DAC_MID, Dds};
use crate::drive::timeline::PhaseMark;
use crate::icd::link::{DriveError, DriveState, StatusReport};
use crate::icd::plan::{DeviceLimits, Level, Plan, Step};
use crate::icd::sense::Fault;
use crate::icd::units::{SAMPLE_RATE, SAMPLES_PER_MS};

/// Samples per block: one DMA half-buffer on the board, one tick of the QEMU pacer (5 ms).
pub const BLOCK_LEN: usize = 250;
/// Ramp to zero on [`Runner::stop`] / [`Runner::fault`], and the least ramp at a plan's end.
pub const STOP_RAMP_MS: u32 = 20;
/// Ramp of the amplitude when a manual setpoint ([`Runner::drive`]) changes.
pub const MANUAL_RAMP_MS: u32 = 20;

/// What the runner is asked to output now: frequency and level, and over how long a new
/// level is reached.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setpoint {
    /// Frequency, mHz.
    pub freq_mhz: u32,
    /// Level (an acceleration target is given whole: the closed loop ramps it).
    pub level: Level,
    /// Ramp to this level, ms (the plan step's, or [`MANUAL_RAMP_MS`]).
    pub ramp_ms: u32,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Idle,
    Plan { step: u16, run: u16, step_left: u32 },
    Manual,
    Stopping { fault: bool },
    Faulted,
}

/// What holds the plan a [`Runner`] reads: the plan itself, or anything that dereferences to
/// one (a lock guard).
pub trait PlanHolder {
    /// The plan held.
    fn plan(&self) -> &Plan;
}

impl PlanHolder for Plan {
    fn plan(&self) -> &Plan {
        self
    }
}

impl<T: Deref<Target = Plan>> PlanHolder for T {
    fn plan(&self) -> &Plan {
        self
    }
}

/// The plan runner, reading its plan through `P` (see the module docs).
#[derive(Debug, Clone)]
pub struct Runner<P = Plan> {
    limits: DeviceLimits,
    /// The plan loaded last (kept after it ends, until the next one).
    plan: Option<P>,
    /// Samples in one repetition of the plan (cached when it starts).
    per_run: u64,
    /// Samples in the steps after the current one, in this repetition.
    rest_of_run: u64,
    mode: Mode,
    dds: Dds,
    freq_mhz: u32,
    gain: i32,
    target: i32,
    inc: i32,
    ramp_left: u32,
    elapsed: u64,
    underruns: u32,
    commands: u32,
    /// Closed loop: the acceleration target, mm/s² (`None`: open loop).
    accel: Option<u32>,
    /// Ramp of the current setpoint, ms.
    ramp_ms: u32,
    fault: Option<Fault>,
    clock: u64,
    mark: PhaseMark,
}

impl<P: PlanHolder> Runner<P> {
    /// An idle runner checking commands against `limits`.
    pub const fn new(limits: DeviceLimits) -> Self {
        Self {
            limits,
            plan: None,
            per_run: 0,
            rest_of_run: 0,
            mode: Mode::Idle,
            dds: Dds::new(0),
            freq_mhz: 0,
            gain: 0,
            target: 0,
            inc: 0,
            ramp_left: 0,
            elapsed: 0,
            underruns: 0,
            commands: 0,
            accel: None,
            ramp_ms: 0,
            fault: None,
            clock: 0,
            mark: PhaseMark { sample: 0, phase: 0, tuning_word: 0 },
        }
    }

    /// The sample clock: samples filled since the runner was made (idle ones included).
    pub fn clock(&self) -> u64 {
        self.clock
    }

    /// The reference phase since the last frequency change.
    pub fn phase_mark(&self) -> PhaseMark {
        self.mark
    }

    /// What the drive is asked to output now; `None` when idle, stopping or faulted.
    pub fn setpoint(&self) -> Option<Setpoint> {
        if !matches!(self.mode, Mode::Plan { .. } | Mode::Manual) {
            return None;
        }
        let level = match self.accel {
            Some(a) => Level::Accel(a),
            None => Level::Drive(dds::q15_of_gain(self.target)),
        };
        Some(Setpoint { freq_mhz: self.freq_mhz, level, ramp_ms: self.ramp_ms })
    }

    /// The device limits commands are checked against.
    pub fn limits(&self) -> &DeviceLimits {
        &self.limits
    }

    /// The latched fault, if any.
    pub fn latched_fault(&self) -> Option<Fault> {
        self.fault
    }

    /// Closed loop: the controller's drive amplitude (Q15, clamped to the device's limit),
    /// reached by a linear ramp over the next [`BLOCK_LEN`] samples. Ignored in open loop and
    /// while stopping.
    pub fn set_effort(&mut self, effort_q15: u16) {
        if self.accel.is_none() || !matches!(self.mode, Mode::Plan { .. } | Mode::Manual) {
            return;
        }
        let effort = effort_q15.min(self.limits.max_amplitude_q15);
        self.ramp_to(dds::gain_of_q15(effort), BLOCK_LEN as u32);
    }

    /// Phase of the next sample (one turn = 2³²).
    pub fn phase(&self) -> u32 {
        self.dds.phase
    }

    /// Current Q31 gain.
    pub fn gain(&self) -> i32 {
        self.gain
    }

    /// Checks later commands against `limits` (a new device configuration); what runs goes on.
    pub fn set_limits(&mut self, limits: DeviceLimits) {
        self.limits = limits;
    }

    /// The plan loaded last (`None` before the first).
    pub fn plan(&self) -> Option<&Plan> {
        self.plan.as_ref().map(PlanHolder::plan)
    }

    /// Starts `plan` at the next sample (replacing whatever runs; the amplitude ramps from its
    /// current value, the phase carries on). Returns the holder of the previous plan (the
    /// firmware releases that buffer by dropping it); a refused plan is dropped.
    pub fn start_plan(&mut self, plan: P) -> Result<Option<P>, DriveError> {
        if self.fault.is_some() {
            return Err(DriveError::Faulted);
        }
        plan.plan().validate(&self.limits).map_err(DriveError::Plan)?;
        self.per_run = plan.plan().steps.iter().map(|s| s.duration_samples() as u64).sum();
        let previous = self.plan.replace(plan);
        self.elapsed = 0;
        self.commands = self.commands.wrapping_add(1);
        self.begin_step(0, 0);
        Ok(previous)
    }

    /// Drives a steady sine (manual mode): the frequency changes at the next sample (phase
    /// kept), the level ramps over [`MANUAL_RAMP_MS`].
    pub fn drive(&mut self, freq_mhz: u32, level: Level) -> Result<(), DriveError> {
        if self.fault.is_some() {
            return Err(DriveError::Faulted);
        }
        self.limits.check_setpoint(freq_mhz, level).map_err(DriveError::Setpoint)?;
        if self.mode != Mode::Manual {
            self.elapsed = 0;
        }
        self.mode = Mode::Manual;
        self.set_freq(freq_mhz);
        self.set_level(level, MANUAL_RAMP_MS);
        self.commands = self.commands.wrapping_add(1);
        Ok(())
    }

    /// Ramps to zero over [`STOP_RAMP_MS`], then idles (or stays faulted: only
    /// [`Runner::clear_fault`] clears a fault).
    pub fn stop(&mut self) {
        self.commands = self.commands.wrapping_add(1);
        match self.mode {
            Mode::Idle | Mode::Faulted => {}
            Mode::Stopping { .. } => {}
            Mode::Plan { .. } | Mode::Manual => {
                self.mode = Mode::Stopping { fault: false };
                self.accel = None;
                self.ramp_to(0, STOP_RAMP_MS * SAMPLES_PER_MS);
            }
        }
    }

    /// Ramps to zero over [`STOP_RAMP_MS`] and latches `fault` ([`DriveState::Faulted`]).
    /// A second fault while one is latched keeps the first (the cause that started it).
    pub fn fault(&mut self, fault: Fault) {
        self.commands = self.commands.wrapping_add(1);
        if self.fault.is_none() {
            self.fault = Some(fault);
        }
        self.accel = None;
        match self.mode {
            Mode::Faulted => {}
            Mode::Idle => self.mode = Mode::Faulted,
            Mode::Stopping { .. } => self.mode = Mode::Stopping { fault: true },
            Mode::Plan { .. } | Mode::Manual => {
                self.mode = Mode::Stopping { fault: true };
                self.ramp_to(0, STOP_RAMP_MS * SAMPLES_PER_MS);
            }
        }
    }

    /// Clears a latched fault: the drive idles (it is already silent, or finishing its ramp to
    /// zero). Returns the fault that was latched.
    pub fn clear_fault(&mut self) -> Option<Fault> {
        let fault = self.fault.take()?;
        self.commands = self.commands.wrapping_add(1);
        match self.mode {
            Mode::Faulted => self.mode = Mode::Idle,
            Mode::Stopping { .. } => self.mode = Mode::Stopping { fault: false },
            _ => {}
        }
        Some(fault)
    }

    /// Counts one missed refill (the output ran ahead of the runner).
    pub fn note_underrun(&mut self) {
        self.underruns = self.underruns.wrapping_add(1);
    }

    /// The current state.
    pub fn state(&self) -> DriveState {
        match self.mode {
            Mode::Idle => DriveState::Idle,
            Mode::Faulted => DriveState::Faulted,
            Mode::Stopping { .. } => DriveState::Stopping,
            // Closed loop: the controller moves the amplitude every block (its ramps are
            // not the plan's).
            Mode::Plan { .. } | Mode::Manual if self.accel.is_some() => DriveState::Running,
            Mode::Plan { .. } | Mode::Manual => {
                if self.ramp_left == 0 || self.inc == 0 {
                    DriveState::Running
                } else if self.inc > 0 {
                    DriveState::RampUp
                } else {
                    DriveState::RampDown
                }
            }
        }
    }

    /// A snapshot for [`crate::icd::link::Request::Status`].
    pub fn status(&self) -> StatusReport {
        let (step, repetition, remaining_samples) = match self.mode {
            Mode::Plan { step, run, step_left } => {
                (Some(step), run, self.remaining_samples(run, step_left))
            }
            _ => (None, 0, 0),
        };
        let silent = matches!(self.mode, Mode::Idle | Mode::Faulted);
        let in_plan = step.is_some();
        let level = self.setpoint().map(|s| s.level);
        StatusReport {
            state: self.state(),
            step,
            repetition,
            // Commands are numbered by whoever queues them (the firmware's drive task).
            run: crate::icd::link::RunNumber(0),
            plan: if in_plan { self.plan().map(|p| p.name.clone()) } else { None },
            remaining_samples,
            fault: self.fault,
            level,
            // The drive task adds what the sensing side knows.
            measured: None,
            warning: false,
            reset_cause: crate::icd::sense::ResetCause::PowerOn,
            clock: self.clock,
            elapsed_samples: self.elapsed,
            sample_rate: SAMPLE_RATE,
            freq_mhz: if silent { 0 } else { self.freq_mhz },
            amplitude_q15: dds::q15_of_gain(self.gain),
            underruns: self.underruns,
            commands: self.commands,
            // The drive task adds what the board measures.
            least_slack_us: None,
            stack_high_water: 0,
        }
    }

    /// Samples until the plan's last step ends, from `step_left` samples before the end of
    /// the current step in repetition `run`: O(1), from the totals cached at the step's start.
    fn remaining_samples(&self, run: u16, step_left: u32) -> u64 {
        let repeat = self.plan().map_or(0, |p| p.repeat);
        let runs_after = repeat.saturating_sub(run + 1) as u64;
        step_left as u64 + self.rest_of_run + runs_after * self.per_run
    }

    /// Step `step` of the plan loaded (only called in plan mode, whose steps exist).
    fn step_of(&self, step: u16) -> Step {
        self.plan().and_then(|p| p.steps.get(step as usize)).copied().unwrap_or(Step {
            freq_mhz: 0,
            level: Level::Drive(0),
            duration_ms: 0,
            ramp_ms: 0,
        })
    }

    fn set_freq(&mut self, freq_mhz: u32) {
        self.freq_mhz = freq_mhz;
        self.dds.tuning_word = dds::tuning_word(freq_mhz);
        self.mark = PhaseMark {
            sample: self.clock,
            phase: self.dds.phase,
            tuning_word: self.dds.tuning_word,
        };
    }

    /// Moves to `level` over `ramp_ms`: the amplitude (open loop) or the acceleration target
    /// (closed loop; the amplitude then follows [`Runner::set_effort`]).
    fn set_level(&mut self, level: Level, ramp_ms: u32) {
        self.ramp_ms = ramp_ms;
        match level {
            Level::Drive(q15) => {
                self.accel = None;
                self.ramp_to(dds::gain_of_q15(q15), ramp_ms * SAMPLES_PER_MS);
            }
            Level::Accel(to) => {
                self.accel = Some(to);
                // Hold the amplitude until the controller speaks.
                self.ramp_to(self.gain, 0);
            }
        }
    }

    fn ramp_to(&mut self, target: i32, samples: u32) {
        self.target = target;
        if samples == 0 || target == self.gain {
            self.gain = target;
            self.inc = 0;
            self.ramp_left = 0;
        } else {
            self.inc = (target - self.gain) / samples as i32;
            self.ramp_left = samples;
        }
    }

    fn begin_step(&mut self, step: u16, run: u16) {
        let s = self.step_of(step);
        let before = if step == 0 { self.per_run } else { self.rest_of_run };
        self.rest_of_run = before.saturating_sub(s.duration_samples() as u64);
        self.mode = Mode::Plan { step, run, step_left: s.duration_samples() };
        self.set_freq(s.freq_mhz);
        self.set_level(s.level, s.ramp_ms);
    }

    fn end_of_step(&mut self, step: u16, run: u16) {
        let (steps, repeat) = self.plan().map_or((0, 0), |p| (p.steps.len(), p.repeat));
        if (step as usize + 1) < steps {
            self.begin_step(step + 1, run);
        } else if run + 1 < repeat {
            self.begin_step(0, run + 1);
        } else {
            let ramp = self.step_of(step).ramp_ms.max(STOP_RAMP_MS);
            self.mode = Mode::Stopping { fault: false };
            self.accel = None;
            self.ramp_to(0, ramp * SAMPLES_PER_MS);
        }
    }

    /// Fills `out` with the next samples (12-bit DAC codes) and advances the plan.
    pub fn fill(&mut self, out: &mut [u16]) {
        let mut pos = 0;
        while pos < out.len() {
            if let Mode::Stopping { fault } = self.mode
                && self.ramp_left == 0
            {
                self.gain = 0;
                self.mode = if fault { Mode::Faulted } else { Mode::Idle };
            }
            if matches!(self.mode, Mode::Idle | Mode::Faulted) {
                out[pos..].fill(DAC_MID);
                self.clock += (out.len() - pos) as u64;
                return;
            }
            let mut n = (out.len() - pos) as u32;
            if let Mode::Plan { step_left, .. } = self.mode {
                n = n.min(step_left);
            }
            if self.ramp_left > 0 {
                n = n.min(self.ramp_left);
            }
            let seg = &mut out[pos..pos + n as usize];
            if self.ramp_left > 0 {
                self.dds.fill_ramp(seg, &mut self.gain, self.inc);
                self.ramp_left -= n;
                if self.ramp_left == 0 {
                    self.gain = self.target;
                }
            } else {
                self.dds.fill_steady(seg, self.gain);
            }
            pos += n as usize;
            self.elapsed += n as u64;
            self.clock += n as u64;
            match self.mode {
                Mode::Plan { step, run, step_left } => {
                    if step_left == n {
                        self.end_of_step(step, run);
                    } else {
                        self.mode = Mode::Plan { step, run, step_left: step_left - n };
                    }
                }
                Mode::Stopping { fault } if self.ramp_left == 0 => {
                    self.gain = 0;
                    self.mode = if fault { Mode::Faulted } else { Mode::Idle };
                }
                _ => {}
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::icd::plan::{PlanError, Step};
    use crate::icd::sense::Fault;
    use std::vec::Vec;

    fn plan(steps: &[Step], repeat: u16) -> Plan {
        Plan {
            name: heapless::String::try_from("test").unwrap(),
            repeat,
            steps: heapless::Vec::from_slice(steps).unwrap(),
        }
    }

    const STEPS: [Step; 3] = [
        Step { freq_mhz: 100_000, level: Level::Drive(16384), duration_ms: 40, ramp_ms: 10 },
        Step { freq_mhz: 250_500, level: Level::Drive(26000), duration_ms: 60, ramp_ms: 5 },
        Step { freq_mhz: 1_234_567, level: Level::Drive(8000), duration_ms: 30, ramp_ms: 3 },
    ];

    /// Runs `runner` block by block until idle; records codes, gains, phases and statuses per
    /// sample (blocks of odd length, so boundaries fall inside blocks).
    struct Trace {
        codes: Vec<u16>,
        step: Vec<Option<u16>>,
        gain: Vec<i32>,
        phase: Vec<u32>,
    }

    fn trace(runner: &mut Runner, block: usize) -> Trace {
        let mut t =
            Trace { codes: Vec::new(), step: Vec::new(), gain: Vec::new(), phase: Vec::new() };
        let mut buf = std::vec![0u16; block];
        // Single samples expose the state at every index; blocks check the same stream.
        let mut single = runner.clone();
        while single.state() != DriveState::Idle {
            t.step.push(single.status().step);
            t.phase.push(single.phase());
            let mut one = [0u16; 1];
            single.fill(&mut one);
            t.gain.push(single.gain());
            t.codes.push(one[0]);
        }
        let mut blocked = Vec::new();
        while blocked.len() < t.codes.len() {
            runner.fill(&mut buf);
            blocked.extend_from_slice(&buf);
        }
        assert_eq!(&blocked[..t.codes.len()], &t.codes[..], "block size changes the stream");
        assert!(blocked[t.codes.len()..].iter().all(|&c| c == DAC_MID));
        t
    }

    #[test]
    fn steps_switch_at_exact_sample_indices() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.start_plan(plan(&STEPS, 2)).unwrap();
        let t = trace(&mut r, 97);
        let per_run: u32 = STEPS.iter().map(|s| s.duration_samples()).sum();
        let mut boundary = 0usize;
        for run in 0..2 {
            for (i, s) in STEPS.iter().enumerate() {
                assert_eq!(
                    t.step[boundary],
                    Some(i as u16),
                    "run {run} step {i} starts at {boundary}"
                );
                if boundary > 0 {
                    assert_ne!(t.step[boundary - 1], Some(i as u16));
                }
                boundary += s.duration_samples() as usize;
            }
        }
        assert_eq!(boundary, 2 * per_run as usize);
        // Then the final ramp to zero (max(last ramp, STOP_RAMP_MS)), then idle.
        assert_eq!(t.codes.len(), boundary + (STOP_RAMP_MS * SAMPLES_PER_MS) as usize);
        assert!(t.step[boundary..].iter().all(|s| s.is_none()));
        assert_eq!(r.status().elapsed_samples, t.codes.len() as u64);
        assert_eq!(r.state(), DriveState::Idle);
    }

    /// The cached totals give the same remaining time as summing the plan's steps: at every
    /// block of two repetitions, `remaining_samples` is exactly the samples left in the plan.
    #[test]
    fn remaining_samples_counts_down_to_the_plans_end() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.start_plan(plan(&STEPS, 2)).unwrap();
        let total: u64 = 2 * STEPS.iter().map(|s| s.duration_samples() as u64).sum::<u64>();
        let mut buf = [0u16; 97];
        let mut filled = 0u64;
        while r.status().step.is_some() {
            assert_eq!(r.status().remaining_samples, total - filled, "after {filled} samples");
            r.fill(&mut buf);
            filled += buf.len() as u64;
        }
        assert!(filled >= total && filled < total + buf.len() as u64);
        assert_eq!(r.status().remaining_samples, 0);
    }

    #[test]
    fn phase_is_continuous_across_steps() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.start_plan(plan(&STEPS, 1)).unwrap();
        let t = trace(&mut r, 250);
        // The phase advances by exactly the current step's tuning word: never reset or jumped.
        let mut idx = 0usize;
        for s in STEPS {
            for _ in 0..s.duration_samples() {
                let want = t.phase[idx].wrapping_add(dds::tuning_word(s.freq_mhz));
                assert_eq!(t.phase[idx + 1], want, "phase jump at sample {idx}");
                idx += 1;
            }
        }
        // The waveform never moves more than one sample's phase step allows:
        // |Δcode| ≤ 2047·2π·f/f_s + 1 LSB of rounding + the ramp's gain change.
        let max_f = STEPS.iter().map(|s| s.freq_mhz).max().unwrap() as f64 / 1000.0;
        let bound = 2047.0 * core::f64::consts::TAU * max_f / SAMPLE_RATE as f64 + 2.0;
        for w in t.codes.windows(2) {
            let d = (w[1] as f64 - w[0] as f64).abs();
            assert!(d <= bound, "waveform jump of {d} LSB (bound {bound})");
        }
    }

    #[test]
    fn ramps_are_monotonic_and_reach_their_targets() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.start_plan(plan(&STEPS, 1)).unwrap();
        let t = trace(&mut r, 64);
        let mut idx = 0usize;
        let mut prev_target = 0i32;
        for s in STEPS {
            let Level::Drive(q15) = s.level else { unreachable!("open-loop steps") };
            let target = dds::gain_of_q15(q15);
            let ramp = s.ramp_samples() as usize;
            let g = &t.gain[idx..idx + ramp];
            if target > prev_target {
                assert!(g.windows(2).all(|w| w[1] >= w[0]), "ramp up not monotonic");
            } else {
                assert!(g.windows(2).all(|w| w[1] <= w[0]), "ramp down not monotonic");
            }
            assert_eq!(t.gain[idx + ramp - 1], target, "ramp ends on its target");
            let end = idx + s.duration_samples() as usize;
            assert!(t.gain[idx + ramp..end].iter().all(|&x| x == target));
            idx = end;
            prev_target = target;
        }
        // Final ramp to zero: monotonic, ends at zero, never a cut.
        let tail = &t.gain[idx..];
        assert!(tail.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(*tail.last().unwrap(), 0);
        let max_drop = tail.windows(2).map(|w| w[0] - w[1]).max().unwrap();
        assert!(max_drop <= prev_target / (STOP_RAMP_MS * SAMPLES_PER_MS) as i32 + 1);
    }

    #[test]
    fn stop_ramps_to_zero_then_idles() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.drive(440_000, Level::Drive(30000)).unwrap();
        let mut buf = [0u16; 5000];
        r.fill(&mut buf);
        assert_eq!(r.state(), DriveState::Running);
        assert_eq!(r.status().amplitude_q15, 30000);
        assert_eq!(r.status().freq_mhz, 440_000);
        r.stop();
        assert_eq!(r.state(), DriveState::Stopping);
        let mut gains = Vec::new();
        for _ in 0..(STOP_RAMP_MS * SAMPLES_PER_MS) {
            let mut one = [0u16; 1];
            r.fill(&mut one);
            gains.push(r.gain());
        }
        assert!(gains.windows(2).all(|w| w[1] <= w[0]));
        assert_eq!(*gains.last().unwrap(), 0);
        r.fill(&mut buf);
        assert_eq!(r.state(), DriveState::Idle);
        assert!(buf.iter().all(|&c| c == DAC_MID));
        assert_eq!(r.status().commands, 2);
    }

    const LOOP_OPEN: Fault =
        Fault { cause: crate::icd::sense::FaultCause::LoopOpen, value: 12, at_sample: 2000 };

    #[test]
    fn fault_latches_until_cleared() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.drive(100_000, Level::Drive(10000)).unwrap();
        let mut buf = [0u16; 2000];
        r.fill(&mut buf);
        r.fault(LOOP_OPEN);
        r.fill(&mut buf);
        r.fill(&mut buf);
        assert_eq!(r.state(), DriveState::Faulted);
        assert!(buf.iter().all(|&c| c == DAC_MID), "silent once ramped down");
        assert_eq!(r.drive(100_000, Level::Drive(1)), Err(DriveError::Faulted));
        assert_eq!(r.start_plan(plan(&STEPS, 1)), Err(DriveError::Faulted));
        // Neither a stop nor a second fault changes what is latched.
        r.stop();
        let later = Fault { at_sample: 9999, ..LOOP_OPEN };
        r.fault(later);
        assert_eq!(r.state(), DriveState::Faulted);
        assert_eq!(r.status().fault, Some(LOOP_OPEN));
        assert_eq!(r.clear_fault(), Some(LOOP_OPEN));
        assert_eq!(r.clear_fault(), None);
        assert_eq!(r.state(), DriveState::Idle);
        assert_eq!(r.status().fault, None);
        assert_eq!(r.drive(100_000, Level::Drive(1)), Ok(()));
    }

    #[test]
    fn closed_loop_takes_its_amplitude_from_the_controller() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        r.drive(180_000, Level::Accel(20_000)).unwrap();
        let mut buf = [0u16; BLOCK_LEN];
        // No effort yet: silent; the closed loop gets the target and its ramp.
        r.fill(&mut buf);
        assert!(buf.iter().all(|&c| c == DAC_MID));
        assert_eq!(r.state(), DriveState::Running);
        let ramp = MANUAL_RAMP_MS * SAMPLES_PER_MS;
        let want = Setpoint { freq_mhz: 180_000, level: Level::Accel(20_000), ramp_ms: 20 };
        assert_eq!(r.setpoint(), Some(want));
        // An effort is reached linearly over the next block, and clamped to the limit.
        r.set_effort(10_000);
        r.fill(&mut buf);
        assert_eq!(r.gain(), dds::gain_of_q15(10_000));
        r.set_effort(40_000);
        r.fill(&mut buf);
        assert_eq!(r.gain(), dds::gain_of_q15(32767));
        for _ in 0..ramp as usize / BLOCK_LEN {
            r.fill(&mut buf);
        }
        assert_eq!(r.state(), DriveState::Running);
        // Open loop again: the effort is ignored.
        r.drive(180_000, Level::Drive(5000)).unwrap();
        r.set_effort(30_000);
        for _ in 0..ramp as usize / BLOCK_LEN + 1 {
            r.fill(&mut buf);
        }
        assert_eq!(r.gain(), dds::gain_of_q15(5000));
    }

    #[test]
    fn phase_marks_follow_frequency_changes() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        let mut buf = [0u16; 333];
        r.fill(&mut buf);
        r.start_plan(plan(&STEPS, 1)).unwrap();
        let mut seen = Vec::new();
        while r.state() != DriveState::Idle {
            // Sample by sample: the mark must predict the phase of every sample.
            let m = r.phase_mark();
            let want =
                m.phase.wrapping_add(((r.clock() - m.sample) as u32).wrapping_mul(m.tuning_word));
            assert_eq!(r.phase(), want, "sample {}", r.clock());
            if seen.last() != Some(&m) {
                seen.push(m);
            }
            r.fill(&mut buf[..1]);
        }
        assert_eq!(seen.len(), STEPS.len());
        assert_eq!(seen[0].sample, 333);
        assert_eq!(seen[1].sample, 333 + STEPS[0].duration_samples() as u64);
    }

    #[test]
    fn invalid_commands_are_refused() {
        let mut r = Runner::<Plan>::new(DeviceLimits::DEFAULT);
        assert!(matches!(r.drive(5_000_000, Level::Drive(1)), Err(DriveError::Setpoint(_))));
        assert!(matches!(r.start_plan(plan(&[], 1)), Err(DriveError::Plan(PlanError::Empty))));
        assert_eq!(r.state(), DriveState::Idle);
        assert_eq!(r.status().commands, 0);
    }
}
