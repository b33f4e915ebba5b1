//! Sensing: the plate's acceleration, read from the LSM6DSL accelerometer on the board.
//!
//! - [`lsm6dsl`]: the driver, generic over any async I2C bus (`embedded_hal_async`): set-up
//!   (range, rate, FIFO threshold on INT1) and FIFO reads of the Z axis, the one the feeder's
//!   plate moves along.
//! - [`task`]: the sense task: set-up, reads on INT1, errors, all handed to the drive task.
//! - [`recovery`]: the I2C bus clear (nine clocks, then a STOP) a board runs before its I2C
//!   driver takes the pins.
//! - [`sim`]: a simulated LSM6DSL register map and FIFO behind the same I2C trait, with
//!   injectable faults, for the host tests and for the QEMU board (QEMU models no I2C).
//!
//! The board supplies the bus and the INT1 line; nothing here touches a register.
//! docs/sensor.md has the register sequence and what is checked only against the simulation.

pub mod lsm6dsl;
pub mod recovery;
pub mod sim;
pub mod task;

#[cfg(all(test, not(target_os = "none")))]
mod tests;
