//! Fail-safe for the B-L475E-IOT01A: on a panic or a HardFault the drive output is parked at
//! mid-scale before anything else happens, then the fault is logged and the core waits for the
//! IWDG's reset. The HardFault handler runs on a stack of its own (`board::fault_entry`), so a
//! stack overflow parks the output too.
//!
//! The drive runs without the CPU: TIM6 triggers the DAC and circular DMA keeps feeding it from
//! the two-block ring. A crash that only stopped the CPU would leave the DMA replaying the last
//! 10 ms into the amplifier forever. So the handlers stop that machinery by raw register writes
//! (stm32-metapac, no driver state: safe from any context, before or after `init`, any number
//! of times) and only then log.
//!
//! Why not panic-probe's own `#[panic_handler]`: it disables interrupts and prints first, and
//! offers no hook before the print. With a probe attached, defmt-rtt may block in that print
//! (probe-rs switches RTT to blocking mode), and while it blocks the DMA replays the ring. The
//! crate's handler cannot be linked next to ours (duplicate `panic_impl` lang item), so this
//! module does what panic-probe does, in a safe order: park, disable interrupts, guard against
//! recursion, print the message through defmt (panic-probe's `print-defmt`), then `udf` into
//! HardFault (panic-probe's `hard_fault()`). `scripts/firmware.sh run` starts probe-rs with
//! `--no-catch-hardfault --no-catch-reset`, so the probe does not halt the core at the
//! HardFault vector before this handler has parked the output.
//!
//! With the PWM drive (feature `drive-pwm`) parking means: stop its DMA and hold 50 % duty,
//! the PWM's mid-scale, with TIM3 left running (see [`super::pwm::park`]).
//!
//! After parking, the handlers also detach from USB ([`detach_usb`]): a halted core no longer
//! answers the host, and a device that just stops answering leaves the host's `chladni` waiting
//! on timeouts; a detached one looks unplugged, so the host reports the link closed at once.

use core::sync::atomic::{AtomicBool, Ordering};

#[cfg(not(feature = "drive-pwm"))]
use chladni_shared::drive::dds::DAC_MID;
use stm32_metapac as pac;

#[cfg(not(feature = "drive-pwm"))]
/// DAC1 channel 1 (index 0 in the metapac's per-channel fields).
const DAC_CH1: usize = 0;
#[cfg(not(feature = "drive-pwm"))]
/// DMA1 channel 3 (index 2), the DAC1 ch1 channel (request 6), see `super::DacOutput`.
const DMA_CH3: usize = 2;

/// Set by the panic handler, so that the HardFault it raises does not log a second fault.
static PANICKED: AtomicBool = AtomicBool::new(false);

/// Stops the drive and holds the DAC at mid-scale (zero signal). Idempotent, needs no state.
///
/// Order: stop TIM6 (no more DAC triggers), disable the DMA channel and the DAC's DMA request
/// (nothing writes DHR any more), clear TEN1 so that a DHR write reaches the output without a
/// trigger (RM0351 DAC_CR: with TEN1 = 0, DHR1 moves to DOR1 one APB clock later; with
/// TEN1 = 1 it would wait for a trigger that no longer comes), then write mid-scale. The
/// channel stays enabled: switching it off would let PA4 float instead of holding mid-scale.
/// Before `init` the peripheral clocks are off, the writes are ignored, and nothing drives.
#[cfg(not(feature = "drive-pwm"))]
pub fn park_output() {
    pac::TIM6.cr1().modify(|w| w.set_cen(false));
    pac::DMA1.ch(DMA_CH3).cr().modify(|w| w.set_en(false));
    pac::DAC1.cr().modify(|w| {
        w.set_dmaen(DAC_CH1, false);
        w.set_ten(DAC_CH1, false);
    });
    pac::DAC1.dhr12r(DAC_CH1).write(|w| w.set_dhr(DAC_MID));
}

/// Detaches the controller from USB: OTG_FS DCTL.SDIS (soft disconnect) makes the core release
/// its DP pull-up, which a host sees as an unplug. Raw register write like [`park_output`]:
/// idempotent, and ignored while the USB clock is still off (before `init`, or before the USB
/// task's first poll).
pub fn detach_usb() {
    pac::USB_OTG_FS.dctl().modify(|w| w.set_sdis(true));
}

/// Stops the PWM drive (feature `drive-pwm`) and holds it at 50 % duty, the PWM's mid-scale
/// (zero signal after the filter): see [`super::pwm::park`]. Idempotent, needs no state.
#[cfg(feature = "drive-pwm")]
pub fn park_output() {
    super::pwm::park();
}

/// Logs the PWM's duty and whether it is parked, for the fault report (feature `drive-pwm`).
#[cfg(feature = "drive-pwm")]
fn report_output() {
    let (duty, parked) = super::pwm::parked_duty();
    if parked {
        defmt::error!("fault: output parked at duty {=u16}", duty);
    } else {
        defmt::error!("fault: output NOT parked (duty {=u16})", duty);
    }
}

/// Logs what the output holds now (DOR1 and whether TIM6 still runs), for the fault report.
#[cfg(not(feature = "drive-pwm"))]
fn report_output() {
    // DOR1 follows DHR1 one APB clock after the write; a few loads later it has.
    let code = pac::DAC1.dor(DAC_CH1).read().dor();
    let tim6_running = pac::TIM6.cr1().read().cen();
    if code == DAC_MID && !tim6_running {
        defmt::error!("fault: output parked at code {=u16}", code);
    } else {
        defmt::error!(
            "fault: output NOT parked (code {=u16}, TIM6 running {})",
            code,
            tim6_running
        );
    }
}

/// Waits here with the output parked, the safe idle state, until the IWDG (started at boot)
/// resets the controller, within its 1 s timeout.
///
/// No reset of our own: the handler has nothing to gain from one, and waiting keeps the RAM
/// a debugger wants to read for as long as the watchdog allows (and for good under a
/// debugger, which freezes the IWDG while the core is halted). The reset then takes the DAC
/// off (PA4 floats: no drive) and the next boot enables it at mid-scale (`dac.rs`).
fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    park_output();
    detach_usb();
    cortex_m::interrupt::disable();
    if !PANICKED.swap(true, Ordering::Relaxed) {
        defmt::error!("panic: {}", defmt::Display2Format(info));
        report_output();
    }
    escalate_to_hard_fault()
}

/// panic-probe's `hard_fault()`: make sure `udf` escalates to HardFault (UsageFault disabled),
/// so a probe sees the same fault as from any other crash.
fn escalate_to_hard_fault() -> ! {
    // SAFETY: only clears USGFAULTENA in SHCSR; nothing else depends on UsageFault.
    unsafe { (*cortex_m::peripheral::SCB::PTR).shcsr.modify(|v| v & !(1 << 18)) };
    cortex_m::asm::udf()
}

/// The HardFault handler, entered on the fault stack (`board::fault_entry`), so it runs after a
/// stack overflow too: park, detach, log, halt. The IWDG, started at boot, keeps counting
/// while the core waits here (it freezes only while a debugger halts the core), so the
/// controller resets within its timeout and the next boot reads the cause `Watchdog`.
pub(crate) fn hard_fault(entry: crate::board::fault_entry::FaultEntry) -> ! {
    park_output();
    detach_usb();
    if !PANICKED.load(Ordering::Relaxed) {
        entry.log();
        report_output();
    }
    halt()
}

/// NMI: an uncorrectable ECC error in flash bank 2 (the plan store) is data, absorbed and
/// returned from ([`super::bank2`]); anything else (an ECC error in the program itself, an SRAM2
/// parity error) is a fault: park, detach, log, halt, as for a HardFault. (cortex-m-rt's
/// default NMI handler would spin with the DMA still replaying the ring.)
// SAFETY (of defining the handler, which cortex-m-rt marks unsafe because an NMI preempts even
// critical sections): it touches only FLASH_ECCR, an atomic counter and the parking registers,
// all of which are safe to access from any context.
#[cortex_m_rt::exception]
unsafe fn NonMaskableInt() {
    if super::bank2::absorb_ecc_error() {
        return;
    }
    park_output();
    detach_usb();
    if !PANICKED.load(Ordering::Relaxed) {
        defmt::error!("NMI (not an ECC error in flash bank 2)");
        report_output();
    }
    halt()
}
