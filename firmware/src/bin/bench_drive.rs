//! Cost of the drive's per-sample path on Cortex-M, in instructions per sample.
//!
//! Run by `scripts/firmware.sh bench qemu`, which boots this image with `-icount shift=0`: QEMU
//! then advances its virtual clock by exactly 1 ns per executed instruction, so the SysTick
//! time base (embassy-time, 1 ms ticks) counts instructions (10⁶ per tick). Each case runs for
//! at least [`MIN_TICKS`] ms of virtual time, i.e. ≥ 10⁸ instructions, so the 1-tick
//! resolution costs < 1 %. Without `-icount` the numbers are meaningless (QEMU's clock then
//! follows the host's).
#![no_std]
#![no_main]

use chladni_firmware::board;
use chladni_shared::drive::dds::{Dds, gain_of_q15, tuning_word};
use chladni_shared::drive::runner::{BLOCK_LEN, Runner};
use chladni_shared::icd::plan::{DeviceLimits, Plan, Step};
use core::hint::black_box;
use embassy_time::Instant;

/// Virtual milliseconds (= 10⁶ instructions under `-icount shift=0`) per case, at least.
const MIN_TICKS: u64 = 100;

/// Runs `f` (which handles one block) until MIN_TICKS have passed; returns instructions per
/// sample, ×100.
fn measure(mut f: impl FnMut(&mut [u16; BLOCK_LEN])) -> u64 {
    let mut block = [0u16; BLOCK_LEN];
    let start = Instant::now();
    let mut blocks = 0u64;
    loop {
        f(&mut block);
        black_box(&mut block);
        blocks += 1;
        let ticks = start.elapsed().as_ticks();
        if ticks >= MIN_TICKS {
            // 1 tick = 1 ms = 10⁶ ns = 10⁶ instructions.
            return ticks * 1_000_000 * 100 / (blocks * BLOCK_LEN as u64);
        }
    }
}

fn report(name: &str, centi: u64) {
    defmt::println!(
        "bench {=str} {=u64}.{=u64:02} instructions/sample",
        name,
        centi / 100,
        centi % 100
    );
}

#[cortex_m_rt::entry]
fn main() -> ! {
    let _board = board::init();
    // Overhead of the measuring loop itself (black_box, clock read) per block.
    let overhead = measure(|b| {
        black_box(b);
    });
    report("loop_overhead", overhead);

    let mut dds = Dds::new(tuning_word(123_456));
    let steady = measure(|b| dds.fill_steady(b, gain_of_q15(20_000)));
    report("dds_steady", steady.saturating_sub(overhead));

    let mut gain = 0i32;
    let ramp = measure(|b| {
        if gain > 1 << 30 {
            gain = 0;
        }
        dds.fill_ramp(b, &mut gain, 3)
    });
    report("dds_ramp", ramp.saturating_sub(overhead));

    // The whole runner: a plan whose steps switch inside blocks, with ramps.
    let mut plan =
        Plan { name: heapless::String::new(), repeat: 1000, steps: heapless::Vec::new() };
    for (f, a, d, r) in
        [(120_000, 16_000, 37, 7), (181_500, 24_000, 53, 3), (1_234_567, 8_000, 41, 11)]
    {
        let _ = plan.steps.push(Step {
            freq_mhz: f,
            level: chladni_shared::icd::plan::Level::Drive(a),
            duration_ms: d,
            ramp_ms: r,
        });
    }
    let mut runner = Runner::new(DeviceLimits::DEFAULT);
    runner.start_plan(plan).expect("bench plan is valid");
    let full = measure(|b| runner.fill(b));
    report("runner_plan", full.saturating_sub(overhead));
    board::exit(0)
}
