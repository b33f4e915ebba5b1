//! Watchdog check in QEMU: the check-in rule, the simulated watchdog and the reset cause,
//! across a real (QEMU machine) reset.
//!
//! First boot (reset cause `PowerOn`): the real drive task plays a sine; two stand-in tasks
//! check in for the link and the drive through `app::watchdog::Supervisor`, and the real
//! `watchdog_task` feeds the board's simulated watchdog. After [`HEALTHY`] (longer than the
//! watchdog's timeout, so feeding must have worked) the drive stand-in stops checking in;
//! the watchdog must then park the output, record the cause and reset the machine.
//!
//! Second boot (cause `Watchdog`): the controller must come up idle with the output at
//! mid-scale. The exit code says what the image saw: [`EXIT_WATCHDOG_IDLE`] is the pass;
//! [`EXIT_WATCHDOG_NOT_IDLE`], [`EXIT_CAUSE_SOFTWARE`], [`EXIT_CAUSE_OTHER`],
//! [`EXIT_NO_RESET`] and [`EXIT_SETUP_FAILED`] are failures. (A reset that lost the record
//! would boot as `PowerOn` again and go round until QEMU's timeout.) Run by
//! `tests/watchdog.rs`.
#![no_std]
#![no_main]

use chladni_firmware::app::drive::{self, Command, DriveShared};
use chladni_firmware::app::watchdog::{ResetCause, Supervisor, Task, TaskSet, watchdog_task};
use chladni_firmware::board::{self, qemu::failsafe};
use chladni_shared::drive::dds::DAC_MID;
use chladni_shared::icd::link::DriveState;
use embassy_time::{Duration, Instant, Timer};

/// Exit code: after a watchdog reset, the controller came up idle at mid-scale (the pass).
const EXIT_WATCHDOG_IDLE: i32 = 0;
/// Exit code: after a watchdog reset, the drive was not idle at mid-scale.
const EXIT_WATCHDOG_NOT_IDLE: i32 = 11;
/// Exit code: the reset cause read `Software`.
const EXIT_CAUSE_SOFTWARE: i32 = 12;
/// Exit code: the reset cause read `Other`.
const EXIT_CAUSE_OTHER: i32 = 13;
/// Exit code: the watchdog did not reset the controller in time after the drive hung.
const EXIT_NO_RESET: i32 = 3;
/// Exit code: the drive never started.
const EXIT_SETUP_FAILED: i32 = 2;

/// How long everyone checks in before the drive stand-in hangs: 2.5 watchdog timeouts.
const HEALTHY: Duration = Duration::from_millis(2_500);
/// The watchdog task's poll period.
const PERIOD: Duration = Duration::from_millis(250);
/// How long after the hang the reset may take (timeout 1 s, plus slack for a loaded host).
const RESET_LIMIT: Duration = Duration::from_secs(10);

static SHARED: DriveShared = DriveShared::new();
static SUPERVISOR: Supervisor = Supervisor::new(TaskSet::of(&[Task::Link, Task::Drive]));
/// The real drive's own check-ins go here, where nobody looks: the stand-in below speaks for
/// the drive, so that it can hang while the samples still flow.
static IGNORED: Supervisor = Supervisor::new(TaskSet::EMPTY);

#[embassy_executor::task]
async fn drive_task(mut output: board::DriveOutput) -> ! {
    drive::run(&SHARED, &IGNORED, &mut output).await
}

#[embassy_executor::task]
async fn dog_task(dog: board::Watchdog) -> ! {
    watchdog_task(&SUPERVISOR, dog, PERIOD).await
}

/// The link stand-in: checks in every 10 ms, forever.
#[embassy_executor::task]
async fn link_task() -> ! {
    loop {
        SUPERVISOR.check_in(Task::Link);
        Timer::after_millis(10).await;
    }
}

/// The drive stand-in: checks in while samples flow, for [`HEALTHY`], then hangs.
#[embassy_executor::task]
async fn hang_task() {
    if SHARED
        .submit(Command::Drive {
            freq_mhz: 150_000,
            level: chladni_shared::icd::plan::Level::Drive(16_384),
        })
        .is_err()
    {
        board::exit(EXIT_SETUP_FAILED);
    }
    let start = Instant::now();
    let mut samples = 0;
    while start.elapsed() < HEALTHY {
        let now = SHARED.status().elapsed_samples;
        if now > samples {
            SUPERVISOR.check_in(Task::Drive);
            samples = now;
        }
        Timer::after_millis(10).await;
    }
    if failsafe::output_code() == DAC_MID && SHARED.status().amplitude_q15 == 0 {
        defmt::error!("watchdog_reset: the drive never ran");
        board::exit(EXIT_SETUP_FAILED);
    }
    defmt::println!(
        "watchdog_reset: fed for {=u64} ms; the drive stops checking in (output at code {=u16})",
        start.elapsed().as_millis(),
        failsafe::output_code()
    );
    Timer::after(RESET_LIMIT).await;
    defmt::error!("watchdog_reset: no reset {=u64} s after the hang", RESET_LIMIT.as_secs());
    board::exit(EXIT_NO_RESET);
}

/// After the watchdog reset: the drive must be idle and the output at mid-scale.
#[embassy_executor::task]
async fn check_idle_task() {
    Timer::after_millis(100).await;
    let status = SHARED.status();
    let code = failsafe::output_code();
    let idle = status.state == DriveState::Idle && status.amplitude_q15 == 0 && code == DAC_MID;
    defmt::println!(
        "watchdog_reset: after the watchdog reset: state {}, amplitude {=u16}, output code {=u16}",
        status.state,
        status.amplitude_q15,
        code
    );
    board::exit(if idle { EXIT_WATCHDOG_IDLE } else { EXIT_WATCHDOG_NOT_IDLE })
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let board = board::init();
    let cause = board::reset_cause();
    defmt::println!("watchdog_reset: boot, reset cause {}", cause);
    match cause {
        ResetCause::PowerOn => board::run(|spawner| {
            spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
            spawner.spawn(dog_task(board.watchdog).expect("dog task: spawn pool exhausted"));
            spawner.spawn(link_task().expect("link task: spawn pool exhausted"));
            spawner.spawn(hang_task().expect("hang task: spawn pool exhausted"));
        }),
        ResetCause::Watchdog => {
            // Not started again: this boot only checks what the reset left.
            let _unstarted = board.watchdog;
            board::run(|spawner| {
                spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
                spawner.spawn(check_idle_task().expect("check task: spawn pool exhausted"));
            })
        }
        ResetCause::Software => board::exit(EXIT_CAUSE_SOFTWARE),
        ResetCause::Other => board::exit(EXIT_CAUSE_OTHER),
    }
}
