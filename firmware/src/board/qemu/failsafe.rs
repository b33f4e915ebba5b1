//! Fail-safe for the QEMU board: the simulated DAC parks at mid-scale on a panic or HardFault,
//! as the real board's DAC does, and the exit code says whether it did.
//!
//! QEMU has no DAC, so "the output" is [`ParkableDac`]: the app's `SimulatedDac` (paced blocks
//! into the simulated plant) plus the code on the imaginary pin, kept in [`OUTPUT_CODE`]. The
//! fault handlers call [`park_output`] first, then read the code back, log it and end QEMU with
//! [`EXIT_PANIC_PARKED`] / [`EXIT_HARD_FAULT_PARKED`], or [`EXIT_FAULT_NOT_PARKED`] when the
//! output is not at mid-scale and frozen (so a handler that forgot to park fails the test).

use core::sync::atomic::{AtomicBool, AtomicU16, Ordering};

use chladni_shared::drive::dds::DAC_MID;
use chladni_shared::drive::runner::BLOCK_LEN;

use crate::app::drive::{SampleOutput, SimulatedDac, Underrun};

/// Exit code: a panic, and the output was parked at mid-scale.
pub const EXIT_PANIC_PARKED: i32 = 101;
/// Exit code: a HardFault, and the output was parked at mid-scale.
pub const EXIT_HARD_FAULT_PARKED: i32 = 102;
/// Exit code: a panic or HardFault, and the output was NOT at mid-scale afterwards.
pub const EXIT_FAULT_NOT_PARKED: i32 = 103;

/// The code the simulated DAC outputs now: the last sample of the block it is playing.
static OUTPUT_CODE: AtomicU16 = AtomicU16::new(DAC_MID);
/// Set by [`park_output`]: from then on the simulated DAC plays mid-scale only.
static PARKED: AtomicBool = AtomicBool::new(false);

/// The QEMU board's drive output: [`SimulatedDac`], publishing its output code, parkable.
pub struct ParkableDac {
    dac: SimulatedDac,
}

impl Default for ParkableDac {
    fn default() -> Self {
        Self::new()
    }
}

impl ParkableDac {
    /// A plant at rest, output at mid-scale, feeding the simulated accelerometer.
    pub fn new() -> Self {
        let dac = SimulatedDac::new()
            .with_sensor(super::sensor::sim(), &super::sensor::PLANT_FAULTS)
            .with_clock(super::time_driver::now_us);
        Self { dac }
    }

    /// The simulated DAC and plant.
    pub fn simulated(&self) -> &SimulatedDac {
        &self.dac
    }
}

impl SampleOutput for ParkableDac {
    async fn write_block(&mut self, block: &[u16]) -> Result<Option<u32>, Underrun> {
        if PARKED.load(Ordering::Acquire) {
            // Frozen: whatever the drive computes, the "pin" stays at mid-scale.
            return self.dac.write_block(&[DAC_MID; BLOCK_LEN][..block.len()]).await;
        }
        if let Some(&last) = block.last() {
            OUTPUT_CODE.store(last, Ordering::Release);
        }
        self.dac.write_block(block).await
    }
}

/// The code on the simulated DAC's output now.
pub fn output_code() -> u16 {
    OUTPUT_CODE.load(Ordering::Acquire)
}

/// Holds the simulated output at mid-scale from now on. Idempotent, safe from any context.
pub fn park_output() {
    PARKED.store(true, Ordering::Release);
    OUTPUT_CODE.store(DAC_MID, Ordering::Release);
}

/// Logs the output's state and returns the exit code for a fault of kind `parked_code`.
fn report_output(parked_code: i32) -> i32 {
    let code = output_code();
    if code == DAC_MID && PARKED.load(Ordering::Acquire) {
        defmt::error!("fault: output parked at code {=u16}", code);
        parked_code
    } else {
        defmt::error!("fault: output NOT parked (code {=u16})", code);
        EXIT_FAULT_NOT_PARKED
    }
}

/// `defmt::panic!` (and defmt's `unwrap!`, `assert!`) end here after printing their message.
#[defmt::panic_handler]
fn defmt_panic() -> ! {
    park_output();
    super::exit(report_output(EXIT_PANIC_PARKED))
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    park_output();
    defmt::error!("panic: {}", defmt::Display2Format(info));
    super::exit(report_output(EXIT_PANIC_PARKED))
}

/// The HardFault handler, entered on the fault stack (`board::fault_entry`), so it runs after a
/// stack overflow too: park, log, then do what the real board does. There the core halts
/// with the output parked and the IWDG, if started, resets the controller within its
/// timeout; here [`super::watchdog::run_out`] counts the simulated watchdog's remaining time
/// down and resets the machine (the next boot reads `Watchdog`). A watchdog that was never
/// started returns at once, and QEMU exits with the code that says what the output did.
pub(crate) fn hard_fault(entry: crate::board::fault_entry::FaultEntry) -> ! {
    park_output();
    entry.log();
    let code = report_output(EXIT_HARD_FAULT_PARKED);
    super::watchdog::run_out();
    super::exit(code)
}
