//! The QEMU board's output: a DAC that exists only in time, driving the simulated shaker +
//! plate, whose acceleration the simulated accelerometer samples.
//!
//! [`SimulatedDac`] takes one block per [`BLOCK_PERIOD`] (paced by embassy-time). Each block
//! runs through the plant ([`Plant`], with the fault a test injected, [`SimFaults`]); each
//! acceleration sample goes to [`SensorSim`], which samples it at the accelerometer's own
//! (slightly wrong) rate with noise and quantisation, and the samples land in the simulated
//! LSM6DSL's FIFO ([`SimCell`]), which the sense task reads over its simulated I2C exactly as
//! it reads the real chip. The sensor simulation follows the rate and range the driver set.
//!
//! A block that arrives more than one block period after the previous one has played out
//! counts as an underrun (one block of slack beyond the hardware's, because QEMU's clock
//! follows the host's and slips under load), and the stream restarts from then.

use core::cell::Cell;

use chladni_shared::drive::plant::{Plant, PlantFault, PlantParams};
use chladni_shared::drive::sensor_sim::{SensorSim, SensorSimConfig};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::{Instant, Timer};

use super::{BLOCK_PERIOD, SampleOutput, Underrun};
use crate::app::sense::lsm6dsl::STANDARD_GRAVITY;
use crate::app::sense::sim::SimCell;

/// The plant fault a test injected, shared with the link task (QEMU's fault injection).
pub type SimFaults = Mutex<CriticalSectionRawMutex, Cell<PlantFault>>;

/// See the module docs.
pub struct SimulatedDac {
    plant: Plant,
    next: Option<Instant>,
    sensor: Option<(&'static SimCell, SensorSim)>,
    faults: Option<&'static SimFaults>,
}

impl Default for SimulatedDac {
    fn default() -> Self {
        Self::new()
    }
}

impl SimulatedDac {
    /// A plant at rest with the default parameters, no sensor.
    pub fn new() -> Self {
        Self { plant: Plant::new(PlantParams::DEFAULT), next: None, sensor: None, faults: None }
    }

    /// Also feeds the simulated accelerometer `sensor` and takes plant faults from `faults`.
    pub fn with_sensor(mut self, sensor: &'static SimCell, faults: &'static SimFaults) -> Self {
        self.sensor = Some((sensor, SensorSim::new(SensorSimConfig::DEFAULT)));
        self.faults = Some(faults);
        self
    }

    /// Runs `block` through the plant and the accelerometer.
    fn simulate(&mut self, block: &[u16]) {
        if let Some(faults) = self.faults {
            self.plant.set_fault(faults.lock(|f| f.get()));
        }
        let Some((cell, sim)) = &mut self.sensor else {
            self.plant.run(block);
            return;
        };
        cell.lock(|chip| {
            let mut chip = chip.borrow_mut();
            // Follow the rate and range the driver configured (nothing is sampled before).
            let Some(odr) = chip.odr() else {
                self.plant.run(block);
                return;
            };
            let lsb = chip.range().sensitivity();
            let cfg = sim.config();
            if cfg.odr_mhz != odr.millihertz() || cfg.lsb_mps2 != lsb {
                // Gravity on Z, in this range's LSB.
                let bias_lsb = (STANDARD_GRAVITY / lsb) as i32;
                let cfg =
                    SensorSimConfig { odr_mhz: odr.millihertz(), lsb_mps2: lsb, bias_lsb, ..*cfg };
                *sim = SensorSim::new(cfg);
            }
            for &code in block {
                let a = self.plant.step(code);
                sim.push(a, |z| chip.push(0, 0, z));
            }
        });
    }
}

impl SampleOutput for SimulatedDac {
    async fn write_block(&mut self, block: &[u16]) -> Result<(), Underrun> {
        let now = Instant::now();
        // `next` is when the previous block has finished playing.
        let (start, result) = match self.next {
            None => (now, Ok(())),
            Some(next) if now > next + BLOCK_PERIOD => (now, Err(Underrun)),
            Some(next) => (next, Ok(())),
        };
        self.simulate(block);
        self.next = Some(start + BLOCK_PERIOD);
        // Double buffering: the block just handed over plays while the next one is filled.
        Timer::at(start).await;
        result
    }
}
