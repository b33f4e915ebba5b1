//! A simulated shaker + plate: one resonant second-order system driven by the DAC output.
//!
//! ẍ + 2ζω₀ẋ + ω₀²x = g·u, with u the DAC output normalised to ±1 (code 2048 ↦ 0) and the
//! plate's acceleration a = ẍ as output (m/s²). Integrated per sample with semi-implicit Euler
//! (stable for ω₀·Δt < 2; ω₀·Δt ≈ 0.02 here), in f32: IEEE single precision gives the same
//! bits on the host and on the Cortex-M4F's FPU, so the QEMU board's plant is deterministic.
//! The sensing issue will read [`Plant::acceleration`] through a simulated accelerometer.
//!
//! [`PlantFault`] breaks the simulated rig on purpose, for the fault monitors' tests and the
//! QEMU board: a disconnected shaker (no force at all) or an amplifier that clips its output.

use crate::drive::dds::DAC_MID;
use crate::icd::units::SAMPLE_RATE;

/// Parameters of the simulated shaker + plate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlantParams {
    /// Resonance, Hz.
    pub f0_hz: f32,
    /// Damping ratio.
    pub zeta: f32,
    /// Force per unit mass at full-scale drive, m/s² (the static-response acceleration scale).
    pub gain: f32,
}

impl PlantParams {
    /// A small plate on a shaker: resonance 180 Hz, ζ = 0.05, 20 m/s² per full scale
    /// (≈ 200 m/s² at resonance).
    pub const DEFAULT: PlantParams = PlantParams { f0_hz: 180.0, zeta: 0.05, gain: 20.0 };
}

/// A deliberate failure of the simulated rig.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PlantFault {
    /// Everything works.
    #[default]
    None,
    /// The shaker is disconnected: the drive produces no force (gain 0).
    Disconnected,
    /// The amplifier clips: the drive's deviation from mid-scale is limited to this many DAC
    /// codes (of 2047).
    Saturated(u16),
}

/// State of the simulated plant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plant {
    fault: PlantFault,
    w2: f32,
    c: f32,
    gain: f32,
    dt: f32,
    x: f32,
    v: f32,
    a: f32,
}

impl Plant {
    /// A plant at rest.
    pub fn new(p: PlantParams) -> Self {
        let w0 = 2.0 * core::f32::consts::PI * p.f0_hz;
        Self {
            fault: PlantFault::None,
            w2: w0 * w0,
            c: 2.0 * p.zeta * w0,
            gain: p.gain / DAC_MID as f32,
            dt: 1.0 / SAMPLE_RATE as f32,
            x: 0.0,
            v: 0.0,
            a: 0.0,
        }
    }

    /// Breaks (or mends) the rig from the next sample on.
    pub fn set_fault(&mut self, fault: PlantFault) {
        self.fault = fault;
    }

    /// The rig's current failure.
    pub fn fault(&self) -> PlantFault {
        self.fault
    }

    /// Advances one sample with DAC code `code`; returns the acceleration, m/s².
    #[inline]
    pub fn step(&mut self, code: u16) -> f32 {
        let mut d = code as i32 - DAC_MID as i32;
        match self.fault {
            PlantFault::None => {}
            PlantFault::Disconnected => d = 0,
            PlantFault::Saturated(limit) => d = d.clamp(-(limit as i32), limit as i32),
        }
        let u = d as f32;
        self.a = self.gain * u - self.c * self.v - self.w2 * self.x;
        self.v += self.a * self.dt;
        self.x += self.v * self.dt;
        self.a
    }

    /// Runs a block of samples; returns the largest |acceleration| in it.
    pub fn run(&mut self, codes: &[u16]) -> f32 {
        let mut peak = 0.0f32;
        for &c in codes {
            let a = self.step(c);
            let m = if a < 0.0 { -a } else { a };
            if m > peak {
                peak = m;
            }
        }
        peak
    }

    /// Acceleration after the last sample, m/s².
    pub fn acceleration(&self) -> f32 {
        self.a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drive::dds::{Dds, gain_of_q15, tuning_word};

    fn steady_peak(freq_mhz: u32) -> f32 {
        let mut plant = Plant::new(PlantParams::DEFAULT);
        let mut dds = Dds::new(tuning_word(freq_mhz));
        let mut buf = [0u16; 250];
        let mut peak = 0.0;
        for i in 0..400 {
            dds.fill_steady(&mut buf, gain_of_q15(16384));
            let p = plant.run(&buf);
            if i >= 300 {
                peak = f32::max(peak, p);
            }
        }
        peak
    }

    #[test]
    fn resonates_near_f0() {
        let at = steady_peak(180_000);
        let below = steady_peak(60_000);
        let above = steady_peak(600_000);
        // At resonance the gain is ≈ 1/(2ζ) = 10 times the static response (10 m/s² here).
        assert!((80.0..=120.0).contains(&at), "peak at resonance {at}");
        assert!(at > 5.0 * below && at > 5.0 * above, "{below} {at} {above}");
    }

    #[test]
    fn faults_cut_or_clip_the_drive() {
        let run = |fault| {
            let mut plant = Plant::new(PlantParams::DEFAULT);
            plant.set_fault(fault);
            assert_eq!(plant.fault(), fault);
            let mut dds = Dds::new(tuning_word(180_000));
            let mut buf = [0u16; 250];
            let mut peak = 0.0f32;
            for _ in 0..200 {
                dds.fill_steady(&mut buf, gain_of_q15(16384));
                peak = plant.run(&buf);
            }
            peak
        };
        let whole = run(PlantFault::None);
        assert_eq!(run(PlantFault::Disconnected), 0.0);
        // Clipped at a tenth of the drive's 1024-code peak: a square-ish wave of ≤ 1/10 the
        // force, so the response falls to between 1/10 and 4/π·1/10 of the whole one.
        let clipped = run(PlantFault::Saturated(102));
        assert!(clipped > 0.09 * whole && clipped < 0.14 * whole, "{clipped} of {whole}");
    }

    #[test]
    fn rests_without_drive() {
        let mut plant = Plant::new(PlantParams::DEFAULT);
        assert_eq!(plant.run(&[DAC_MID; 1000]), 0.0);
    }
}
