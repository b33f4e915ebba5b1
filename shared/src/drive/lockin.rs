//! Lock-in detection: the amplitude and phase of the plate's acceleration at the drive
//! frequency, with the DDS's own phase as the reference.
//!
//! Each accelerometer sample x is taken at its own instant t (from
//! [`crate::drive::timeline::SensorTimebase`]); the reference is the DDS's phase φ(t) at that
//! instant ([`PhaseMark::phase_at`]), its sine and cosine from the DDS's table. Over a window
//! of whole drive cycles the samples are fitted with x = A·sin φ + B·cos φ + D (least squares,
//! the "three-parameter sine fit"), so that
//! - **DC** (gravity on Z is 1 g ≈ 2 000 LSB at ±16 g, a hundred times a small response) is
//!   removed exactly, whatever the window's alignment to the samples;
//! - **harmonics** of the drive have whole cycles in the window and drop out (as in a plain
//!   multiply-and-average lock-in), up to the one-sample raggedness of the window's ends;
//! - **any drive frequency works, also above the sensor's Nyquist**: the reference is
//!   evaluated at each sample's true instant, so an aliased drive is still fitted at its own
//!   phase. The normal equations account for uneven phase coverage (a few samples per cycle
//!   at 2 kHz). Only exact aliasing to DC or Nyquist (f a multiple of ODR/2), where sin and
//!   cos cannot be told from each other or from DC, is refused: the fit is then singular and
//!   the window yields nothing ([`LockIn::singular_windows`] counts them).
//!
//! The sums are integers (reference Q16, samples in LSB, i64 sums, centred in i128), so the
//! estimate is the same bit for bit on the host and the controller; one f64 division gives
//! A and B, then f32 for the outputs: amplitude by an integer square root (exact to the mm/s²),
//! phase by `micromath`'s `atan2` (within 0.16°; its `sqrt` is only 5 % and is not used).
//!
//! Why not `idsp::Lockin`: it demodulates with a phase given per sample too, but low-passes
//! with IIR biquads. That leaves ripple at 2f (and the gravity DC leaks through the reference's
//! own DC at low sample counts), settles over several time constants instead of one window,
//! and assumes a uniform sample rate; a whole-cycle window gives exact harmonic and DC
//! rejection and one independent estimate per window, which is what a per-window PI step and
//! the fault monitors want.
//!
//! Window: the least whole number of drive cycles lasting at least the minimum window
//! ([`MIN_WINDOW_SAMPLES`] DAC samples, 5 ms = one block, by default): one cycle at 180 Hz,
//! 3 at 600 Hz, 10 at 2 kHz. Windows tile time exactly (each starts where the last ended).
//! A new [`PhaseMark`] that changes the waveform (a frequency change) restarts the window.

use crate::drive::dds::sine_q30;
use crate::drive::timeline::{DacTime, PhaseMark, TIME_FRAC_BITS};
use crate::icd::sense::Measurement;

/// Default least window length, DAC samples (5 ms: one block).
pub const MIN_WINDOW_SAMPLES: u32 = 250;
/// Window lengthening above the sensor's Nyquist frequency (20 ms by default).
pub const ALIASED_WINDOW_FACTOR: u32 = 4;
/// Most samples in one window (keeps the integer sums far from overflow).
pub const MAX_WINDOW_SAMPLES: i64 = 1 << 16;

/// Acceleration per LSB at the LSM6DSL's ±16 g range (0.488 mg/LSB), m/s².
pub const LSB_16G_MPS2: f32 = 0.488e-3 * 9.806_65;

/// One window's estimate: x ≈ A·sin φ + B·cos φ (+ DC), in sensor LSB.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Estimate {
    /// A: the component in phase with the drive's sine, LSB.
    pub in_phase: f32,
    /// B: the component in phase with the drive's cosine (90° ahead), LSB.
    pub quadrature: f32,
    /// The DC the fit removed, LSB.
    pub dc: f32,
    /// Samples in the window.
    pub samples: u32,
    /// The window's end (instant just after its last sample may be), DAC time.
    pub end: DacTime,
    /// Acceleration per LSB, m/s².
    pub lsb_mps2: f32,
}

impl Estimate {
    /// Amplitude (peak) in mm/s², rounded (integer square root: the same on every target).
    pub fn accel_mmps2(&self) -> u32 {
        let a = self.in_phase * self.lsb_mps2 * 1000.0;
        let b = self.quadrature * self.lsb_mps2 * 1000.0;
        // ×4 then halve the root: half-mm resolution before rounding.
        let sq = 4.0 * (a * a + b * b);
        let r = (sq as u64).isqrt(); // ⌊2·amplitude⌋
        r.div_ceil(2) as u32
    }

    /// Amplitude (peak), m/s².
    pub fn accel_mps2(&self) -> f32 {
        self.accel_mmps2() as f32 / 1000.0
    }

    /// Phase of the acceleration against the drive's sine, degrees in (−180, 180]: positive
    /// when the acceleration leads.
    pub fn phase_deg(&self) -> f32 {
        use micromath::F32Ext;
        F32Ext::atan2(self.quadrature, self.in_phase) * (180.0 / core::f32::consts::PI)
    }

    /// The wire form.
    pub fn measurement(&self) -> Measurement {
        let mdeg = self.phase_deg() * 1000.0;
        let mut m = if mdeg >= 0.0 { (mdeg + 0.5) as i32 } else { (mdeg - 0.5) as i32 };
        if m <= -180_000 {
            m += 360_000;
        }
        Measurement { accel_mmps2: self.accel_mmps2(), phase_mdeg: m.min(180_000) }
    }
}

/// Running integer sums of one window.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
struct Sums {
    n: i64,
    x: i64,
    s: i64,
    c: i64,
    xs: i64,
    xc: i64,
    ss: i64,
    cc: i64,
    sc: i64,
}

impl Sums {
    fn add(&mut self, x: i16, phase: u32) {
        // Q16 reference: |s|, |c| ≤ 2¹⁶, so x·s < 2³¹ and s·s ≤ 2³² per sample.
        let s = (sine_q30(phase) >> 14) as i64;
        let c = (sine_q30(phase.wrapping_add(1 << 30)) >> 14) as i64;
        let x = x as i64;
        self.n += 1;
        self.x += x;
        self.s += s;
        self.c += c;
        self.xs += x * s;
        self.xc += x * c;
        self.ss += s * s;
        self.cc += c * c;
        self.sc += s * c;
    }

    /// Solves the centred normal equations; None when singular (too few samples, or the
    /// phases do not separate sin, cos and DC).
    fn solve(&self) -> Option<(f32, f32, f32)> {
        if self.n < 3 {
            return None;
        }
        let n = self.n as i128;
        let centred = |xy: i64, x: i64, y: i64| n * xy as i128 - x as i128 * y as i128;
        let sxs = centred(self.xs, self.x, self.s);
        let sxc = centred(self.xc, self.x, self.c);
        let sss = centred(self.ss, self.s, self.s);
        let scc = centred(self.cc, self.c, self.c);
        let ssc = centred(self.sc, self.s, self.c);
        // Each term is below 2⁵⁶·2⁵⁶ for n ≤ 2¹⁶ samples: i128 is exact.
        let det = sss * scc - ssc * ssc;
        // Singular or nearly so: the phases cover too little of the circle.
        if det <= 0 || det < (sss * scc) / 64 {
            return None;
        }
        let num_a = scc * sxs - ssc * sxc;
        let num_b = sss * sxc - ssc * sxs;
        let q16 = 65536.0f64;
        let a = num_a as f64 / det as f64 * q16;
        let b = num_b as f64 / det as f64 * q16;
        let dc = (self.x as f64 - a / q16 * self.s as f64 - b / q16 * self.c as f64) / n as f64;
        Some((a as f32, b as f32, dc as f32))
    }
}

/// The lock-in. See the module docs.
#[derive(Debug, Clone)]
pub struct LockIn {
    lsb_mps2: f32,
    min_window: u32,
    /// DAC samples per sensor sample, Q16.16 (0: unknown), to lengthen windows above Nyquist.
    sensor_period_q16: u32,
    mark: Option<PhaseMark>,
    /// Window length, DAC time (0: no drive, nothing measured).
    window: DacTime,
    start: Option<DacTime>,
    sums: Sums,
    last: Option<Estimate>,
    singular: u32,
}

impl LockIn {
    /// A lock-in for a sensor of `lsb_mps2` m/s² per LSB, with windows of at least
    /// [`MIN_WINDOW_SAMPLES`].
    pub const fn new(lsb_mps2: f32) -> Self {
        Self {
            lsb_mps2,
            min_window: MIN_WINDOW_SAMPLES,
            sensor_period_q16: 0,
            mark: None,
            window: 0,
            start: None,
            sums: Sums { n: 0, x: 0, s: 0, c: 0, xs: 0, xc: 0, ss: 0, cc: 0, sc: 0 },
            last: None,
            singular: 0,
        }
    }

    /// The same with another least window, DAC samples (longer: less noise, slower).
    pub const fn with_min_window(mut self, samples: u32) -> Self {
        self.min_window = samples;
        self
    }

    /// Tells the sensor's period (DAC samples per sample, Q16.16): a drive above the sensor's
    /// Nyquist frequency gets [`ALIASED_WINDOW_FACTOR`] times the least window, because its
    /// harmonics alias to within a few hundred Hz of it and need a longer window to drop out.
    pub fn set_sensor_period(&mut self, period_q16: u32) {
        self.sensor_period_q16 = period_q16;
        if let Some(m) = self.mark {
            self.window = window_len(m.tuning_word, self.min_window_for(m.tuning_word));
        }
    }

    fn min_window_for(&self, tuning_word: u32) -> u32 {
        // f/f_s,sensor = tw·P / 2³²·2¹⁶; above ½ the drive aliases.
        let ratio = tuning_word as u64 * self.sensor_period_q16 as u64;
        if ratio > 1 << (31 + TIME_FRAC_BITS) {
            self.min_window * ALIASED_WINDOW_FACTOR
        } else {
            self.min_window
        }
    }

    /// Follows the drive's waveform: a mark that changes it (another frequency, a phase jump)
    /// restarts the window; one that only moves along the same waveform is ignored.
    pub fn set_mark(&mut self, mark: PhaseMark) {
        if let Some(m) = self.mark
            && !m.differs_from(&mark)
        {
            return;
        }
        self.mark = Some(mark);
        self.window = window_len(mark.tuning_word, self.min_window_for(mark.tuning_word));
        self.restart();
    }

    /// Drops the window in progress (the estimate from the last complete one stays).
    pub fn restart(&mut self) {
        self.start = None;
        self.sums = Sums::default();
    }

    /// The window's length, DAC time (Q48.16), 0 without a drive frequency.
    pub fn window(&self) -> DacTime {
        self.window
    }

    /// Takes one sample taken at instant `t`; returns the estimate of a window it completed.
    /// Samples from before the current mark (the previous frequency) are dropped.
    pub fn push(&mut self, x: i16, t: DacTime) -> Option<Estimate> {
        let mark = self.mark?;
        if self.window == 0 || t < crate::drive::timeline::dac_time(mark.sample) {
            return None;
        }
        let start = *self.start.get_or_insert(t);
        let mut done = None;
        if t >= start + self.window || self.sums.n >= MAX_WINDOW_SAMPLES {
            let end = start + self.window;
            done = self.finish(end);
            // The next window starts where this one ended, unless data was missing for longer.
            self.start = Some(if t >= end + self.window { t } else { end.min(t) });
        }
        self.sums.add(x, mark.phase_at(t));
        done
    }

    fn finish(&mut self, end: DacTime) -> Option<Estimate> {
        let sums = core::mem::take(&mut self.sums);
        match sums.solve() {
            Some((a, b, dc)) => {
                let e = Estimate {
                    in_phase: a,
                    quadrature: b,
                    dc,
                    samples: sums.n as u32,
                    end,
                    lsb_mps2: self.lsb_mps2,
                };
                self.last = Some(e);
                Some(e)
            }
            None => {
                self.singular = self.singular.wrapping_add(1);
                None
            }
        }
    }

    /// The last complete window's estimate.
    pub fn last(&self) -> Option<Estimate> {
        self.last
    }

    /// Forgets the last estimate too (a new run).
    pub fn clear(&mut self) {
        self.restart();
        self.last = None;
    }

    /// Windows that gave no estimate (singular fit: exact aliasing to DC or Nyquist).
    pub fn singular_windows(&self) -> u32 {
        self.singular
    }
}

/// The least whole number of cycles of `tuning_word` lasting ≥ `min_samples`, as DAC time.
fn window_len(tuning_word: u32, min_samples: u32) -> DacTime {
    if tuning_word == 0 {
        return 0;
    }
    // Cycles k = ceil(min·tw / 2³²), at least 1; length = k·2³²/tw samples.
    let k = ((min_samples as u64 * tuning_word as u64).div_ceil(1 << 32)).max(1);
    (((k as u128) << (32 + TIME_FRAC_BITS)) / tuning_word as u128) as DacTime
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::drive::dds::tuning_word;
    use crate::drive::timeline::dac_time;

    /// Samples of `amp`·sin(φ + θ) + harmonics + DC at an asynchronous rate; returns the
    /// estimates of all complete windows.
    fn run(
        freq_mhz: u32,
        odr_hz: f64,
        amp: f64,
        theta_deg: f64,
        h2: f64,
        dc: f64,
    ) -> std::vec::Vec<Estimate> {
        let mark =
            PhaseMark { sample: 100, phase: 0x4000_0000, tuning_word: tuning_word(freq_mhz) };
        let mut li = LockIn::new(LSB_16G_MPS2);
        li.set_mark(mark);
        li.set_sensor_period(crate::drive::timeline::nominal_period_q16((odr_hz * 1000.0) as u32));
        let period = 50_000.0 / odr_hz;
        let mut out = std::vec::Vec::new();
        for k in 0..20_000u64 {
            let t_samples = 100.0 + 3.7 + k as f64 * period;
            let t = (t_samples * 65536.0) as u64;
            let phi = mark.phase_at(t) as f64 / 2f64.powi(32) * core::f64::consts::TAU;
            let th = theta_deg.to_radians();
            let x = amp * (phi + th).sin()
                + h2 * amp * (2.0 * phi + 1.0).sin()
                + h2 / 2.0 * amp * (3.0 * phi + 2.0).sin()
                + dc;
            if let Some(e) = li.push(x.round() as i16, t) {
                out.push(e);
            }
        }
        out
    }

    #[test]
    fn measures_amplitude_and_phase_with_dc_and_harmonics() {
        for (f, odr) in [
            (60_000, 3330.0),
            (180_000, 6660.0),
            (600_000, 3330.0),
            (2_000_000, 3330.0),
            (1_234_000, 6660.0),
        ] {
            let es = run(f, odr, 1000.0, 30.0, 0.1, 2048.0);
            assert!(es.len() > 10, "{f}: {} windows", es.len());
            let worst_a = es
                .iter()
                .map(|e| {
                    (e.accel_mmps2() as f64 / (1000.0 * LSB_16G_MPS2 as f64 * 1000.0) - 1.0).abs()
                })
                .fold(0.0, f64::max);
            let worst_p =
                es.iter().map(|e| (e.phase_deg() as f64 - 30.0).abs()).fold(0.0, f64::max);
            std::println!(
                "lock-in {} Hz @ {odr} S/s, 10 % 2nd + 5 % 3rd harmonic, 1 g DC: amplitude error {:.3} %, phase error {:.3}°",
                f as f64 / 1000.0,
                worst_a * 100.0,
                worst_p
            );
            assert!(worst_a < 0.01, "{f}: amplitude error {worst_a}");
            assert!(worst_p < 0.5, "{f}: phase error {worst_p}");
        }
    }

    #[test]
    fn exact_alias_to_dc_is_refused() {
        // 3330 Hz drive sampled at 3330 S/s: every sample sees the same phase.
        let es = run(3_330_000, 3330.0, 1000.0, 0.0, 0.0, 0.0);
        assert!(es.is_empty());
    }

    #[test]
    fn windows_are_whole_cycles_of_at_least_the_minimum() {
        for f in [1_000u32, 60_000, 180_000, 600_000, 2_000_000] {
            let w = window_len(tuning_word(f), MIN_WINDOW_SAMPLES) as f64 / 65536.0;
            let cycles = w * tuning_word(f) as f64 / 2f64.powi(32);
            assert!(
                (cycles - cycles.round()).abs() < 1e-6 && w >= 250.0 - 1e-6,
                "{f}: {w} {cycles}"
            );
            assert!(w < 250.0 + 50_000_000.0 / f as f64, "{f}: {w}");
        }
        let mut li = LockIn::new(1.0);
        assert_eq!(li.push(5, dac_time(10)), None); // no mark yet
        li.set_mark(PhaseMark { sample: 0, phase: 0, tuning_word: 0 });
        assert_eq!(li.window(), 0);
    }

    #[test]
    fn phase_wire_form_is_in_range() {
        let e = Estimate {
            in_phase: -1.0,
            quadrature: -0.0,
            dc: 0.0,
            samples: 3,
            end: 0,
            lsb_mps2: 1.0,
        };
        let m = e.measurement();
        assert!(m.phase_mdeg > -180_000 && m.phase_mdeg <= 180_000, "{m:?}");
        assert_eq!(m.accel_mmps2, 1000);
    }
}
