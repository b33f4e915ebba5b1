//! The B-L475E-IOT01A: embassy-stm32 drivers, flashed with probe-rs.
//!
//! - Host link ([`Link`]): USB CDC-ACM on USB OTG FS ([`usb`]), VID:PID and product string from
//!   `chladni_shared::icd::link`, serial number = the chip's unique id. The USB device runs in
//!   a task of its own ([`spawn_tasks`]).
//! - Debug console: USART1 on the ST-LINK virtual COM port, 115200 8N1, a boot banner only
//!   ([`console`]); defmt logs go over RTT.
//! - Sensor ([`Sensor`]): the LSM6DSL accelerometer on I2C2 (PB10/PB11, 400 kHz, DMA1 ch4/5)
//!   with its INT1 on PD11 ([`sensor`]); set up here, read by the app's sense driver.
//! - Drive ([`DriveOutput`]): DAC1 ch1 on PA4, TIM6-paced, fed by circular DMA ([`dac`]); or,
//!   with the cargo feature `drive-pwm`, TIM3 ch3 PWM on PB0 (Arduino D3), its duty fed by
//!   circular DMA ([`pwm`], docs/pwm.md; not yet run on a board).
//! - Watchdog ([`Watchdog`], [`reset_cause`]): the IWDG, 1 s nominal, and the reset cause
//!   from RCC_CSR ([`watchdog`]).
//! - Plan store ([`Flash`]): flash bank 2 (0x0808_0000, 512 KiB), async through the FLASH
//!   interrupt ([`bank2`]: with the L47x data cache erratum worked around and ECC errors read
//!   as data). The program is linked into bank 1 only (memory.x: FLASH = 512 KiB at
//!   0x0800_0000), and the L475's two banks are read-while-write, so erasing a plan page
//!   (about 22 ms) never stalls the code running from bank 1.
//! - Clocks ([`clocks`]): 80 MHz SYSCLK and 48 MHz USB from MSI locked to the 32.768 kHz crystal.
//! - A panic, HardFault or unexpected NMI parks the output at mid-scale first, then detaches
//!   from USB ([`failsafe`]).
//!
//! Scheduling: the drive task runs on embassy's `InterruptExecutor`, polled from UART4's
//! vector (UART4 is unused on this board) at NVIC priority 14 ([`start_drive_executor`]);
//! everything else (link, store, USB device, sense, watchdog) runs on the thread-mode executor
//! below it, so no link or store work can delay a refill: the drive must refill half its ring
//! within one block (5 ms) and now only waits for interrupt handlers and critical sections.
//! The interrupt handlers (OTG_FS, FLASH, DMA1_CHANNEL3..5, I2C2_EV/ER, EXTI15_10, TIM2 for
//! embassy-time) keep embassy-stm32's default priority 0, above the drive, so they never
//! preempt each other, and each does a bounded amount of work (OTG_FS: drain the RX FIFO, at
//! most a few packets; I2C2 and its DMA: wake the waiting task).
//! The DMA keeps playing the ring whatever the CPU does.
//!
//! Hardware status: everything USB and flash-related here is built and checked against the
//! embassy sources but not yet run on a board (QEMU models neither); docs/firmware.md has the
//! bring-up checklist. The same holds for the sensor's I2C2 and INT1 (docs/sensor.md).

pub mod bank2;
pub mod clocks;
pub mod console;
#[cfg(not(feature = "drive-pwm"))]
pub mod dac;
pub mod failsafe;
#[cfg(feature = "drive-pwm")]
pub mod pwm;
pub mod sensor;
pub mod usb;
pub mod watchdog;

use core::ops::Range;

use defmt_rtt as _;
use embassy_stm32::{bind_interrupts, dma, exti, flash, i2c, interrupt, peripherals};
use embedded_storage_async::nor_flash::NorFlash;
use stm32_metapac as pac;

/// This board's identity on the link.
pub const BOARD: chladni_shared::icd::link::Board = chladni_shared::icd::link::Board::Stm32l475;

/// The host link: USB CDC-ACM (see [`usb`] for its read and write rules).
pub type Link = usb::UsbLink;

/// Flash bank 2, for the plan store: embassy-stm32's async region (native async on the L4:
/// program and erase complete through the FLASH interrupt) with the L4's data cache erratum and
/// ECC errors handled ([`bank2`]). Offsets are relative to the start of the bank (0x0808_0000);
/// 2 KiB pages, 8-byte (double-word) writes, erased state 0xFF, and a double word can be
/// written only once between erases.
pub type Flash = bank2::Bank2;

/// Offsets within [`Flash`] given to the plan store: all of bank 2 (256 pages of 2 KiB).
pub const STORE_RANGE: Range<u32> = 0..flash::BANK2_REGION.size;

// The store's layout, checked when the image is built: bank 2 is the 512 KiB that memory.x
// leaves out of the program, and the range is whole pages.
const _: () = {
    assert!(STORE_RANGE.end == 512 * 1024);
    assert!(<Flash as NorFlash>::ERASE_SIZE == 2048);
    assert!(<Flash as NorFlash>::WRITE_SIZE == 8);
    assert!(STORE_RANGE.start.is_multiple_of(2048) && STORE_RANGE.end.is_multiple_of(2048));
};

/// No fault injection on real hardware (`InjectFault` is answered `Unsupported`).
pub const INJECT: Option<fn(chladni_shared::icd::link::TestFault)> = None;

/// The drive output: DAC1 ch1 fed by circular DMA, paced by TIM6.
#[cfg(not(feature = "drive-pwm"))]
pub type DriveOutput = dac::DacOutput;
/// The drive output: TIM3 ch3 PWM on PB0, its duty fed by circular DMA (feature `drive-pwm`).
#[cfg(feature = "drive-pwm")]
pub type DriveOutput = pwm::PwmOutput;

/// The watchdog: the IWDG, started by [`init`] first thing with a boot window, set to its
/// running timeout by the watchdog task.
pub type Watchdog = watchdog::Watchdog;

pub use watchdog::reset_cause;

pub use sensor::{Sensor, SensorBus, SensorIrq};

/// The initialised board.
pub struct Board {
    /// Host link.
    pub link: Link,
    /// Flash bank 2 for the plan store (always present on this board).
    pub flash: Option<Flash>,
    /// Drive output.
    pub drive: DriveOutput,
    /// The LSM6DSL accelerometer's bus and INT1 line.
    pub sensor: Sensor,
    /// This board's background work, for [`spawn_tasks`].
    pub tasks: BoardTasks,
    /// The independent watchdog, running with its boot window since the start of [`init`];
    /// `app::watchdog::watchdog_task` sets the running timeout.
    pub watchdog: Watchdog,
}

/// What this board runs in the background: the USB device.
pub struct BoardTasks {
    usb: usb::UsbDevice,
}

bind_interrupts!(struct Irqs {
    #[cfg(not(feature = "drive-pwm"))]
    DMA1_CHANNEL3 => dma::InterruptHandler<peripherals::DMA1_CH3>;
    #[cfg(feature = "drive-pwm")]
    DMA1_CHANNEL2 => dma::InterruptHandler<peripherals::DMA1_CH2>;
    OTG_FS => embassy_stm32::usb::InterruptHandler<peripherals::USB_OTG_FS>;
    FLASH => flash::InterruptHandler;
    I2C2_EV => i2c::EventInterruptHandler<peripherals::I2C2>;
    I2C2_ER => i2c::ErrorInterruptHandler<peripherals::I2C2>;
    DMA1_CHANNEL4 => dma::InterruptHandler<peripherals::DMA1_CH4>;
    DMA1_CHANNEL5 => dma::InterruptHandler<peripherals::DMA1_CH5>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// Brings the board up: clocks, the debug console's banner, USB, flash bank 2, then the drive
/// output (last, so that nothing blocking runs once its DMA plays).
pub fn init() -> Board {
    // The stack first (nothing deep has run yet), then the watchdog (before anything that can
    // hang: `embassy_stm32::init` waits for the LSE and the PLLs without a limit), then the
    // reset flags, whoever asks for them later: reading also clears them.
    super::stack::paint();
    watchdog::start_for_boot();
    let cause = reset_cause();
    let p = embassy_stm32::init(clocks::config());
    clocks::check();
    // A debugger halting the core (breakpoint, or a fault caught before its handler runs)
    // also stops TIM6, so the DAC holds one code instead of the DMA replaying the ring.
    pac::DBGMCU.apb1fzr1().modify(|w| w.set_tim6(true));
    start_cycle_counter();
    console::start(p.USART1, p.PB6);
    let (link, usb) = usb::new(p.USB_OTG_FS, p.PA12, p.PA11);
    let flash = bank2::Bank2::new(flash::Flash::new(p.FLASH, Irqs).into_regions().bank2_region);
    let sensor = sensor::new(p.I2C2, p.PB10, p.PB11, p.DMA1_CH4, p.DMA1_CH5, p.PD11, p.EXTI11);
    let watchdog = watchdog::Watchdog::new(p.IWDG);
    defmt::info!("reset cause: {}", cause);
    #[cfg(not(feature = "drive-pwm"))]
    let drive = dac::DacOutput::new(p.DAC1, p.PA4, p.DMA1_CH3, p.TIM6);
    #[cfg(feature = "drive-pwm")]
    let drive = pwm::PwmOutput::new(p.TIM3, p.PB0, p.DMA1_CH2);
    Board { link, flash: Some(flash), drive, sensor, tasks: BoardTasks { usb }, watchdog }
}

/// What [`refill_clock`] counts.
pub const REFILL_CLOCK_UNIT: &str = "cycles (DWT CYCCNT, 80 MHz)";

/// The core's cycle counter (DWT CYCCNT, wraps every 53 s at 80 MHz): the drive's per-block
/// refill cost.
pub fn refill_clock() -> u32 {
    cortex_m::peripheral::DWT::cycle_count()
}

/// Turns DWT CYCCNT on (trace enable in DEMCR, then CYCCNTENA). A debugger may have done it
/// already; doing it again is harmless.
fn start_cycle_counter() {
    // SAFETY: only DCB.DEMCR's TRCENA and DWT_CTRL's CYCCNTENA are written, at boot, before
    // any task runs; nothing else in the firmware uses the DWT or the DCB.
    let mut core = unsafe { cortex_m::Peripherals::steal() };
    core.DCB.enable_trace();
    core.DWT.enable_cycle_counter();
}

/// Spawns this board's background tasks: the USB device ([`usb::run`]). Call once.
pub fn spawn_tasks(spawner: embassy_executor::Spawner, tasks: BoardTasks) {
    spawner.spawn(usb::run(tasks.usb).expect("usb task: spawn pool exhausted"));
}

/// The slack of a refill handed to a DMA ring of `capacity` samples with `free` of them free
/// (`WritableRingBuffer::len`): the samples still queued ahead of it, in µs at the sample rate;
/// `None` if the ring has just overrun (the write then reports the underrun).
fn slack_us<E>(capacity: usize, free: Result<usize, E>) -> Option<u32> {
    let queued = capacity.saturating_sub(free.ok()?) as u64;
    Some((queued * 1_000_000 / u64::from(chladni_shared::icd::units::SAMPLE_RATE)) as u32)
}

/// The drive's executor (see the module docs).
static DRIVE_EXECUTOR: embassy_executor::InterruptExecutor =
    embassy_executor::InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    // SAFETY: the executor's own interrupt handler, and nothing else calls it.
    unsafe { DRIVE_EXECUTOR.on_interrupt() }
}

/// Starts the drive's interrupt executor at NVIC priority 14 (below every interrupt handler,
/// above thread mode) and returns its spawner. Call once.
pub fn start_drive_executor() -> embassy_executor::SendSpawner {
    use embassy_stm32::interrupt::{InterruptExt, Priority};
    interrupt::UART4.set_priority(Priority::P14);
    DRIVE_EXECUTOR.start(interrupt::UART4)
}

/// Runs embassy's thread-mode executor forever; `init` spawns the first tasks.
pub fn run(init: impl FnOnce(embassy_executor::Spawner)) -> ! {
    static EXECUTOR: static_cell::StaticCell<embassy_executor::Executor> =
        static_cell::StaticCell::new();
    EXECUTOR.init(embassy_executor::Executor::new()).run(init)
}
