//! Fail-safe check in QEMU: drive the simulated DAC through the real drive task, then crash and
//! let the board's fault handlers park the output.
//!
//! The crash is chosen on the semihosting command line: `crash=panic` (a Rust panic),
//! `crash=hardfault` (an undefined instruction, which escalates to HardFault because
//! UsageFault is not enabled) or `crash=stack-overflow` (real recursion until the stack runs
//! off the bottom of SRAM2, with the watchdog running as in the firmware). The handlers end
//! QEMU with `board::qemu::failsafe::EXIT_PANIC_PARKED` / `EXIT_HARD_FAULT_PARKED`, or
//! `EXIT_FAULT_NOT_PARKED`; [`EXIT_SETUP_FAILED`] means the crash was never reached.
//!
//! The stack overflow goes on as on the board: the HardFault handler (on its own stack) parks
//! the output and waits for the watchdog, which resets the machine; the second boot reads the
//! reset cause and exits [`EXIT_IDLE_AFTER_RESET`] if it is `Watchdog` and the drive is idle
//! at mid-scale ([`EXIT_NOT_IDLE_AFTER_RESET`] if not, [`EXIT_OVERFLOW_SURVIVED`] if the
//! recursion ever came back). Run by `tests/failsafe.rs`.
#![no_std]
#![no_main]

use chladni_firmware::app::drive::{self, Command, DriveShared};
use chladni_firmware::app::watchdog::{ResetCause, Supervisor, TaskSet, watchdog_task};
use chladni_firmware::board::{self, fault_entry, qemu::failsafe, qemu::flash};
use chladni_shared::drive::dds::DAC_MID;
use chladni_shared::icd::link::DriveState;
use embassy_time::{Duration, Instant, Timer};

/// Exit code: no crash happened (bad argument, or the drive never left mid-scale).
const EXIT_SETUP_FAILED: i32 = 2;
/// Exit code: the recursion meant to overflow the stack returned.
const EXIT_OVERFLOW_SURVIVED: i32 = 4;
/// Exit code: booted again after a watchdog reset, drive idle, output at mid-scale (the pass
/// of `crash=stack-overflow`).
const EXIT_IDLE_AFTER_RESET: i32 = 0;
/// Exit code: booted again after a watchdog reset, but not idle at mid-scale.
const EXIT_NOT_IDLE_AFTER_RESET: i32 = 11;

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
/// No task is supervised: the watchdog (started only for `crash=stack-overflow`) is fed every
/// period until the crash, after which nothing feeds it.
static SUPERVISOR: Supervisor = Supervisor::new(TaskSet::EMPTY);

/// The way to crash.
#[derive(Clone, Copy, PartialEq, defmt::Format)]
enum Crash {
    Panic,
    HardFault,
    StackOverflow,
}

/// Bytes of each recursion level's own frame: 32 KiB of stack is gone in ~128 levels.
const FRAME: usize = 256;

/// Recurses until the stack runs out (`depth` never reaches `u32::MAX` first). Each level
/// keeps a buffer the optimiser cannot drop and uses the deeper result, so there is neither
/// a tail call nor a loop to turn it into.
#[inline(never)]
fn dive(depth: u32) -> u32 {
    let mut frame = [0u8; FRAME];
    frame[0] = depth as u8;
    core::hint::black_box(&mut frame);
    if depth == u32::MAX {
        return 0;
    }
    dive(depth + 1).wrapping_add(u32::from(core::hint::black_box(&frame)[FRAME - 1]))
}

#[embassy_executor::task]
async fn dog_task(dog: board::Watchdog) -> ! {
    watchdog_task(&SUPERVISOR, dog, Duration::from_millis(250)).await
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
        Crash::StackOverflow => {
            let sum = dive(0);
            defmt::error!("failsafe: the recursion returned ({=u32})", sum);
            board::exit(EXIT_OVERFLOW_SURVIVED)
        }
    }
}

/// After the watchdog reset: the drive must be idle and the output at mid-scale.
#[embassy_executor::task]
async fn check_idle_task() {
    Timer::after_millis(100).await;
    let status = SHARED.status();
    let code = failsafe::output_code();
    let idle = status.state == DriveState::Idle && status.amplitude_q15 == 0 && code == DAC_MID;
    defmt::println!(
        "failsafe: after the reset: state {}, amplitude {=u16}, output code {=u16}",
        status.state,
        status.amplitude_q15,
        code
    );
    board::exit(if idle { EXIT_IDLE_AFTER_RESET } else { EXIT_NOT_IDLE_AFTER_RESET })
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let board = board::init();
    let cause = board::reset_cause();
    defmt::println!("failsafe: boot, reset cause {}", cause);
    if cause != ResetCause::PowerOn {
        // The fault stack was painted before the crash and survives QEMU's reset.
        defmt::println!(
            "failsafe: the fault handler used {=u32} B of the {=usize} B fault stack",
            fault_entry::high_water(),
            fault_entry::FAULT_STACK_SIZE
        );
        // Not started again: this boot only checks what the reset left.
        let _unstarted = board.watchdog;
        board::run(|spawner| {
            spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
            spawner.spawn(check_idle_task().expect("check task: spawn pool exhausted"));
        })
    }
    fault_entry::paint();
    let mut arg = [0u8; 256];
    let crash = match flash::cmdline_arg("crash", &mut arg) {
        Some("panic") => Crash::Panic,
        Some("hardfault") => Crash::HardFault,
        Some("stack-overflow") => Crash::StackOverflow,
        other => {
            defmt::error!("failsafe: want crash=panic|hardfault|stack-overflow, got {}", other);
            board::exit(EXIT_SETUP_FAILED)
        }
    };
    board::run(|spawner| {
        if crash == Crash::StackOverflow {
            spawner.spawn(dog_task(board.watchdog).expect("dog task: spawn pool exhausted"));
        }
        spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
        spawner.spawn(crash_task(crash).expect("crash task: spawn pool exhausted"));
    })
}
