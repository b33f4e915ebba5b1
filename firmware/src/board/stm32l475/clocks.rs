//! The clock tree: 80 MHz system clock for the drive, 48 MHz for USB, both from MSI locked to
//! the 32.768 kHz crystal.
//!
//! ```text
//! LSE 32.768 kHz (X3) ──► MSI PLL mode: MSI 4 MHz locked to LSE
//! MSI 4 MHz ─► PLLM /1 ─┬► PLL1    ×40 = 160 MHz ─► R /2 ─► SYSCLK 80 MHz ─► TIM6 ─► 50 kS/s
//!                       └► PLLSAI1 ×24 =  96 MHz ─► Q /2 ─► CLK48 48 MHz  ─► USB OTG FS
//! ```
//!
//! Why PLLSAI1-Q for USB, not MSI at 48 MHz: embassy-stm32 0.6.0's `rcc::init` (rcc/l.rs)
//! switches SYSCLK to MSI, then calls `msi_enable(config.msi)` while MSI still clocks the core,
//! and only sets the flash wait states (FLASH_ACR.LATENCY, from the final HCLK) afterwards, just
//! before switching to the PLL. With `msi = RANGE48M` the core would run at 48 MHz on the reset
//! latency of 0 wait states (good to 16 MHz in range 1): instruction fetches go wrong and it
//! faults. Besides, PLL1 fed from 48 MHz would need another divider chain. PLLSAI1 leaves MSI,
//! PLL1, SYSCLK and TIM6 exactly as they were (same registers as before USB), and embassy sets
//! it up in the same `init` (`config.rcc.pllsai1`; on the L47x, PLLSAI1 shares PLL1's source
//! and M divider, which `init` checks are equal: both MSI, /1).
//!
//! Accuracy: USB full speed allows ±0.25 %, and embassy-stm32's OTG driver panics unless the
//! nominal CLK48 is within 48 MHz ± 120 kHz (usb/mod.rs `common_init`): 4 MHz × 24 / 2 is
//! 48 MHz exactly. Locked to LSE, MSI is as stable as the crystal; its exact locked frequency
//! is the datasheet's "MSI in PLL mode" value for range 6 (3.998 MHz there, i.e. −0.06 %: the
//! same offset on SYSCLK, the sample rate and CLK48; well inside USB's tolerance). Untested on
//! hardware: measure it (see docs/firmware.md).

use embassy_stm32::rcc::mux::Clk48sel;
use stm32_metapac as pac;

/// embassy-stm32's configuration for this clock tree (see the module documentation).
///
/// embassy-stm32 0.6.0 sets MSIPLLEN itself in `rcc::init` when `ls.lse` is a 32 768 Hz crystal,
/// after LSERDY (rcc/l.rs), which is the order RM0351 asks for. `default_lse` also clocks the
/// (unused) RTC from LSE instead of LSI.
pub fn config() -> embassy_stm32::Config {
    use embassy_stm32::rcc::*;
    let mut config = embassy_stm32::Config::default();
    config.rcc.ls = LsConfig::default_lse();
    config.rcc.msi = Some(MSIRange::RANGE4M);
    config.rcc.pll = Some(Pll {
        source: PllSource::MSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL40,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    // VCO 96 MHz (RM0351: 64..344 MHz from a 4..16 MHz input), Q output 48 MHz.
    config.rcc.pllsai1 = Some(Pll {
        source: PllSource::MSI,
        prediv: PllPreDiv::DIV1,
        mul: PllMul::MUL24,
        divp: None,
        divq: Some(PllQDiv::DIV2),
        divr: None,
    });
    config.rcc.mux.clk48sel = Clk48sel::PLLSAI1_Q;
    config
}

/// Logs the clock tree's state: MSI locked to LSE (or why not) and the USB clock's source.
pub fn check() {
    let lse_ready = pac::RCC.bdcr().read().lserdy();
    let msi_pll = pac::RCC.cr().read().msipllen();
    if lse_ready && msi_pll {
        defmt::info!("clocks: 80 MHz from MSI 4 MHz locked to LSE 32.768 kHz (MSI PLL mode)");
    } else {
        defmt::warn!("clocks: MSI untrimmed (LSE ready {}, MSIPLLEN {})", lse_ready, msi_pll);
    }
    let sai1_ready = pac::RCC.cr().read().pllsai1rdy();
    let clk48 = pac::RCC.ccipr().read().clk48sel();
    if sai1_ready && clk48 == Clk48sel::PLLSAI1_Q {
        defmt::info!("clocks: USB 48 MHz from PLLSAI1 (MSI 4 MHz x24 /2)");
    } else {
        defmt::warn!(
            "clocks: USB clock not ready (PLLSAI1 ready {}, CLK48SEL {})",
            sai1_ready,
            clk48 as u8
        );
    }
}
