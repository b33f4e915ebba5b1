//! [`ClosedLoop`]: the one object the firmware's drive task calls once per block to sense,
//! control and watch the drive.
//!
//! Per block the drive task
//! 1. reads the accelerometer's FIFO and hands the batch over with the DAC sample count at the
//!    read ([`ClosedLoop::push_batch`]), or a bus error ([`ClosedLoop::push_sensor_error`]);
//! 2. calls [`ClosedLoop::update`] with the clock, the runner's latest [`PhaseMark`], the
//!    level asked for, the effort ceiling, and whether the drive is on;
//! 3. applies [`LoopOutput`]: in closed loop, `effort_q15` is the drive amplitude for the next
//!    block (ramped linearly across that block by the runner, so the output never steps); on
//!    `fault`, the runner faults (ramps to zero and latches). `measurement` is the newest
//!    lock-in estimate, open loop or closed (status shows it always).
//!
//! Chain: batch → [`SensorTimebase`] (each sample's instant on the DAC clock) → [`LockIn`]
//! (with the DDS's phase at that instant; a new mark takes over at its own sample, so samples
//! taken before a frequency change are still demodulated at the old frequency) → loop check →
//! [`AmplitudeController`] → effort; [`Monitors`] watch it all.
//!
//! # States of a closed-loop run
//! - **Check** (from rest, whenever a target appears while idle): drive `check_effort_q15`
//!   for `check_ms`, then the last complete lock-in window must show ≥ `check_min_mmps2`, or
//!   the run faults with [`FaultCause::LoopCheck`] and the value measured. Otherwise the plant
//!   gain Ĝ = response / check effort seeds the controller.
//! - **Run**: the PI with feed-forward, the setpoint ramping from the check's response to the
//!   target over `ramp_ms`. A changed target ramps from the current setpoint.
//! - **Regain** (a frequency change while running): the effort is held for `check_ms` (the
//!   plate rings at its own frequency after the change; that transient decays with the plate's
//!   τ), then the last window re-measures Ĝ; then Run again, ramping from that response.
//!
//! A fault latches (reported in every [`LoopOutput`], effort `None`) until
//! [`ClosedLoop::clear_fault`].

use crate::drive::control::{AmplitudeController, Ramp};
use crate::drive::lockin::{Estimate, LockIn};
use crate::drive::monitor::{ClosedInput, MonitorInput, Monitors};
use crate::drive::timeline::{PhaseMark, SensorTimebase, TIME_FRAC_BITS, dac_time};
use crate::icd::sense::{ControlConfig, Fault, FaultCause, Measurement, SensorFault};
use crate::icd::units::SAMPLES_PER_MS;
use micromath::F32Ext;
#[cfg(test)]
extern crate std;

/// What the drive task tells [`ClosedLoop::update`] once per block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockInput {
    /// DAC samples output since boot, now.
    pub now_sample: u64,
    /// The runner's latest phase mark (may lie ahead of `now_sample`: the block being filled).
    pub mark: PhaseMark,
    /// Closed loop: the acceleration target, mm/s². `None`: open loop.
    pub target_mmps2: Option<u32>,
    /// Ramp of a target change, ms (a plan step's `ramp_ms`).
    pub ramp_ms: u32,
    /// Highest effort the controller may use, Q15.
    pub effort_ceiling_q15: u16,
    /// Whether a drive is being output (not idle, not faulted).
    pub driving: bool,
    /// The runner's own amplitude now, Q15 (what open-loop drives output).
    pub open_effort_q15: u16,
}

/// What [`ClosedLoop::update`] answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LoopOutput {
    /// Closed loop: the effort for the next block, Q15. `None`: open loop (or faulted).
    pub effort_q15: Option<u16>,
    /// The newest measurement, if a lock-in window completed since the last update.
    pub measurement: Option<Measurement>,
    /// The response is outside the warn band (closed loop, settled).
    pub warning: bool,
    /// The latched fault, if any.
    pub fault: Option<Fault>,
}

/// Where a closed-loop run is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Stage {
    /// Open loop or idle.
    Open,
    /// The loop check, started at this sample.
    Check {
        /// Its first sample.
        start: u64,
    },
    /// Holding the effort for `check_ms` after a frequency change (the plate's transient
    /// dies down), then re-measuring the gain.
    Regain {
        /// The first sample at the new frequency (as the drive task saw it).
        since: u64,
    },
    /// The PI controls.
    Run,
}

/// See the module docs.
#[derive(Debug, Clone)]
pub struct ClosedLoop {
    cfg: ControlConfig,
    timebase: SensorTimebase,
    lockin: LockIn,
    mark: Option<PhaseMark>,
    next_mark: Option<PhaseMark>,
    fresh: Option<Estimate>,
    mark_switched: bool,
    stage: Stage,
    ctrl: Option<AmplitudeController>,
    monitors: Monitors,
    fault: Option<Fault>,
    /// The loop check's estimates: (window end sample, response mm/s²).
    check_points: heapless::Vec<(u64, u32), CHECK_POINTS>,
}

/// Most estimates kept during a loop check (the newest win).
const CHECK_POINTS: usize = 64;

impl ClosedLoop {
    /// A loop with thresholds `cfg`, for a sensor of nominal rate `odr_mhz` and `lsb_mps2`
    /// m/s² per LSB.
    pub fn new(cfg: ControlConfig, odr_mhz: u32, lsb_mps2: f32) -> Self {
        let timebase = SensorTimebase::new(odr_mhz);
        let mut lockin = LockIn::new(lsb_mps2);
        lockin.set_sensor_period(timebase.period_q16());
        Self {
            cfg,
            timebase,
            lockin,
            mark: None,
            next_mark: None,
            fresh: None,
            mark_switched: false,
            stage: Stage::Open,
            ctrl: None,
            monitors: Monitors::new(cfg),
            fault: None,
            check_points: heapless::Vec::new(),
        }
    }

    /// New thresholds (a configuration change).
    pub fn set_config(&mut self, cfg: ControlConfig) {
        self.cfg = cfg;
        self.monitors.set_config(cfg);
    }

    /// The sensor timebase (for reports: the period estimate).
    pub fn timebase(&self) -> &SensorTimebase {
        &self.timebase
    }

    /// The lock-in (for reports: the last estimate in f32).
    pub fn lockin(&self) -> &LockIn {
        &self.lockin
    }

    /// The controller of the closed-loop run, if one runs.
    pub fn controller(&self) -> Option<&AmplitudeController> {
        self.ctrl.as_ref()
    }

    /// Where the run is.
    pub fn stage(&self) -> Stage {
        self.stage
    }

    /// Takes a batch of samples (oldest first) read from the FIFO at DAC sample `stamp`.
    pub fn push_batch(&mut self, samples: &[i16], stamp: u64) {
        let Some(newest) = self.timebase.push_batch(samples.len(), stamp) else { return };
        self.monitors.data(stamp);
        let n = samples.len();
        for (i, &x) in samples.iter().enumerate() {
            let t = self.timebase.sample_time(newest, n, i);
            if let Some(next) = self.next_mark
                && t >= dac_time(next.sample)
            {
                self.switch_mark(next);
            }
            if let Some(e) = self.lockin.push(x, t) {
                self.fresh = Some(e);
            }
        }
    }

    /// A sensor error: faults at the next update. An overrun also restarts the timebase
    /// (samples were lost, so the count no longer matches the clock).
    pub fn push_sensor_error(&mut self, e: SensorFault) {
        if e == SensorFault::Overrun {
            self.timebase.reset();
            self.lockin.restart();
        }
        self.monitors.sensor_error(e);
    }

    /// Clears a latched fault; the next closed-loop run starts with a loop check.
    /// Sensor errors reported before the clear are forgotten with it: a sensor still broken
    /// reports again (and faults again) with its next error.
    pub fn clear_fault(&mut self) {
        self.fault = None;
        self.stage = Stage::Open;
        self.ctrl = None;
        self.monitors = Monitors::new(self.cfg);
    }

    fn switch_mark(&mut self, mark: PhaseMark) {
        self.next_mark = None;
        let differs = self.mark.is_none_or(|m| m.differs_from(&mark));
        self.mark = Some(mark);
        if differs {
            self.lockin.set_mark(mark);
            self.fresh = None;
            self.mark_switched = true;
        }
    }

    /// One call per block. See the module docs.
    pub fn update(&mut self, input: &BlockInput) -> LoopOutput {
        match self.mark {
            None => self.switch_mark(input.mark),
            Some(m) if m.differs_from(&input.mark) => self.next_mark = Some(input.mark),
            Some(_) => {}
        }
        let fresh = self.fresh.take();
        let measurement = fresh.map(|e| e.measurement());
        if self.fault.is_some() {
            self.stage = Stage::Open;
            self.ctrl = None;
            return LoopOutput { effort_q15: None, measurement, warning: false, fault: self.fault };
        }
        let step = self.step(input, fresh);
        let effort = step.map(|s| s.0);
        if let Some(f) = step.and_then(|s| s.1) {
            self.fault = Some(f);
        }
        let closed = match (self.stage, &self.ctrl, input.target_mmps2) {
            (Stage::Run, Some(c), Some(target)) => Some(ClosedInput {
                target_mmps2: target,
                ramp_end: c.ramp().end(),
                demand_q15: c.demand_q15(),
                model_mmps2: c.model_mmps2(),
                ceiling_q15: input.effort_ceiling_q15,
            }),
            _ => None,
        };
        let mi = MonitorInput {
            now: input.now_sample,
            driving: input.driving,
            effort_q15: effort.unwrap_or(input.open_effort_q15),
            response_mmps2: measurement.map(|m| m.accel_mmps2),
            closed,
            retuned: self.mark_switched,
        };
        if self.fault.is_none() {
            self.fault = self.monitors.check(&mi);
        }
        self.mark_switched = false;
        if self.fault.is_some() {
            self.stage = Stage::Open;
            self.ctrl = None;
        }
        LoopOutput {
            effort_q15: if self.fault.is_some() { None } else { effort },
            measurement,
            warning: self.monitors.warning(),
            fault: self.fault,
        }
    }

    /// The closed-loop state machine: the effort for the next block and a loop-check fault.
    fn step(&mut self, i: &BlockInput, fresh: Option<Estimate>) -> Option<(u16, Option<Fault>)> {
        let Some(target) = i.target_mmps2 else {
            self.stage = Stage::Open;
            self.ctrl = None;
            return None;
        };
        let ceiling = i.effort_ceiling_q15;
        let ramp_len = i.ramp_ms as u64 * SAMPLES_PER_MS as u64;
        let now = i.now_sample;
        match self.stage {
            Stage::Open => {
                self.stage = Stage::Check { start: now };
                self.lockin.clear();
                self.check_points.clear();
                Some((self.cfg.check_effort_q15.min(ceiling), None))
            }
            Stage::Check { start } => {
                if let Some(e) = fresh {
                    if self.check_points.is_full() {
                        self.check_points.remove(0);
                    }
                    let _ = self.check_points.push((e.end >> TIME_FRAC_BITS, e.accel_mmps2()));
                }
                self.check(i, start, target, ramp_len)
            }
            Stage::Regain { .. } | Stage::Run if self.mark_switched => {
                self.stage = Stage::Regain { since: now };
                self.ctrl.as_ref().map(|c| (c.effort(), None))
            }
            Stage::Regain { since } => {
                let hold = self.cfg.check_ms as u64 * SAMPLES_PER_MS as u64;
                let ctrl = self.ctrl.as_mut()?;
                if now >= since + hold
                    && let Some(e) = self.lockin.last()
                    && e.end >= dac_time(since + hold / 2)
                {
                    let y = e.accel_mmps2();
                    let gain = y as f32 / ctrl.effort().max(1) as f32;
                    ctrl.regain(gain, y, now, ramp_len);
                    self.monitors.new_setpoint();
                    self.stage = Stage::Run;
                }
                Some((ctrl.effort(), None))
            }
            Stage::Run => {
                let ctrl = self.ctrl.as_mut()?;
                if target != ctrl.ramp().target() {
                    ctrl.set_target(target, now, ramp_len);
                    self.monitors.new_setpoint();
                }
                if let Some(e) = fresh {
                    let mid = (e.end - self.lockin.window() / 2) >> TIME_FRAC_BITS;
                    ctrl.update(e.accel_mmps2(), mid, now, ceiling);
                }
                Some((ctrl.effort().min(ceiling), None))
            }
        }
    }

    fn check(
        &mut self,
        i: &BlockInput,
        start: u64,
        target: u32,
        ramp_len: u64,
    ) -> Option<(u16, Option<Fault>)> {
        let effort = self.cfg.check_effort_q15.min(i.effort_ceiling_q15);
        let now = i.now_sample;
        if now < start + self.cfg.check_ms as u64 * SAMPLES_PER_MS as u64 {
            return Some((effort, None));
        }
        // The last window must have ended in the check's second half (after the rise).
        let half = start + self.cfg.check_ms as u64 * SAMPLES_PER_MS as u64 / 2;
        let y = match self.check_points.last() {
            Some(&(end, y)) if end >= half => y,
            _ => 0,
        };
        if y < self.cfg.check_min_mmps2 {
            let f = Fault { cause: FaultCause::LoopCheck, value: y as i32, at_sample: now };
            return Some((0, Some(f)));
        }
        // The model's decay per update (one update per window).
        let (y_inf, alpha) = extrapolate_rise(&self.check_points);
        let gain = y_inf as f32 / effort.max(1) as f32;
        #[cfg(test)]
        if std::env::var("CHLADNI_TRACE").is_ok() {
            std::println!("check: {:?} y_inf {y_inf} alpha {alpha}", self.check_points);
        }
        let ramp = Ramp::new(y, target, now, ramp_len);
        self.ctrl = Some(AmplitudeController::new(gain, effort, ramp).with_lag(alpha));
        self.monitors.new_setpoint();
        self.stage = Stage::Run;
        Some((effort, None))
    }
}

/// From the loop check's estimates (one per lock-in window, oldest first), the response the
/// check effort would settle to and the envelope's decay per window, assuming a first-order
/// rise (a resonant plate's envelope): with y₁, y₂, y₃ the responses k windows apart ending
/// with the newest (k = a third of the windows, so the drive's own start ramp is left out),
/// q = (y₃ − y₂)/(y₂ − y₁) and y∞ = y₃ + (y₃ − y₂)·q/(1 − q); neither needs the instant the drive
/// started. The decay per window is q^(1/k). q is clamped to [0, 0.8] (off resonance the
/// envelope is up at once and q is noise), so y∞ is at most y₃ + 4·(y₃ − y₂); a rise of less
/// than 5 % over the three points counts as settled (q = 0, y∞ = y₃).
pub fn extrapolate_rise(points: &[(u64, u32)]) -> (u32, f32) {
    let Some(&(_, y3)) = points.last() else { return (0, 0.0) };
    let k = ((points.len().saturating_sub(1)) / 3).max(1);
    if points.len() < 2 * k + 1 {
        return (y3, 0.0);
    }
    let y2 = points[points.len() - 1 - k].1;
    let y1 = points[points.len() - 1 - 2 * k].1;
    // Still rising by more than 5 % over the last 2k windows, or settled (and q is noise).
    if y2 <= y1 || y3 <= y2 || (y3 - y1) * 20 < y3 {
        return (y3, 0.0);
    }
    let q = ((y3 - y2) as f32 / (y2 - y1) as f32).clamp(0.0, 0.8);
    let y_inf = y3 as f32 + (y3 - y2) as f32 * q / (1.0 - q);
    let per_window = if q > 0.0 { F32Ext::powf(q, 1.0 / k as f32) } else { 0.0 };
    ((y_inf + 0.5) as u32, per_window)
}
