//! Resonances from a frequency sweep: local maxima of the response amplitude, the peak
//! refined by a parabola, and Q from the half-power points. Used by the host's Bode plot and
//! the tests.
//!
//! - **Peak**: a point higher than both neighbours. Its frequency is refined by the vertex of
//!   the parabola through the three points in (log f, dB). Log frequency because sweeps are
//!   usually logarithmic (even spacing there) and a resonance is symmetric in log f
//!   (|H(f₀·r)| = |H(f₀/r)| for the displacement response of a lightly damped mode); dB because
//!   near the peak 1/|H|² is a parabola in f, so the log-amplitude is close to one too, much
//!   closer than the linear amplitude over the few points a sweep has.
//! - **Q**: f₀ / (f₊ − f₋), with f± where the amplitude falls to peak/√2 (−3 dB) on either side,
//!   interpolated linearly in (log f, dB) between the two sweep points that straddle it. If a
//!   side never falls that far within the sweep, Q is `None`.

/// One point of a sweep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepPoint {
    /// Drive frequency, Hz.
    pub freq_hz: f32,
    /// Response amplitude (any linear unit, e.g. m/s² per unit drive).
    pub amplitude: f32,
    /// Phase, degrees (carried along, not used for the peak).
    pub phase_deg: f32,
}

/// A resonance found in a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Resonance {
    /// Index of the highest sweep point.
    pub index: usize,
    /// Refined peak frequency, Hz.
    pub freq_hz: f32,
    /// Refined peak amplitude.
    pub amplitude: f32,
    /// Quality factor from the −3 dB points, if both lie within the sweep.
    pub q: Option<f32>,
}

fn ln(x: f32) -> f32 {
    micromath::F32Ext::ln(x)
}

fn exp(x: f32) -> f32 {
    micromath::F32Ext::exp(x)
}

fn db(a: f32) -> f32 {
    20.0 * micromath::F32Ext::log10(a.max(1e-30))
}

/// The resonances of `sweep` (sorted by frequency, at least 3 points), strongest first, at most
/// `out.len()` of them; returns how many were written.
pub fn find_resonances(sweep: &[SweepPoint], out: &mut [Resonance]) -> usize {
    let mut n = 0;
    for i in 1..sweep.len().saturating_sub(1) {
        let (a, b, c) = (sweep[i - 1], sweep[i], sweep[i + 1]);
        if !(b.amplitude > a.amplitude && b.amplitude >= c.amplitude) {
            continue;
        }
        let r = refine(sweep, i);
        // Keep the strongest `out.len()`: replace the weakest if this one is stronger.
        if n < out.len() {
            out[n] = r;
            n += 1;
        } else if let Some(w) = out.iter_mut().min_by(|x, y| x.amplitude.total_cmp(&y.amplitude))
            && w.amplitude < r.amplitude
        {
            *w = r;
        }
    }
    out[..n].sort_unstable_by(|x, y| y.amplitude.total_cmp(&x.amplitude));
    n
}

/// The parabola vertex through points i−1, i, i+1 in (ln f, dB), and Q.
fn refine(s: &[SweepPoint], i: usize) -> Resonance {
    let (x0, x1, x2) = (ln(s[i - 1].freq_hz), ln(s[i].freq_hz), ln(s[i + 1].freq_hz));
    let (y0, y1, y2) = (db(s[i - 1].amplitude), db(s[i].amplitude), db(s[i + 1].amplitude));
    // Vertex of the interpolating parabola (divided differences).
    let d01 = (y1 - y0) / (x1 - x0);
    let d12 = (y2 - y1) / (x2 - x1);
    let a = (d12 - d01) / (x2 - x0);
    let (xv, yv) = if a < 0.0 {
        let b = d01 - a * (x0 + x1);
        let xv = (-b / (2.0 * a)).clamp(x0, x2);
        (xv, y0 + (xv - x0) * d01 + a * (xv - x0) * (xv - x1))
    } else {
        (x1, y1)
    };
    let f0 = exp(xv);
    let half = yv - 3.010_3;
    let lo = crossing(s, i, half, false);
    let hi = crossing(s, i, half, true);
    let q = match (lo, hi) {
        (Some(l), Some(h)) if h > l => Some(f0 / (h - l)),
        _ => None,
    };
    Resonance { index: i, freq_hz: f0, amplitude: micromath::F32Ext::powf(10.0, yv / 20.0), q }
}

/// Where the response first falls below `level` dB walking from `i` up (or down), in Hz.
fn crossing(s: &[SweepPoint], i: usize, level: f32, up: bool) -> Option<f32> {
    let mut k = i;
    loop {
        let next = if up { k + 1 } else { k.checked_sub(1)? };
        let p = *s.get(next)?;
        let (ya, yb) = (db(s[k].amplitude), db(p.amplitude));
        if yb <= level {
            let t = (ya - level) / (ya - yb);
            let (xa, xb) = (ln(s[k].freq_hz), ln(p.freq_hz));
            return Some(exp(xa + t * (xb - xa)));
        }
        k = next;
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::drive::dds::{Dds, gain_of_q15, tuning_word};
    use crate::drive::lockin::{LSB_16G_MPS2, LockIn};
    use crate::drive::plant::{Plant, PlantParams};
    use crate::drive::sensor_sim::{SensorSim, SensorSimConfig};
    use crate::drive::timeline::{PhaseMark, SensorTimebase};
    use std::vec::Vec;

    /// The steady response of the simulated plant at `f_hz`, measured through the sensor
    /// and the lock-in (asynchronous clock, noise), as the firmware would sweep it.
    fn measure(f_hz: f32) -> SweepPoint {
        let freq_mhz = (f_hz * 1000.0) as u32;
        let mut plant = Plant::new(PlantParams::DEFAULT);
        let mut dds = Dds::new(tuning_word(freq_mhz));
        let cfg = SensorSimConfig::DEFAULT;
        let mut sensor = SensorSim::new(cfg);
        let mut tb = SensorTimebase::new(cfg.odr_mhz);
        let mut li = LockIn::new(LSB_16G_MPS2);
        li.set_sensor_period(tb.period_q16());
        li.set_mark(PhaseMark { sample: 0, phase: 0, tuning_word: dds.tuning_word });
        let mut codes = [0u16; 250];
        let (mut amp, mut ph, mut n) = (0f32, 0f32, 0f32);
        for b in 0..160u64 {
            dds.fill_steady(&mut codes, gain_of_q15(3000));
            let mut batch = Vec::new();
            for &c in &codes {
                sensor.push(plant.step(c), |x| batch.push(x));
            }
            if let Some(newest) = tb.push_batch(batch.len(), (b + 1) * 250) {
                for (i, &x) in batch.iter().enumerate() {
                    let t = tb.sample_time(newest, batch.len(), i);
                    if let (Some(e), true) = (li.push(x, t), b >= 100) {
                        amp += e.accel_mps2();
                        ph += e.phase_deg();
                        n += 1.0;
                    }
                }
            }
        }
        SweepPoint { freq_hz: f_hz, amplitude: amp / n, phase_deg: ph / n }
    }

    #[test]
    fn finds_the_plants_resonance_and_q() {
        // 40 points, logarithmic from 100 to 320 Hz (≈ 3 % apart).
        let sweep: Vec<SweepPoint> =
            (0..40).map(|k| measure(100.0 * (3.2f32).powf(k as f32 / 39.0))).collect();
        let mut out = [Resonance { index: 0, freq_hz: 0.0, amplitude: 0.0, q: None }; 4];
        let n = find_resonances(&sweep, &mut out);
        assert_eq!(n, 1, "{:?}", &out[..n]);
        let r = out[0];
        let q = r.q.expect("both half-power points in the sweep");
        std::println!(
            "resonance: f0 {:.2} Hz (plant 180, {:+.2} %), Q {q:.2} (1/(2ζ) = 10), peak {:.1} m/s²",
            r.freq_hz,
            (r.freq_hz / 180.0 - 1.0) * 100.0,
            r.amplitude
        );
        assert!((r.freq_hz / 180.0 - 1.0).abs() < 0.01, "f0 {}", r.freq_hz);
        // The acceleration response's half-power width is that of a ζ = 0.05 mode, Q ≈ 10.
        assert!((q - 10.0).abs() < 1.0, "Q {q}");
        // The phase goes through +90° (acceleration leads the force) at resonance.
        assert!((sweep[r.index].phase_deg - 90.0).abs() < 20.0, "{}", sweep[r.index].phase_deg);
    }

    #[test]
    fn no_peak_in_a_monotonic_sweep() {
        let sweep: Vec<SweepPoint> = (1..10)
            .map(|k| SweepPoint { freq_hz: k as f32, amplitude: k as f32, phase_deg: 0.0 })
            .collect();
        let mut out = [Resonance { index: 0, freq_hz: 0.0, amplitude: 0.0, q: None }; 2];
        assert_eq!(find_resonances(&sweep, &mut out), 0);
        assert_eq!(find_resonances(&sweep[..2], &mut out), 0);
    }
}
