//! The drive: the signal the controller sends to the shaker, computed sample by sample.
//!
//! - [`dds`]: sine synthesis (phase accumulator, interpolated table, 12-bit DAC codes).
//! - [`runner`]: the plan runner filling sample blocks, step boundaries exact to the sample.
//! - [`pwm`]: the PWM drive option's duty mapping, carrier plan and reconstruction filter.
//! - [`plant`]: a simulated shaker + plate (resonant second-order system) for the QEMU board.

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
