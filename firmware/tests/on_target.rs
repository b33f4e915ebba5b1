//! On-target tests, run on Cortex-M in QEMU by `scripts/firmware.sh test qemu`
//! (defmt-test; the verdict leaves QEMU through semihosting's exit code).
//!
//! `shared_vectors` prints `vector <name> <digest>` for every `chladni_shared::vectors`
//! entry; the host test `tests/on_target.rs` compares those digests with its own, which proves
//! the shared code gives the same bits on both sides.
#![no_std]
#![no_main]

use chladni_firmware::board::qemu::flash::{self, FileFlash};

/// Flash bank 2 in the erased temporary file that scripts/qemu-run.sh passes.
fn open_flash() -> FileFlash {
    let mut arg = [0u8; 256];
    let path = flash::cmdline_arg("flash", &mut arg).expect("no flash= on the command line");
    FileFlash::open(path).expect("open the flash file")
}

/// Outcome of [`timer_task`]: 0 running, 1 passed, 2 failed.
static TIMER_RESULT: core::sync::atomic::AtomicU8 = core::sync::atomic::AtomicU8::new(0);

/// Timers through the SysTick driver's queue: a single one, then two in deadline order.
#[embassy_executor::task]
async fn timer_task() {
    use embassy_time::{Duration, Instant, Timer};
    let start = Instant::now();
    Timer::after(Duration::from_millis(20)).await;
    let waited = start.elapsed();
    let t0 = Instant::now();
    let (late, early) = embassy_futures::join::join(
        async {
            Timer::after(Duration::from_millis(30)).await;
            Instant::now()
        },
        async {
            Timer::after(Duration::from_millis(10)).await;
            Instant::now()
        },
    )
    .await;
    // The tick rate matches the host's clock: a wrong core-clock assumption would be off by a
    // factor (20x for 80 MHz vs 4 MHz), far outside this band, which leaves room for QEMU's
    // time slipping under load.
    let h0 = chladni_firmware::board::qemu::host_time_s();
    Timer::after(Duration::from_millis(3000)).await;
    let host_s = chladni_firmware::board::qemu::host_time_s() - h0;
    defmt::println!("3 s of embassy time took {} s of host time", host_s);
    let ok = (2..=8).contains(&host_s)
        && waited >= Duration::from_millis(20)
        && early < late
        && early - t0 >= Duration::from_millis(10)
        && late - t0 >= Duration::from_millis(30);
    defmt::println!(
        "timers: waited {} ms for 20 ms; 10 ms timer at {} ms, 30 ms timer at {} ms",
        waited.as_millis(),
        (early - t0).as_millis(),
        (late - t0).as_millis()
    );
    TIMER_RESULT.store(if ok { 1 } else { 2 }, core::sync::atomic::Ordering::Release);
}

/// The link's answer to `request` (no flash: nothing is stored).
fn answer(request: chladni_shared::icd::link::Request) -> chladni_shared::icd::link::Response {
    use chladni_firmware::app::link::{Identity, Link};
    use core::cell::RefCell;
    use embassy_sync::blocking_mutex::{Mutex, raw::CriticalSectionRawMutex};
    type TestLink = Link<'static, chladni_firmware::board::qemu::flash::FileFlash>;
    // Statics, as in the application (the drive ~9 KiB: the staged plan, the sweep's points;
    // the link ~17 KiB, which beside the request's future would not fit the 32 KiB stack).
    static DRIVE: chladni_firmware::app::drive::DriveShared =
        chladni_firmware::app::drive::DriveShared::new();
    static LINK: static_cell::StaticCell<TestLink> = static_cell::StaticCell::new();
    static TAKEN: Mutex<CriticalSectionRawMutex, RefCell<Option<&'static mut TestLink>>> =
        Mutex::new(RefCell::new(None));
    let link = TAKEN.lock(|t| t.borrow_mut().take()).unwrap_or_else(|| {
        let identity = Identity { board: chladni_shared::icd::link::Board::Qemu, inject: None };
        LINK.init_with(|| Link::new(identity, &DRIVE, None))
    });
    let response =
        embassy_futures::block_on(link.handle(7, 1, request, embassy_time::Instant::now()));
    TAKEN.lock(|t| *t.borrow_mut() = Some(link));
    response
}

#[defmt_test::tests]
mod tests {
    use chladni_firmware::app::drive::DriveShared;
    use chladni_shared::icd::link::{self, Board, PROTOCOL_VERSION, Request, Response};

    use chladni_firmware::board::qemu::flash::{self, FileFlashError};
    use embedded_storage::nor_flash::{NorFlash, NorFlashErrorKind, ReadNorFlash};

    #[init]
    fn init() {
        // SysTick time driver, USART1 and flash, as the application brings them up.
        let _board = chladni_firmware::board::init();
    }

    #[test]
    fn time_driver_ticks_and_fires_timers() {
        use core::sync::atomic::Ordering;
        chladni_firmware::board::qemu::executor::run_until(
            |spawner| spawner.spawn(super::timer_task().unwrap()),
            || super::TIMER_RESULT.load(Ordering::Acquire) != 0,
        );
        assert_eq!(super::TIMER_RESULT.load(Ordering::Acquire), 1, "see the log above");
    }

    #[test]
    fn file_flash_behaves_like_nor_flash() {
        let mut f = super::open_flash();
        assert_eq!(f.capacity(), 512 * 1024);
        let last_page = (flash::CAPACITY - flash::PAGE_SIZE) as u32;
        let mut buf = [0u8; 16];
        f.read(last_page, &mut buf).unwrap();
        assert_eq!(buf, [0xff; 16], "a fresh bank reads erased");

        f.write(last_page, &[0x12, 0x34, 0x56, 0x78, 0x9a, 0xbc, 0xde, 0xf0]).unwrap();
        f.read(last_page, &mut buf[..8]).unwrap();
        assert_eq!(buf[..8], [0x12, 0x34, 0x56, 0x78, 0x9a, 0xbc, 0xde, 0xf0]);

        // Programming only clears bits: writing 0xff changes nothing, 0x0f masks.
        f.write(last_page, &[0xff; 8]).unwrap();
        f.write(last_page, &[0x0f; 8]).unwrap();
        f.read(last_page, &mut buf[..8]).unwrap();
        assert_eq!(buf[..8], [0x02, 0x04, 0x06, 0x08, 0x0a, 0x0c, 0x0e, 0x00]);

        f.erase(last_page, last_page + flash::PAGE_SIZE as u32).unwrap();
        f.read(last_page, &mut buf).unwrap();
        assert_eq!(buf, [0xff; 16], "erase restores 0xff");

        let not_aligned = FileFlashError::Request(NorFlashErrorKind::NotAligned);
        assert_eq!(f.write(3, &[0; 8]), Err(not_aligned));
        assert_eq!(f.erase(100, 2048), Err(not_aligned));
        let out = FileFlashError::Request(NorFlashErrorKind::OutOfBounds);
        assert_eq!(f.write(flash::CAPACITY as u32, &[0; 8]), Err(out));
    }

    #[test]
    fn file_flash_pages_persist_and_stay_inside_the_bank() {
        let page = (flash::CAPACITY - 2 * flash::PAGE_SIZE) as u32;
        let mut f = super::open_flash();
        f.erase(page, page + flash::PAGE_SIZE as u32).unwrap();
        // A whole page, more than the driver's 256-byte chunks, in one write.
        let mut data = [0u8; flash::PAGE_SIZE];
        data.iter_mut().enumerate().for_each(|(i, b)| *b = (i * 7 + 3) as u8);
        f.write(page, &data).unwrap();

        // The bytes live in the host file: a second handle reads them back.
        let mut g = super::open_flash();
        let mut back = [0u8; flash::PAGE_SIZE];
        g.read(page, &mut back).unwrap();
        assert!(back == data, "page read back differs");
        let mut next = [0u8; 8];
        g.read(page + flash::PAGE_SIZE as u32, &mut next).unwrap();
        assert_eq!(next, [0xff; 8], "the next page is untouched");

        // Erasing the page restores it, and only it.
        g.erase(page, page + flash::PAGE_SIZE as u32).unwrap();
        f.read(page, &mut back).unwrap();
        assert!(back.iter().all(|&b| b == 0xff), "erased page reads 0xff");

        // Requests outside the bank or off the 8-byte / 2 KiB grid are refused untouched.
        let end = flash::CAPACITY as u32;
        let out = FileFlashError::Request(NorFlashErrorKind::OutOfBounds);
        assert_eq!(f.erase(end, end + flash::PAGE_SIZE as u32), Err(out));
        assert_eq!(f.write(end - 8, &[0; 16]), Err(out));
        assert_eq!(f.read(end - 4, &mut [0; 8]), Err(out));
        let not_aligned = FileFlashError::Request(NorFlashErrorKind::NotAligned);
        assert_eq!(f.write(page, &[0; 12]), Err(not_aligned));
        assert_eq!(f.erase(page, page + 100), Err(not_aligned));
        f.read(page, &mut next).unwrap();
        assert_eq!(next, [0xff; 8], "refused writes changed nothing");
    }

    #[test]
    fn shared_vectors() {
        for (name, vector) in chladni_shared::vectors::ALL {
            match vector() {
                Ok(digest) => defmt::println!("vector {=str} {=u64:016x}", name, digest),
                Err(why) => defmt::panic!("vector {=str} failed: {=str}", name, why),
            }
        }
    }

    #[test]
    fn ping_echoes_nonce() {
        assert_eq!(
            super::answer(Request::Ping(link::Ping { nonce: 0x5eed })),
            Response::Ping(0x5eed)
        );
    }

    #[test]
    fn info_names_board_and_protocol() {
        match super::answer(Request::GetInfo(link::GetInfo)) {
            Response::GetInfo(info) => {
                assert_eq!(info.board, Board::Qemu);
                assert_eq!(info.protocol_version, PROTOCOL_VERSION);
                assert_eq!(info.firmware_version.as_str(), chladni_firmware::FIRMWARE_VERSION);
            }
            other => defmt::panic!("unexpected {}", other),
        }
    }

    #[test]
    fn drive_core_runs_a_plan_to_idle() {
        use chladni_firmware::app::drive::DriveCore;
        use chladni_shared::drive::runner::BLOCK_LEN;
        use chladni_shared::icd::link::DriveState;
        use chladni_shared::icd::plan::{Plan, Step};
        let shared = DriveShared::new();
        let mut plan =
            Plan { name: heapless::String::new(), repeat: 1, steps: heapless::Vec::new() };
        for (f, d) in [(100_000, 12), (200_000, 8)] {
            let s = Step {
                freq_mhz: f,
                level: chladni_shared::icd::plan::Level::Drive(10_000),
                duration_ms: d,
                ramp_ms: 2,
            };
            plan.steps.push(s).unwrap();
        }
        shared.run_plan(&plan).unwrap();
        let mut core = DriveCore::new(&shared);
        let mut block = [0u16; BLOCK_LEN];
        let mut steps_seen = [false; 2];
        for _ in 0..100 {
            core.refill(&mut block);
            let s = shared.status();
            if let Some(i) = s.step {
                steps_seen[i as usize] = true;
            }
            if s.state == DriveState::Idle {
                break;
            }
        }
        let s = shared.status();
        assert_eq!(s.state, DriveState::Idle);
        assert_eq!(steps_seen, [true, true]);
        // 20 ms of steps + the 20 ms ramp to zero at 50 samples/ms.
        assert_eq!(s.elapsed_samples, 40 * 50);
    }

    #[test]
    fn sensor_driver_reads_the_boards_simulated_lsm6dsl() {
        use chladni_firmware::app::sense::lsm6dsl::{Config, Lsm6dsl, Odr, Range, SensorError};
        use chladni_firmware::app::sense::sim::{Fault, OdrPacer};
        use chladni_firmware::board::qemu::sensor;
        use embassy_futures::block_on;

        let sim = sensor::sim();
        let with = |f: &mut dyn FnMut(&mut chladni_firmware::app::sense::sim::SimLsm6dsl)| {
            sim.lock(|s| f(&mut s.borrow_mut()))
        };
        let mut dev_sensor = sensor::new();
        let mut dev = Lsm6dsl::new(dev_sensor.bus);
        let cfg = Config { range: Range::G8, odr: Odr::Hz3330, fifo_threshold: 100 };
        block_on(dev.init(cfg)).unwrap();
        with(&mut |s| {
            assert_eq!(
                (s.range(), s.odr(), s.threshold_sets()),
                (Range::G8, Some(Odr::Hz3330), 100)
            )
        });

        // 30 ms of a 50 kHz plant in 250-sample blocks: 99.9 sensor samples due, 99 whole.
        let mut pacer = OdrPacer::new(50_000);
        let mut pushed = 0i16;
        for _ in 0..6 {
            for _ in 0..pacer.advance(250, cfg.odr) {
                with(&mut |s| s.push(0, 0, pushed * 3 - 150));
                pushed += 1;
            }
        }
        assert_eq!(pushed, 99);
        assert!(!dev_sensor.irq.is_high(), "99 sets: below the threshold of 100");
        with(&mut |s| s.push_accel(-9.80665));
        assert!(dev_sensor.irq.is_high());
        block_on(dev_sensor.irq.wait_threshold()); // already high: returns at once

        let mut out = [0i16; 128];
        assert_eq!(block_on(dev.read_z(&mut out)), Ok(100));
        for (i, &z) in out[..99].iter().enumerate() {
            assert_eq!(z, i as i16 * 3 - 150);
        }
        assert_eq!(out[99], -4098, "-1 g at 0.244 mg/LSB");
        assert!(!dev_sensor.irq.is_high());

        with(&mut |s| s.set_fault(Fault::Nack));
        assert_eq!(block_on(dev.read_z(&mut out)), Err(SensorError::Nack));
        with(&mut |s| s.set_fault(Fault::None));
    }
}
