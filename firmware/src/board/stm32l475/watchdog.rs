//! The B-L475E-IOT01A's watchdog: the independent watchdog (IWDG) on the LSI, and the reset
//! cause from RCC_CSR.
//!
//! Timeout: [`TIMEOUT_US`] = 1 s at the LSI's nominal 32 kHz (embassy-stm32 picks prescaler
//! /8 and reload 3999: 4000 ticks of 250 µs). The LSI is an RC oscillator: the STM32L475
//! datasheet gives 31.04–32.96 kHz at 3 V and 30 °C and 29.5–34 kHz over the full voltage and
//! temperature range, so the real timeout lies between 32 000 / 34 000 s = 941 ms and
//! 32 000 / 29 500 s = 1085 ms. `app::watchdog::watchdog_task` polls every 250 ms and every
//! task checks in at least once per poll, so a healthy controller pets at least every 500 ms:
//! 441 ms of margin against the shortest timeout, and a hung task resets the controller within
//! 1.1 s of the last pet.
//!
//! The IWDG is frozen while a debugger halts the core (DBGMCU APB1FZR1.DBG_IWDG_STOP), so a
//! breakpoint does not reset the board under the debugger. Once started it cannot be stopped
//! (only a reset does): [`Watchdog`] is created by `board::init` but started by the watchdog
//! task.
//!
//! A watchdog reset resets the DAC too (PA4 back to analog input, floating: the amplifier sees
//! no drive), and the firmware boots idle with the drive at zero.

use core::cell::Cell;

use critical_section::Mutex;
use embassy_stm32::peripherals;
use embassy_stm32::wdg::IndependentWatchdog;
use stm32_metapac as pac;

use crate::app::watchdog::{self, ResetCause, ResetFlags};

/// The IWDG timeout asked for, µs (at the nominal 32 kHz LSI; see the module docs).
pub const TIMEOUT_US: u32 = 1_000_000;

/// The cause read at boot, once.
static CAUSE: Mutex<Cell<Option<ResetCause>>> = Mutex::new(Cell::new(None));

/// The independent watchdog, configured ([`TIMEOUT_US`]) but not started.
pub struct Watchdog {
    iwdg: IndependentWatchdog<'static, peripherals::IWDG>,
}

impl Watchdog {
    /// Configures the IWDG (prescaler, reload) without starting it.
    pub(super) fn new(iwdg: embassy_stm32::Peri<'static, peripherals::IWDG>) -> Self {
        pac::DBGMCU.apb1fzr1().modify(|w| w.set_iwdg(true));
        Self { iwdg: IndependentWatchdog::new(iwdg, TIMEOUT_US) }
    }
}

impl watchdog::Watchdog for Watchdog {
    fn start(&mut self) {
        self.iwdg.unleash();
        // A pet right away: the countdown starts full whatever the reload write left.
        self.iwdg.pet();
        defmt::info!("watchdog: IWDG started, timeout {=u32} ms nominal", TIMEOUT_US / 1000);
    }

    fn pet(&mut self) {
        self.iwdg.pet();
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
