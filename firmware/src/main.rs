//! Controller firmware entry point: bring the board up, then run one task per concern.
#![no_std]
#![no_main]

use chladni_firmware::{app, board};

#[embassy_executor::task]
async fn link_task(mut link: board::Link) -> ! {
    app::link::serve(app::link::Identity { board: board::BOARD }, &mut link).await
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
        spawner.spawn(link_task(board.link).expect("link task: spawn pool exhausted"));
    })
}
