//! The B-L475E-IOT01A as QEMU 10 models it (`qemu-system-arm -M b-l475e-iot01a`).
//!
//! QEMU models the core, NVIC, SysTick, RCC, GPIO and the USARTs; every other peripheral reads
//! 0 and ignores writes (see "Board facts" in the design notes). So this board does not call
//! `embassy_stm32::init` (it would spin forever on a PWR bit) and brings its own drivers:
//! - [`time_driver`]: embassy-time on SysTick (1 kHz), because no TIM ever ticks in QEMU;
//! - [`usart`]: USART1 with 32-bit register accesses and an RX interrupt;
//! - [`executor`]: embassy's executor sleeping with WFI instead of WFE (which QEMU spins on);
//! - [`flash`]: flash bank 2 kept in a host file through semihosting (QEMU's flash is inert);
//! - defmt over semihosting, and [`exit`] to end QEMU with a status code;
//! - [`sensor`]: the LSM6DSL accelerometer, simulated (QEMU has no I2C devices);
//! - [`failsafe`]: the simulated DAC parks at mid-scale on a panic or HardFault, and the exit
//!   code says whether it did.
//! - [`watchdog`]: a simulated watchdog counted down by the SysTick time driver; when it runs
//!   out it parks the drive, records the cause in RAM that survives the reset, and resets
//!   (SYSRESETREQ), so [`reset_cause`] says `Watchdog` on the next boot.

pub mod executor;
pub mod failsafe;
pub mod flash;
pub mod sensor;
pub mod time_driver;
pub mod usart;
pub mod watchdog;

use defmt_semihosting as _;

/// This board's identity on the link.
pub const BOARD: chladni_shared::icd::link::Board = chladni_shared::icd::link::Board::Qemu;

/// The host link: USART1, reached by the host through QEMU's `-serial` chardev.
pub type Link = usart::Usart1;

/// The drive output: no DAC in QEMU, so a simulated one paced by the time driver, feeding the
/// simulated shaker + plate, which the fault handlers park.
pub type DriveOutput = failsafe::ParkableDac;

pub use sensor::{Sensor, SensorBus, SensorIrq};
/// The watchdog: simulated, counted down by the time driver (see [`watchdog`]).
pub type Watchdog = watchdog::Watchdog;
pub use watchdog::reset_cause;

/// The link's fault injection: the simulated plant and sensor break on request.
pub const INJECT: Option<fn(chladni_shared::icd::link::TestFault)> = Some(sensor::inject);

/// Flash bank 2 for the plan store: a host file (see [`flash`]).
pub type Flash = flash::FileFlash;

/// The part of [`Flash`] the plan store uses: all of bank 2.
pub const STORE_RANGE: core::ops::Range<u32> = 0..flash::CAPACITY as u32;

/// The initialised board.
pub struct Board {
    /// Host link.
    pub link: Link,
    /// Flash bank 2, when QEMU was given a backing file (`flash=PATH` on the semihosting
    /// command line); without one there is no plan store.
    pub flash: Option<Flash>,
    /// Drive output.
    pub drive: DriveOutput,
    /// The simulated LSM6DSL accelerometer's bus and INT1 line.
    pub sensor: Sensor,
    /// This board's own tasks: none in QEMU.
    pub tasks: BoardTasks,
    /// The (simulated) watchdog, not started: `app::watchdog::watchdog_task` starts it.
    pub watchdog: Watchdog,
}

/// Background work of the board itself (the real board runs its USB device here).
pub struct BoardTasks;

/// Spawns the board's own tasks: QEMU has none.
pub fn spawn_tasks(_spawner: embassy_executor::Spawner, _tasks: BoardTasks) {}

/// Brings the board up: time driver first (everything else may wait on time), then the link.
pub fn init() -> Board {
    super::stack::paint();
    let core = cortex_m::Peripherals::take().expect("board::init called twice");
    time_driver::start(core.SYST);
    let mut arg = [0u8; 256];
    let flash = flash::cmdline_arg("flash", &mut arg).and_then(|path| {
        let opened = flash::FileFlash::open(path);
        match &opened {
            Ok(_) => defmt::info!("flash bank 2 backed by {=str}", path),
            Err(e) => defmt::error!("cannot use {=str} as flash: {}", path, e),
        }
        opened.ok()
    });
    Board {
        link: usart::Usart1::new(),
        flash,
        drive: DriveOutput::new(),
        sensor: sensor::new(),
        tasks: BoardTasks,
        watchdog: Watchdog::new(),
    }
}

pub use executor::{run, start_drive_executor};

/// What [`refill_clock`] counts: QEMU models no DWT cycle counter, so the time driver's
/// nanoseconds, which are instructions when QEMU runs with `-icount shift=0`
/// (`scripts/firmware.sh bench`), 2ᴺ ns per instruction with `shift=N` (`chladni emulator --mips`).
pub const REFILL_CLOCK_UNIT: &str = "ns of QEMU time (instructions under -icount shift=0)";

/// The drive's per-block refill cost clock (see [`REFILL_CLOCK_UNIT`]); wraps every 4.3 s.
pub fn refill_clock() -> u32 {
    time_driver::now_ns() as u32
}

/// Host wall-clock time in seconds since the epoch (semihosting `SYS_TIME`), so tests can
/// compare the firmware's sense of time with the host's. (`SYS_CLOCK` would be QEMU's CPU time,
/// which stands still while the core sleeps in WFI, and QEMU 10 does not implement
/// `SYS_ELAPSED`.)
pub fn host_time_s() -> u32 {
    // SAFETY: SYS_TIME takes no argument and only returns a value.
    unsafe { cortex_m_semihosting::syscall1(cortex_m_semihosting::nr::TIME, 0) as u32 }
}

/// Ends the QEMU process with exit status `code` (semihosting `SYS_EXIT_EXTENDED`: QEMU exits
/// with the subcode when the reason is `ADP_Stopped_ApplicationExit`; plain `SYS_EXIT` on
/// 32-bit Arm only knows success and failure, i.e. 0 or 1).
pub fn exit(code: i32) -> ! {
    const SYS_EXIT_EXTENDED: usize = 0x20;
    const ADP_STOPPED_APPLICATION_EXIT: usize = 0x2_0026;
    let block = [ADP_STOPPED_APPLICATION_EXIT, code as u32 as usize];
    loop {
        // SAFETY: SYS_EXIT_EXTENDED reads the two words of `block`, which outlives the call.
        unsafe { cortex_m_semihosting::syscall1(SYS_EXIT_EXTENDED, block.as_ptr() as usize) };
    }
}
