//! Fault monitors: each watches one way the drive can go wrong and, past its threshold from
//! [`ControlConfig`], produces a [`Fault`] (cause, value in the cause's unit, sample).
//!
//! | monitor | trips when | value |
//! |---|---|---|
//! | over-acceleration | one measurement > `max_accel_mmps2` (at once) | mm/s² |
//! | loop open (collapse) | a measurement below 1/[`COLLAPSE_RATIO`] of the reference response | mm/s² |
//! | loop open (absent) | effort ≥ `open_loop_effort_q15` and response < `open_loop_mmps2` for `open_loop_ms` | mm/s² |
//! | no data | driving and no sensor sample for `no_data_ms` | ms |
//! | saturation (short) | closed loop, response below 1/[`SHORT_RATIO`] of the controller's model for `saturation_ms` | Q15 demand |
//! | saturation (ceiling) | closed loop and the controller's demand ≥ its ceiling for `saturation_ms` | Q15 demand |
//! | out of band | closed loop, settled, outside ± `abort_band_mdb` for `band_ms` | mdB |
//! | sensor | a sensor error passed in (at once) | 0 |
//!
//! The warn band (± `warn_band_mdb`, settled) sets a warning, no fault. "Settled" starts when
//! the setpoint ramp has ended and the response has come within the warn band once, or
//! `band_ms` after the ramp's end, whichever is first, so a slow plate still gets watched.
//! The loop check's own fault ([`crate::icd::sense::FaultCause::LoopCheck`]) is raised by
//! [`crate::drive::closed_loop`], which runs the check.
//!
//! **Loop open, fast.** When the shaker's force goes, the plate rings down freely: its response
//! falls as e^(−t/τ) (τ = 1/(ζω₀), 17.7 ms for the simulated plate) however hard it is driven.
//! The collapse rule compares each measurement with the reference response: the largest one
//! since the last change of the drive (a new frequency or phase, a new closed-loop setpoint,
//! or the effort falling by more than a tenth), once `check_ms` have passed after that change
//! (the plate's own transient has died down by then, as for the loop check). A response that
//! falls to under 1/8 of it at an effort that did not fall is a shaker that no longer drives
//! the plate: 1/8 is τ·ln 8 = 37 ms of free decay. Why 1/8 and not less: a clipping amplifier
//! also cuts the response, to 4c/πA of it (c the clip level, A the drive's peak: 1/4.75 for the
//! QEMU rig's 2 % clip under a 12 % drive), and off resonance the plate's ringing at its own
//! frequency beats against the drive's, dipping the clipped response to about 1/6 for a
//! moment; 1/8 keeps that a saturation. The floor is the plate's: a plate of higher Q rings
//! longer, and no accelerometer-only rule can see its force gone sooner than its ring-down.
//! The absent rule (absolute threshold, `open_loop_ms`) stays for drives that never had a
//! response to compare with (a drive started on a cut cable).
//!
//! **Saturation, fast.** In closed loop the controller's reference model says what the
//! response should be by now. A response under half of it for `saturation_ms` is a drive that
//! does not get through in full (a clipping amplifier, a ceiling): it would take the integrator
//! hundreds of milliseconds to climb to the ceiling and show it there (the ceiling rule, kept).
//! A cut shaker also falls short of the model, so the collapse rule, checked first, names it
//! before `saturation_ms` pass.
//!
//! Time is the DAC sample clock; a timer condition is tested once per block (5 ms), so a
//! timed fault trips between its threshold and one block after it. Conditions on the response
//! are evaluated when a measurement arrives (per lock-in window).

use crate::icd::sense::{ControlConfig, Fault, FaultCause, SensorFault};
use crate::icd::units::SAMPLES_PER_MS;

/// What the monitors are told once per block.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MonitorInput {
    /// The DAC sample clock now.
    pub now: u64,
    /// Whether the drive is on (a nonzero effort is being output or ramped).
    pub driving: bool,
    /// The effort output now, Q15.
    pub effort_q15: u16,
    /// A new measurement this block: amplitude, mm/s².
    pub response_mmps2: Option<u32>,
    /// Closed loop: the target (final, not ramped), the ramp's end sample, and the
    /// controller's demand (Q15, before clamping) and ceiling.
    pub closed: Option<ClosedInput>,
    /// The drive's waveform changed since the last check (a new frequency or phase).
    pub retuned: bool,
}

/// The collapse rule's ratio: a response under 1/8 of the reference is loop open (see the
/// module docs for why 8).
pub const COLLAPSE_RATIO: u32 = 8;
/// The least reference response the collapse rule judges by, in multiples of
/// `open_loop_mmps2` (smaller responses are too close to the noise for a ratio).
pub const COLLAPSE_MIN_MULTIPLE: u32 = 4;
/// The short-saturation ratio: a response under half of the controller's model.
pub const SHORT_RATIO: u32 = 2;

/// The collapse rule's reference: the largest response since the last change, and the effort
/// that gave it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Reference {
    response_mmps2: u32,
    effort_q15: u16,
}

/// The closed-loop part of [`MonitorInput`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ClosedInput {
    /// The target the ramp leads to, mm/s².
    pub target_mmps2: u32,
    /// Sample at which the setpoint ramp ends.
    pub ramp_end: u64,
    /// The controller's demand before clamping, Q15.
    pub demand_q15: u32,
    /// The controller's reference model: the response expected by now, mm/s².
    pub model_mmps2: u32,
    /// The effort ceiling, Q15.
    pub ceiling_q15: u16,
}

/// The monitors' state. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct Monitors {
    cfg: ControlConfig,
    last_data: u64,
    open_since: Option<u64>,
    saturated_since: Option<u64>,
    short_since: Option<u64>,
    reference: Option<Reference>,
    /// The collapse rule judges from this sample on (`check_ms` after the last change).
    armed_from: u64,
    out_since: Option<u64>,
    settled: bool,
    warning: bool,
    was_driving: bool,
    sensor: Option<SensorFault>,
    last_response: Option<u32>,
}

const fn ms(ms: u32) -> u64 {
    ms as u64 * SAMPLES_PER_MS as u64
}

impl Monitors {
    /// Monitors with thresholds `cfg`.
    pub const fn new(cfg: ControlConfig) -> Self {
        Self {
            cfg,
            last_data: 0,
            open_since: None,
            saturated_since: None,
            short_since: None,
            reference: None,
            // Armed `check_ms` after the first check that drives.
            armed_from: u64::MAX,
            out_since: None,
            settled: false,
            warning: false,
            was_driving: false,
            sensor: None,
            last_response: None,
        }
    }

    /// The thresholds.
    pub fn config(&self) -> &ControlConfig {
        &self.cfg
    }

    /// New thresholds (a configuration change); timers keep running.
    pub fn set_config(&mut self, cfg: ControlConfig) {
        self.cfg = cfg;
    }

    /// Sensor samples arrived at sample `now`.
    pub fn data(&mut self, now: u64) {
        self.last_data = now;
    }

    /// A sensor error: the next [`Monitors::check`] faults with it.
    pub fn sensor_error(&mut self, e: SensorFault) {
        self.sensor.get_or_insert(e);
    }

    /// A new setpoint (closed loop): out-of-band watching waits for settling again.
    pub fn new_setpoint(&mut self) {
        self.settled = false;
        self.out_since = None;
        self.warning = false;
        self.short_since = None;
        self.reference = None;
        self.armed_from = u64::MAX;
    }

    /// Whether the response is outside the warn band (settled, closed loop).
    pub fn warning(&self) -> bool {
        self.warning
    }

    /// Runs every monitor; returns the first fault found (in the order of the table above).
    pub fn check(&mut self, i: &MonitorInput) -> Option<Fault> {
        let fault = |cause, value: i64| Fault {
            cause,
            value: value.clamp(i32::MIN as i64, i32::MAX as i64) as i32,
            at_sample: i.now,
        };
        if !i.driving {
            // Nothing to protect: a sensor error now is forgotten (a sensor still broken
            // reports again, and faults the next drive within one retry).
            *self = Self { cfg: self.cfg, last_data: i.now, ..Self::new(self.cfg) };
            return None;
        }
        if let Some(s) = self.sensor.take() {
            return Some(fault(FaultCause::Sensor(s), 0));
        }
        if !self.was_driving {
            // The no-data gap counts from the start of the drive.
            self.was_driving = true;
            self.last_data = self.last_data.max(i.now);
        }
        if i.retuned || self.armed_from == u64::MAX {
            // A change of the drive: judge collapse again once the plate's transient is over.
            self.reference = None;
            self.armed_from = i.now.saturating_add(ms(self.cfg.check_ms));
        }
        if i.response_mmps2.is_some() {
            self.last_response = i.response_mmps2;
        }
        if let Some(y) = i.response_mmps2
            && y > self.cfg.max_accel_mmps2
        {
            return Some(fault(FaultCause::OverAcceleration, y as i64));
        }
        if let Some(y) = self.collapse(i) {
            return Some(fault(FaultCause::LoopOpen, y as i64));
        }
        if let Some(f) = self.loop_open(i) {
            return Some(fault(FaultCause::LoopOpen, f as i64));
        }
        let gap = i.now.saturating_sub(self.last_data);
        if gap >= ms(self.cfg.no_data_ms) {
            return Some(fault(FaultCause::NoData, (gap / SAMPLES_PER_MS as u64) as i64));
        }
        let Some(c) = i.closed else {
            self.short_since = None;
            return None;
        };
        if let Some(d) = self.short(i, &c) {
            return Some(fault(FaultCause::Saturation, d as i64));
        }
        if let Some(d) = self.saturation(i.now, &c) {
            return Some(fault(FaultCause::Saturation, d as i64));
        }
        self.band(i, &c).map(|mdb| fault(FaultCause::OutOfBand, mdb as i64))
    }

    /// The collapse rule (see the module docs): the response now, if it collapsed.
    fn collapse(&mut self, i: &MonitorInput) -> Option<u32> {
        let y = i.response_mmps2?;
        if i.now < self.armed_from {
            return None;
        }
        let reference = match self.reference {
            // The effort fell by more than a tenth: the response falls with it, legitimately
            // (and lags it): start again after the transient.
            Some(r) if (i.effort_q15 as u32) * 10 < r.effort_q15 as u32 * 9 => {
                self.reference = None;
                self.armed_from = i.now.saturating_add(ms(self.cfg.check_ms));
                return None;
            }
            Some(r) if r.response_mmps2 >= y => r,
            _ => {
                self.reference = Some(Reference { response_mmps2: y, effort_q15: i.effort_q15 });
                return None;
            }
        };
        let floor = self.cfg.open_loop_mmps2.saturating_mul(COLLAPSE_MIN_MULTIPLE);
        let collapsed = reference.response_mmps2 >= floor
            && y.saturating_mul(COLLAPSE_RATIO) < reference.response_mmps2;
        collapsed.then_some(y)
    }

    /// The short-saturation rule: the demand, once the response has stayed under half of the
    /// controller's model for `saturation_ms`.
    fn short(&mut self, i: &MonitorInput, c: &ClosedInput) -> Option<u32> {
        if let Some(y) = i.response_mmps2 {
            if y.saturating_mul(SHORT_RATIO) >= c.model_mmps2 {
                self.short_since = None;
                return None;
            }
            self.short_since.get_or_insert(i.now);
        }
        let since = self.short_since?;
        (i.now - since >= ms(self.cfg.saturation_ms)).then_some(c.demand_q15)
    }

    fn loop_open(&mut self, i: &MonitorInput) -> Option<u32> {
        let y = self.last_response?;
        let open = i.effort_q15 >= self.cfg.open_loop_effort_q15 && y < self.cfg.open_loop_mmps2;
        if !open {
            self.open_since = None;
            return None;
        }
        let since = *self.open_since.get_or_insert(i.now);
        (i.now - since >= ms(self.cfg.open_loop_ms)).then_some(y)
    }

    fn saturation(&mut self, now: u64, c: &ClosedInput) -> Option<u32> {
        if c.demand_q15 < c.ceiling_q15 as u32 {
            self.saturated_since = None;
            return None;
        }
        let since = *self.saturated_since.get_or_insert(now);
        (now - since >= ms(self.cfg.saturation_ms)).then_some(c.demand_q15)
    }

    fn band(&mut self, i: &MonitorInput, c: &ClosedInput) -> Option<i32> {
        if i.now < c.ramp_end {
            return None;
        }
        let y = i.response_mmps2?;
        let dev = deviation_mdb(y, c.target_mmps2);
        let outside_warn = dev.unsigned_abs() > self.cfg.warn_band_mdb;
        if !self.settled {
            let late = i.now - c.ramp_end >= ms(self.cfg.band_ms);
            self.settled = !outside_warn || late;
            if !self.settled {
                return None;
            }
        }
        self.warning = outside_warn;
        // Below the target with drive to spare, the controller is still climbing: if it gets
        // there, fine; if it cannot, it ends at its ceiling and that is the cause to name
        // (saturation), not the band.
        let climbing = dev < 0 && c.demand_q15 < c.ceiling_q15 as u32;
        if dev.unsigned_abs() <= self.cfg.abort_band_mdb || climbing {
            self.out_since = None;
            return None;
        }
        let since = *self.out_since.get_or_insert(i.now);
        (i.now - since >= ms(self.cfg.band_ms)).then_some(dev)
    }
}

/// 20·log10(y/target) in millidecibels (±200 dB for a zero on either side).
pub fn deviation_mdb(y: u32, target: u32) -> i32 {
    use micromath::F32Ext;
    match (y, target) {
        (0, 0) => 0,
        (0, _) => -200_000,
        (_, 0) => 200_000,
        _ => {
            let db = 20.0 * F32Ext::log10(y as f32 / target as f32);
            (db * 1000.0) as i32
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deviation_in_mdb() {
        assert_eq!(deviation_mdb(1000, 1000), 0);
        assert!((deviation_mdb(2000, 1000) - 6021).abs() < 25);
        assert!((deviation_mdb(500, 1000) + 6021).abs() < 25);
        assert_eq!(deviation_mdb(0, 5), -200_000);
    }

    #[test]
    fn sensor_error_faults_at_once_while_driving_and_idle_resets_timers() {
        let mut m = Monitors::new(ControlConfig::DEFAULT);
        m.sensor_error(SensorFault::Bus);
        let i = MonitorInput {
            now: 7,
            driving: true,
            effort_q15: 0,
            response_mmps2: None,
            closed: None,
            retuned: false,
        };
        assert_eq!(m.check(&i).map(|f| f.cause), Some(FaultCause::Sensor(SensorFault::Bus)));
        // Not driving: a sensor error is forgotten, and no no-data fault however long.
        m.sensor_error(SensorFault::Nack);
        let idle = MonitorInput { now: 1_000_000, driving: false, ..i };
        assert_eq!(m.check(&idle), None);
        assert_eq!(m.check(&MonitorInput { now: 1_000_001, ..idle }), None);
        assert_eq!(m.check(&MonitorInput { now: 1_000_002, ..i }), None);
    }

    /// Open loop at a steady effort: `y` at sample `now`.
    fn measured(now: u64, effort_q15: u16, y: u32) -> MonitorInput {
        MonitorInput {
            now,
            driving: true,
            effort_q15,
            response_mmps2: Some(y),
            closed: None,
            retuned: false,
        }
    }

    #[test]
    fn collapse_waits_out_the_transient_and_follows_the_effort() {
        let cfg = ControlConfig::DEFAULT;
        let hold = ms(cfg.check_ms);
        let mut m = Monitors::new(cfg);
        let mut t = 0;
        let feed = |m: &mut Monitors, t: &mut u64, effort, y| {
            *t += 250;
            m.data(*t);
            m.check(&measured(*t, effort, y))
        };
        // Within check_ms of the start a collapse is not judged (the plate's transient).
        assert_eq!(feed(&mut m, &mut t, 2000, 10_000), None);
        assert_eq!(feed(&mut m, &mut t, 2000, 100), None);
        while t < hold + 250 {
            assert_eq!(feed(&mut m, &mut t, 2000, 10_000), None);
        }
        // Armed: 1/8 of the reference is the limit.
        assert_eq!(feed(&mut m, &mut t, 2000, 1_300), None);
        let f = feed(&mut m, &mut t, 2100, 1_200).expect("collapsed");
        assert_eq!((f.cause, f.value), (FaultCause::LoopOpen, 1_200));
        // An effort that falls by more than a tenth starts the reference again.
        let mut m = Monitors::new(cfg);
        while t < 4 * hold {
            assert_eq!(feed(&mut m, &mut t, 2000, 10_000), None);
        }
        assert_eq!(feed(&mut m, &mut t, 1700, 1_000), None);
        assert_eq!(feed(&mut m, &mut t, 1700, 1_000), None, "held off after the effort fell");
    }

    #[test]
    fn short_of_the_model_is_saturation_after_saturation_ms() {
        let cfg = ControlConfig::DEFAULT;
        let mut m = Monitors::new(cfg);
        let closed = ClosedInput {
            target_mmps2: 10_000,
            ramp_end: 0,
            demand_q15: 9_000,
            model_mmps2: 10_000,
            ceiling_q15: 32_767,
        };
        let at = |now, y| MonitorInput { closed: Some(closed), ..measured(now, 9_000, y) };
        m.data(1_000);
        assert_eq!(m.check(&at(1_000, 9_900)), None);
        // Just under half of the model from sample 2000 on: saturation saturation_ms later.
        let start = 2_000;
        let end = start + ms(cfg.saturation_ms);
        let mut now = start;
        while now < end {
            m.data(now);
            assert_eq!(m.check(&at(now, 4_999)), None, "{now}");
            now += 250;
        }
        m.data(end);
        let f = m.check(&at(end, 4_999)).expect("saturated");
        assert_eq!((f.cause, f.value, f.at_sample), (FaultCause::Saturation, 9_000, end));
    }
}
