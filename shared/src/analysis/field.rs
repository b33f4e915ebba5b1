//! Force fields of a straight node, and their exact integrals over polygon pieces.
//!
//! The node is the plate's y-axis, `d = x`. The force per unit area is along
//! x, `f_x = −k(x)·g(x)`, with `k = gain_right` for x > 0 and `gain_left` for x < 0:
//! - sign:   g = sign x
//! - linear: g = x
//! - sine:   g = sin(πx/w)·(w/π), i.e. the field sin(πx/w) scaled by w/π so that it tends
//!   to the linear field as w → ∞ (a positive factor: rest orientations are unchanged).
//!
//! On one side of the node (x ≥ 0 or x ≤ 0) a region's integrals follow from Green's
//! theorem with `G(x) = ∫₀ˣ g`: `∫∫ g dA = ∮ G dy` and `∫∫ y g dA = ∮ y G dy`. Because
//! `G(0) = 0`, the part of the boundary that runs along the cut contributes nothing, so the
//! clipped region's integrals are sums over the boundary *pieces* lying on that side:
//! clipping needs no buffer. [`piece`] gives the exact integral along one straight piece.

use crate::analysis::fx::{self, Fx};

/// Which field law.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FieldKind {
    /// Constant magnitude, pointing at the node (paper eq. 5).
    Sign,
    /// Proportional to the distance from the node (paper §5.2).
    Linear,
    /// `sin(π d / w)`: zero at the node and at the antinode, `w` (mm) away.
    Sine {
        /// Distance from the node to the next antinode, in the part's units (mm).
        wavelength: Fx,
    },
}

/// A straight-node field with separate gains on the two sides of the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Field {
    /// The law.
    pub kind: FieldKind,
    /// Gain k₋ on the left (x < 0) side; must be > 0.
    pub gain_left: Fx,
    /// Gain k₊ on the right (x > 0) side; must be > 0.
    pub gain_right: Fx,
}

impl Field {
    /// Equal unit gains.
    pub const fn symmetric(kind: FieldKind) -> Field {
        Field { kind, gain_left: Fx::ONE, gain_right: Fx::ONE }
    }
    /// Is `t(θ + 180°) = t(θ)`? True when both gains are equal (all laws are odd in x).
    pub fn is_symmetric(&self) -> bool {
        self.gain_left == self.gain_right
    }
}

/// The law in normalised units, ready for [`piece`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Law {
    /// g = sign x.
    Sign,
    /// g = x.
    Linear,
    /// g = sin(a x)/a with `a = π / w`.
    Sine {
        /// π / w in normalised units.
        a: Fx,
    },
}

/// Integrals along one straight boundary piece from `(x0, y0)` to `(x1, y1)` that lies on
/// one side of the node.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PieceSums {
    /// `∫ G(x) dy` (contribution to `∫∫ g dA`; for the sign law, to the area).
    pub p: Fx,
    /// `∫ g(x) dy` (contribution to the derivative of `p` with respect to a shift in x).
    pub d: Fx,
    /// `∫ y G(x) dy` (contribution to `∫∫ y g dA`).
    pub q: Fx,
}

impl PieceSums {
    /// Accumulates.
    #[inline]
    pub fn add(&mut self, o: PieceSums) {
        self.p += o.p;
        self.d += o.d;
        self.q += o.q;
    }
}

/// `ω(v) = (1 − sinc v)/v²` (1/6 at 0).
fn omega(v: Fx) -> Fx {
    if v.abs() <= Fx::HALF {
        let v2 = v * v;
        let mut p = Fx::ONE - v2 * Fx::ratio(1, 110);
        p = Fx::ONE - v2 * Fx::ratio(1, 72) * p;
        p = Fx::ONE - v2 * Fx::ratio(1, 42) * p;
        p = Fx::ONE - v2 * Fx::ratio(1, 20) * p;
        Fx::ratio(1, 6) * p
    } else {
        (Fx::ONE - fx::sinc(v)) / (v * v)
    }
}

/// `ψ(v) = j₁(v)/v = (sin v − v cos v)/v³` (1/3 at 0).
fn psi(v: Fx) -> Fx {
    if v.abs() <= Fx::HALF {
        let v2 = v * v;
        let mut p = Fx::ONE - v2 * Fx::ratio(1, 88);
        p = Fx::ONE - v2 * Fx::ratio(1, 54) * p;
        p = Fx::ONE - v2 * Fx::ratio(1, 28) * p;
        p = Fx::ONE - v2 * Fx::ratio(1, 10) * p;
        Fx::ratio(1, 3) * p
    } else {
        fx::j1(v) / v
    }
}

/// Exact integrals along a straight piece. With the midpoint `(m, q)` and half-extents
/// `(h, k)` (so `x = m + h u`, `y = q + k u`, `u ∈ [−1, 1]`):
/// - sign:   `p = 2k m`, `d = 2k`, `q = 2k (m q + h k / 3)`
/// - linear: `p = k (m² + h²/3)`, `d = 2k m`, `q = k (q (m² + h²/3) + 2 k m h / 3)`
/// - sine:   `p = 2k B`, `d = 2k m sinc(am) sinc(ah)`, `q = 2k (q B + k m h sinc(am) ψ(ah))`
///   with `B = (m²/2) sinc²(am/2) + cos(am) h² ω(ah)` — written with `sinc`, `ω`, `ψ` so
///   nothing cancels for small `a` or short pieces.
#[inline]
pub fn piece(law: Law, x0: Fx, y0: Fx, x1: Fx, y1: Fx) -> PieceSums {
    let m = (x0 + x1).half();
    let h = (x1 - x0).half();
    let q = (y0 + y1).half();
    let k2 = y1 - y0; // 2k
    let k = k2.half();
    match law {
        Law::Sign => PieceSums { p: k2 * m, d: k2, q: k2 * (m * q + h * k * Fx::ratio(1, 3)) },
        Law::Linear => {
            let b = m * m + h * h * Fx::ratio(1, 3);
            PieceSums { p: k * b, d: k2 * m, q: k * (q * b + (k * m * h) * Fx::ratio(2, 3)) }
        }
        Law::Sine { a } => {
            let am = a * m;
            let ah = a * h;
            let (_, cos_am) = fx::sincos_rad(am);
            let sinc_am = fx::sinc(am);
            let sinc_half = fx::sinc(am.half());
            let sinc_ah = fx::sinc(ah);
            let b = (m * m).half() * sinc_half * sinc_half + cos_am * (h * h) * omega(ah);
            PieceSums {
                p: k2 * b,
                d: k2 * m * sinc_am * sinc_ah,
                q: k2 * (q * b + k * m * h * sinc_am * psi(ah)),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    fn f(x: Fx) -> f64 {
        x.raw() as f64 / 4294967296.0
    }
    fn q(x: f64) -> Fx {
        Fx((x * 4294967296.0).round() as i64)
    }

    /// Gauss–Legendre (20-point composite) reference for ∫ G dy, ∫ g dy, ∫ y G dy.
    fn numeric(a: f64, x0: f64, y0: f64, x1: f64, y1: f64) -> (f64, f64, f64) {
        let g = |x: f64| (a * x).sin() / a;
        let gg = |x: f64| (1.0 - (a * x).cos()) / (a * a);
        let n = 2000;
        let (mut p, mut d, mut qq) = (0.0, 0.0, 0.0);
        for i in 0..n {
            // midpoint rule, fine enough for 1e-7
            let u = (i as f64 + 0.5) / n as f64;
            let x = x0 + (x1 - x0) * u;
            let y = y0 + (y1 - y0) * u;
            let dy = (y1 - y0) / n as f64;
            p += gg(x) * dy;
            d += g(x) * dy;
            qq += y * gg(x) * dy;
        }
        (p, d, qq)
    }

    #[test]
    fn sine_piece_matches_quadrature() {
        let cases = [
            (1.0, 0.1, -0.3, 0.7, 0.4),
            (2.5, 0.0, 0.5, 0.6, -0.2),
            (0.01, -0.4, 0.1, -0.2, 0.9),
            (3.0, -0.9, -0.2, -0.1, 0.3),
            (1.5, 0.3, 0.3, 0.3, -0.6),
        ];
        for (a, x0, y0, x1, y1) in cases {
            let s = piece(Law::Sine { a: q(a) }, q(x0), q(y0), q(x1), q(y1));
            let (p, d, qq) = numeric(a, x0, y0, x1, y1);
            assert!((f(s.p) - p).abs() < 1e-6, "p {a} {} vs {p}", f(s.p));
            assert!((f(s.d) - d).abs() < 1e-6, "d {a} {} vs {d}", f(s.d));
            assert!((f(s.q) - qq).abs() < 1e-6, "q {a} {} vs {qq}", f(s.q));
        }
    }

    #[test]
    fn small_wavenumber_sine_tends_to_linear() {
        let (x0, y0, x1, y1) = (q(0.2), q(-0.5), q(0.8), q(0.3));
        let s = piece(Law::Sine { a: q(1e-4) }, x0, y0, x1, y1);
        let l = piece(Law::Linear, x0, y0, x1, y1);
        assert!((s.p - l.p).abs() < Fx(100));
        assert!((s.d - l.d).abs() < Fx(100));
        assert!((s.q - l.q).abs() < Fx(100));
    }
}
