//! Frequency sweeps seen from the host: the request built from user units and checked before
//! any connection ([`sweep_request`]), the measured points in SI units ([`SweepSample`]), the
//! resonances found in them ([`find_resonances`]) and the CSV form ([`to_csv`]).
//!
//! The controller steps its drive over geometrically spaced frequencies and measures the
//! plate's response at each (docs/protocol.md, `Sweep`); it reports raw lock-in values and
//! nothing more. Finding resonances is analysis, so it lives here, tested on synthetic
//! second-order responses:
//! - a resonance is a local maximum of the amplitude that stands out of the noise: its
//!   prominence (height over its base, the higher of the lowest points on either side before a
//!   higher point; a side that runs to the sweep's end does not bound it) is at least 3 dB and at least [`NOISE_FACTOR`] times the point-to-point noise;
//! - its frequency is the vertex of the parabola through the three points around the maximum,
//!   in log-frequency (the points are equally spaced there);
//! - its Q is f₀/(f₂−f₁), f₁ and f₂ the half-power (amplitude/√2, −3 dB) crossings, each
//!   interpolated linearly in log-frequency between the two points around it; `None` when a
//!   side has no crossing within the sweep (or meets a higher point first).

use chladni_shared::icd::link::{Sweep, SweepError, SweepPoint};
use chladni_shared::icd::plan::DeviceLimits;
use chladni_shared::icd::units::{AmplitudeError, FrequencyError, MilliDeg, MilliHz, MmPerS2, Q15};
use serde::Serialize;

/// A peak must stand this many times the point-to-point noise over its base.
pub const NOISE_FACTOR: f64 = 6.0;
/// ... and at least this ratio (3 dB) over its base.
const MIN_PROMINENCE_RATIO: f64 = std::f64::consts::SQRT_2;

/// Why a sweep was not started: each names the value and the range to give.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SweepInputError {
    /// `--from` or `--to` outside the drive's range.
    #[error("{flag}: {error}")]
    Frequency {
        /// The option.
        flag: &'static str,
        /// The conversion's refusal.
        error: FrequencyError,
    },
    /// The amplitude is not a fraction of full scale.
    #[error("--amplitude: {0}")]
    Amplitude(AmplitudeError),
    /// The sweep's shape (points, range order, dwell).
    #[error("{0}")]
    Shape(SweepError),
}

/// The `Sweep` request for a sweep given in user units (Hz, fraction of full scale, ms),
/// checked as the controller checks it ([`Sweep::check`], the drive's frequency range).
pub fn sweep_request(
    from_hz: f64,
    to_hz: f64,
    points: u16,
    amplitude: f64,
    dwell_ms: u32,
) -> Result<Sweep, SweepInputError> {
    let freq = |flag, hz| {
        MilliHz::from_hz_within(hz, &DeviceLimits::DEFAULT)
            .map_err(|error| SweepInputError::Frequency { flag, error })
    };
    let sweep = Sweep {
        from_mhz: freq("--from", from_hz)?.0,
        to_mhz: freq("--to", to_hz)?.0,
        points,
        amplitude_q15: Q15::from_fraction(amplitude).map_err(SweepInputError::Amplitude)?.0,
        dwell_ms,
    };
    sweep.check().map_err(SweepInputError::Shape)?;
    Ok(sweep)
}

/// The time a sweep takes, ms (points × dwell; the controller adds little).
pub fn sweep_ms(sweep: &Sweep) -> u64 {
    u64::from(sweep.points) * u64::from(sweep.dwell_ms)
}

/// One sweep point in SI units (`None`: the sensor gave no measurement there).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SweepSample {
    /// Drive frequency, Hz.
    pub freq_hz: f64,
    /// Acceleration amplitude at the drive frequency, m/s².
    pub accel_mps2: Option<f64>,
    /// Phase of the acceleration against the drive, degrees.
    pub phase_deg: Option<f64>,
}

impl From<&SweepPoint> for SweepSample {
    fn from(p: &SweepPoint) -> Self {
        SweepSample {
            freq_hz: MilliHz(p.freq_mhz).to_hz(),
            accel_mps2: p.measured.map(|m| MmPerS2(m.accel_mmps2).to_mps2()),
            phase_deg: p.measured.map(|m| MilliDeg(m.phase_mdeg).to_deg()),
        }
    }
}

/// A resonance found in a sweep.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resonance {
    /// Peak frequency (parabolic refinement in log-frequency), Hz.
    pub freq_hz: f64,
    /// Quality factor from the half-power bandwidth; `None` when a crossing is missing.
    pub q: Option<f64>,
    /// Peak amplitude (the parabola's vertex), m/s².
    #[serde(skip)]
    pub accel_mps2: f64,
}

/// The measured points of `samples`, as (ln f, amplitude).
fn measured(samples: &[SweepSample]) -> Vec<(f64, f64)> {
    samples
        .iter()
        .filter(|s| s.freq_hz > 0.0)
        .filter_map(|s| s.accel_mps2.map(|a| (s.freq_hz.ln(), a)))
        .collect()
}

/// Point-to-point noise: the median distance of each point from the mean of its neighbours.
fn noise(pts: &[(f64, f64)]) -> f64 {
    let mut d: Vec<f64> =
        pts.windows(3).map(|w| (w[1].1 - (w[0].1 + w[2].1) / 2.0).abs()).collect();
    if d.is_empty() {
        return 0.0;
    }
    d.sort_by(f64::total_cmp);
    d[d.len() / 2]
}

/// The base of peak `i`: on each side, the lowest point before a higher one. A side that runs
/// to the sweep's end without a higher point does not bound the peak (it may go on outside
/// the sweep), so the base is the higher of the bounded sides' lows, or, for the sweep's
/// highest point, the lowest of both.
fn base(pts: &[(f64, f64)], i: usize) -> f64 {
    let peak = pts[i].1;
    // (lowest point, whether a higher point ended the walk)
    let side = |range: &mut dyn Iterator<Item = usize>| {
        let mut low = peak;
        for j in range {
            if pts[j].1 > peak {
                return (low, true);
            }
            low = low.min(pts[j].1);
        }
        (low, false)
    };
    let (left, right) = (side(&mut (0..i).rev()), side(&mut (i + 1..pts.len())));
    match (left, right) {
        ((l, true), (r, true)) => l.max(r),
        ((l, true), _) => l,
        (_, (r, true)) => r,
        ((l, false), (r, false)) => l.min(r),
    }
}

/// Vertex of the parabola through three points: (x, y), clamped to the outer two x.
fn vertex(p: [(f64, f64); 3]) -> (f64, f64) {
    let [(x0, y0), (x1, y1), (x2, y2)] = p;
    let den = (x1 - x0) * (y1 - y2) - (x1 - x2) * (y1 - y0);
    if den.abs() < f64::EPSILON * y1.abs().max(1e-300) {
        return (x1, y1);
    }
    let num = (x1 - x0).powi(2) * (y1 - y2) - (x1 - x2).powi(2) * (y1 - y0);
    let x = (x1 - 0.5 * num / den).clamp(x0, x2);
    // Lagrange form of the same parabola, evaluated at the vertex.
    let l = |xa: f64, xb: f64, xc: f64| (x - xb) * (x - xc) / ((xa - xb) * (xa - xc));
    let y = y0 * l(x0, x1, x2) + y1 * l(x1, x0, x2) + y2 * l(x2, x0, x1);
    (x, y.max(y1))
}

/// Where the amplitude first falls below `level` walking from peak `i` by `step` (±1), as
/// ln f interpolated between the two points around the crossing; `None` at the sweep's end or
/// at a point above `peak` first.
fn crossing(pts: &[(f64, f64)], i: usize, step: isize, level: f64, peak: f64) -> Option<f64> {
    let mut j = i;
    loop {
        let k = j.checked_add_signed(step).filter(|&k| k < pts.len())?;
        let (a, b) = (pts[j], pts[k]);
        if b.1 > peak {
            return None;
        }
        if b.1 < level {
            let t = (a.1 - level) / (a.1 - b.1);
            return Some(a.0 + t * (b.0 - a.0));
        }
        j = k;
    }
}

/// The resonances in a sweep, by frequency (see the module docs for the method).
pub fn find_resonances(samples: &[SweepSample]) -> Vec<Resonance> {
    let pts = measured(samples);
    let noise = noise(&pts);
    let mut found = Vec::new();
    for i in 1..pts.len().saturating_sub(1) {
        let a = pts[i].1;
        if !(a > pts[i - 1].1 && a >= pts[i + 1].1) {
            continue;
        }
        let base = base(&pts, i);
        if a < base * MIN_PROMINENCE_RATIO || a - base <= NOISE_FACTOR * noise {
            continue;
        }
        let (x, peak) = vertex([pts[i - 1], pts[i], pts[i + 1]]);
        let level = peak / std::f64::consts::SQRT_2;
        let f0 = x.exp();
        let lo = crossing(&pts, i, -1, level, peak);
        let hi = crossing(&pts, i, 1, level, peak);
        let q = lo.zip(hi).map(|(lo, hi)| f0 / (hi.exp() - lo.exp()));
        found.push(Resonance { freq_hz: f0, q, accel_mps2: peak });
    }
    found
}

/// The points as CSV: `freq_hz,accel_mps2,phase_deg`, empty fields where nothing was measured.
pub fn to_csv(samples: &[SweepSample]) -> String {
    let mut out = String::from("freq_hz,accel_mps2,phase_deg\n");
    let opt = |v: Option<f64>, digits: usize| v.map_or(String::new(), |v| format!("{v:.digits$}"));
    for s in samples {
        out.push_str(&format!(
            "{:.3},{},{}\n",
            s.freq_hz,
            opt(s.accel_mps2, 3),
            opt(s.phase_deg, 3)
        ));
    }
    out
}

#[cfg(test)]
mod tests;
