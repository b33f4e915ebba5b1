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
//! The slack a block reports is the time from its hand-over to the end of the block playing
//! then (0 when late).
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
    now_us: Option<fn() -> u64>,
}

impl Default for SimulatedDac {
    fn default() -> Self {
        Self::new()
    }
}

impl SimulatedDac {
    /// A plant at rest with the default parameters, no sensor.
    pub fn new() -> Self {
        Self {
            plant: Plant::new(PlantParams::DEFAULT),
            next: None,
            sensor: None,
            faults: None,
            now_us: None,
        }
    }

    /// Also feeds the simulated accelerometer `sensor` and takes plant faults from `faults`.
    pub fn with_sensor(mut self, sensor: &'static SimCell, faults: &'static SimFaults) -> Self {
        self.sensor = Some((sensor, SensorSim::new(SensorSimConfig::DEFAULT)));
        self.faults = Some(faults);
        self
    }

    /// Also reads a finer clock than embassy-time's ticks (µs; the QEMU board's SysTick
    /// count), for the refill slack; without one the slack is in whole ticks.
    pub fn with_clock(mut self, now_us: fn() -> u64) -> Self {
        self.now_us = Some(now_us);
        self
    }

    /// Runs `block` through the plant and the accelerometer. The plant and sensor models run
    /// outside any lock; the chip is locked only to read its rate and range and to queue the
    /// block's few samples (the sense task reads it from a lower priority).
    fn simulate(&mut self, block: &[u16]) {
        if let Some(faults) = self.faults {
            self.plant.set_fault(faults.lock(|f| f.get()));
        }
        let Some((cell, sim)) = &mut self.sensor else {
            self.plant.run(block);
            return;
        };
        let (odr, lsb) = cell.lock(|chip| {
            let chip = chip.borrow();
            (chip.odr(), chip.range().sensitivity())
        });
        // Follow the rate and range the driver configured (nothing is sampled before).
        let Some(odr) = odr else {
            self.plant.run(block);
            return;
        };
        let cfg = sim.config();
        if cfg.odr_mhz != odr.millihertz() || cfg.lsb_mps2 != lsb {
            // Gravity on Z, in this range's LSB.
            let bias_lsb = (STANDARD_GRAVITY / lsb) as i32;
            let cfg =
                SensorSimConfig { odr_mhz: odr.millihertz(), lsb_mps2: lsb, bias_lsb, ..*cfg };
            *sim = SensorSim::new(cfg);
        }
        let mut samples = heapless::Vec::<i16, SAMPLES_PER_BLOCK_MAX>::new();
        for &code in block {
            let a = self.plant.step(code);
            sim.push(a, |z| {
                let _ = samples.push(z);
            });
        }
        cell.lock(|chip| {
            let mut chip = chip.borrow_mut();
            samples.iter().for_each(|&z| chip.push(0, 0, z));
        });
    }

    /// µs between now and `next`, when the output runs dry (0 if already past).
    fn slack_us(&self, now: Instant, next: Instant) -> u32 {
        let now_us = self.now_us.map_or(now.as_micros(), |f| f());
        next.as_micros().saturating_sub(now_us).min(u64::from(u32::MAX)) as u32
    }
}

/// Most accelerometer samples one block yields: 6.66 kHz (the fastest rate the driver sets)
/// for 5 ms is 34.
const SAMPLES_PER_BLOCK_MAX: usize = 64;

impl SampleOutput for SimulatedDac {
    async fn write_block(&mut self, block: &[u16]) -> Result<Option<u32>, Underrun> {
        let now = Instant::now();
        // `next` is when the previous block has finished playing.
        let (start, result) = match self.next {
            None => (now, Ok(None)),
            Some(next) if now > next + BLOCK_PERIOD => (now, Err(Underrun)),
            Some(next) => (next, Ok(Some(self.slack_us(now, next)))),
        };
        self.simulate(block);
        self.next = Some(start + BLOCK_PERIOD);
        // Double buffering: the block just handed over plays while the next one is filled.
        Timer::at(start).await;
        result
    }
}
