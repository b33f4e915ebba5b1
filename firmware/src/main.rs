//! Controller firmware entry point: bring the board up, then run one task per concern.
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
    use chladni_firmware::{app, board};

    /// Shared by the link task (commands in, status out) and the drive task.
    static DRIVE: app::drive::DriveShared = app::drive::DriveShared::new();

    #[embassy_executor::task]
    async fn link_task(mut port: board::Link, flash: Option<board::Flash>) -> ! {
        // Yielding: a long store request must not keep the drive task from its next block.
        let store = flash.map(|flash| {
            app::store::PlanStore::new(
                app::store::yielding::Yielding::new(flash),
                board::STORE_RANGE,
            )
        });
        if store.is_none() {
            defmt::warn!("no flash: plans and configuration cannot be stored");
        }
        let identity = app::link::Identity { board: board::BOARD };
        let mut link = app::link::Link::new(identity, &DRIVE, store);
        link.load_config().await;
        app::link::serve(&mut link, &mut port).await
    }

    #[embassy_executor::task]
    async fn drive_task(mut output: board::DriveOutput) -> ! {
        app::drive::run(&DRIVE, &mut output).await
    }

    #[cortex_m_rt::entry]
    fn main() -> ! {
        let board = board::init();
        defmt::info!(
            "chladni firmware {} ({}) build {=u32:08x}",
            chladni_firmware::FIRMWARE_VERSION,
            board::BOARD.name(),
            chladni_firmware::BUILD_ID
        );
        board::run(|spawner| {
            spawner.spawn(
                link_task(board.link, board.flash).expect("link task: spawn pool exhausted"),
            );
            spawner.spawn(drive_task(board.drive).expect("drive task: spawn pool exhausted"));
            board::spawn_tasks(spawner, board.tasks);
        })
    }
}
