//! The drive: the signal the controller sends to the shaker, computed sample by sample, and
//! the closed amplitude loop around it (docs/control.md).
//!
//! - [`dds`]: sine synthesis (phase accumulator, interpolated table, 12-bit DAC codes).
//! - [`runner`]: the plan runner filling sample blocks, step boundaries exact to the sample.
//! - [`pwm`]: the PWM drive option's duty mapping, carrier plan and reconstruction filter.
//! - [`plant`]: a simulated shaker + plate (resonant second-order system) for the QEMU board,
//!   with deliberate faults (disconnected, clipping amplifier).
//! - [`timeline`]: the DDS's phase at any instant ([`timeline::PhaseMark`]) and each sensor
//!   sample's instant on the DAC clock ([`timeline::SensorTimebase`]).
//! - [`lockin`]: amplitude and phase at the drive frequency, a whole-cycle sine fit on the
//!   DDS's own phase (DC and harmonics out, any frequency incl. above the sensor's Nyquist).
//! - [`control`]: the PI amplitude controller with feed-forward from the measured plant gain.
//! - [`monitor`]: the fault monitors (loop open, out of band, over-acceleration, no data,
//!   saturation, sensor errors) with thresholds from [`crate::icd::sense::ControlConfig`].
//! - [`closed_loop`]: [`closed_loop::ClosedLoop`], the one call per block of the drive task:
//!   timebase → lock-in → loop check → controller, monitors.
//! - [`sensor_sim`]: the simulated accelerometer (own clock, noise, 16-bit quantisation).

pub mod closed_loop;
pub mod control;
pub mod dds;
pub mod lockin;
#[cfg(test)]
mod loop_tests;
pub mod monitor;
pub mod plant;
pub mod pwm;
pub mod runner;
pub mod sensor_sim;
pub mod timeline;
