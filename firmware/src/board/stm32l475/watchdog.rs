//! The B-L475E-IOT01A's watchdog: the independent watchdog (IWDG) on the LSI, and the reset
//! cause from RCC_CSR.
//!
//! Timeout: [`TIMEOUT_MS`] = 1 s at the LSI's nominal 32 kHz (prescaler /8 and reload 3999:
//! 4000 ticks of 250 µs). The LSI is an RC oscillator: the STM32L475
//! datasheet gives 31.04–32.96 kHz at 3 V and 30 °C and 29.5–34 kHz over the full voltage and
//! temperature range, so the real timeout lies between 32 000 / 34 000 s = 941 ms and
//! 32 000 / 29 500 s = 1085 ms. `app::watchdog::watchdog_task` polls every 250 ms and every
//! task checks in at least once per poll, so a healthy controller pets at least every 500 ms:
//! 441 ms of margin against the shortest timeout, and a hung task resets the controller within
//! 1.1 s of the last pet.
//!
//! The IWDG is frozen while a debugger halts the core (DBGMCU APB1FZR1.DBG_IWDG_STOP), so a
//! breakpoint does not reset the board under the debugger. Once started it cannot be stopped
//! (only a reset does).
//!
//! **Started first, before anything that can hang.** `board::init` calls [`start_for_boot`]
//! before `embassy_stm32::init`, which waits without a limit for the LSE crystal (LSERDY; the
//! datasheet's typical start-up is 2 s) and the PLLs: a dead crystal then gives a reset loop
//! that the log names (`reset cause Watchdog`), not a silent hang. The boot window is
//! [`BOOT_TIMEOUT_MS`] (prescaler /32, reload 3999: 4 s at the nominal 32 kHz, 3.76–4.34 s over
//! the LSI's range), longer than the crystal's start-up. The watchdog task's
//! [`Watchdog::start`] then sets the 1 s running timeout and pets.
//!
//! After a HardFault or panic the core waits with the output parked (`failsafe.rs`) and the
//! IWDG resets it within the timeout: the next boot reads `Watchdog`.
//!
//! A watchdog reset resets the DAC too (PA4 back to analog input, floating: the amplifier sees
//! no drive), and the firmware boots idle with the drive at zero.

use core::cell::Cell;

use critical_section::Mutex;
use embassy_stm32::peripherals;
use stm32_metapac as pac;
use stm32_metapac::iwdg::vals::{Key, Pr};

use crate::app::watchdog::{self, ResetCause, ResetFlags};

/// The running timeout, ms (at the nominal 32 kHz LSI; see the module docs): prescaler /8,
/// reload 3999, 4000 ticks of 250 µs.
pub const TIMEOUT_MS: u32 = 1_000;
const RUN: (Pr, u16) = (Pr::DIVIDE_BY8, 3999);

/// The boot window, ms: prescaler /32, reload 3999, 4000 ticks of 1 ms.
pub const BOOT_TIMEOUT_MS: u32 = 4_000;
const BOOT: (Pr, u16) = (Pr::DIVIDE_BY32, 3999);

/// Polls of IWDG_SR while a new prescaler or reload reaches the LSI domain (a few LSI
/// cycles, ~150 µs; the loop is far longer at 4–80 MHz).
const UPDATE_POLLS: u32 = 100_000;

/// The cause read at boot, once.
static CAUSE: Mutex<Cell<Option<ResetCause>>> = Mutex::new(Cell::new(None));

/// Starts the IWDG with the boot window [`BOOT_TIMEOUT_MS`]. Raw registers: it runs before
/// `embassy_stm32::init` (the START key also switches the LSI on).
pub(super) fn start_for_boot() {
    pac::DBGMCU.apb1fzr1().modify(|w| w.set_iwdg(true));
    pac::IWDG.kr().write(|w| w.set_key(Key::START));
    configure(BOOT);
}

/// Sets prescaler and reload, waits until the LSI domain has them, then reloads the counter.
fn configure((pr, reload): (Pr, u16)) {
    pac::IWDG.kr().write(|w| w.set_key(Key::ENABLE));
    pac::IWDG.pr().write(|w| w.set_pr(pr));
    pac::IWDG.rlr().write(|w| w.set_rl(reload));
    let mut polls = 0;
    while polls < UPDATE_POLLS && {
        let sr = pac::IWDG.sr().read();
        sr.pvu() || sr.rvu()
    } {
        polls += 1;
    }
    pac::IWDG.kr().write(|w| w.set_key(Key::RESET));
}

/// The independent watchdog, running with the boot window since [`start_for_boot`].
pub struct Watchdog {
    _iwdg: embassy_stm32::Peri<'static, peripherals::IWDG>,
}

impl Watchdog {
    /// Takes the IWDG (so that nothing else configures it); it already runs.
    pub(super) fn new(iwdg: embassy_stm32::Peri<'static, peripherals::IWDG>) -> Self {
        Self { _iwdg: iwdg }
    }
}

impl watchdog::Watchdog for Watchdog {
    fn start(&mut self) {
        configure(RUN);
        defmt::info!("watchdog: IWDG timeout {=u32} ms nominal (was the boot window)", TIMEOUT_MS);
    }

    fn pet(&mut self) {
        pac::IWDG.kr().write(|w| w.set_key(Key::RESET));
    }
}

/// Why the controller started, from RCC_CSR's reset flags; the flags are then cleared (RMVF)
/// so that the next reset's flags are its own. The first call's answer is kept.
pub fn reset_cause() -> ResetCause {
    critical_section::with(|cs| {
        let cause = CAUSE.borrow(cs);
        if let Some(known) = cause.get() {
            return known;
        }
        let csr = pac::RCC.csr().read();
        let flags = ResetFlags {
            watchdog: csr.iwdgrstf() || csr.wwdgrstf(),
            software: csr.sftrstf(),
            brown_out: csr.borrstf(),
            pin: csr.pinrstf(),
        };
        pac::RCC.csr().modify(|w| w.set_rmvf(true));
        let known = flags.cause();
        defmt::info!(
            "reset cause {} (RCC_CSR {=u32:#010x}: LPWR OBL FW flags count as Other)",
            known,
            csr.0
        );
        cause.set(Some(known));
        known
    })
}
