//! Fail-safe check in QEMU: drive the simulated DAC through the real drive task, then crash and
//! let the board's fault handlers park the output.
//!
//! The crash is chosen on the semihosting command line: `crash=panic` (a Rust panic) or
//! `crash=hardfault` (an undefined instruction, which escalates to HardFault because
//! UsageFault is not enabled). The handlers end QEMU with
//! `board::qemu::failsafe::EXIT_PANIC_PARKED` / `EXIT_HARD_FAULT_PARKED`, or
//! `EXIT_FAULT_NOT_PARKED`; [`EXIT_SETUP_FAILED`] means the crash was never reached. Run by
//! `tests/failsafe.rs`.
#![no_std]
#![no_main]

use chladni_firmware::app::drive::{self, Command, DriveShared};
use chladni_firmware::app::watchdog::{Supervisor, TaskSet};
use chladni_firmware::board::{self, qemu::failsafe, qemu::flash};
use chladni_shared::drive::dds::DAC_MID;
use embassy_time::{Duration, Instant, Timer};

/// Exit code: no crash happened (bad argument, or the drive never left mid-scale).
const EXIT_SETUP_FAILED: i32 = 2;

/// The drive before the crash: 150 Hz at half amplitude, well inside the device limits.
const DRIVE: Command =
    Command::Drive { freq_mhz: 150_000, level: chladni_shared::icd::plan::Level::Drive(16_384) };

/// How far from mid-scale the output must be before the crash: clearly driven, not a ramp's
/// first steps (half amplitude swings about ±1000 codes).
const DRIVEN: u16 = 256;

/// How long the drive may take to move the output off mid-scale (its ramp is far shorter;
/// the rest is slack for a loaded host).
const START_LIMIT: Duration = Duration::from_secs(10);

static SHARED: DriveShared = DriveShared::new();
/// No watchdog in this image: the drive's check-ins go nowhere.
static SUPERVISOR: Supervisor = Supervisor::new(TaskSet::EMPTY);

/// The way to crash.
#[derive(Clone, Copy, defmt::Format)]
enum Crash {
    Panic,
    HardFault,
}

#[embassy_executor::task]
async fn drive_task(mut output: board::DriveOutput) -> ! {
    drive::run(&SHARED, &SUPERVISOR, &mut output).await
}

#[embassy_executor::task]
async fn crash_task(crash: Crash) {
    if let Err(e) = SHARED.submit(DRIVE) {
        defmt::error!("failsafe: drive refused: {}", e);
        board::exit(EXIT_SETUP_FAILED);
    }
    // Wait until samples flow and the output is well away from mid-scale: a park that merely
    // left an idle output alone would prove nothing.
    let start = Instant::now();
    while SHARED.status().amplitude_q15 == 0 || failsafe::output_code().abs_diff(DAC_MID) < DRIVEN {
        if start.elapsed() > START_LIMIT {
            defmt::error!(
                "failsafe: output still at mid-scale after {} ms",
                START_LIMIT.as_millis()
            );
            board::exit(EXIT_SETUP_FAILED);
        }
        Timer::after_millis(1).await;
    }
    let status = SHARED.status();
    defmt::println!(
        "failsafe: driving, output at code {=u16} after {=u64} samples; crash by {}",
        failsafe::output_code(),
        status.elapsed_samples,
        crash
    );
    match crash {
        Crash::Panic => panic!("deliberate panic (failsafe test)"),
        Crash::HardFault => cortex_m::asm::udf(),
    }
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let board = board::init();
    let mut arg = [0u8; 256];
    let crash = match flash::cmdline_arg("crash", &mut arg) {
        Some("panic") => Crash::Panic,
        Some("hardfault") => Crash::HardFault,
        other => {
            defmt::error!("failsafe: want crash=panic|hardfault, got {}", other);
            board::exit(EXIT_SETUP_FAILED)
        }
    };
    board::run(|spawner| {
        spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
        spawner.spawn(crash_task(crash).expect("crash task: spawn pool exhausted"));
    })
}
