//! The JSON shapes of the controller's status, telemetry and stored plans, as `chladni device
//! --json` prints them and `chladni serve` answers them (keys in alphabetical order; documented
//! in docs/device.md, "Drive and status" and "Telemetry"). One home, so the CLI and the cell's
//! HTTP API never disagree.

use chladni_shared::icd::link::{StatusReport, Telemetry};
use chladni_shared::icd::plan::Level;
use chladni_shared::icd::sense::Fault;
use chladni_shared::icd::store::PlanSummary;
use chladni_shared::icd::units::{MilliDeg, MilliHz, MmPerS2, Q15};
use serde::Serialize;

/// The `status --json` object: the keys of protocol v1's status; `fault`, `plan`,
/// `remaining_ms`, `run` (v3); the sensing and control keys `accel_mps2`, `phase_deg`,
/// `effort`, `target_accel_mps2`, `warning`, `reset_cause` (v4; `fault` became an object).
#[derive(Debug, Clone, Serialize)]
pub struct StatusJson {
    /// Measured acceleration amplitude, m/s² (null without a measurement).
    pub accel_mps2: Option<f64>,
    pub amplitude: f64,
    /// The drive output (the control effort in closed loop), fraction of full scale.
    pub effort: f64,
    pub elapsed_ms: f64,
    pub fault: Option<FaultJson>,
    pub freq_hz: f64,
    /// The least refill slack since the controller started, µs (null before the first block).
    pub least_slack_us: Option<u32>,
    /// Measured phase against the drive, degrees (null without a measurement).
    pub phase_deg: Option<f64>,
    pub plan: Option<String>,
    pub remaining_ms: f64,
    pub reset_cause: &'static str,
    pub run: u32,
    /// The most stack the controller has used, bytes (0: not measured).
    pub stack_high_water: u32,
    pub state: &'static str,
    pub step: Option<u16>,
    /// The closed-loop target as ramped so far, m/s² (null in open loop or idle).
    pub target_accel_mps2: Option<f64>,
    pub underruns: u32,
    pub warning: bool,
}

/// A latched fault: `{"cause", "value", "unit", "at_s"}`.
#[derive(Debug, Clone, Serialize)]
pub struct FaultJson {
    pub at_s: f64,
    pub cause: &'static str,
    pub unit: &'static str,
    pub value: i32,
}

impl FaultJson {
    pub fn of(f: &Fault, sample_rate: u32) -> Self {
        FaultJson {
            at_s: f.at_sample as f64 / f64::from(sample_rate.max(1)),
            cause: f.cause.name(),
            unit: f.cause.unit(),
            value: f.value,
        }
    }

    /// For people: cause, value with its unit, time, and the fix.
    pub fn text(&self) -> String {
        let value = if self.unit.is_empty() {
            String::new()
        } else {
            format!(" {} {}", self.value, self.unit)
        };
        format!(
            "{}{value} at {:.3} s (`chladni device clear-fault` clears it)",
            self.cause, self.at_s
        )
    }
}

impl From<&StatusReport> for StatusJson {
    fn from(s: &StatusReport) -> Self {
        StatusJson {
            accel_mps2: s.measured.map(|m| MmPerS2(m.accel_mmps2).to_mps2()),
            amplitude: Q15(s.amplitude_q15).to_fraction(),
            effort: Q15(s.amplitude_q15).to_fraction(),
            elapsed_ms: s.elapsed_ms(),
            fault: s.fault.map(|f| FaultJson::of(&f, s.sample_rate)),
            freq_hz: MilliHz(s.freq_mhz).to_hz(),
            least_slack_us: s.least_slack_us,
            phase_deg: s.measured.map(|m| MilliDeg(m.phase_mdeg).to_deg()),
            plan: s.plan.as_ref().map(|p| p.to_string()),
            remaining_ms: s.remaining_ms(),
            reset_cause: s.reset_cause.name(),
            run: s.run.0,
            stack_high_water: s.stack_high_water,
            state: s.state.name(),
            step: s.step,
            target_accel_mps2: s.level.and_then(Level::accel_mmps2).map(|a| MmPerS2(a).to_mps2()),
            underruns: s.underruns,
            warning: s.warning,
        }
    }
}

/// One line of `monitor --json`: the sample's number, how many are still to come, and the
/// status keys of `status --json`.
#[derive(Debug, Clone, Serialize)]
pub struct TelemetryJson {
    pub left: u32,
    pub seq: u32,
    #[serde(flatten)]
    pub status: StatusJson,
}

impl From<&Telemetry> for TelemetryJson {
    fn from(t: &Telemetry) -> Self {
        TelemetryJson { left: t.left, seq: t.seq, status: StatusJson::from(&t.status) }
    }
}

/// One stored plan, as `plans --json`, `upload --json` and `delete --json` print it.
#[derive(Debug, Clone, Serialize)]
pub struct PlanJson {
    pub bytes: u32,
    /// The plan CRC (CRC-32/ISO-HDLC), as a number; the tables print it as 8 hex digits.
    pub crc: u32,
    pub name: String,
    pub slot: u8,
    pub steps: u16,
    pub total_ms: u64,
}

impl From<&PlanSummary> for PlanJson {
    fn from(p: &PlanSummary) -> Self {
        PlanJson {
            bytes: p.bytes,
            crc: p.crc,
            name: p.name.to_string(),
            slot: p.slot,
            steps: p.steps,
            total_ms: p.total_ms,
        }
    }
}

/// The `plans --json` object.
#[derive(Debug, Clone, Serialize)]
pub struct PlansJson {
    pub free_bytes: u32,
    pub plans: Vec<PlanJson>,
}
