//! A simulated LSM6DSL Z axis for the QEMU board and the closed-loop tests: it is fed the
//! plant's acceleration once per DAC sample and emits 16-bit samples at its own rate.
//!
//! - **Clock**: nominal ODR × (1 + offset ppm), carried as the time to the next sample in
//!   Q32.32 DAC samples (integer, so the sample instants are exact and the same everywhere).
//!   The real sensor runs from its own oscillator; the offset makes the asynchrony explicit.
//! - **Sampling**: linear interpolation between the two DAC samples around each instant; the
//!   first sample is taken half a DAC sample before the first one pushed (DAC sample k's
//!   acceleration belongs to instant k), then one every period.
//! - **Offset**: a constant in LSB (gravity on Z: 1 g ≈ 2 049 LSB at ±16 g).
//! - **Noise**: a seeded xorshift32; the sum of four uniform variates (Irwin–Hall, nearly
//!   Gaussian), scaled to σ = `noise_lsb` LSB. The real part's density is 80 µg/√Hz (about
//!   9 LSB rms at ±16 g over its 3 kHz band); [`SensorSimConfig::DEFAULT`] uses σ = 4 LSB.
//! - **Quantisation**: rounded to the LSB, clipped to ±32 767 (full scale), like the part.
//!
//! Everything is f32 or integer (IEEE single is identical on the host and the M4F's FPU).

use crate::drive::lockin::LSB_16G_MPS2;
use crate::icd::units::SAMPLE_RATE;

/// How the simulated sensor behaves.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SensorSimConfig {
    /// Nominal output data rate, mHz (6 660 000 or 3 330 000 for the LSM6DSL's fast rates).
    pub odr_mhz: u32,
    /// Offset of the sensor's clock from nominal, ppm (the part's is within a few %).
    pub offset_ppm: i32,
    /// Acceleration per LSB, m/s².
    pub lsb_mps2: f32,
    /// Standard deviation of the added noise, LSB.
    pub noise_lsb: f32,
    /// Constant added to every sample, LSB (gravity).
    pub bias_lsb: i32,
    /// Seed of the noise generator (not 0).
    pub seed: u32,
}

impl SensorSimConfig {
    /// 6.66 kHz, 1 % fast, ±16 g, σ = 4 LSB, 1 g of gravity.
    pub const DEFAULT: SensorSimConfig = SensorSimConfig {
        odr_mhz: 6_660_000,
        offset_ppm: 10_000,
        lsb_mps2: LSB_16G_MPS2,
        noise_lsb: 4.0,
        bias_lsb: 2049,
        seed: 0x1234_5678,
    };
}

/// The simulated sensor. See the module docs.
#[derive(Debug, Clone)]
pub struct SensorSim {
    cfg: SensorSimConfig,
    /// DAC samples per sensor sample, Q32.32.
    period_q32: u64,
    /// From the previous DAC sample to the next sensor sample, Q32.32 DAC samples.
    until_next_q32: u64,
    prev: f32,
    rng: u32,
    inv_lsb: f32,
    produced: u64,
}

impl SensorSim {
    /// A sensor whose first sample falls right after the first DAC sample pushed.
    pub fn new(cfg: SensorSimConfig) -> Self {
        let rate_mhz = cfg.odr_mhz as i128 * (1_000_000 + cfg.offset_ppm as i128) / 1_000_000;
        let rate_mhz = rate_mhz.max(1) as u128;
        let period_q32 = (((SAMPLE_RATE as u128 * 1000) << 32) / rate_mhz) as u64;
        Self {
            cfg,
            period_q32,
            until_next_q32: 1 << 31,
            prev: 0.0,
            rng: if cfg.seed == 0 { 1 } else { cfg.seed },
            inv_lsb: 1.0 / cfg.lsb_mps2,
            produced: 0,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &SensorSimConfig {
        &self.cfg
    }

    /// True DAC samples per sensor sample.
    pub fn period(&self) -> f64 {
        self.period_q32 as f64 / 4_294_967_296.0
    }

    /// Samples produced so far.
    pub fn produced(&self) -> u64 {
        self.produced
    }

    /// Takes the acceleration (m/s²) of the next DAC sample; hands each sensor sample that
    /// falls in the interval since the previous DAC sample to `sink`.
    pub fn push(&mut self, accel_mps2: f32, mut sink: impl FnMut(i16)) {
        const ONE: u64 = 1 << 32;
        while self.until_next_q32 <= ONE {
            let frac = (self.until_next_q32 >> 8) as f32 / (1u32 << 24) as f32;
            let a = self.prev + (accel_mps2 - self.prev) * frac;
            sink(self.quantise(a));
            self.produced += 1;
            self.until_next_q32 += self.period_q32;
        }
        self.until_next_q32 -= ONE;
        self.prev = accel_mps2;
    }

    fn quantise(&mut self, a: f32) -> i16 {
        let v = a * self.inv_lsb + self.cfg.bias_lsb as f32 + self.noise();
        let r = if v >= 0.0 { (v + 0.5) as i32 } else { (v - 0.5) as i32 };
        r.clamp(-32_767, 32_767) as i16
    }

    /// Irwin–Hall(4) noise scaled to σ = `noise_lsb`: four uniforms on [−½, ½) have σ = 1/√3.
    fn noise(&mut self) -> f32 {
        if self.cfg.noise_lsb == 0.0 {
            return 0.0;
        }
        let mut sum = 0i32;
        for _ in 0..4 {
            self.rng ^= self.rng << 13;
            self.rng ^= self.rng >> 17;
            self.rng ^= self.rng << 5;
            sum += (self.rng >> 16) as i32 - (1 << 15);
        }
        const SQRT3: f32 = 1.732_050_8;
        sum as f32 / 65_536.0 * SQRT3 * self.cfg.noise_lsb
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    fn collect(cfg: SensorSimConfig, dac_samples: usize, accel: impl Fn(usize) -> f32) -> Vec<i16> {
        let mut s = SensorSim::new(cfg);
        let mut out = Vec::new();
        for k in 0..dac_samples {
            s.push(accel(k), |x| out.push(x));
        }
        assert_eq!(s.produced(), out.len() as u64);
        out
    }

    #[test]
    fn rate_follows_the_clock_offset() {
        for ppm in [-20_000, 0, 13_000] {
            let cfg = SensorSimConfig { offset_ppm: ppm, ..SensorSimConfig::DEFAULT };
            let n = collect(cfg, 500_000, |_| 0.0).len() as f64; // 10 s
            let want = 66_600.0 * (1.0 + ppm as f64 * 1e-6);
            assert!((n - want).abs() <= 1.0, "{ppm} ppm: {n} vs {want}");
        }
    }

    #[test]
    fn noise_has_its_sigma_and_quantisation_clips() {
        let cfg = SensorSimConfig { noise_lsb: 4.0, bias_lsb: 100, ..SensorSimConfig::DEFAULT };
        let xs = collect(cfg, 200_000, |_| 0.0);
        let mean = xs.iter().map(|&x| x as f64).sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|&x| (x as f64 - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        // Rounding adds 1/12 LSB² of variance.
        assert!((mean - 100.0).abs() < 0.1, "mean {mean}");
        assert!((var - 16.0 - 1.0 / 12.0).abs() < 0.5, "variance {var}");
        let cfg = SensorSimConfig { noise_lsb: 0.0, bias_lsb: 0, ..SensorSimConfig::DEFAULT };
        let big = collect(cfg, 100, |k| if k % 2 == 0 { 1000.0 } else { -1000.0 });
        assert!(big.iter().all(|&x| x == 32_767 || x == -32_767 || x.abs() < 32_767));
        assert!(big.contains(&32_767) || big.contains(&-32_767));
    }

    #[test]
    fn samples_interpolate_the_acceleration() {
        let cfg = SensorSimConfig { noise_lsb: 0.0, bias_lsb: 0, ..SensorSimConfig::DEFAULT };
        let s = SensorSim::new(cfg);
        let p = s.period();
        // A ramp of 1 LSB per DAC sample: sample k is taken half a DAC sample before the first
        // one pushed, plus k periods (the first interpolates from rest, so skip it).
        let xs = collect(cfg, 1000, |k| k as f32 * LSB_16G_MPS2);
        for (k, &x) in xs.iter().enumerate().skip(1) {
            let want = -0.5 + k as f64 * p; // DAC sample index = value in LSB
            assert!((x as f64 - want).abs() <= 0.51, "sample {k}: {x} vs {want}");
        }
    }
}
