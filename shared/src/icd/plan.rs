//! Drive plans: an ordered list of frequency steps, run `repeat` times, and their validation
//! against the limits of a device.
//!
//! A plan is the same value on the host (written as JSON by the planner, read by
//! `chladni device run-file`) and on the wire ([`crate::icd::link::Request::RunPlan`]). Units are
//! integers so that both sides compute the same sample counts: frequency in millihertz,
//! level either a drive amplitude in Q15 (32767 ≈ full scale of the output, open loop) or a
//! plate acceleration in mm/s² that the controller holds (closed loop), times in milliseconds.
//!
//! JSON form:
//! ```json
//! {"name": "square-45", "repeat": 1,
//!  "steps": [{"freq_mhz": 120000, "level": {"Drive": 16384}, "duration_ms": 500, "ramp_ms": 20},
//!            {"freq_mhz": 180000, "level": {"Accel": 20000}, "duration_ms": 500, "ramp_ms": 20}]}
//! ```

use serde::{Deserialize, Serialize};

use super::units::SAMPLES_PER_MS;
pub use crate::icd::sense::Level;

/// Most steps a plan may hold (it is uploaded in chunks, see [`crate::icd::store`]).
pub const MAX_STEPS: usize = 256;
/// Longest plan name, in bytes.
pub const MAX_NAME: usize = 32;

/// One step: drive at `freq_mhz` at `level` for `duration_ms`; the amplitude (open loop) or
/// the acceleration target (closed loop) moves from its previous value to this step's over the
/// first `ramp_ms` (linearly).
/// The frequency switches at the step's first sample, keeping the phase.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Step {
    /// Drive frequency, millihertz.
    pub freq_mhz: u32,
    /// Drive amplitude (open loop) or acceleration target (closed loop).
    pub level: Level,
    /// Step length, milliseconds (ramp included).
    pub duration_ms: u32,
    /// Amplitude ramp at the start of the step, milliseconds (≤ `duration_ms`).
    pub ramp_ms: u32,
}

impl Step {
    /// Step length in samples.
    pub const fn duration_samples(&self) -> u32 {
        self.duration_ms.saturating_mul(SAMPLES_PER_MS)
    }
    /// Ramp length in samples.
    pub const fn ramp_samples(&self) -> u32 {
        self.ramp_ms.saturating_mul(SAMPLES_PER_MS)
    }
}

/// A named sequence of steps, run `repeat` times (1 = once). At its end the drive ramps to zero
/// over the last step's ramp (at least [`crate::drive::runner::STOP_RAMP_MS`]) and goes idle.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Plan {
    /// Name, for logs and status.
    pub name: heapless::String<MAX_NAME>,
    /// How many times the steps run (≥ 1).
    pub repeat: u16,
    /// The steps, in order.
    pub steps: heapless::Vec<Step, MAX_STEPS>,
}

impl Plan {
    /// Makes `self` a copy of `other` in place. `clone_from` would build the whole plan
    /// (5 KiB) as a temporary first, and on the controller that lands on the link's stack.
    pub fn copy_from(&mut self, other: &Plan) {
        self.name.clone_from(&other.name);
        self.repeat = other.repeat;
        self.steps.clear();
        for step in &other.steps {
            // Same capacity on both sides: every step fits.
            let _ = self.steps.push(*step);
        }
    }

    /// Total length of all runs, milliseconds (without the final ramp to zero).
    pub fn total_ms(&self) -> u64 {
        self.steps.iter().map(|s| s.duration_ms as u64).sum::<u64>() * self.repeat as u64
    }

    /// Checks the plan against `limits`; the first problem found is returned.
    pub fn validate(&self, limits: &DeviceLimits) -> Result<(), PlanError> {
        limits.check_plan_header(self.repeat, self.steps.len().min(u16::MAX as usize) as u16)?;
        for (i, s) in self.steps.iter().enumerate() {
            limits.check_step(i as u16, s)?;
        }
        limits.check_total_ms(self.total_ms())
    }
}

/// What a device can do; plans are validated against it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceLimits {
    /// Lowest drive frequency, millihertz.
    pub min_freq_mhz: u32,
    /// Highest drive frequency, millihertz.
    pub max_freq_mhz: u32,
    /// Highest amplitude, Q15 (also the closed loop's effort ceiling).
    pub max_amplitude_q15: u16,
    /// Highest closed-loop acceleration target, mm/s².
    pub max_accel_mmps2: u32,
    /// Most steps per plan.
    pub max_steps: u16,
    /// Longest plan (all repeats), milliseconds.
    pub max_total_ms: u64,
}

impl DeviceLimits {
    /// The controller's limits: 1–2000 Hz, full DAC scale, 100 m/s², [`MAX_STEPS`] steps, one hour.
    pub const DEFAULT: DeviceLimits = DeviceLimits {
        min_freq_mhz: 1_000,
        max_freq_mhz: 2_000_000,
        max_amplitude_q15: 32767,
        max_accel_mmps2: 100_000,
        max_steps: MAX_STEPS as u16,
        max_total_ms: 3_600_000,
    };

    /// Checks a setpoint (frequency and level), a manual drive's or a plan step's.
    pub fn check_setpoint(&self, freq_mhz: u32, level: Level) -> Result<(), SetpointError> {
        if freq_mhz < self.min_freq_mhz || freq_mhz > self.max_freq_mhz {
            return Err(SetpointError::FrequencyOutOfRange {
                freq_mhz,
                min_mhz: self.min_freq_mhz,
                max_mhz: self.max_freq_mhz,
            });
        }
        match level {
            Level::Drive(amplitude_q15) if amplitude_q15 > self.max_amplitude_q15 => {
                Err(SetpointError::AmplitudeTooHigh {
                    amplitude_q15,
                    max_q15: self.max_amplitude_q15,
                })
            }
            Level::Accel(accel_mmps2) if accel_mmps2 > self.max_accel_mmps2 => {
                Err(SetpointError::AccelTooHigh { accel_mmps2, max_mmps2: self.max_accel_mmps2 })
            }
            _ => Ok(()),
        }
    }
}

impl DeviceLimits {
    /// Checks plan step number `index`: its setpoint, a non-zero length, a ramp within it.
    pub fn check_step(&self, index: u16, s: &Step) -> Result<(), PlanError> {
        self.check_setpoint(s.freq_mhz, s.level).map_err(|e| e.at_step(index))?;
        if s.duration_ms == 0 {
            return Err(PlanError::ZeroDuration { step: index });
        }
        if s.ramp_ms > s.duration_ms {
            return Err(PlanError::RampLongerThanStep {
                step: index,
                ramp_ms: s.ramp_ms,
                duration_ms: s.duration_ms,
            });
        }
        Ok(())
    }

    /// Checks the length of all repeats of a plan, ms.
    pub fn check_total_ms(&self, total_ms: u64) -> Result<(), PlanError> {
        if total_ms > self.max_total_ms {
            return Err(PlanError::TooLong { total_ms, max_ms: self.max_total_ms });
        }
        Ok(())
    }
}

impl Default for DeviceLimits {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a plan was refused. `step` is the step's index in the plan, 0-based (what the wire
/// carries); the message (`Display`) numbers steps from 1, as people read them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PlanError {
    /// The plan has no steps.
    Empty,
    /// More steps than the device takes.
    TooManySteps {
        /// Steps in the plan.
        count: u16,
        /// The limit.
        max: u16,
    },
    /// `repeat` is 0.
    ZeroRepeat,
    /// A step's frequency is outside the device's range.
    FrequencyOutOfRange {
        /// Step index, 0-based (the message prints it 1-based).
        step: u16,
        /// The frequency asked for, mHz.
        freq_mhz: u32,
        /// Lowest allowed, mHz.
        min_mhz: u32,
        /// Highest allowed, mHz.
        max_mhz: u32,
    },
    /// A step's amplitude is above the device's maximum.
    AmplitudeTooHigh {
        /// Step index, 0-based (the message prints it 1-based).
        step: u16,
        /// The amplitude asked for, Q15.
        amplitude_q15: u16,
        /// Highest allowed, Q15.
        max_q15: u16,
    },
    /// A step's acceleration target is above the device's maximum.
    AccelTooHigh {
        /// Step index, 0-based (the message prints it 1-based).
        step: u16,
        /// The target asked for, mm/s².
        accel_mmps2: u32,
        /// Highest allowed, mm/s².
        max_mmps2: u32,
    },
    /// A step lasts 0 ms.
    ZeroDuration {
        /// Step index, 0-based (the message prints it 1-based).
        step: u16,
    },
    /// A step's ramp is longer than the step.
    RampLongerThanStep {
        /// Step index, 0-based (the message prints it 1-based).
        step: u16,
        /// The ramp, ms.
        ramp_ms: u32,
        /// The step, ms.
        duration_ms: u32,
    },
    /// All repeats together last longer than the device allows.
    TooLong {
        /// Plan length, ms.
        total_ms: u64,
        /// The limit, ms.
        max_ms: u64,
    },
}

/// Why a setpoint (frequency, amplitude) is outside the device's limits. A manual drive is
/// refused with this error alone; a plan step's becomes a [`PlanError`] naming the step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SetpointError {
    /// The frequency is outside the device's range.
    FrequencyOutOfRange {
        /// The frequency asked for, mHz.
        freq_mhz: u32,
        /// Lowest allowed, mHz.
        min_mhz: u32,
        /// Highest allowed, mHz.
        max_mhz: u32,
    },
    /// The amplitude is above the device's maximum.
    AmplitudeTooHigh {
        /// The amplitude asked for, Q15.
        amplitude_q15: u16,
        /// Highest allowed, Q15.
        max_q15: u16,
    },
    /// The acceleration target is above the device's maximum.
    AccelTooHigh {
        /// The target asked for, mm/s².
        accel_mmps2: u32,
        /// Highest allowed, mm/s².
        max_mmps2: u32,
    },
}

impl SetpointError {
    /// The same problem, found in plan step `step`.
    pub const fn at_step(self, step: u16) -> PlanError {
        match self {
            SetpointError::FrequencyOutOfRange { freq_mhz, min_mhz, max_mhz } => {
                PlanError::FrequencyOutOfRange { step, freq_mhz, min_mhz, max_mhz }
            }
            SetpointError::AmplitudeTooHigh { amplitude_q15, max_q15 } => {
                PlanError::AmplitudeTooHigh { step, amplitude_q15, max_q15 }
            }
            SetpointError::AccelTooHigh { accel_mmps2, max_mmps2 } => {
                PlanError::AccelTooHigh { step, accel_mmps2, max_mmps2 }
            }
        }
    }
}

/// A milli-unit (mHz as Hz, mm/s² as m/s²) as `X.mmm` (exact: no float formatting on the
/// controller).
struct Hz(u32);

impl core::fmt::Display for Hz {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{}.{:03}", self.0 / 1000, self.0 % 1000)
    }
}

impl core::fmt::Display for SetpointError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            SetpointError::FrequencyOutOfRange { freq_mhz, min_mhz, max_mhz } => write!(
                f,
                "frequency {} Hz outside {}..={} Hz",
                Hz(freq_mhz),
                Hz(min_mhz),
                Hz(max_mhz)
            ),
            SetpointError::AmplitudeTooHigh { amplitude_q15, max_q15 } => {
                write!(f, "amplitude {amplitude_q15}/32768 above the maximum {max_q15}/32768")
            }
            SetpointError::AccelTooHigh { accel_mmps2, max_mmps2 } => write!(
                f,
                "acceleration target {} m/s² above the maximum {} m/s²",
                Hz(accel_mmps2),
                Hz(max_mmps2)
            ),
        }
    }
}

impl core::error::Error for SetpointError {}

/// A step index (0-based, as on the wire) as people number steps: from 1, as `chladni plan`
/// prints them.
fn step_number(index: u16) -> u32 {
    u32::from(index) + 1
}

impl core::fmt::Display for PlanError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            PlanError::Empty => write!(f, "plan has no steps"),
            PlanError::TooManySteps { count, max } => {
                write!(f, "plan has {count} steps, the device takes at most {max}")
            }
            PlanError::ZeroRepeat => write!(f, "repeat must be at least 1"),
            PlanError::FrequencyOutOfRange { step, freq_mhz, min_mhz, max_mhz } => {
                let e = SetpointError::FrequencyOutOfRange { freq_mhz, min_mhz, max_mhz };
                write!(f, "step {}: {e}", step_number(step))
            }
            PlanError::AmplitudeTooHigh { step, amplitude_q15, max_q15 } => {
                let e = SetpointError::AmplitudeTooHigh { amplitude_q15, max_q15 };
                write!(f, "step {}: {e}", step_number(step))
            }
            PlanError::AccelTooHigh { step, accel_mmps2, max_mmps2 } => {
                let e = SetpointError::AccelTooHigh { accel_mmps2, max_mmps2 };
                write!(f, "step {}: {e}", step_number(step))
            }
            PlanError::ZeroDuration { step } => {
                write!(f, "step {}: duration is 0 ms", step_number(step))
            }
            PlanError::RampLongerThanStep { step, ramp_ms, duration_ms } => write!(
                f,
                "step {}: ramp {ramp_ms} ms longer than the step ({duration_ms} ms)",
                step_number(step)
            ),
            PlanError::TooLong { total_ms, max_ms } => {
                write!(f, "plan lasts {total_ms} ms, the device allows at most {max_ms} ms")
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn step(freq_mhz: u32, amplitude_q15: u16, duration_ms: u32, ramp_ms: u32) -> Step {
        Step { freq_mhz, level: Level::Drive(amplitude_q15), duration_ms, ramp_ms }
    }

    fn plan(steps: &[Step]) -> Plan {
        Plan {
            name: heapless::String::try_from("t").unwrap(),
            repeat: 1,
            steps: heapless::Vec::from_slice(steps).unwrap(),
        }
    }

    #[test]
    fn copy_from_makes_an_equal_plan_over_a_longer_one() {
        let long: heapless::Vec<Step, MAX_STEPS> =
            (0..MAX_STEPS as u32).map(|i| step(1_000 + i, 100, 10, 0)).collect();
        let mut dst = plan(&long);
        dst.repeat = 7;
        let mut src = plan(&[step(2_000, 200, 20, 5), step(3_000, 300, 30, 5)]);
        src.name = heapless::String::try_from("second").unwrap();
        dst.copy_from(&src);
        assert_eq!(dst, src);
        let full = plan(&long);
        dst.copy_from(&full);
        assert_eq!(dst, full);
    }

    #[test]
    fn valid_plan_passes() {
        let p = plan(&[step(1_000, 0, 1, 0), step(2_000_000, 32767, 100, 100)]);
        assert_eq!(p.validate(&DeviceLimits::DEFAULT), Ok(()));
        assert_eq!(p.total_ms(), 101);
    }

    #[test]
    fn each_error_is_named() {
        let l = DeviceLimits::DEFAULT;
        assert_eq!(plan(&[]).validate(&l), Err(PlanError::Empty));
        let mut p = plan(&[step(100_000, 100, 10, 0)]);
        p.repeat = 0;
        assert_eq!(p.validate(&l), Err(PlanError::ZeroRepeat));
        assert_eq!(
            plan(&[step(100_000, 1, 10, 0), step(999, 1, 10, 0)]).validate(&l),
            Err(PlanError::FrequencyOutOfRange {
                step: 1,
                freq_mhz: 999,
                min_mhz: 1_000,
                max_mhz: 2_000_000
            })
        );
        assert!(matches!(
            plan(&[step(2_000_001, 1, 10, 0)]).validate(&l),
            Err(PlanError::FrequencyOutOfRange { step: 0, .. })
        ));
        assert_eq!(
            plan(&[step(100_000, 40_000, 10, 0)]).validate(&l),
            Err(PlanError::AmplitudeTooHigh { step: 0, amplitude_q15: 40_000, max_q15: 32767 })
        );
        assert_eq!(
            plan(&[step(100_000, 1, 0, 0)]).validate(&l),
            Err(PlanError::ZeroDuration { step: 0 })
        );
        assert_eq!(
            plan(&[step(100_000, 1, 10, 11)]).validate(&l),
            Err(PlanError::RampLongerThanStep { step: 0, ramp_ms: 11, duration_ms: 10 })
        );
        let mut p = plan(&[step(100_000, 1, 3_600_000, 0)]);
        assert_eq!(p.validate(&l), Ok(()));
        p.repeat = 2;
        assert_eq!(
            p.validate(&l),
            Err(PlanError::TooLong { total_ms: 7_200_000, max_ms: 3_600_000 })
        );
        let small = DeviceLimits { max_steps: 1, ..l };
        assert_eq!(
            plan(&[step(100_000, 1, 1, 0); 2]).validate(&small),
            Err(PlanError::TooManySteps { count: 2, max: 1 })
        );
    }

    #[test]
    fn setpoint_errors_name_the_value_and_range_and_no_step() {
        let l = DeviceLimits::DEFAULT;
        assert_eq!(l.check_setpoint(2_000_000, Level::Drive(32767)), Ok(()));
        let fast = l.check_setpoint(5_000_000, Level::Drive(1)).unwrap_err();
        assert_eq!(
            fast,
            SetpointError::FrequencyOutOfRange {
                freq_mhz: 5_000_000,
                min_mhz: 1_000,
                max_mhz: 2_000_000
            }
        );
        assert_eq!(std::format!("{fast}"), "frequency 5000.000 Hz outside 1.000..=2000.000 Hz");
        let loud = l.check_setpoint(440_000, Level::Drive(40_000)).unwrap_err();
        assert_eq!(std::format!("{loud}"), "amplitude 40000/32768 above the maximum 32767/32768");
        // In a plan, the same problem names its step, numbered from 1 (index 3 is step 4);
        // the last index a plan can carry still has its number.
        assert_eq!(
            std::format!("{}", fast.at_step(3)),
            "step 4: frequency 5000.000 Hz outside 1.000..=2000.000 Hz"
        );
        let last = PlanError::ZeroDuration { step: u16::MAX };
        assert_eq!(std::format!("{last}"), "step 65536: duration is 0 ms");
        let ramp = PlanError::RampLongerThanStep { step: 0, ramp_ms: 11, duration_ms: 10 };
        assert_eq!(std::format!("{ramp}"), "step 1: ramp 11 ms longer than the step (10 ms)");
    }

    extern crate std;
}
