//! A simulated watchdog for QEMU, which models no IWDG: a countdown in SysTick ticks, and the
//! reset cause kept in RAM that survives the reset.
//!
//! [`Watchdog`] has the surface of the real board's (`app::watchdog::Watchdog`: start, pet).
//! The time driver calls [`on_tick`] from its SysTick interrupt (1 kHz); when the countdown
//! runs out it does what the real IWDG reset amounts to, in a safe order: park the drive at
//! mid-scale (the fail-safe: the real reset takes the DAC off, so the amplifier sees no
//! drive), record [`ResetCause::Watchdog`] in [`RECORD`], then SYSRESETREQ. QEMU's NVIC turns
//! SYSRESETREQ into a machine reset: the core boots again from the vector table and RAM keeps
//! its contents, except what QEMU's `-kernel` loader rewrites (the ELF's loadable segments),
//! so the record lives in `.uninit`, which cortex-m-rt neither loads nor zeroes.
//!
//! [`reset_cause`] reads the record at boot: a watchdog record says `Watchdog`, none says
//! `PowerOn` (QEMU starts with zeroed RAM); then it clears the record, so a later reset of
//! another kind is not reported as a watchdog reset. The first call's answer is kept.

use core::cell::Cell;
use core::mem::MaybeUninit;

use critical_section::Mutex;

use crate::app::watchdog::{self, ResetCause};

/// The watchdog's timeout, ms: as the real board's nominal timeout.
pub const TIMEOUT_MS: u32 = 1_000;

/// "WDOG": the record holds a cause written by this firmware, not RAM noise.
const MAGIC: u32 = 0x5744_4F47;

/// The record that survives a reset: [`MAGIC`], then the cause's code.
#[unsafe(link_section = ".uninit.chladni_reset_record")]
static mut RECORD: MaybeUninit<[u32; 2]> = MaybeUninit::uninit();

/// The cause codes in [`RECORD`].
const CODE_WATCHDOG: u32 = 1;
const CODE_SOFTWARE: u32 = 2;

/// Ticks left before the reset; `None` while the watchdog is not started.
static COUNTDOWN: Mutex<Cell<Option<u32>>> = Mutex::new(Cell::new(None));

/// The cause read at boot, once.
static CAUSE: Mutex<Cell<Option<ResetCause>>> = Mutex::new(Cell::new(None));

/// The simulated watchdog. Like the IWDG, once started it cannot be stopped.
pub struct Watchdog {
    timeout_ticks: u32,
}

impl Watchdog {
    /// A watchdog of [`TIMEOUT_MS`] (1 kHz ticks), not started.
    pub const fn new() -> Self {
        Self { timeout_ticks: TIMEOUT_MS }
    }

    /// A watchdog of `timeout_ms`, not started (for tests that want a short one).
    pub const fn with_timeout_ms(timeout_ms: u32) -> Self {
        Self { timeout_ticks: timeout_ms }
    }
}

impl Default for Watchdog {
    fn default() -> Self {
        Self::new()
    }
}

impl watchdog::Watchdog for Watchdog {
    fn start(&mut self) {
        self.pet();
    }

    fn pet(&mut self) {
        critical_section::with(|cs| COUNTDOWN.borrow(cs).set(Some(self.timeout_ticks)));
    }
}

/// Counts one SysTick down; at zero, parks the drive, records the cause and resets. Called by
/// the time driver's interrupt.
pub fn on_tick() {
    let expired = critical_section::with(|cs| {
        let countdown = COUNTDOWN.borrow(cs);
        match countdown.get() {
            Some(0) => true,
            Some(n) => {
                countdown.set(Some(n - 1));
                false
            }
            None => false,
        }
    });
    if expired {
        super::failsafe::park_output();
        defmt::error!("watchdog: not fed for {=u32} ms: reset", TIMEOUT_MS);
        reset_with(CODE_WATCHDOG)
    }
}

/// From a fault handler (interrupts can no longer run): lets the started watchdog's remaining
/// time run out as the real IWDG does while the core is halted, counting SysTick's wraps by
/// its COUNTFLAG instead of its interrupt, then resets through [`on_tick`]. Returns at once
/// if the watchdog was never started.
pub fn run_out() {
    /// SYST_CSR; bit 16 is COUNTFLAG (set at each wrap, cleared by the read).
    const SYST_CSR: *const u32 = 0xE000_E010 as *const u32;
    if critical_section::with(|cs| COUNTDOWN.borrow(cs).get()).is_none() {
        return;
    }
    defmt::error!("fault: halted; the watchdog resets the controller when it runs out");
    loop {
        // SAFETY: SYST_CSR is an always-readable System Control Space register; reading it
        // only clears COUNTFLAG, which nothing else reads once a fault handler runs.
        if unsafe { SYST_CSR.read_volatile() } & (1 << 16) != 0 {
            on_tick();
        }
    }
}

/// Resets the controller on purpose: recorded as [`ResetCause::Software`].
pub fn software_reset() -> ! {
    reset_with(CODE_SOFTWARE)
}

fn reset_with(code: u32) -> ! {
    write_record([MAGIC, code]);
    cortex_m::peripheral::SCB::sys_reset()
}

fn write_record(words: [u32; 2]) {
    // SAFETY: RECORD is only touched here and in `read_record`, both with volatile accesses
    // of whole words through a raw pointer (no reference to the static mut is made); the
    // writer runs just before a reset, the reader at boot.
    unsafe { core::ptr::write_volatile(core::ptr::addr_of_mut!(RECORD).cast::<[u32; 2]>(), words) }
}

fn read_record() -> [u32; 2] {
    // SAFETY: as in `write_record`; any bit pattern is a valid [u32; 2], so reading RAM that
    // was never written is defined (it is checked against MAGIC).
    unsafe { core::ptr::read_volatile(core::ptr::addr_of!(RECORD).cast::<[u32; 2]>()) }
}

/// Why the controller started: the record left before the last reset, read once and cleared.
pub fn reset_cause() -> ResetCause {
    critical_section::with(|cs| {
        let cause = CAUSE.borrow(cs);
        if let Some(known) = cause.get() {
            return known;
        }
        let known = match read_record() {
            [MAGIC, CODE_WATCHDOG] => ResetCause::Watchdog,
            [MAGIC, CODE_SOFTWARE] => ResetCause::Software,
            [MAGIC, _] => ResetCause::Other,
            _ => ResetCause::PowerOn,
        };
        write_record([0, 0]);
        cause.set(Some(known));
        known
    })
}
