//! The f64 reference for the rest analysis of `chladni_shared::analysis::rest`, written independently
//! on purpose: explicit Sutherland–Hodgman clipping of every ring at the node, side
//! integrals by Gauss–Legendre quadrature of Green's boundary integrals (exact for the
//! polynomial laws, ~1e-15 for the sine law), balance by false position on a bracket, roots by dense
//! sampling (0.5°) over the full turn and bisection. Slow and simple; used by the tests to
//! check the fixed-point code (agreement within 0.05° on stable orientations).

use crate::model::angle::wrap_deg;
use crate::model::field::Law;
use crate::model::part::Part;

/// A straight-node field with a gain per side.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefField {
    /// Law.
    pub law: Law,
    /// Gain on x < 0.
    pub gain_left: f64,
    /// Gain on x > 0.
    pub gain_right: f64,
}

/// A rest orientation in degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RefRest {
    /// θ in [0, 360).
    pub deg: f64,
    /// Stable?
    pub stable: bool,
}

/// The reference analyser: the part relative to its centroid.
#[derive(Debug, Clone)]
pub struct Reference {
    rings: Vec<Vec<[f64; 2]>>,
    field: RefField,
    radius: f64,
    scale: f64,
}

/// 5-point Gauss–Legendre nodes and weights on [−1, 1].
pub(crate) const GL: [(f64, f64); 5] = [
    (0.0, 0.568_888_888_888_888_9),
    (-0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (0.538_469_310_105_683_1, 0.478_628_670_499_366_5),
    (-0.906_179_845_938_664, 0.236_926_885_056_189_08),
    (0.906_179_845_938_664, 0.236_926_885_056_189_08),
];

impl Reference {
    /// Prepares a validated part.
    pub fn new(part: &Part, field: RefField) -> Reference {
        let [cx, cy] = part.centroid();
        let a = part.area();
        let rings: Vec<Vec<[f64; 2]>> =
            part.rings().map(|r| r.iter().map(|p| [p[0] - cx, p[1] - cy]).collect()).collect();
        let radius = rings.iter().flatten().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
        let scale = match field.law {
            Law::Sign => a * radius,
            _ => a * radius * radius,
        } * field.gain_left.max(field.gain_right);
        Reference { rings, field, radius, scale }
    }

    /// g(x) up to a constant factor (the linear law without its length scale, which changes
    /// no rest orientation): the reference's own, independent of [`Law::g`].
    fn g(&self, x: f64) -> f64 {
        match self.field.law {
            Law::Sign => x.signum(),
            Law::Linear => x,
            Law::Sine { wavelength_mm: w } => (std::f64::consts::PI * x / w).sin(),
        }
    }

    /// H(x) = ∫₀ˣ g: closed form for the polynomial laws, 5-point Gauss on [0, x] for sine.
    fn big_h(&self, x: f64, side: f64) -> f64 {
        match self.field.law {
            Law::Sign => side * x,
            Law::Linear => 0.5 * x * x,
            Law::Sine { .. } => {
                GL.iter().map(|(v, wv)| wv * self.g(0.5 * x * (v + 1.0))).sum::<f64>() * 0.5 * x
            }
        }
    }

    /// F and M at orientation `deg`, centroid at x = `s`.
    pub fn force_moment(&self, deg: f64, s: f64) -> (f64, f64) {
        let (sn, cs) = deg.to_radians().sin_cos();
        let (mut force, mut moment) = (0.0, 0.0);
        for ring in &self.rings {
            let moved: Vec<[f64; 2]> =
                ring.iter().map(|p| [cs * p[0] - sn * p[1] + s, sn * p[0] + cs * p[1]]).collect();
            for (side, k) in [(1.0, self.field.gain_right), (-1.0, self.field.gain_left)] {
                let clipped = clip(&moved, side);
                // ∫∫ h dA = ∮ H dy with H(x) = ∫₀ˣ h: H by quadrature in x (inner), edge
                // integral by quadrature along the edge (outer).
                let n = clipped.len();
                for i in 0..n {
                    let (p, q) = (clipped[i], clipped[(i + 1) % n]);
                    let dy = q[1] - p[1];
                    if dy == 0.0 {
                        continue;
                    }
                    for (u, wu) in GL {
                        let t = 0.5 * (u + 1.0);
                        let (x, y) = (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]));
                        let big_h = self.big_h(x, side);
                        let f = -k * big_h; // force density integral contribution
                        force += f * wu * 0.5 * dy;
                        moment += -y * f * wu * 0.5 * dy;
                    }
                }
            }
        }
        (force, moment)
    }

    /// Balance offset and t(θ): F is decreasing in s, positive with the part wholly left of
    /// the node and negative wholly right of it, so the root is bracketed in ±R. Illinois
    /// false position on that bracket (a secant step, the end kept twice in a row has its
    /// value halved), down to 10⁻¹² R: a few tens of evaluations where plain bisection took
    /// sixty; the fixed-point code's own method is Newton on its exact ∂F/∂s.
    pub fn balance(&self, deg: f64) -> (f64, f64) {
        let (mut lo, mut hi) = (-self.radius * 1.001, self.radius * 1.001);
        let (mut f_lo, mut f_hi) = (self.force_moment(deg, lo).0, self.force_moment(deg, hi).0);
        let tol = 1e-12 * self.radius;
        let mut kept = 0i8; // which end was kept last: −1 lo, 1 hi
        let mut s = 0.5 * (lo + hi);
        for _ in 0..200 {
            let secant = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
            s = if secant > lo && secant < hi { secant } else { 0.5 * (lo + hi) };
            let f = self.force_moment(deg, s).0;
            if f == 0.0 {
                break;
            }
            if f > 0.0 {
                (lo, f_lo) = (s, f);
                if kept == 1 {
                    f_hi *= 0.5;
                }
                kept = 1;
            } else {
                (hi, f_hi) = (s, f);
                if kept == -1 {
                    f_lo *= 0.5;
                }
                kept = -1;
            }
            if hi - lo <= tol {
                s = 0.5 * (lo + hi);
                break;
            }
        }
        (s, self.force_moment(deg, s).1)
    }

    /// t(θ).
    pub fn turn(&self, deg: f64) -> f64 {
        self.balance(deg).1
    }

    /// Rest orientations over 360° (empty and `true` when neutral).
    pub fn rests(&self) -> (Vec<RefRest>, bool) {
        let n = 720;
        let t: Vec<f64> = (0..n).map(|i| self.turn(i as f64 * 360.0 / n as f64)).collect();
        if t.iter().all(|v| v.abs() <= 1e-6 * self.scale) {
            return (Vec::new(), true);
        }
        let mut out = Vec::new();
        for i in 0..n {
            let (a, b) = (t[i], t[(i + 1) % n]);
            if (a > 0.0) != (b > 0.0) {
                let (mut lo, mut hi) = (i as f64 * 0.5, (i + 1) as f64 * 0.5);
                for _ in 0..32 {
                    let mid = 0.5 * (lo + hi);
                    if (self.turn(mid) > 0.0) == (a > 0.0) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                out.push(RefRest { deg: wrap_deg(0.5 * (lo + hi)), stable: a > 0.0 });
            }
        }
        out.sort_by(|p, q| p.deg.total_cmp(&q.deg));
        (out, false)
    }
}

/// Sutherland–Hodgman clip of a ring to `side·x ≥ 0`.
fn clip(ring: &[[f64; 2]], side: f64) -> Vec<[f64; 2]> {
    let mut out = Vec::with_capacity(ring.len() + 4);
    let n = ring.len();
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        let (da, db) = (side * a[0], side * b[0]);
        if da >= 0.0 {
            out.push(a);
        }
        if (da >= 0.0) != (db >= 0.0) && da != 0.0 && db != 0.0 {
            let t = da / (da - db);
            out.push([0.0, a[1] + t * (b[1] - a[1])]);
        }
    }
    out
}
