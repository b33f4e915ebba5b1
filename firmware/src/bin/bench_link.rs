//! Cost of the link's heaviest requests on Cortex-M, in instructions: `UploadChunk` (32 steps)
//! and `RunPlan` of a 256-step stored plan, through `Link::handle` (admission, the handler, the
//! plan store over a RAM flash laid out like bank 2, the drive's hand-over), as the link task
//! runs them; framing is not included.
//!
//! Run by `scripts/firmware.sh bench-link qemu`, which boots this image with `-icount shift=0`:
//! QEMU then advances its virtual clock by exactly 1 ns per executed instruction. SysTick runs
//! from the 4 MHz reset clock, so one SysTick count is 250 instructions and a 1 ms tick 10⁶;
//! [`now`] reads both, so one measurement is good to ±250 instructions, and each figure is the
//! mean of [`ROUNDS`] requests. Without `-icount` the numbers are meaningless.
#![no_std]
#![no_main]

use chladni_firmware::app::drive::{DriveCore, DriveShared};
use chladni_firmware::app::link::{Identity, Link};
use chladni_firmware::app::store::PlanStore;
use chladni_firmware::board;
use chladni_shared::drive::runner::BLOCK_LEN;
use chladni_shared::icd::link::{Board, Endpoint, Request, Response, RunPlan, UploadCommit};
use chladni_shared::icd::plan::{Level, Plan, Step};
use chladni_shared::icd::store::{CHUNK_STEPS, PlanRef, UploadBegin, UploadChunk};
use cortex_m::peripheral::SYST;
use embassy_time::Instant;
use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};
use static_cell::ConstStaticCell;

/// Requests measured per figure.
const ROUNDS: u64 = 20;
/// Pages of the RAM flash (32 KiB: room for the plan, its replacement and garbage).
const PAGES: usize = 16;
const PAGE: usize = 2048;
/// Instructions per SysTick count (4 MHz SysTick, 1 ns per instruction).
const PER_COUNT: u64 = 250;
/// SysTick counts per 1 ms tick.
const RELOAD: u64 = 4_000;

/// Instructions since boot: ms ticks and the SysTick count within the tick.
fn now() -> u64 {
    loop {
        let ticks = Instant::now().as_ticks();
        let count = SYST::get_current() as u64;
        if Instant::now().as_ticks() == ticks {
            return (ticks * RELOAD + (RELOAD - 1 - count.min(RELOAD - 1))) * PER_COUNT;
        }
    }
}

/// A RAM NOR flash: erase sets bits, programming clears them (8-byte words, 2 KiB pages). The
/// bytes are kept inverted, so that the zeroed RAM it starts from reads as erased flash.
struct RamFlash(&'static mut [u8; PAGES * PAGE]);

#[derive(Debug, defmt::Format)]
struct OutOfBounds;

impl NorFlashError for OutOfBounds {
    fn kind(&self) -> NorFlashErrorKind {
        NorFlashErrorKind::OutOfBounds
    }
}

impl ErrorType for RamFlash {
    type Error = OutOfBounds;
}

impl ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = offset as usize;
        let src = self.0.get(at..at + bytes.len()).ok_or(OutOfBounds)?;
        bytes.iter_mut().zip(src).for_each(|(b, s)| *b = !s);
        Ok(())
    }

    fn capacity(&self) -> usize {
        PAGES * PAGE
    }
}

impl NorFlash for RamFlash {
    const WRITE_SIZE: usize = 8;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        self.0.get_mut(from as usize..to as usize).ok_or(OutOfBounds)?.fill(0);
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let at = offset as usize;
        let dst = self.0.get_mut(at..at + bytes.len()).ok_or(OutOfBounds)?;
        dst.iter_mut().zip(bytes).for_each(|(d, b)| *d |= !b);
        Ok(())
    }
}

/// A 256-step plan with steps of every shape the encoding has (closed and open loop).
fn plan() -> Plan {
    let steps = (0..256u32).map(|i| Step {
        freq_mhz: 100_000 + i * 997,
        level: if i % 2 == 0 { Level::Drive(1_000 + i as u16) } else { Level::Accel(5_000 + i) },
        duration_ms: 20 + i,
        ramp_ms: i % 7,
    });
    Plan {
        name: heapless::String::try_from("bench").unwrap_or_default(),
        repeat: 1,
        steps: steps.collect(),
    }
}

/// Sends one request as session 1; the response and the instructions it took.
async fn call(link: &mut Link<'_, RamFlash>, request: Request) -> (Response, u64) {
    let start = now();
    let response = link.handle(1, 1, request, Instant::now()).await;
    (response, now() - start)
}

/// Uploads `p` (into slot 0); the instructions of its `UploadChunk`s, summed, and their number.
async fn upload(link: &mut Link<'_, RamFlash>, p: &Plan) -> (u64, u64) {
    let (begun, _) = call(link, UploadBegin::of(p, Some(0)).into_request()).await;
    defmt::assert!(matches!(begun, Response::UploadBegin(0)), "{}", begun);
    let (mut sum, mut chunks) = (0, 0);
    for (i, steps) in p.steps.chunks(CHUNK_STEPS).enumerate() {
        let chunk = UploadChunk { index: i as u16, steps: steps.iter().copied().collect() };
        let (answer, cost) = call(link, chunk.into_request()).await;
        defmt::assert!(matches!(answer, Response::UploadChunk(_)), "{}", answer);
        sum += cost;
        chunks += 1;
    }
    let (committed, _) = call(link, UploadCommit.into_request()).await;
    defmt::assert!(matches!(committed, Response::UploadCommit(_)), "{}", committed);
    (sum, chunks)
}

static DRIVE: DriveShared = DriveShared::new();

/// The bench, as a task: the link lives in its (static) state, as in the firmware's link task.
#[embassy_executor::task]
async fn bench() {
    static FLASH: ConstStaticCell<[u8; PAGES * PAGE]> = ConstStaticCell::new([0; PAGES * PAGE]);
    let store = PlanStore::new(RamFlash(FLASH.take()), 0..(PAGES * PAGE) as u32);
    let identity = Identity { board: Board::Qemu, inject: None };
    let mut link = Link::new(identity, &DRIVE, Some(store));
    link.load_config().await;
    let mut core = DriveCore::new(&DRIVE);
    let mut block = [0u16; BLOCK_LEN];
    let p = plan();

    let (mut chunk_sum, mut chunks) = (0, 0);
    for _ in 0..ROUNDS / 4 {
        let (sum, n) = upload(&mut link, &p).await;
        chunk_sum += sum;
        chunks += n;
    }
    defmt::println!("bench upload_chunk_32_steps {=u64} instructions", chunk_sum / chunks);

    let mut run_sum = 0;
    for _ in 0..ROUNDS {
        let run = RunPlan { plan: PlanRef::Slot(0), repeat: None };
        let (answer, cost) = call(&mut link, run.into_request()).await;
        defmt::assert!(matches!(answer, Response::RunPlan(_)), "{}", answer);
        run_sum += cost;
        // The drive takes the plan (not measured), so the command queue never fills.
        core.refill(&mut block);
    }
    defmt::println!("bench run_plan_256_steps {=u64} instructions", run_sum / ROUNDS);
    board::exit(0)
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let _board = board::init();
    board::run(|spawner| spawner.spawn(bench().expect("bench task: spawn pool exhausted")))
}
