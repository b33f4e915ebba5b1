//! Cost of the drive on Cortex-M: the per-sample path in instructions per sample, and the
//! whole refill of a block (commands, sensor ingest and lock-in, PI and monitors, DDS, status
//! publish) in instructions per block, steady and at a plan switch.
//!
//! Run by `scripts/firmware.sh bench qemu`, which boots this image with `-icount shift=0`: QEMU
//! then advances its virtual clock by exactly 1 ns per executed instruction, so the SysTick
//! time base (embassy-time, 1 ms ticks) counts instructions (10⁶ per tick). Each case runs for
//! at least [`MIN_TICKS`] ms of virtual time, i.e. ≥ 10⁸ instructions, so the 1-tick
//! resolution costs < 1 %. Without `-icount` the numbers are meaningless (QEMU's clock then
//! follows the host's).
#![no_std]
#![no_main]

use chladni_firmware::app::drive::{DriveCore, DriveShared};
use chladni_firmware::app::sense::lsm6dsl::STANDARD_GRAVITY;
use chladni_firmware::app::sense::task::CONFIG as SENSE;
use chladni_firmware::board;
use chladni_firmware::board::qemu::time_driver::now_ns;
use chladni_shared::drive::dds::{Dds, gain_of_q15, tuning_word};
use chladni_shared::drive::plant::{Plant, PlantParams};
use chladni_shared::drive::runner::{BLOCK_LEN, Runner};
use chladni_shared::drive::sensor_sim::{SensorSim, SensorSimConfig};
use chladni_shared::icd::plan::{DeviceLimits, Level, MAX_STEPS, Plan, Step};
use core::hint::black_box;
use embassy_time::Instant;
use static_cell::StaticCell;

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
    drive_blocks();
    board::exit(0)
}

/// Blocks refilled by [`drive_blocks`]: 256 steps of 20 ms are 1024 blocks; the second plan is
/// staged and switched to at block [`SWITCH_AT`].
const BLOCKS: u32 = 1_500;
const SWITCH_AT: u32 = 600;

/// Instructions (ns under `-icount shift=0`) of a series of events: mean, max, count.
#[derive(Default)]
struct Cost {
    sum: u64,
    max: u64,
    n: u64,
}

impl Cost {
    fn add(&mut self, ns: u64) {
        self.sum += ns;
        self.max = self.max.max(ns);
        self.n += 1;
    }

    fn report(&self, name: &str) {
        defmt::println!(
            "bench {=str} mean {=u64} max {=u64} instructions/block over {=u64} blocks",
            name,
            self.sum / self.n.max(1),
            self.max,
            self.n
        );
    }
}

/// Times `f` in instructions (SysTick resolution: 250).
fn timed<T>(f: impl FnOnce() -> T) -> (T, u64) {
    let t0 = now_ns();
    let out = f();
    (out, now_ns() - t0)
}

/// Fills `plan` (in a static: two 5 KiB plans would not fit the stack) with a closed-loop plan
/// of [`MAX_STEPS`] 20 ms steps around the simulated plate's resonance.
fn closed_plan(plan: &mut Plan, name: &str, base_mhz: u32) {
    plan.name = name.try_into().unwrap_or_default();
    plan.repeat = 1;
    plan.steps.clear();
    for i in 0..MAX_STEPS as u32 {
        let step = Step {
            freq_mhz: base_mhz + (i % 16) * 500,
            level: Level::Accel(20_000 + (i % 4) * 1_000),
            duration_ms: 20,
            ramp_ms: 5,
        };
        let _ = plan.steps.push(step);
    }
}

fn empty_plan() -> Plan {
    Plan { name: heapless::String::new(), repeat: 0, steps: heapless::Vec::new() }
}

/// The drive task's whole refill, block by block, as the firmware runs it: a 256-step
/// closed-loop plan, the simulated plate and accelerometer feeding the sensor queue (their
/// cost is not counted: on the board they are the physics), a second 256-step plan staged
/// through the link's call and switched to mid-run; and the link's status read.
fn drive_blocks() {
    static DRIVE: DriveShared = DriveShared::new();
    let lsb = SENSE.range.sensitivity();
    DRIVE.set_sensor_scale(lsb, SENSE.odr.millihertz());
    let mut plant = Plant::new(PlantParams::DEFAULT);
    let bias_lsb = (STANDARD_GRAVITY / lsb) as i32;
    let cfg = SensorSimConfig {
        odr_mhz: SENSE.odr.millihertz(),
        lsb_mps2: lsb,
        bias_lsb,
        ..SensorSimConfig::DEFAULT
    };
    let mut sensor = SensorSim::new(cfg);
    let mut core = DriveCore::new(&DRIVE);
    static FIRST: StaticCell<Plan> = StaticCell::new();
    static SECOND: StaticCell<Plan> = StaticCell::new();
    let (first, second) = (FIRST.init_with(empty_plan), SECOND.init_with(empty_plan));
    closed_plan(first, "first", 172_000);
    closed_plan(second, "second", 176_000);
    let (staged, stage_ns) = timed(|| DRIVE.run_plan(first));
    staged.expect("first bench plan is valid");
    let (mut steady, mut switch, mut status) = (Cost::default(), Cost::default(), Cost::default());
    let mut block = [0u16; BLOCK_LEN];
    let mut stage = Cost::default();
    stage.add(stage_ns);
    for n in 0..BLOCKS {
        if n == SWITCH_AT {
            let (staged, ns) = timed(|| DRIVE.run_plan(second));
            staged.expect("second bench plan is valid");
            stage.add(ns);
        }
        let ((), ns) = timed(|| core.refill(&mut block));
        if n == 0 || n == SWITCH_AT {
            switch.add(ns)
        } else {
            steady.add(ns)
        }
        let (s, ns) = timed(|| DRIVE.status());
        black_box(s);
        status.add(ns);
        let mut z = heapless::Vec::<i16, 64>::new();
        for &code in &block {
            sensor.push(plant.step(code), |v| {
                let _ = z.push(v);
            });
        }
        DRIVE.push_batch(&z);
    }
    steady.report("refill_steady");
    switch.report("refill_plan_start");
    stage.report("link_run_plan_256");
    status.report("link_status_read");
    let s = DRIVE.status();
    defmt::println!("bench drive end state {} fault {} measured {}", s.state, s.fault, s.measured);
}
