//! The accelerometer in QEMU: QEMU models no I2C, so the sensor is the app's simulated
//! LSM6DSL ([`crate::app::sense::sim`]) in a static, behind a critical-section mutex. The sense
//! task talks to it through [`SensorBus`] exactly as it talks to the real chip over I2C2; the
//! drive side (the simulated plant) pushes samples into it through [`sim`] at the rate the
//! driver configured (`SimLsm6dsl::odr`, `OdrPacer`).
//!
//! INT1 is the simulation's threshold flag, polled every millisecond ([`SensorIrq`]): pushes
//! come from whatever code plays the plant, which need not know about a waker.

use core::cell::RefCell;

use embassy_sync::blocking_mutex::Mutex;
use embassy_time::Timer;

use crate::app::sense::sim::{SharedSim, SimCell, SimLsm6dsl};

/// The simulated sensor: registers and FIFO (about 4.2 KiB of RAM).
static SIM: SimCell = Mutex::new(RefCell::new(SimLsm6dsl::new()));

/// The simulated sensor, for the code that pushes samples (and for tests that inject faults).
pub fn sim() -> &'static SimCell {
    &SIM
}

/// The sensor's bus: I2C transactions on the simulated register map.
pub type SensorBus = SharedSim;

/// How often [`SensorIrq::wait_threshold`] looks at the simulated INT1.
const POLL_MS: u64 = 1;

/// The simulated INT1 line: high while the FIFO holds at least the threshold.
pub struct SensorIrq {
    sim: &'static SimCell,
}

impl SensorIrq {
    /// Waits until INT1 is high (at once if it already is), polling every [`POLL_MS`] ms.
    pub async fn wait_threshold(&mut self) {
        while !self.is_high() {
            Timer::after_millis(POLL_MS).await;
        }
    }

    /// INT1's level now.
    pub fn is_high(&self) -> bool {
        self.sim.lock(|sim| sim.borrow().int1())
    }
}

/// The accelerometer's bus and interrupt line.
pub struct Sensor {
    /// The simulated LSM6DSL as an I2C device.
    pub bus: SensorBus,
    /// Its INT1 (FIFO threshold).
    pub irq: SensorIrq,
}

/// The simulated sensor's bus and INT1: handles on the one static simulation ([`sim`]), so
/// the board's `init` and the on-target tests may each take one.
pub fn new() -> Sensor {
    Sensor { bus: SharedSim(&SIM), irq: SensorIrq { sim: &SIM } }
}
