//! The LSM6DSL's wiring on the B-L475E-IOT01A: I2C2 (PB10 SCL, PB11 SDA, AF4; the board's
//! own pull-ups, shared with the other on-board sensors) at 400 kHz with DMA (DMA1 channel 4
//! TX, channel 5 RX, request 3), and its INT1 on PD11 (EXTI line 11, interrupt EXTI15_10).
//!
//! The driver itself is board-independent (`app::sense::lsm6dsl`); this module only builds its
//! bus and the INT1 wait.

use embassy_stm32::exti::ExtiInput;
use embassy_stm32::gpio::Pull;
use embassy_stm32::i2c::{self, I2c, Master};
use embassy_stm32::mode::Async;
use embassy_stm32::time::Hertz;
use embassy_stm32::{Peri, peripherals};

use super::Irqs;

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

/// The accelerometer's bus and interrupt line.
pub struct Sensor {
    /// I2C2 at 400 kHz.
    pub bus: SensorBus,
    /// INT1 (FIFO threshold).
    pub irq: SensorIrq,
}

/// I2C clock: the LSM6DSL's fast mode.
const I2C_HZ: u32 = 400_000;

/// Sets up I2C2 and the INT1 input; sends nothing on the bus.
pub(super) fn new(
    i2c2: Peri<'static, peripherals::I2C2>,
    scl: Peri<'static, peripherals::PB10>,
    sda: Peri<'static, peripherals::PB11>,
    tx_dma: Peri<'static, peripherals::DMA1_CH4>,
    rx_dma: Peri<'static, peripherals::DMA1_CH5>,
    int1: Peri<'static, peripherals::PD11>,
    exti: Peri<'static, peripherals::EXTI11>,
) -> Sensor {
    let mut config = i2c::Config::default();
    config.frequency = Hertz(I2C_HZ);
    // embassy-stm32 0.6.0: peripheral, SCL, SDA, TX DMA, RX DMA, interrupt bindings, config.
    let bus = I2c::new(i2c2, scl, sda, tx_dma, rx_dma, Irqs, config);
    // INT1 is push-pull, active high; the pull-down holds it low while the sensor is
    // absent or resetting, so a missing sensor never looks like a full FIFO.
    let int1 = ExtiInput::new(int1, exti, Pull::Down, Irqs);
    Sensor { bus, irq: SensorIrq { int1 } }
}
