//! Samples of a rest analysis (the fixed-point core's [`Analyzer`] and [`Analysis`]): the turn
//! function t(θ) and the alignment function a(θ) sampled evenly over a turn, and the part posed
//! at its first stable rest. One sampling behind `analyze --samples`, `--csv` and `--plot`.

use chladni_shared::analysis::fx::{Bam, Fx};
use chladni_shared::analysis::rest::{Analysis, Analyzer};
use chladni_shared::icd::units::{bam_from_deg, deg_from_bam};
use serde::Serialize;

use crate::model::part::Part;

/// One sample of a rest analysis: the turn function t(θ) (normalised so that max |t| = 1 over
/// the samples; 0 everywhere for a neutral part) and the alignment function a(θ), the stable
/// orientation a part starting at θ turns to.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, serde::Deserialize)]
pub struct TurnSample {
    /// Orientation θ (degrees, [0, 360]).
    pub theta_deg: f64,
    /// t(θ) / max |t|: > 0 turns counter-clockwise.
    pub turn: f64,
    /// a(θ) (degrees, [0, 360)).
    pub alignment_deg: f64,
}

/// Binary angle → degrees in [0, 360), rounded to 1e-6° for display.
pub fn deg(a: Bam) -> f64 {
    let d = (deg_from_bam(a) * 1e6).round() / 1e6;
    if d >= 360.0 { 0.0 } else { d }
}

/// The node offset `s` (the analyzer's scaled fixed point) in mm.
pub fn offset_mm(an: &Analyzer<'_>, s: Fx) -> f64 {
    Fx::to_f64(s) * (-an.shift() as f64).exp2()
}

/// `n` (≥ 2) samples of t(θ) (normalised to max |t| = 1, 0 for a neutral part) and a(θ), θ
/// evenly from 0° to 360°: the one sampling behind `--samples`, `--csv` and the plot. The
/// scale is the largest |t| over these samples and every 0.5°, so it does not depend on n.
pub fn turn_samples(an: &Analyzer<'_>, a: &Analysis, n: usize) -> Vec<TurnSample> {
    let raw = |n: usize| {
        let mut guess = Fx::ZERO;
        (0..n)
            .map(|i| {
                let d = i as f64 * 360.0 / (n - 1) as f64;
                let b = an.balance(bam_from_deg(d), guess);
                guess = b.offset;
                let alignment_deg = deg(a.align(bam_from_deg(d), b.turn.signum()));
                TurnSample { theta_deg: d, turn: Fx::to_f64(b.turn), alignment_deg }
            })
            .collect::<Vec<_>>()
    };
    let peak = |s: &[TurnSample]| s.iter().fold(0.0f64, |m, p| m.max(p.turn.abs()));
    let mut out = raw(n.max(2));
    let max = peak(&out).max(if n == 721 { 0.0 } else { peak(&raw(721)) });
    for p in &mut out {
        p.turn = if max > 0.0 && !a.neutral { p.turn / max } else { 0.0 };
    }
    out
}

/// The part's rings posed at its first stable rest (orientation 0 when it has none) on the
/// node, plate frame (mm), and that orientation (degrees).
pub fn rest_pose(part: &Part, an: &Analyzer<'_>, a: &Analysis) -> (Vec<Vec<[f64; 2]>>, f64) {
    let pose = a.rests.iter().find(|r| r.stable).map_or(0, |r| r.angle);
    let s = offset_mm(an, an.balance(pose, Fx::ZERO).offset);
    let c = an.centroid_mm();
    let (cx, cy) = (Fx::to_f64(c.x), Fx::to_f64(c.y));
    let (sn, cs) = (deg(pose)).to_radians().sin_cos();
    let rings = part
        .rings()
        .map(|r| {
            r.iter()
                .map(|p| {
                    let (x, y) = (p[0] - cx, p[1] - cy);
                    [cs * x - sn * y + s, sn * x + cs * y]
                })
                .collect()
        })
        .collect();
    (rings, deg(pose))
}
