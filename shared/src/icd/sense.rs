//! Sensing and control on the wire: how loud a drive is asked to be ([`Level`]: a drive
//! fraction, open loop, or an acceleration held by the controller), what the accelerometer
//! measures ([`Measurement`]), why the drive stopped on its own ([`Fault`]), the thresholds the
//! fault monitors use ([`ControlConfig`]), and why the controller last reset ([`ResetCause`]).
//!
//! Integers only, in milli-units (mm/s², millidegrees, millidecibels), so the host and the
//! controller agree bit for bit and every type here is `Eq`.

use serde::{Deserialize, Serialize};

/// The level of a drive: a plan step's or a manual drive's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Level {
    /// Open loop: the drive amplitude, Q15 fraction of the output's full scale (0..=32767).
    Drive(u16),
    /// Closed loop: the plate's acceleration amplitude (peak) the controller holds, mm/s².
    Accel(u32),
}

impl Level {
    /// The acceleration target, mm/s², if closed loop.
    pub const fn accel_mmps2(self) -> Option<u32> {
        match self {
            Level::Accel(a) => Some(a),
            Level::Drive(_) => None,
        }
    }
}

/// What the accelerometer says the plate does at the drive frequency (lock-in output).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Measurement {
    /// Acceleration amplitude (peak) at the drive frequency, mm/s².
    pub accel_mmps2: u32,
    /// Phase of the acceleration against the drive's sine, millidegrees in (−180 000, 180 000].
    pub phase_mdeg: i32,
}

/// A sensor failure as the link reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorFault {
    /// The sensor did not acknowledge its address (absent, unpowered, bus stuck).
    Nack,
    /// WHO_AM_I read back another device's id.
    WrongId(u8),
    /// The sensor's FIFO overran: samples were lost.
    Overrun,
    /// Any other bus error.
    Bus,
}

impl SensorFault {
    /// Lowercase name as printed by the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            SensorFault::Nack => "sensor_nack",
            SensorFault::WrongId(_) => "sensor_wrong_id",
            SensorFault::Overrun => "sensor_overrun",
            SensorFault::Bus => "sensor_bus",
        }
    }
}

/// Why the drive ramped to zero by itself. Each cause says what [`Fault::value`] holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FaultCause {
    /// The drive was on and the plate did not answer (shaker disconnected, amplifier off).
    /// Value: the acceleration measured, mm/s².
    LoopOpen,
    /// The loop check before a closed-loop run saw too little response for its drive.
    /// Value: the acceleration measured, mm/s².
    LoopCheck,
    /// The response stayed outside the abort band around the target.
    /// Value: its deviation from the target, millidecibels (signed).
    OutOfBand,
    /// The acceleration went over the configured limit. Value: the acceleration, mm/s².
    OverAcceleration,
    /// The sensor failed. Value: 0.
    Sensor(SensorFault),
    /// No sensor data arrived for too long. Value: milliseconds since the last sample.
    NoData,
    /// The controller needed more drive than allowed for too long.
    /// Value: the effort asked for, Q15 (may exceed 32767).
    Saturation,
}

impl FaultCause {
    /// Lowercase name as printed by the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            FaultCause::LoopOpen => "loop_open",
            FaultCause::LoopCheck => "loop_check",
            FaultCause::OutOfBand => "out_of_band",
            FaultCause::OverAcceleration => "over_acceleration",
            FaultCause::Sensor(s) => s.name(),
            FaultCause::NoData => "no_data",
            FaultCause::Saturation => "saturation",
        }
    }

    /// The unit of [`Fault::value`] for this cause.
    pub const fn unit(self) -> &'static str {
        match self {
            FaultCause::LoopOpen | FaultCause::LoopCheck | FaultCause::OverAcceleration => "mm/s²",
            FaultCause::OutOfBand => "mdB",
            FaultCause::Sensor(_) => "",
            FaultCause::NoData => "ms",
            FaultCause::Saturation => "Q15",
        }
    }
}

/// A latched fault: what, how much, when. It stays until an explicit `ClearFault`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Fault {
    /// What went wrong.
    pub cause: FaultCause,
    /// The offending value (unit: [`FaultCause::unit`]).
    pub value: i32,
    /// When, in drive samples since the controller started (the sample clock).
    pub at_sample: u64,
}

/// Why the controller last started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResetCause {
    /// Power on or brown-out.
    PowerOn,
    /// The independent watchdog (a task stopped checking in).
    Watchdog,
    /// A software reset request.
    Software,
    /// The reset pin or anything else.
    Other,
}

impl ResetCause {
    /// Lowercase name as printed by the CLI.
    pub const fn name(self) -> &'static str {
        match self {
            ResetCause::PowerOn => "power_on",
            ResetCause::Watchdog => "watchdog",
            ResetCause::Software => "software",
            ResetCause::Other => "other",
        }
    }
}

/// Thresholds of the fault monitors and the loop check (part of the stored configuration).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ControlConfig {
    /// Response below which a drive of at least [`ControlConfig::open_loop_effort_q15`] counts
    /// as "no response" (loop open), mm/s².
    pub open_loop_mmps2: u32,
    /// Least drive at which a missing response is a fault, Q15.
    pub open_loop_effort_q15: u16,
    /// How long the response may be missing before the loop-open fault, ms.
    pub open_loop_ms: u32,
    /// Half-width of the warning band around a closed-loop target, millidecibels.
    pub warn_band_mdb: u32,
    /// Half-width of the abort band around a closed-loop target, millidecibels.
    pub abort_band_mdb: u32,
    /// How long the response may stay outside the abort band (after settling), ms.
    pub band_ms: u32,
    /// Over-acceleration limit: any measurement above it faults at once, mm/s².
    pub max_accel_mmps2: u32,
    /// Longest gap in sensor data while driving, ms.
    pub no_data_ms: u32,
    /// How long the controller may sit at its effort ceiling before the saturation fault, ms.
    pub saturation_ms: u32,
    /// Drive level of the loop check before a closed-loop run, Q15.
    pub check_effort_q15: u16,
    /// Length of the loop check, ms.
    pub check_ms: u32,
    /// Least response the loop check must see, mm/s².
    pub check_min_mmps2: u32,
}

impl ControlConfig {
    /// Factory thresholds, sized for the simulated plate (about 200 m/s² at resonance at full
    /// drive; see the docs on control).
    pub const DEFAULT: ControlConfig = ControlConfig {
        open_loop_mmps2: 50,
        open_loop_effort_q15: 4_000,
        open_loop_ms: 100,
        warn_band_mdb: 1_000,
        abort_band_mdb: 3_000,
        band_ms: 500,
        max_accel_mmps2: 150_000,
        no_data_ms: 12,
        saturation_ms: 50,
        check_effort_q15: 3_200,
        check_ms: 60,
        check_min_mmps2: 100,
    };
}

impl Default for ControlConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}
