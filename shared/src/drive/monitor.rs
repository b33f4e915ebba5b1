//! Fault monitors: each watches one way the drive can go wrong and, past its threshold from
//! [`ControlConfig`], produces a [`Fault`] (cause, value in the cause's unit, sample).
//!
//! | monitor | trips when | value |
//! |---|---|---|
//! | over-acceleration | one measurement > `max_accel_mmps2` (at once) | mm/s² |
//! | loop open | effort ≥ `open_loop_effort_q15` and response < `open_loop_mmps2` for `open_loop_ms` | mm/s² |
//! | no data | driving and no sensor sample for `no_data_ms` | ms |
//! | saturation | closed loop and the controller's demand ≥ its ceiling for `saturation_ms` | Q15 demand |
//! | out of band | closed loop, settled, outside ± `abort_band_mdb` for `band_ms` | mdB |
//! | sensor | a sensor error passed in (at once) | 0 |
//!
//! The warn band (± `warn_band_mdb`, settled) sets a warning, no fault. "Settled" starts when
//! the setpoint ramp has ended and the response has come within the warn band once, or
//! `band_ms` after the ramp's end, whichever is first, so a slow plate still gets watched.
//! The loop check's own fault ([`crate::icd::sense::FaultCause::LoopCheck`]) is raised by
//! [`crate::drive::closed_loop`], which runs the check.
//!
//! Time is the DAC sample clock; a timer condition is tested once per block (5 ms), so a
//! timed fault trips between its threshold and one block after it. Conditions on the response
//! are evaluated when a measurement arrives (per lock-in window).

use crate::drive::dds::SAMPLES_PER_MS;
use crate::icd::sense::{ControlConfig, Fault, FaultCause, SensorFault};

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
        if i.response_mmps2.is_some() {
            self.last_response = i.response_mmps2;
        }
        if let Some(y) = i.response_mmps2
            && y > self.cfg.max_accel_mmps2
        {
            return Some(fault(FaultCause::OverAcceleration, y as i64));
        }
        if let Some(f) = self.loop_open(i) {
            return Some(fault(FaultCause::LoopOpen, f as i64));
        }
        let gap = i.now.saturating_sub(self.last_data);
        if gap >= ms(self.cfg.no_data_ms) {
            return Some(fault(FaultCause::NoData, (gap / SAMPLES_PER_MS as u64) as i64));
        }
        let c = i.closed?;
        if let Some(d) = self.saturation(i.now, &c) {
            return Some(fault(FaultCause::Saturation, d as i64));
        }
        self.band(i, &c).map(|mdb| fault(FaultCause::OutOfBand, mdb as i64))
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
        };
        assert_eq!(m.check(&i).map(|f| f.cause), Some(FaultCause::Sensor(SensorFault::Bus)));
        // Not driving: a sensor error is forgotten, and no no-data fault however long.
        m.sensor_error(SensorFault::Nack);
        let idle = MonitorInput { now: 1_000_000, driving: false, ..i };
        assert_eq!(m.check(&idle), None);
        assert_eq!(m.check(&MonitorInput { now: 1_000_001, ..idle }), None);
        assert_eq!(m.check(&MonitorInput { now: 1_000_002, ..i }), None);
    }
}
