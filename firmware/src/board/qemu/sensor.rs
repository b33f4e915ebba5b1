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

use core::cell::Cell;
use core::sync::atomic::{AtomicBool, Ordering};

use chladni_shared::drive::plant::PlantFault;
use chladni_shared::icd::link::TestFault;

use crate::app::drive::simulated::SimFaults;
use crate::app::sense::sim::{Fault, SharedSim, SimCell, SimLsm6dsl};

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

impl crate::app::sense::task::DataReady for SensorIrq {
    async fn wait(&mut self) {
        if STALL.load(Ordering::Acquire) {
            // A task stuck in its driver (the fault `StallTask` simulates): it never yields,
            // so no task checks in and the watchdog resets the controller.
            loop {
                cortex_m::asm::nop();
            }
        }
        self.wait_threshold().await
    }
}

/// Set by the injected fault `StallTask`: the sense task hangs in its next wait.
static STALL: AtomicBool = AtomicBool::new(false);

/// The plant's injected fault, read by the simulated DAC every block.
pub static PLANT_FAULTS: SimFaults = Mutex::new(Cell::new(PlantFault::None));

/// Simulates `fault` (the link's `InjectFault`, for the fault monitors' end-to-end tests).
pub fn inject(fault: TestFault) {
    let set_sensor = |f: Fault| SIM.lock(|s| s.borrow_mut().set_fault(f));
    match fault {
        TestFault::ShakerDisconnected => PLANT_FAULTS.lock(|p| p.set(PlantFault::Disconnected)),
        // A fiftieth of the DAC's swing: no drive the controller may ask for reaches the
        // targets the tests set, so it must end at its ceiling.
        TestFault::AmplifierSaturated => PLANT_FAULTS.lock(|p| p.set(PlantFault::Saturated(41))),
        TestFault::SensorSilent => set_sensor(Fault::Silent),
        // 0x69: the id of another ST part (LSM6DS3 answers 0x69), as a swapped board would.
        TestFault::SensorWrongId => set_sensor(Fault::WrongId(0x69)),
        TestFault::StallTask => STALL.store(true, Ordering::Release),
        TestFault::Heal => {
            PLANT_FAULTS.lock(|p| p.set(PlantFault::None));
            set_sensor(Fault::None);
        }
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
