//! Direct digital synthesis of the drive sine, in integers only.
//!
//! - Sample rate [`SAMPLE_RATE`] (the sample clock of the wire contract, `icd::units`).
//! - Phase: a 32-bit accumulator, one turn = 2³². Tuning word = f·2³²/f_s, so the frequency
//!   resolution is f_s/2³² ≈ 11.6 µHz; frequencies are given in millihertz.
//! - Sine: a [`TABLE_LEN`]-entry table of sin in Q30 (plus one guard entry), linearly
//!   interpolated with the next 22 phase bits. The table is computed at compile time by a
//!   `const fn` (Taylor series in f64); no float at run time.
//! - Amplitude: a gain in Q31 ([`gain_of_q15`] maps a Q15 amplitude to it, scaled so that
//!   amplitude 1.0 peaks at ±2047 LSB and never needs clamping).
//! - Output: 12-bit DAC codes centred at [`DAC_MID`] (2048).
//!
//! The per-sample path is [`Dds::fill_steady`] / [`Dds::fill_ramp`]: a handful of loads,
//! two 32×32→64 multiplies and shifts.

use crate::icd::units::SAMPLE_RATE;

/// log2 of the sine table length.
pub const TABLE_BITS: u32 = 10;
/// Sine table entries per turn.
pub const TABLE_LEN: usize = 1 << TABLE_BITS;
/// Phase bits below the table index, used for interpolation.
const FRAC_BITS: u32 = 32 - TABLE_BITS;
/// DAC mid-scale code (zero output).
pub const DAC_MID: u16 = 2048;
/// Largest DAC code.
pub const DAC_MAX: u16 = 4095;
/// Q31 gain per Q15 amplitude unit: amplitude 32767 (≈1.0) peaks at 2047.37 LSB, which
/// rounds to 2047, so codes stay within 1..=4095 without a clamp.
pub const GAIN_PER_Q15: i32 = 65_518;
/// Output of the sine·gain product is Q29; this many bits are dropped to get 12-bit codes
/// (±2¹¹ full scale).
const OUT_SHIFT: u32 = 29 - 11;

/// Q31 gain for a Q15 amplitude (0..=32767).
pub const fn gain_of_q15(amplitude_q15: u16) -> i32 {
    let a = if amplitude_q15 > 32767 { 32767 } else { amplitude_q15 };
    a as i32 * GAIN_PER_Q15
}

/// Q15 amplitude (rounded) of a Q31 gain: the inverse of [`gain_of_q15`], for status reports.
pub const fn q15_of_gain(gain: i32) -> u16 {
    let g = if gain < 0 { 0 } else { gain };
    ((g + GAIN_PER_Q15 / 2) / GAIN_PER_Q15) as u16
}

/// Tuning word (phase increment per sample) for a frequency in millihertz, rounded to nearest.
pub const fn tuning_word(freq_mhz: u32) -> u32 {
    let denom = SAMPLE_RATE as u64 * 1000;
    (((freq_mhz as u64) << 32) + denom / 2).wrapping_div(denom) as u32
}

/// Frequency in millihertz (rounded) of a tuning word.
pub const fn freq_mhz_of(tuning_word: u32) -> u32 {
    ((tuning_word as u64 * SAMPLE_RATE as u64 * 1000 + (1 << 31)) >> 32) as u32
}

const fn sin_f64(x: f64) -> f64 {
    // x in [-π, π]; fold into [-π/2, π/2], then a Taylor series to well below f64 precision.
    const PI: f64 = core::f64::consts::PI;
    let x = if x > PI / 2.0 {
        PI - x
    } else if x < -PI / 2.0 {
        -PI - x
    } else {
        x
    };
    let x2 = x * x;
    let mut term = x;
    let mut sum = x;
    let mut n = 1u32;
    while n < 15 {
        let k = (2 * n) as f64;
        term = -term * x2 / (k * (k + 1.0));
        sum += term;
        n += 1;
    }
    sum
}

const fn build_table() -> [i32; TABLE_LEN + 1] {
    let mut t = [0i32; TABLE_LEN + 1];
    let mut i = 0;
    while i <= TABLE_LEN {
        // Angle in [-π, π): index i ↦ 2π·i/N, wrapped.
        let turns = i as f64 / TABLE_LEN as f64;
        let turns = if turns >= 0.5 { turns - 1.0 } else { turns };
        let s = sin_f64(turns * 2.0 * core::f64::consts::PI) * (1u64 << 30) as f64;
        t[i] = if s >= 0.0 { (s + 0.5) as i32 } else { (s - 0.5) as i32 };
        i += 1;
    }
    t
}

/// sin(2π·i/[`TABLE_LEN`]) in Q30, with a guard entry `TABLE[TABLE_LEN] = TABLE[0]`.
pub static TABLE: [i32; TABLE_LEN + 1] = build_table();

/// Interpolated sine of a phase (one turn = 2³²), Q30.
#[inline(always)]
pub fn sine_q30(phase: u32) -> i32 {
    let i = (phase >> FRAC_BITS) as usize;
    let frac = (phase & ((1 << FRAC_BITS) - 1)) as i64;
    let a = TABLE[i];
    let b = TABLE[i + 1];
    a + (((b - a) as i64 * frac) >> FRAC_BITS) as i32
}

/// sine·gain before DAC quantisation: Q29 (±2²⁹ full scale).
#[inline(always)]
pub fn scaled(phase: u32, gain: i32) -> i32 {
    ((sine_q30(phase) as i64 * gain as i64) >> 32) as i32
}

/// 12-bit DAC code of a Q29 sample (rounded, centred at [`DAC_MID`]).
#[inline(always)]
pub fn dac_code(sample_q29: i32) -> u16 {
    (DAC_MID as i32 + ((sample_q29 + (1 << (OUT_SHIFT - 1))) >> OUT_SHIFT)) as u16
}

/// The oscillator: phase and tuning word. Changing the tuning word keeps the phase, so a
/// frequency change never makes the waveform jump.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Dds {
    /// Phase of the next sample (one turn = 2³²).
    pub phase: u32,
    /// Phase increment per sample.
    pub tuning_word: u32,
}

impl Dds {
    /// An oscillator at phase 0.
    pub const fn new(tuning_word: u32) -> Self {
        Self { phase: 0, tuning_word }
    }

    /// Fills `out` at constant `gain`.
    #[inline(never)]
    pub fn fill_steady(&mut self, out: &mut [u16], gain: i32) {
        let step = self.tuning_word;
        let mut phase = self.phase;
        for o in out.iter_mut() {
            *o = dac_code(scaled(phase, gain));
            phase = phase.wrapping_add(step);
        }
        self.phase = phase;
    }

    /// Fills `out` while the gain moves by `inc` per sample (the first sample uses
    /// `*gain + inc`); leaves the last gain in `*gain`.
    #[inline(never)]
    pub fn fill_ramp(&mut self, out: &mut [u16], gain: &mut i32, inc: i32) {
        let step = self.tuning_word;
        let mut phase = self.phase;
        let mut g = *gain;
        for o in out.iter_mut() {
            g += inc;
            *o = dac_code(scaled(phase, g));
            phase = phase.wrapping_add(step);
        }
        self.phase = phase;
        *gain = g;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    #[test]
    fn table_is_sine() {
        for (i, &v) in TABLE.iter().enumerate() {
            let want = (i as f64 / TABLE_LEN as f64 * core::f64::consts::TAU).sin() * 2f64.powi(30);
            assert!((v as f64 - want).abs() <= 0.5 + 1e-6, "entry {i}: {v} vs {want}");
        }
        assert_eq!(TABLE[0], 0);
        assert_eq!(TABLE[TABLE_LEN], 0);
        assert_eq!(TABLE[TABLE_LEN / 4], 1 << 30);
    }

    #[test]
    fn interpolation_error_is_small() {
        let mut worst = 0f64;
        for k in 0..200_000u64 {
            let phase = (k.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as u32;
            let want = (phase as f64 / 2f64.powi(32) * core::f64::consts::TAU).sin();
            let got = sine_q30(phase) as f64 / 2f64.powi(30);
            worst = worst.max((got - want).abs());
        }
        // Linear interpolation over 1024 entries: (2π/1024)²/8 ≈ 4.7e-6.
        assert!(worst < 5e-6, "worst error {worst}");
    }

    #[test]
    fn tuning_words_resolve_better_than_10_mhz() {
        for f in [1_000u32, 1_001, 123_456, 1_999_990, 2_000_000] {
            let back = freq_mhz_of(tuning_word(f));
            assert_eq!(back, f);
            let exact = f as f64 / 1000.0;
            let got = tuning_word(f) as f64 * SAMPLE_RATE as f64 / 2f64.powi(32);
            assert!((got - exact).abs() < 1e-5);
        }
    }

    #[test]
    fn full_scale_codes_stay_in_range() {
        let g = gain_of_q15(u16::MAX);
        let mut dds = Dds::new(tuning_word(997_000));
        let mut out = std::vec![0u16; 100_000];
        dds.fill_steady(&mut out, g);
        let (lo, hi) = (out.iter().min().unwrap(), out.iter().max().unwrap());
        assert_eq!((*lo, *hi), (1, 4095));
        assert_eq!(q15_of_gain(g), 32767);
        assert_eq!(q15_of_gain(gain_of_q15(12345)), 12345);
        let mut zero = [0u16; 16];
        dds.fill_steady(&mut zero, 0);
        assert!(zero.iter().all(|&c| c == DAC_MID));
    }

    /// Kaiser window (β = 20: side lobes far below −150 dB), so SFDR is measured without
    /// coherent sampling.
    fn kaiser(n: usize, beta: f64) -> Vec<f64> {
        fn i0(x: f64) -> f64 {
            let (mut sum, mut term) = (1.0, 1.0);
            for k in 1..200 {
                term *= (x / (2.0 * k as f64)).powi(2);
                sum += term;
                if term < sum * 1e-17 {
                    break;
                }
            }
            sum
        }
        let denom = i0(beta);
        (0..n)
            .map(|i| {
                let r = 2.0 * i as f64 / (n - 1) as f64 - 1.0;
                i0(beta * (1.0 - r * r).sqrt()) / denom
            })
            .collect()
    }

    /// Spurious-free dynamic range in dB: carrier power over the largest other bin, ignoring
    /// DC and the window's main lobes (±`guard` bins) around DC and the carrier.
    fn sfdr_db(samples: &[f64], freq_hz: f64) -> f64 {
        use rustfft::{FftPlanner, num_complex::Complex};
        let n = samples.len();
        let mean = samples.iter().sum::<f64>() / n as f64;
        let w = kaiser(n, 20.0);
        let mut buf: Vec<Complex<f64>> =
            samples.iter().zip(&w).map(|(s, w)| Complex::new((s - mean) * w, 0.0)).collect();
        FftPlanner::new().plan_fft_forward(n).process(&mut buf);
        let power: Vec<f64> = buf[..n / 2].iter().map(|c| c.norm_sqr()).collect();
        let carrier_bin = (freq_hz * n as f64 / SAMPLE_RATE as f64).round() as usize;
        let guard = 24;
        let carrier = power[carrier_bin.saturating_sub(guard)..carrier_bin + guard]
            .iter()
            .cloned()
            .fold(0.0, f64::max);
        let spur = power
            .iter()
            .enumerate()
            .filter(|(k, _)| *k > guard && k.abs_diff(carrier_bin) > guard)
            .map(|(_, p)| *p)
            .fold(0.0, f64::max);
        10.0 * (carrier / spur).log10()
    }

    /// SFDR at a few frequencies over 2¹⁶ samples, before (Q29) and after 12-bit quantisation.
    /// Prints the figures for the notes (`cargo test -p chladni-shared sfdr -- --nocapture`).
    #[test]
    fn sfdr_before_and_after_quantisation() {
        const N: usize = 1 << 16;
        for freq_mhz in [55_500u32, 440_125, 1_234_567, 1_999_990] {
            let gain = gain_of_q15(32767);
            let mut dds = Dds::new(tuning_word(freq_mhz));
            let mut ideal = Vec::with_capacity(N);
            let mut phase = dds.phase;
            for _ in 0..N {
                ideal.push(scaled(phase, gain) as f64);
                phase = phase.wrapping_add(dds.tuning_word);
            }
            let mut codes = std::vec![0u16; N];
            dds.fill_steady(&mut codes, gain);
            let quantised: Vec<f64> = codes.iter().map(|&c| c as f64).collect();
            let f = freq_mhz as f64 / 1000.0;
            let (before, after) = (sfdr_db(&ideal, f), sfdr_db(&quantised, f));
            std::println!(
                "sfdr {f:>9.3} Hz: {before:6.1} dBc before, {after:5.1} dBc after 12-bit"
            );
            assert!(before >= 100.0, "{f} Hz: SFDR before quantisation {before:.1} dB");
            assert!(after >= 70.0, "{f} Hz: SFDR after quantisation {after:.1} dB");
        }
    }
}
