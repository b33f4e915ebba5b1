//! Controller firmware entry point: bring the board up, then run one task per concern: the
//! link (requests, store, telemetry), the drive (samples, closed loop, faults), the sense task
//! (the accelerometer), the watchdog (fed only while the other three check in) and the stack
//! gauge (the painted stack's high water, into the status).
//!
//! The drive runs on the board's interrupt executor, above all the others (thread mode), so a
//! long request on the link never makes a refill late.
//!
//! The image exists only for the controller (`target_os = "none"`); a host build of this
//! binary says where to build it instead.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("the firmware runs on the controller: scripts/firmware.sh build qemu|stm32l475");
    std::process::exit(2);
}

#[cfg(target_os = "none")]
mod image {
    use chladni_firmware::app::watchdog::{Supervisor, Task, TaskSet};
    use chladni_firmware::{app, board};
    use embassy_time::Duration;

    /// Shared by the link task (commands in, status out), the sense task (samples in) and
    /// the drive task.
    static DRIVE: app::drive::DriveShared = app::drive::DriveShared::new();
    /// The tasks the watchdog waits for.
    static SUPERVISOR: Supervisor =
        Supervisor::new(TaskSet::of(&[Task::Link, Task::Drive, Task::Sense]));
    /// How often the watchdog task looks at the check-ins (the dog's timeout is 1 s).
    const WATCHDOG_POLL: Duration = Duration::from_millis(250);
    /// How often the stack gauge reads the painted stack (a read is ≤ 8 Ki words).
    const STACK_POLL: Duration = Duration::from_millis(200);

    /// The store's flash: yielding, so a long store request lets the other thread-mode tasks
    /// (sense, watchdog, USB) run between its flash operations.
    type StoreFlash = app::store::yielding::Yielding<board::Flash>;
    /// The link's state (~17 KiB: the store's index and cache, the plan buffer) lives here,
    /// built in place once, not in the link task's future or on its stack.
    static LINK: static_cell::StaticCell<app::link::Link<'static, StoreFlash>> =
        static_cell::StaticCell::new();

    /// Builds the link into [`LINK`]. Out of line and called from `main` before the drive's
    /// executor starts: building it takes about 18 KiB of stack for a moment (the link is made
    /// by value, then moved into place), which the drive must not stack on top of, and which
    /// must not sit in the link task's poll frame (on the stack whenever the drive preempts
    /// the link).
    #[inline(never)]
    fn make_link(flash: Option<board::Flash>) -> &'static mut app::link::Link<'static, StoreFlash> {
        LINK.init_with(|| {
            let store = flash.map(|flash| {
                app::store::PlanStore::new(
                    app::store::yielding::Yielding::new(flash),
                    board::STORE_RANGE,
                )
            });
            if store.is_none() {
                defmt::warn!("no flash: plans and configuration cannot be stored");
            }
            let identity = app::link::Identity { board: board::BOARD, inject: board::INJECT };
            app::link::Link::new(identity, &DRIVE, store)
        })
    }

    #[embassy_executor::task]
    async fn link_task(
        mut port: board::Link,
        link: &'static mut app::link::Link<'static, StoreFlash>,
    ) -> ! {
        link.load_config().await;
        app::link::serve(link, &mut port, &SUPERVISOR).await
    }

    #[embassy_executor::task]
    async fn drive_task(mut output: board::DriveOutput) -> ! {
        let (clock, unit) = (board::refill_clock, board::REFILL_CLOCK_UNIT);
        app::drive::run_metered(&DRIVE, &SUPERVISOR, &mut output, clock, unit).await
    }

    #[embassy_executor::task]
    async fn sense_task(sensor: board::Sensor) -> ! {
        let board::Sensor { bus, mut irq } = sensor;
        app::sense::task::run(&DRIVE, &SUPERVISOR, bus, &mut irq).await
    }

    #[embassy_executor::task]
    async fn stack_task() -> ! {
        let mut reported = 0;
        loop {
            let used = board::stack::high_water();
            DRIVE.set_stack_high_water(used);
            // Logged in 256-byte steps, so a slowly deepening stack does not flood the log.
            if used >= reported + 256 {
                reported = used;
                defmt::info!("stack: high water {=u32} B of {=u32}", used, board::stack::size());
            }
            embassy_time::Timer::after(STACK_POLL).await;
        }
    }

    #[embassy_executor::task]
    async fn watchdog_task(dog: board::Watchdog) -> ! {
        app::watchdog::watchdog_task(&SUPERVISOR, dog, WATCHDOG_POLL).await
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let board = board::init();
        let cause = board::reset_cause();
        DRIVE.set_reset_cause(cause);
        defmt::info!(
            "chladni firmware {} ({}) build {=u32:08x}, reset cause {}",
            chladni_firmware::FIRMWARE_VERSION,
            board::BOARD.name(),
            chladni_firmware::BUILD_ID,
            cause
        );
        let link = make_link(board.flash);
        let drive = board::start_drive_executor();
        drive.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
        board::run(|spawner| {
            // The watchdog first: on the board the IWDG has run since the start of
            // `board::init` (its boot window); its task sets the running timeout.
            spawner
                .spawn(watchdog_task(board.watchdog).expect("watchdog task: spawn pool exhausted"));
            spawner.spawn(link_task(board.link, link).expect("link task: spawn pool exhausted"));
            spawner.spawn(stack_task().expect("stack task: spawn pool exhausted"));
            spawner.spawn(sense_task(board.sensor).expect("sense task: spawn pool exhausted"));
            board::spawn_tasks(spawner, board.tasks);
        })
    }
}
