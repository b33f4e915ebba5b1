//! The B-L475E-IOT01A as QEMU 10 models it (`qemu-system-arm -M b-l475e-iot01a`).
//!
//! QEMU models the core, NVIC, SysTick, RCC, GPIO and the USARTs; every other peripheral reads
//! 0 and ignores writes (see "Board facts" in the design notes). So this board does not call
//! `embassy_stm32::init` (it would spin forever on a PWR bit) and brings its own drivers:
//! - [`time_driver`]: embassy-time on SysTick (1 kHz), because no TIM ever ticks in QEMU;
//! - [`usart`]: USART1 with 32-bit register accesses and an RX interrupt;
//! - [`executor`]: embassy's executor sleeping with WFI instead of WFE (which QEMU spins on);
//! - defmt over semihosting, and [`exit`] to end QEMU with a status code.

pub mod executor;
pub mod time_driver;
pub mod usart;

use defmt_semihosting as _;

/// This board's identity on the link.
pub const BOARD: chladni_shared::link::Board = chladni_shared::link::Board::Qemu;

/// The host link: USART1, reached by the host through QEMU's `-serial` chardev.
pub type Link = usart::Usart1;

/// The drive output: no DAC in QEMU, so a simulated one paced by the time driver, feeding the
/// simulated shaker + plate.
pub type DriveOutput = crate::app::drive::SimulatedDac;

/// The initialised board.
pub struct Board {
    /// Host link.
    pub link: Link,
    /// Drive output.
    pub drive: DriveOutput,
}

/// Brings the board up: time driver first (everything else may wait on time), then the link.
pub fn init() -> Board {
    let core = cortex_m::Peripherals::take().expect("board::init called twice");
    time_driver::start(core.SYST);
    Board { link: usart::Usart1::new(), drive: DriveOutput::new() }
}

pub use executor::run;

/// Ends the QEMU process with `code` (semihosting `SYS_EXIT_EXTENDED`).
pub fn exit(code: i32) -> ! {
    loop {
        cortex_m_semihosting::debug::exit(if code == 0 {
            cortex_m_semihosting::debug::EXIT_SUCCESS
        } else {
            cortex_m_semihosting::debug::EXIT_FAILURE
        });
    }
}

#[defmt::panic_handler]
fn defmt_panic() -> ! {
    exit(101)
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    defmt::error!("panic: {}", defmt::Display2Format(info));
    exit(101)
}

#[cortex_m_rt::exception]
unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
    defmt::error!("hard fault at pc {=u32:#010x}", frame.pc());
    exit(102)
}
