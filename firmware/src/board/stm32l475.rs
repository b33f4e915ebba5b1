//! The B-L475E-IOT01A: embassy-stm32 drivers, flashed with probe-rs.
//!
//! The host link is USART1 on the ST-LINK virtual COM port (PB6 TX / PB7 RX), 115200 8N1.

use defmt_rtt as _;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, peripherals};
use static_cell::StaticCell;

/// This board's identity on the link.
pub const BOARD: chladni_shared::link::Board = chladni_shared::link::Board::Stm32l475;

/// The host link: USART1 through the ST-LINK virtual COM port.
pub type Link = BufferedUart<'static>;

/// The initialised board.
pub struct Board {
    /// Host link.
    pub link: Link,
}

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<peripherals::USART1>;
});

/// Brings the board up with embassy-stm32's defaults (MSI 4 MHz; the drive issue raises it).
pub fn init() -> Board {
    let p = embassy_stm32::init(embassy_stm32::Config::default());
    static TX: StaticCell<[u8; 1024]> = StaticCell::new();
    static RX: StaticCell<[u8; 1024]> = StaticCell::new();
    let mut config = usart::Config::default();
    config.baudrate = 115_200;
    let link = BufferedUart::new(
        p.USART1,
        p.PB7,
        p.PB6,
        TX.init([0; 1024]),
        RX.init([0; 1024]),
        Irqs,
        config,
    )
    .expect("USART1 config");
    Board { link }
}

/// Runs embassy's thread-mode executor forever; `init` spawns the first tasks.
pub fn run(init: impl FnOnce(embassy_executor::Spawner)) -> ! {
    static EXECUTOR: StaticCell<embassy_executor::Executor> = StaticCell::new();
    EXECUTOR.init(embassy_executor::Executor::new()).run(init)
}

/// A panic resets the MCU into its safe idle state (drive off) after logging.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    cortex_m::peripheral::SCB::sys_reset()
}
