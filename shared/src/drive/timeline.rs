//! Time on the DAC's sample clock: the drive's phase at any instant ([`PhaseMark`]) and the
//! instant of each accelerometer sample ([`SensorTimebase`]).
//!
//! The accelerometer runs on its own oscillator, asynchronous to the DAC, and the firmware only
//! knows when it *read* a batch (a DAC sample count, the stamp), not when each sample was taken.
//! The lock-in needs the drive's phase at each sensor sample's true instant, so both halves meet
//! here, in fixed point:
//!
//! - Instants are [`DacTime`]: DAC samples since boot in Q48.16 (a `u64`; 2⁴⁸ samples at 50 kS/s
//!   is 178 years, 2⁻¹⁶ sample is 0.3 ns, which at 2 kHz is 2·10⁻⁴ degrees of phase).
//! - [`PhaseMark::phase_at`] is exact modular arithmetic on the DDS's own phase accumulator: the
//!   phase the DDS had (or will have) at that instant, fraction included.
//! - [`SensorTimebase`] models sample k of the sensor stream at t(k) = t₀ + k·P, with P (DAC
//!   samples per sensor sample, Q16.16) estimated online.
//!
//! # The timebase estimator and its error
//!
//! A batch of n samples stamped S (S DAC samples output, so the read happened in [S − 1, S))
//! says only that its newest sample was taken in (S − 1 − P, S); the estimator takes S − ½ as
//! the read's instant. The estimator uses that bound,
//! which holds whatever the read jitter, rather than an average, which would depend on it:
//!
//! - **Period**: P̂ = (S − S_a)/(N − N_a), the slope between an anchor batch and the newest
//!   one (N counts sensor samples). Each stamp is off by e ∈ [0, P + 1), so the slope is off by
//!   at most (P + 1)/(N − N_a): after a window of [`PERIOD_WINDOW`] samples, < 2·10⁻⁴ relative.
//!   Two anchors leapfrog every window, so the baseline stays between one and two windows and a
//!   drifting sensor clock is followed. Until the first anchor is two batches old, P̂ is the
//!   nominal one (the ODR's, up to a few % off).
//! - **Offset**: the newest sample's time is the tightest upper bound the recent stamps give,
//!   t̂ = min over the last [`BOUND_BATCHES`] batches j of S_j + (N − N_j)·P̂: each stamp
//!   carried forward to the newest sample by the period. True times never exceed the stamps,
//!   so each term is an upper bound (up to P̂'s error times N − N_j), and the minimum touches
//!   the truth whenever one of those batches was read just after its newest sample (the read
//!   cadence beats with the sensor clock, so with random read delays that is 1 batch in P).
//!   Keeping only recent batches forgets bounds that a slightly wrong P̂ would carry too far.
//!
//! Error (measured in the tests with ±2 % clock offsets and random read jitter of up to one
//! sensor period): a few tenths of a DAC sample once the period window has filled, at worst one
//! sensor period (the stamp bound itself) on the first batch or if the read cadence locks to
//! the sensor clock so that stamps never come close to a sample. A constant time offset only
//! turns the measured phase (by 360°·f·offset); it does not change the amplitude.

/// An instant on the DAC sample clock: samples since boot, Q48.16.
pub type DacTime = u64;

/// Fraction bits of [`DacTime`] and of the period estimate.
pub const TIME_FRAC_BITS: u32 = 16;

/// The [`DacTime`] of the start of DAC sample `sample`.
pub const fn dac_time(sample: u64) -> DacTime {
    sample << TIME_FRAC_BITS
}

/// The DDS's phase at one DAC sample, valid until the next frequency change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PhaseMark {
    /// The DAC sample (samples since boot).
    pub sample: u64,
    /// The DDS phase at that sample (one turn = 2³²).
    pub phase: u32,
    /// The phase increment per sample from then on.
    pub tuning_word: u32,
}

impl PhaseMark {
    /// The phase at instant `t` (before or after the mark), fraction of a sample included.
    pub fn phase_at(&self, t: DacTime) -> u32 {
        // Modulo 2³², so wrapping arithmetic on the low 32 bits of the sample difference is
        // exact, also for instants before the mark.
        let delta = ((t >> TIME_FRAC_BITS).wrapping_sub(self.sample)) as u32;
        let frac = t & ((1 << TIME_FRAC_BITS) - 1);
        let whole = self.tuning_word.wrapping_mul(delta);
        let part = ((self.tuning_word as u64 * frac) >> TIME_FRAC_BITS) as u32;
        self.phase.wrapping_add(whole).wrapping_add(part)
    }

    /// Whether `other` describes a different waveform (another frequency or a phase jump), so
    /// that a measurement running on this mark must restart.
    pub fn differs_from(&self, other: &PhaseMark) -> bool {
        self.tuning_word != other.tuning_word || other.phase_at(dac_time(self.sample)) != self.phase
    }
}

/// Batches whose stamps bound the newest sample's instant.
pub const BOUND_BATCHES: usize = 32;

/// Sensor samples per leapfrog window of the period estimate (≈ 1.2 s at 6.66 kHz).
pub const PERIOD_WINDOW: u64 = 8192;

/// The nominal period in DAC samples per sensor sample, Q16.16, of an output data rate in mHz.
pub const fn nominal_period_q16(odr_mhz: u32) -> u32 {
    let num = (crate::icd::units::SAMPLE_RATE as u64 * 1000) << TIME_FRAC_BITS;
    if odr_mhz == 0 { 0 } else { ((num + odr_mhz as u64 / 2) / odr_mhz as u64) as u32 }
}

/// Sensor samples' worth of time beyond twice a batch's own that a gap between batches may
/// span before the timebase starts again (a silent sensor; 64 samples ≈ 19 ms at 3.33 kHz,
/// against reads every ~5 ms).
const GAP_SLACK: u64 = 64;

/// A batch the anchors remember: its stamp and the sensor-sample count after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Anchor {
    stamp: DacTime,
    count: u64,
}

/// Gives each sensor sample its instant on the DAC clock. See the module docs.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SensorTimebase {
    nominal_q16: u32,
    period_q16: u32,
    /// Instant of the newest sample so far (None before the first batch).
    newest: Option<DacTime>,
    /// Sensor samples seen.
    count: u64,
    older: Option<Anchor>,
    newer: Option<Anchor>,
    recent: [Anchor; BOUND_BATCHES],
    recent_len: usize,
    recent_next: usize,
}

impl SensorTimebase {
    /// A timebase starting from the nominal output data rate `odr_mhz` (e.g. 6 660 000).
    pub const fn new(odr_mhz: u32) -> Self {
        let p = nominal_period_q16(odr_mhz);
        Self {
            nominal_q16: p,
            period_q16: p,
            newest: None,
            count: 0,
            older: None,
            newer: None,
            recent: [Anchor { stamp: 0, count: 0 }; BOUND_BATCHES],
            recent_len: 0,
            recent_next: 0,
        }
    }

    /// Forgets everything but the nominal rate (after lost samples: a FIFO overrun, a restart).
    pub fn reset(&mut self) {
        let nominal = self.nominal_q16;
        *self = Self::new(0);
        self.nominal_q16 = nominal;
        self.period_q16 = nominal;
    }

    /// The current period estimate, DAC samples per sensor sample, Q16.16.
    pub fn period_q16(&self) -> u32 {
        self.period_q16
    }

    /// The period estimate as f32 DAC samples (for reports).
    pub fn period(&self) -> f32 {
        self.period_q16 as f32 / (1u32 << TIME_FRAC_BITS) as f32
    }

    /// Takes a batch of `n` samples read at DAC sample `stamp`; returns the instant of the
    /// batch's newest sample. Sample i (0 = oldest) of the batch is at
    /// [`SensorTimebase::sample_time`]`(newest, n, i)`.
    pub fn push_batch(&mut self, n: usize, stamp: u64) -> Option<DacTime> {
        if n == 0 {
            return None;
        }
        // S samples output: the read happened in [S − 1, S); centre the bound at S − ½.
        let s = dac_time(stamp).saturating_sub(1 << (TIME_FRAC_BITS - 1));
        // Far more time passed since the last batch than these samples explain: the sensor
        // was silent (or restarted), so the old anchors no longer count the same samples.
        if let Some(prev) = self.newest {
            let explained = (2 * n as u64 + GAP_SLACK) * self.period_q16 as u64;
            if s > prev + explained {
                self.reset();
            }
        }
        self.count += n as u64;
        self.update_period(s);
        self.recent[self.recent_next] = Anchor { stamp: s, count: self.count };
        self.recent_next = (self.recent_next + 1) % BOUND_BATCHES;
        self.recent_len = (self.recent_len + 1).min(BOUND_BATCHES);
        let p = self.period_q16 as u64;
        let t = self.recent[..self.recent_len]
            .iter()
            .map(|a| a.stamp + (self.count - a.count) * p)
            .min()
            .unwrap_or(s);
        self.newest = Some(t);
        Some(t)
    }

    /// Instant of sample `i` (0 = oldest) of a batch of `n` whose newest sample is at `newest`.
    pub fn sample_time(&self, newest: DacTime, n: usize, i: usize) -> DacTime {
        let back = n.saturating_sub(1).saturating_sub(i) as u64;
        newest.saturating_sub(back * self.period_q16 as u64)
    }

    fn update_period(&mut self, s: DacTime) {
        let here = Anchor { stamp: s, count: self.count };
        match (self.older, self.newer) {
            (None, _) => self.older = Some(here),
            (Some(a), newer) => {
                let span = self.count - a.count;
                if span > 0 && s > a.stamp {
                    // Two anchors in the first window only once it is long enough to beat the
                    // nominal rate's few % (two stamps' error over ≥ 64 samples: < 2 %).
                    if span >= 64 {
                        self.period_q16 = ((s - a.stamp) / span) as u32;
                    }
                }
                match newer {
                    None if span >= PERIOD_WINDOW => self.newer = Some(here),
                    Some(b) if self.count - b.count >= PERIOD_WINDOW => {
                        self.older = Some(b);
                        self.newer = Some(here);
                    }
                    _ => {}
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::drive::dds::{Dds, tuning_word};

    #[test]
    fn phase_at_matches_the_dds() {
        let mut dds = Dds::new(tuning_word(123_456));
        dds.phase = 0x1234_5678;
        let mark = PhaseMark { sample: 1000, phase: dds.phase, tuning_word: dds.tuning_word };
        let mut phase = dds.phase;
        for k in 0..5000u64 {
            assert_eq!(mark.phase_at(dac_time(1000 + k)), phase);
            phase = phase.wrapping_add(dds.tuning_word);
        }
        // Before the mark, and half-way between samples.
        let before = mark.phase_at(dac_time(990));
        assert_eq!(before, dds.phase.wrapping_sub(dds.tuning_word * 10));
        let half = mark.phase_at(dac_time(1000) + (1 << 15));
        assert_eq!(half, dds.phase.wrapping_add(dds.tuning_word / 2));
        let later = PhaseMark { sample: 1010, phase: mark.phase_at(dac_time(1010)), ..mark };
        assert!(!mark.differs_from(&later));
        assert!(mark.differs_from(&PhaseMark { tuning_word: 7, ..later }));
        assert!(mark.differs_from(&PhaseMark { phase: later.phase ^ 1 << 30, ..later }));
    }

    /// A sensor at `odr_hz`·(1 + offset) read every block with a random extra delay; returns
    /// the worst and the mean |error| of the sample instants after the first `settle` batches.
    fn timebase_error(odr_hz: f64, offset: f64, jitter_blocks: f64, batches: usize) -> (f64, f64) {
        let nominal_mhz = (odr_hz * 1000.0) as u32;
        let period = 50_000.0 / (odr_hz * (1.0 + offset)); // true DAC samples per sample
        let mut tb = SensorTimebase::new(nominal_mhz);
        let t0 = 17.3; // first sensor sample, DAC samples
        let mut taken = 0u64; // samples taken and read so far
        let mut rng = 0x2545_f491_4f6c_dd1du64;
        let (mut worst, mut sum, mut cnt) = (0f64, 0f64, 0usize);
        for b in 1..=batches {
            rng ^= rng << 13;
            rng ^= rng >> 7;
            rng ^= rng << 17;
            let jitter = (rng >> 11) as f64 / (1u64 << 53) as f64 * jitter_blocks * 250.0;
            let read_at = b as f64 * 250.0 + jitter;
            let available = ((read_at - t0) / period).floor() as u64 + 1;
            let n = (available - taken) as usize;
            // S samples output: the read happened in [S − 1, S).
            let newest = tb.push_batch(n, read_at.floor() as u64 + 1).unwrap();
            if b > batches / 2 {
                for i in 0..n {
                    let k = taken + i as u64;
                    let truth = t0 + k as f64 * period;
                    let got = tb.sample_time(newest, n, i) as f64 / 65536.0;
                    worst = worst.max((got - truth).abs());
                    sum += (got - truth).abs();
                    cnt += 1;
                }
            }
            taken = available;
        }
        (worst, sum / cnt as f64)
    }

    #[test]
    fn timebase_follows_an_offset_clock_through_jitter() {
        for (odr, offset, jitter) in
            [(6660.0, 0.02, 0.3), (6660.0, -0.02, 0.3), (3330.0, 0.013, 0.5), (3330.0, -0.02, 0.0)]
        {
            let (worst, mean) = timebase_error(odr, offset, jitter, 2000);
            std::println!(
                "timebase {odr} Hz {:+.1} %, jitter {jitter} block: worst {worst:.3}, mean \
                 {mean:.3} DAC samples",
                offset * 100.0
            );
            let period = 50_000.0 / odr;
            assert!(worst < period / 4.0, "worst {worst} of period {period}");
            assert!(mean < 1.0, "mean {mean}");
        }
    }

    #[test]
    fn a_silent_sensor_starts_the_timebase_again() {
        let mut tb = SensorTimebase::new(3_330_000);
        let p = 50_000.0 / 3330.0;
        // Reads every 250 DAC samples, ~16.7 samples each, then 2 s of silence.
        let mut produced = 0.0f64;
        for k in 1..=400u64 {
            let due = (k * 250) as f64 / p;
            let n = (due - produced).floor();
            produced += n;
            tb.push_batch(n as usize, k * 250);
        }
        let before = tb.period();
        let newest = tb.push_batch(16, 400 * 250 + 100_000).unwrap();
        // Without the restart the 2 s gap would pass for 16 samples' worth of time.
        assert!((tb.period() - before).abs() < 0.01, "{} vs {before}", tb.period());
        assert_eq!(newest, dac_time(400 * 250 + 100_000) - (1 << 15));
    }

    #[test]
    fn nominal_period() {
        assert_eq!(nominal_period_q16(6_660_000) >> 16, 7);
        let p = nominal_period_q16(3_330_000) as f64 / 65536.0;
        assert!((p - 50_000.0 / 3330.0).abs() < 1e-4);
        let mut tb = SensorTimebase::new(6_660_000);
        assert_eq!(tb.push_batch(0, 5), None);
        assert_eq!(tb.push_batch(3, 250), Some(dac_time(250) - (1 << 15)));
        tb.reset();
        assert_eq!(tb.period_q16(), nominal_period_q16(6_660_000));
    }
}
