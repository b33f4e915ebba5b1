//! The LSM6DSL's wiring on the B-L475E-IOT01A: I2C2 (PB10 SCL, PB11 SDA, AF4; shared with the
//! other on-board sensors) at 400 kHz with DMA (DMA1 channel 4 TX, channel 5 RX, request 3),
//! and its INT1 on PD11 (EXTI line 11, interrupt EXTI15_10).
//!
//! So that the bus cannot hang the controller (docs/sensor.md, "Bus hangs"):
//! - before embassy's I2C driver takes the pins, [`recover_bus`] runs the board-independent
//!   bus clear (`app::sense::recovery`: up to nine clocks on SCL until SDA is high, then a
//!   STOP) with the pins as open-drain GPIOs, for a sensor left mid-read by a reset;
//! - each transfer has a [`TRANSFER_TIMEOUT`] (embassy's default, 1 s, is the watchdog's
//!   whole timeout), and the sense task bounds every operation again;
//! - the internal pull-ups (about 40 kΩ) are on, as ST's own board support package for this
//!   board configures I2C2; in parallel with any external resistors they change little.
//!
//! The driver itself is board-independent (`app::sense::lsm6dsl`); this module only builds its
//! bus and the INT1 wait.

use embassy_stm32::exti::ExtiInput;
use embassy_stm32::gpio::{Flex, Pull, Speed};
use embassy_stm32::i2c::{self, I2c, Master};
use embassy_stm32::mode::Async;
use embassy_stm32::time::Hertz;
use embassy_stm32::{Peri, peripherals};
use embassy_time::Duration;

use super::Irqs;
use crate::app::sense::recovery::{self, OpenDrainPins};

/// The sensor's bus: embassy-stm32's async I2C2 (implements `embedded_hal_async::i2c::I2c`).
pub type SensorBus = I2c<'static, Async, Master>;

/// The sensor's INT1 line, high while its FIFO holds at least the threshold.
pub struct SensorIrq {
    int1: ExtiInput<'static, Async>,
}

impl SensorIrq {
    /// Waits until INT1 is high (at once if it already is). The line stays high until the
    /// FIFO is read below the threshold, so a level wait cannot miss an edge.
    pub async fn wait_threshold(&mut self) {
        self.int1.wait_for_high().await;
    }

    /// INT1's level now.
    pub fn is_high(&self) -> bool {
        self.int1.is_high()
    }
}

impl crate::app::sense::task::DataReady for SensorIrq {
    async fn wait(&mut self) {
        self.wait_threshold().await
    }
}

/// The accelerometer's bus and interrupt line.
pub struct Sensor {
    /// I2C2 at 400 kHz.
    pub bus: SensorBus,
    /// INT1 (FIFO threshold).
    pub irq: SensorIrq,
}

/// I2C clock: the LSM6DSL's fast mode.
const I2C_HZ: u32 = 400_000;

/// The longest one transfer may take before embassy's driver gives up (`Error::Timeout`):
/// the longest transfer, a 64-set FIFO burst of 384 bytes, takes about 9 ms at 400 kHz.
pub const TRANSFER_TIMEOUT: Duration = Duration::from_millis(25);

/// SCL and SDA as open-drain GPIOs with the internal pull-ups, for the bus clear.
struct BitBang<'a> {
    scl: Flex<'a>,
    sda: Flex<'a>,
}

impl OpenDrainPins for BitBang<'_> {
    fn set_scl(&mut self, high: bool) {
        if high { self.scl.set_high() } else { self.scl.set_low() }
    }
    fn set_sda(&mut self, high: bool) {
        if high { self.sda.set_high() } else { self.sda.set_low() }
    }
    fn scl(&self) -> bool {
        self.scl.is_high()
    }
    fn sda(&self) -> bool {
        self.sda.is_high()
    }
    fn half_period(&mut self) {
        // 5 µs: 100 kHz, which every device on the bus takes.
        embassy_time::block_for(Duration::from_micros(5));
    }
}

/// The bus clear on PB10/PB11 (lines released first, so a free bus sees only a STOP); logs
/// what it did. The pins go back to the I2C driver afterwards (dropping a `Flex` disconnects
/// the pin; `I2c::new` then sets its alternate function).
fn recover_bus(scl: Peri<'_, peripherals::PB10>, sda: Peri<'_, peripherals::PB11>) {
    let (mut scl, mut sda) = (Flex::new(scl), Flex::new(sda));
    scl.set_high();
    sda.set_high();
    scl.set_as_input_output_pull(Speed::Low, Pull::Up);
    sda.set_as_input_output_pull(Speed::Low, Pull::Up);
    // The pull-ups charge the lines' capacitance in well under a half period.
    embassy_time::block_for(Duration::from_micros(5));
    match recovery::recover(&mut BitBang { scl, sda }) {
        Ok(done) if done.clocks > 0 => {
            defmt::warn!("sense: I2C2 was held by a device; freed after {=u8} clocks", done.clocks)
        }
        Ok(_) => {}
        Err(stuck) => defmt::error!("sense: I2C2 bus clear failed: {}", stuck.name()),
    }
}

/// Frees the bus, then sets up I2C2 and the INT1 input; sends nothing else on the bus.
pub(super) fn new(
    i2c2: Peri<'static, peripherals::I2C2>,
    scl: Peri<'static, peripherals::PB10>,
    sda: Peri<'static, peripherals::PB11>,
    tx_dma: Peri<'static, peripherals::DMA1_CH4>,
    rx_dma: Peri<'static, peripherals::DMA1_CH5>,
    int1: Peri<'static, peripherals::PD11>,
    exti: Peri<'static, peripherals::EXTI11>,
) -> Sensor {
    let (mut scl, mut sda) = (scl, sda);
    recover_bus(scl.reborrow(), sda.reborrow());
    let mut config = i2c::Config::default();
    config.frequency = Hertz(I2C_HZ);
    config.timeout = TRANSFER_TIMEOUT;
    config.scl_pullup = true;
    config.sda_pullup = true;
    // embassy-stm32 0.6.0: peripheral, SCL, SDA, TX DMA, RX DMA, interrupt bindings, config.
    let bus = I2c::new(i2c2, scl, sda, tx_dma, rx_dma, Irqs, config);
    // INT1 is push-pull, active high; the pull-down holds it low while the sensor is
    // absent or resetting, so a missing sensor never looks like a full FIFO.
    let int1 = ExtiInput::new(int1, exti, Pull::Down, Irqs);
    Sensor { bus, irq: SensorIrq { int1 } }
}
