//! Host tests of the LSM6DSL driver against the simulated register map: set-up as configured,
//! the identity and bus failures, FIFO reads (order, exact values, partial reads, splits,
//! overrun and recovery), the INT1 threshold, and the simulation's own rules.

use std::vec::Vec;

use embassy_futures::block_on;
use embedded_hal_async::i2c::{ErrorKind, ErrorType, I2c, Operation, SevenBitAddress};

use super::lsm6dsl::{
    ADDRESS, Config, FIFO_WORDS, Lsm6dsl, MAX_THRESHOLD_SETS, Odr, Range, SensorError, reg,
};
use super::sim::{Fault, OdrPacer, SimLsm6dsl};

fn cfg(range: Range, odr: Odr, fifo_threshold: u16) -> Config {
    Config { range, odr, fifo_threshold }
}

const DEFAULT: Config = Config { range: Range::G4, odr: Odr::Hz6660, fifo_threshold: 32 };

/// A simulated sensor, set up by the driver with `config`.
fn ready(sim: &mut SimLsm6dsl, config: Config) -> Lsm6dsl<&mut SimLsm6dsl> {
    let mut dev = Lsm6dsl::new(sim);
    block_on(dev.init(config)).expect("init against a healthy simulated sensor");
    dev
}

/// Distinct, sign-varied Z values covering the extremes.
fn z_values(n: usize) -> Vec<i16> {
    let mut state = 0x1234_5678u32;
    (0..n)
        .map(|i| match i {
            0 => i16::MIN,
            1 => i16::MAX,
            2 => -1,
            _ => {
                state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                (state >> 16) as i16
            }
        })
        .collect()
}

/// Pushes one set per value, X and Y distinct from Z so a misaligned read would show.
fn push_all(sim: &mut SimLsm6dsl, zs: &[i16]) {
    for (i, &z) in zs.iter().enumerate() {
        sim.push(1000 + i as i16, -1000 - i as i16, z);
    }
}

fn read_all(dev: &mut Lsm6dsl<&mut SimLsm6dsl>, chunk: usize) -> Vec<i16> {
    let mut got = Vec::new();
    let mut out = std::vec![0i16; chunk];
    loop {
        let n = block_on(dev.read_z(&mut out)).expect("read");
        if n == 0 {
            return got;
        }
        got.extend_from_slice(&out[..n]);
    }
}

#[test]
fn init_writes_range_rate_fifo_and_int1_as_configured() {
    for range in Range::ALL {
        for odr in Odr::ALL {
            let threshold = 1 + (odr.code() as u16 * 67 + range.code() as u16) % MAX_THRESHOLD_SETS;
            let mut sim = SimLsm6dsl::new();
            ready(&mut sim, cfg(range, odr, threshold));
            assert_eq!(sim.range(), range);
            assert_eq!(sim.odr(), Some(odr));
            assert_eq!(sim.threshold_sets(), threshold);
            assert_eq!(sim.threshold_words(), 3 * threshold);
            assert_eq!(sim.fifo_mode(), reg::FIFO_MODE_CONTINUOUS);
            assert_eq!(sim.register(reg::FIFO_CTRL5) >> 3, odr.code(), "FIFO at the XL rate");
            assert_eq!(sim.register(reg::FIFO_CTRL3), 0b001, "XL only, no decimation");
            assert_eq!(sim.register(reg::CTRL2_G), 0, "gyroscope off");
            assert_eq!(sim.register(reg::CTRL3_C), reg::CTRL3_BDU | reg::CTRL3_IF_INC);
            assert_eq!(sim.register(reg::INT1_CTRL), reg::INT1_FTH);
        }
    }
}

#[test]
fn init_resets_the_chip_first() {
    let mut sim = SimLsm6dsl::new();
    // A previous life: gyroscope on, other interrupts routed, FIFO full of old samples.
    sim.transaction_sync(ADDRESS, &mut [Operation::Write(&[reg::CTRL1_XL, 0x40, 0x40])]).unwrap();
    sim.transaction_sync(ADDRESS, &mut [Operation::Write(&[reg::INT1_CTRL, 0xF7])]).unwrap();
    let fifo_on = [reg::FIFO_CTRL3, 0b001, 0, 4 << 3 | reg::FIFO_MODE_CONTINUOUS];
    sim.transaction_sync(ADDRESS, &mut [Operation::Write(&fifo_on)]).unwrap();
    push_all(&mut sim, &z_values(50));
    assert_eq!(sim.fifo_level(), 150);

    let mut dev = ready(&mut sim, DEFAULT);
    assert_eq!(read_all(&mut dev, 64), Vec::<i16>::new(), "old samples are gone");
    assert_eq!(sim.register(reg::CTRL2_G), 0);
    assert_eq!(sim.register(reg::INT1_CTRL), reg::INT1_FTH);
}

#[test]
fn a_wrong_id_is_reported_and_nothing_is_written() {
    for id in [0x00, 0x69, 0x6B, 0x6C, 0xFF] {
        let mut sim = SimLsm6dsl::new();
        sim.set_fault(Fault::WrongId(id));
        let mut dev = Lsm6dsl::new(&mut sim);
        assert_eq!(block_on(dev.init(DEFAULT)), Err(SensorError::WrongId(id)));
        assert_eq!(dev.config(), None);
        assert_eq!(sim.odr(), None, "accelerometer left off");
        assert_eq!(sim.register(reg::INT1_CTRL), 0);
    }
}

#[test]
fn an_absent_sensor_is_a_nack_for_init_and_reads() {
    let mut sim = SimLsm6dsl::new();
    sim.set_fault(Fault::Nack);
    let mut dev = Lsm6dsl::new(&mut sim);
    assert_eq!(block_on(dev.init(DEFAULT)), Err(SensorError::Nack));
    assert_eq!(block_on(dev.read_z(&mut [0; 8])), Err(SensorError::Nack));
    // A sensor that dies after set-up.
    let mut sim = SimLsm6dsl::new();
    let mut dev = ready(&mut sim, DEFAULT);
    drop(dev);
    sim.set_fault(Fault::Nack);
    dev = Lsm6dsl::new(&mut sim);
    assert_eq!(block_on(dev.read_z(&mut [0; 8])), Err(SensorError::Nack));
}

#[test]
fn the_sim_answers_only_at_its_address() {
    let mut sim = SimLsm6dsl::new();
    let mut id = [0u8];
    for addr in [0x00, 0x6B, 0x1E, 0x7F] {
        let r = block_on(I2c::write_read(&mut sim, addr, &[reg::WHO_AM_I], &mut id));
        assert!(r.is_err(), "address {addr:#x} must NACK");
    }
    block_on(I2c::write_read(&mut sim, ADDRESS, &[reg::WHO_AM_I], &mut id)).unwrap();
    assert_eq!(id, [0x6A]);
}

#[test]
fn bad_thresholds_are_refused_before_touching_the_bus() {
    for t in [0, MAX_THRESHOLD_SETS + 1, u16::MAX] {
        let mut sim = SimLsm6dsl::new();
        sim.set_fault(Fault::Nack); // any bus access would turn into Nack
        let mut dev = Lsm6dsl::new(&mut sim);
        assert_eq!(
            block_on(dev.init(cfg(Range::G2, Odr::Hz104, t))),
            Err(SensorError::BadThreshold(t))
        );
    }
    let mut sim = SimLsm6dsl::new();
    ready(&mut sim, cfg(Range::G2, Odr::Hz104, MAX_THRESHOLD_SETS));
    assert_eq!(sim.threshold_words(), 3 * MAX_THRESHOLD_SETS);
}

#[test]
fn pushed_samples_come_back_in_order_and_exact() {
    let mut sim = SimLsm6dsl::new();
    let zs = z_values(600); // 1800 words: under the 2048 of the FIFO, over several bursts
    let mut dev = ready(&mut sim, DEFAULT);
    drop(dev);
    push_all(&mut sim, &zs);
    dev = Lsm6dsl::new(&mut sim);
    let mut out = std::vec![0i16; 1000];
    let n = block_on(dev.read_z(&mut out)).unwrap();
    assert_eq!(&out[..n], &zs[..]);
    assert_eq!(block_on(dev.read_z(&mut out)), Ok(0));
}

#[test]
fn partial_reads_continue_where_the_last_one_stopped() {
    let zs = z_values(50);
    for chunk in [1, 3, 7, 49, 50, 64] {
        let mut sim = SimLsm6dsl::new();
        drop(ready(&mut sim, DEFAULT));
        push_all(&mut sim, &zs);
        let mut dev = Lsm6dsl::new(&mut sim);
        assert_eq!(read_all(&mut dev, chunk), zs, "chunks of {chunk}");
    }
}

#[test]
fn interleaved_pushes_and_reads_lose_nothing() {
    let zs = z_values(2000);
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    let mut got = Vec::new();
    let mut out = [0i16; 40];
    for batch in zs.chunks(37) {
        push_all(&mut sim, batch);
        let mut dev = Lsm6dsl::new(&mut sim);
        let n = block_on(dev.read_z(&mut out)).unwrap();
        got.extend_from_slice(&out[..n]);
    }
    let mut dev = Lsm6dsl::new(&mut sim);
    got.extend(read_all(&mut dev, 64));
    assert_eq!(got, zs);
}

#[test]
fn a_split_set_is_skipped_to_the_next_x() {
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &[11, 22, 33]);
    // Someone read one word (X of the first set) outside the driver.
    let mut word = [0u8; 2];
    sim.transaction_sync(
        ADDRESS,
        &mut [Operation::Write(&[reg::FIFO_DATA_OUT_L]), Operation::Read(&mut word)],
    )
    .unwrap();
    assert_eq!(i16::from_le_bytes(word), 1000);
    let mut dev = Lsm6dsl::new(&mut sim);
    assert_eq!(read_all(&mut dev, 8), [22, 33]);
}

#[test]
fn an_overrun_is_reported_once_then_reads_recover() {
    let sets_that_fit = usize::from(FIFO_WORDS / 3); // 682 sets = 2046 words
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &z_values(sets_that_fit));
    assert!(!sim.overrun(), "2046 words fit");
    let mut dev = Lsm6dsl::new(&mut sim);
    assert_eq!(read_all(&mut dev, 1000).len(), sets_that_fit);

    push_all(&mut sim, &z_values(sets_that_fit + 1)); // 2049 words: one lost
    assert!(sim.overrun());
    let mut dev = Lsm6dsl::new(&mut sim);
    let mut out = [0i16; 16];
    assert_eq!(block_on(dev.read_z(&mut out)), Err(SensorError::Overrun));
    assert_eq!(block_on(dev.read_z(&mut out)), Ok(0), "restarted empty");
    assert!(!sim.overrun());
    assert_eq!(sim.fifo_mode(), reg::FIFO_MODE_CONTINUOUS, "and running again");
    let fresh = z_values(5);
    push_all(&mut sim, &fresh);
    let mut dev = Lsm6dsl::new(&mut sim);
    assert_eq!(read_all(&mut dev, 16), fresh);
}

#[test]
fn int1_follows_the_fifo_threshold() {
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, cfg(Range::G2, Odr::Hz1660, 10)));
    push_all(&mut sim, &z_values(9));
    assert!(!sim.int1());
    push_all(&mut sim, &[7]);
    assert!(sim.int1());
    let mut dev = Lsm6dsl::new(&mut sim);
    let status = block_on(dev.fifo_status()).unwrap();
    assert!(status.threshold && !status.empty && !status.overrun);
    assert_eq!(status.words, 30);
    let mut out = [0i16; 4];
    assert_eq!(block_on(dev.read_z(&mut out)), Ok(4));
    assert!(!sim.int1(), "below the threshold again");
}

#[test]
fn a_silent_sensor_sets_up_but_never_fills() {
    let mut sim = SimLsm6dsl::new();
    sim.set_fault(Fault::Silent);
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &z_values(100));
    assert!(!sim.int1());
    let mut dev = Lsm6dsl::new(&mut sim);
    assert_eq!(block_on(dev.read_z(&mut [0; 8])), Ok(0));
}

#[test]
fn nothing_enters_the_fifo_before_init() {
    let mut sim = SimLsm6dsl::new();
    push_all(&mut sim, &z_values(10));
    assert_eq!(sim.fifo_level(), 0);
}

/// Counts transactions, to hold the driver to its burst reads.
struct Counting<'a> {
    sim: &'a mut SimLsm6dsl,
    transactions: usize,
}

impl ErrorType for Counting<'_> {
    type Error = super::sim::SimError;
}

impl I2c<SevenBitAddress> for Counting<'_> {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.transactions += 1;
        self.sim.transaction_sync(address, operations)
    }
}

#[test]
fn fifo_reads_take_one_status_read_and_one_burst_per_64_sets() {
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &z_values(600));
    let mut dev = Lsm6dsl::new(Counting { sim: &mut sim, transactions: 0 });
    let mut out = [0i16; 600];
    assert_eq!(block_on(dev.read_z(&mut out)), Ok(600));
    assert_eq!(dev.release().transactions, 1 + 600usize.div_ceil(64));
}

/// A bus failing with one error kind.
struct Failing(ErrorKind);

#[derive(Debug)]
struct KindError(ErrorKind);

impl embedded_hal_async::i2c::Error for KindError {
    fn kind(&self) -> ErrorKind {
        self.0
    }
}

impl ErrorType for Failing {
    type Error = KindError;
}

impl I2c<SevenBitAddress> for Failing {
    async fn transaction(&mut self, _: u8, _: &mut [Operation<'_>]) -> Result<(), KindError> {
        Err(KindError(self.0))
    }
}

#[test]
fn bus_errors_map_to_nack_or_bus() {
    use embedded_hal_async::i2c::NoAcknowledgeSource;
    let cases = [
        (ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address), SensorError::Nack),
        (ErrorKind::NoAcknowledge(NoAcknowledgeSource::Data), SensorError::Nack),
        (ErrorKind::NoAcknowledge(NoAcknowledgeSource::Unknown), SensorError::Nack),
        (ErrorKind::ArbitrationLoss, SensorError::Bus),
        (ErrorKind::Bus, SensorError::Bus),
        (ErrorKind::Overrun, SensorError::Bus),
        (ErrorKind::Other, SensorError::Bus),
    ];
    for (kind, want) in cases {
        let mut dev = Lsm6dsl::new(Failing(kind));
        assert_eq!(block_on(dev.init(DEFAULT)), Err(want), "{kind:?}");
        assert_eq!(block_on(dev.read_z(&mut [0; 4])), Err(want), "{kind:?}");
    }
}

#[test]
fn error_names_are_distinct() {
    let all = [
        SensorError::Nack,
        SensorError::WrongId(0),
        SensorError::Overrun,
        SensorError::Bus,
        SensorError::BadThreshold(0),
        SensorError::ResetStuck,
        SensorError::Timeout,
    ];
    for (i, a) in all.iter().enumerate() {
        assert!(!a.name().is_empty());
        for b in &all[i + 1..] {
            assert_ne!(a.name(), b.name());
        }
    }
}

#[test]
fn sensitivity_matches_full_scale_over_16_bits() {
    for range in Range::ALL {
        // The datasheet's sensitivities are the full scale over 2^15, rounded to 3 digits.
        let lsb_at_full_scale = range.full_scale() / range.sensitivity();
        assert!(
            (lsb_at_full_scale / 32768.0 - 1.0).abs() < 0.002,
            "{range:?}: {lsb_at_full_scale}"
        );
        assert_eq!(Range::from_code(range.code()), range);
    }
    assert!((Range::G2.sensitivity() - 0.061e-3 * 9.80665).abs() < 1e-9);
    assert!((Range::G16.sensitivity() - 0.488e-3 * 9.80665).abs() < 1e-9);
}

#[test]
fn odr_codes_round_trip_and_rates_rise() {
    for (i, odr) in Odr::ALL.iter().enumerate() {
        assert_eq!(Odr::from_code(odr.code()), Some(*odr));
        assert_eq!(usize::from(odr.code()), i + 1);
        if i > 0 {
            assert!(odr.hz() > Odr::ALL[i - 1].hz());
        }
    }
    assert_eq!(Odr::from_code(0), None, "power-down");
    assert_eq!(Odr::from_code(11), None, "1.6 Hz is low-power only");
    assert_eq!(Odr::Hz6660.hz(), 6660.0);
    assert_eq!(Odr::Hz12_5.hz(), 12.5);
}

#[test]
fn accelerations_are_scaled_at_the_configured_range_and_saturate() {
    for range in Range::ALL {
        let mut sim = SimLsm6dsl::new();
        drop(ready(&mut sim, cfg(range, Odr::Hz833, 4)));
        for accel in [0.0, 1.0, -9.80665, 12.34, -0.001] {
            let lsb = sim.to_lsb(accel);
            let back = f32::from(lsb) * range.sensitivity();
            assert!((back - accel).abs() <= range.sensitivity() / 2.0 + 1e-6, "{range:?} {accel}");
        }
        assert_eq!(sim.to_lsb(range.full_scale() * 1.5), i16::MAX);
        assert_eq!(sim.to_lsb(-range.full_scale() * 1.5), i16::MIN);
        sim.push_accel(9.80665);
        let mut dev = Lsm6dsl::new(&mut sim);
        let mut out = [0i16; 1];
        assert_eq!(block_on(dev.read_z(&mut out)), Ok(1));
        assert_eq!(out[0], (1000.0 / range.mg_per_lsb()).round() as i16, "1 g at {range:?}");
    }
}

#[test]
fn the_output_registers_hold_the_last_sample() {
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &[-12345]);
    let mut z = [0u8; 2];
    sim.transaction_sync(
        ADDRESS,
        &mut [Operation::Write(&[reg::OUTZ_L_XL]), Operation::Read(&mut z)],
    )
    .unwrap();
    assert_eq!(i16::from_le_bytes(z), -12345);
}

#[test]
fn without_auto_increment_a_burst_rereads_one_register() {
    let mut sim = SimLsm6dsl::new();
    drop(ready(&mut sim, DEFAULT));
    push_all(&mut sim, &[5, 6]);
    sim.transaction_sync(ADDRESS, &mut [Operation::Write(&[reg::CTRL3_C, 0])]).unwrap();
    let mut bytes = [0u8; 4];
    sim.transaction_sync(
        ADDRESS,
        &mut [Operation::Write(&[reg::FIFO_DATA_OUT_L]), Operation::Read(&mut bytes)],
    )
    .unwrap();
    let x = 1000i16.to_le_bytes()[0];
    assert_eq!(bytes, [x; 4], "the same low byte four times, nothing popped");
    assert_eq!(sim.fifo_level(), 6);
}

#[test]
fn the_pacer_gives_the_odr_exactly_over_time() {
    for odr in Odr::ALL {
        let mut pacer = OdrPacer::new(50_000);
        // 10 s of 250-sample blocks at 50 kHz.
        let total: u64 = (0..2000).map(|_| u64::from(pacer.advance(250, odr))).sum();
        assert_eq!(total * 1000, u64::from(odr.millihertz()) * 10, "{odr:?}");
    }
}

// ---- The sense task on a bus that hangs ----

use core::cell::RefCell;

use chladni_shared::icd::sense::SensorFault;
use embassy_futures::select::{Either, select};
use embassy_time::{Duration, Instant, Timer};

use super::task::{self, DataReady, SenseSink};
use crate::app::watchdog::{Supervisor, Task, TaskSet};

/// Records what the sense task reports.
#[derive(Default)]
struct Recorder {
    faults: RefCell<Vec<SensorFault>>,
    batches: RefCell<usize>,
}

impl SenseSink for Recorder {
    fn set_scale(&self, _: f32, _: u32) {}
    fn push_batch(&self, _: &[i16]) {
        *self.batches.borrow_mut() += 1;
    }
    fn push_error(&self, fault: SensorFault) {
        self.faults.borrow_mut().push(fault);
    }
}

/// INT1 that is always high: the task reads as often as it can.
struct AlwaysReady;

impl DataReady for AlwaysReady {
    async fn wait(&mut self) {}
}

/// The simulated sensor, whose bus hangs for good (a transfer that never completes) after
/// `left` transactions.
struct HangAfter {
    sim: SimLsm6dsl,
    left: usize,
}

impl ErrorType for HangAfter {
    type Error = super::sim::SimError;
}

impl I2c<SevenBitAddress> for HangAfter {
    async fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        if self.left == 0 {
            return core::future::pending().await;
        }
        self.left -= 1;
        self.sim.transaction_sync(address, operations)
    }
}

/// Runs the sense task on `bus` until it has reported `faults` faults and the supervisor has
/// seen it check in that many times since the first fault (the watchdog's question, asked
/// every 10 ms); fails after 10 s. Returns the recorder.
fn run_until_faults(bus: HangAfter, faults: usize) -> Recorder {
    let supervisor = Supervisor::new(TaskSet::of(&[Task::Sense]));
    let recorder = Recorder::default();
    let checker = async {
        let start = Instant::now();
        let mut check_ins = 0;
        while recorder.faults.borrow().len() < faults || check_ins < faults {
            assert!(
                start.elapsed() < Duration::from_secs(10),
                "after 10 s: {} fault(s) reported, {check_ins} check-in(s) seen",
                recorder.faults.borrow().len()
            );
            Timer::after_millis(10).await;
            if supervisor.poll() && !recorder.faults.borrow().is_empty() {
                check_ins += 1;
            }
        }
    };
    let mut irq = AlwaysReady;
    match block_on(select(task::run(&recorder, &supervisor, bus, &mut irq), checker)) {
        Either::First(never) => never,
        Either::Second(()) => recorder,
    }
}

#[test]
fn a_bus_that_hangs_at_set_up_is_a_fault_and_the_task_keeps_checking_in() {
    let recorder = run_until_faults(HangAfter { sim: SimLsm6dsl::new(), left: 0 }, 3);
    let faults = recorder.faults.borrow();
    assert!(faults.iter().all(|f| *f == SensorError::Timeout.fault()), "{faults:?}");
    assert_eq!(*recorder.batches.borrow(), 0);
}

#[test]
fn a_bus_that_hangs_mid_read_is_a_fault_and_the_task_keeps_checking_in() {
    // Set-up takes 7 transactions plus the reset polls; the sim's reset is immediate (one
    // poll), so 20 leave room for a few reads before the hang.
    let recorder = run_until_faults(HangAfter { sim: SimLsm6dsl::new(), left: 20 }, 3);
    assert_eq!(recorder.faults.borrow()[0], SensorError::Timeout.fault());
}
