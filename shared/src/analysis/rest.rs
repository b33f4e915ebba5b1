//! Rest orientations of a planar part at a straight node: balance offset, turn function
//! t(θ), exact roots with stable/unstable classification, alignment function a(θ).
//!
//! Conventions: the node is the plate's y-axis (d = x). Orientation θ turns
//! the part, as drawn in its file, counter-clockwise about its centroid c. For each θ the
//! part is translated along x by the *balance offset* s (position of c) until the force
//! F = ∫ f_x dA vanishes; then `t(θ) = M`, the moment about c. t > 0 turns the part
//! counter-clockwise. A root where t goes from + to − (increasing θ) is stable.
//!
//! Method, all in Q31.32 ([`crate::analysis::fx`]):
//! 1. Normalise: subtract the bounding-box centre and shift by a power of two (exact) so the
//!    part lies within (−½, ½)²; subtract the centroid. Results are scale-free (the sine
//!    wavelength is scaled by the same power of two).
//! 2. One *pass* over the edges at (θ, s) rotates each vertex, splits edges at the node and
//!    sums the exact piece integrals of [`crate::analysis::field::piece`]: it yields F, ∂F/∂s and M in
//!    O(n), with no clipped polygon stored.
//! 3. Balance: safeguarded Newton on s within [−R, R] (R = the part's radius about c), F is
//!    decreasing in s; started from the extrapolation of the previous samples.
//! 4. Sample t at [`SAMPLES`] equally spaced angles over the field's period (180° when the
//!    gains are equal: t(θ + 180°) = t(θ), else 360°), then refine every sign change by the
//!    Illinois method down to a few binary-angle units (≈ 10⁻⁶°).
//!
//! Cost: O(n) per pass, about `SAMPLES · 2 + roots · 20` passes per analysis.

use heapless::Vec;

use crate::analysis::field::{Field, FieldKind, Law, PieceSums, piece};
use crate::analysis::fx::{self, Bam, Fx, HALF_TURN};
use crate::analysis::geometry::{self, Pt};

/// Turn-function samples per field period before root refinement.
pub const SAMPLES: usize = 128;
/// Most rest orientations (stable + unstable, over 360°) an analysis can hold.
pub const MAX_RESTS: usize = 64;
/// Newton tolerance on the balance offset (normalised units, ≈ 1.5·10⁻⁸).
const OFFSET_TOL: Fx = Fx(1 << 6);
/// Root refinement stops when the bracket is this many binary-angle units wide.
const ROOT_TOL: u64 = 16;

/// Why a part or field cannot be analysed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnalysisError {
    /// No rings at all.
    NoOutline,
    /// A ring has fewer than three vertices.
    TooFewVertices {
        /// Ring index (0 = outline).
        ring: usize,
    },
    /// The outline is not counter-clockwise or a hole is not clockwise (or has zero area).
    Winding {
        /// Ring index (0 = outline).
        ring: usize,
    },
    /// The shape has no area.
    ZeroArea,
    /// The part spans more than 2²⁹ units: it would overflow the fixed-point range.
    TooLarge,
    /// A gain is zero or negative.
    BadGain,
    /// Sine field: the part is wider than the node-to-antinode distance allows (2R > w).
    WavelengthTooShort,
    /// More rest orientations than [`MAX_RESTS`].
    TooManyRests,
    /// The centroid lies outside the part's bounding box: rings that cross, or a hole outside
    /// the outline (a valid part's centroid is inside its convex hull).
    CentroidOutside,
}

impl core::fmt::Display for AnalysisError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            AnalysisError::NoOutline => write!(f, "no outline"),
            AnalysisError::TooFewVertices { ring } => {
                write!(f, "ring {ring} has fewer than 3 vertices")
            }
            AnalysisError::Winding { ring: 0 } => {
                write!(f, "the outline is not counter-clockwise (or has no area)")
            }
            AnalysisError::Winding { ring } => {
                write!(f, "hole {ring} is not clockwise (or has no area)")
            }
            AnalysisError::ZeroArea => write!(f, "the part has no area"),
            AnalysisError::TooLarge => write!(f, "the part spans more than 2^29 mm"),
            AnalysisError::BadGain => write!(f, "a gain is zero or negative"),
            AnalysisError::WavelengthTooShort => {
                write!(f, "the wavelength is shorter than the part's diameter")
            }
            AnalysisError::TooManyRests => write!(f, "more than {MAX_RESTS} rest orientations"),
            AnalysisError::CentroidOutside => write!(
                f,
                "the centroid lies outside the part's bounding box (crossing rings, or a hole \
                 outside the outline)"
            ),
        }
    }
}

/// A rest orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rest {
    /// Orientation θ (binary angle).
    pub angle: Bam,
    /// Stable (t goes from + to −), otherwise unstable.
    pub stable: bool,
}

/// Result of [`Analyzer::analyze`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Analysis {
    /// All rest orientations over 360°, sorted by angle.
    pub rests: Vec<Rest, MAX_RESTS>,
    /// Every orientation is at rest (|t| negligible everywhere); `rests` is then empty.
    pub neutral: bool,
    /// Symmetry order m: the rest pattern repeats every 360°/m (for a neutral part, the
    /// field's own order: 2 for equal gains, else 1).
    pub order: u32,
}

impl Analysis {
    /// Period of the rest pattern in binary-angle units (2³² / order).
    pub fn period(&self) -> u64 {
        (1u64 << 32) / self.order as u64
    }
    /// The stable orientation reached from `theta`, given the sign of t(θ) there
    /// (counter-clockwise to the next stable rest when t > 0, clockwise when t < 0; a root
    /// maps to itself). Neutral parts stay where they are.
    pub fn align(&self, theta: Bam, t_sign: i32) -> Bam {
        let stable = || self.rests.iter().filter(|r| r.stable);
        if t_sign == 0 || stable().next().is_none() {
            return theta;
        }
        // Distance to each stable rest, counter-clockwise (t > 0) or clockwise (t < 0).
        let dist = |r: &Rest| {
            if t_sign > 0 { r.angle.wrapping_sub(theta) } else { theta.wrapping_sub(r.angle) }
        };
        stable().min_by_key(|r| dist(r)).map_or(theta, |r| r.angle)
    }
}

/// Force, its derivative along x, and moment at one pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ForceMoment {
    /// F (x component; normalised units).
    pub force: Fx,
    /// ∂F/∂s.
    pub dforce: Fx,
    /// M about the centroid (counter-clockwise positive).
    pub moment: Fx,
}

/// A balanced pose at one orientation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Balance {
    /// Balance offset s: x of the centroid (normalised units) where F = 0.
    pub offset: Fx,
    /// t(θ) = M at that offset (normalised units).
    pub turn: Fx,
}

/// A part prepared for analysis in one field.
#[derive(Debug, Clone)]
pub struct Analyzer<'a> {
    rings: &'a [&'a [Pt]],
    origin: Pt,
    shift: i32,
    centroid: Pt,
    area: Fx,
    radius: Fx,
    law: Law,
    k_left: Fx,
    k_right: Fx,
    symmetric: bool,
}

/// Bounding-box centre of the part, and the largest shift that brings it within (−½, ½)².
fn normalisation(rings: &[&[Pt]]) -> Result<(Pt, i32), AnalysisError> {
    let (mut lo, mut hi) = (rings[0][0], rings[0][0]);
    for p in rings.iter().flat_map(|r| r.iter()) {
        lo = Pt::new(lo.x.min(p.x), lo.y.min(p.y));
        hi = Pt::new(hi.x.max(p.x), hi.y.max(p.y));
    }
    let limit = Fx::from_int(1 << 29);
    if (hi.x.half() - lo.x.half()) > limit || (hi.y.half() - lo.y.half()) > limit {
        return Err(AnalysisError::TooLarge);
    }
    let origin = Pt::new(lo.x.half() + hi.x.half(), lo.y.half() + hi.y.half());
    let extent = (hi.x - origin.x).max(origin.x - lo.x).max(hi.y - origin.y).max(origin.y - lo.y);
    if extent <= Fx::ZERO {
        return Err(AnalysisError::ZeroArea);
    }
    // Largest shift with extent · 2^shift < ½.
    let bits = 64 - extent.raw().leading_zeros() as i32;
    let shift = 31 - bits;
    Ok((origin, shift))
}

impl<'a> Analyzer<'a> {
    /// Prepares a part: `rings[0]` is the outline (counter-clockwise), the others holes
    /// (clockwise), coordinates in mm. Validity of the polygon itself (simple, holes inside)
    /// is the importer's job; this checks what the maths needs.
    pub fn new(rings: &'a [&'a [Pt]], field: Field) -> Result<Self, AnalysisError> {
        if rings.is_empty() {
            return Err(AnalysisError::NoOutline);
        }
        for (i, r) in rings.iter().enumerate() {
            if r.len() < 3 {
                return Err(AnalysisError::TooFewVertices { ring: i });
            }
        }
        let (origin, shift) = normalisation(rings)?;
        let mut me = Analyzer {
            rings,
            origin,
            shift,
            centroid: Pt::default(),
            area: Fx::ZERO,
            radius: Fx::ZERO,
            law: Law::Sign,
            k_left: Fx::ONE,
            k_right: Fx::ONE,
            symmetric: true,
        };
        me.measure()?;
        me.apply_field(field)?;
        Ok(me)
    }

    /// Winding and moments in normalised coordinates: area, centroid and radius of the part.
    fn measure(&mut self) -> Result<(), AnalysisError> {
        let mut total = geometry::Moments::default();
        for (i, r) in self.rings.iter().enumerate() {
            let m = geometry::edge_moments(
                geometry::edges(r).map(|(a, b)| (self.to_box(a), self.to_box(b))),
            );
            if (i == 0) != (m.area > Fx::ZERO) || m.area.is_zero() {
                return Err(AnalysisError::Winding { ring: i });
            }
            total = total + m;
        }
        if total.area <= Fx::ZERO {
            return Err(AnalysisError::ZeroArea);
        }
        self.area = total.area;
        self.centroid = total.centroid().ok_or(AnalysisError::ZeroArea)?;
        // The box is (−½, ½)²; a centroid beyond it means crossing rings, and its distance
        // would overflow the products below.
        let c = self.centroid;
        if c.x < -Fx::HALF || c.x > Fx::HALF || c.y < -Fx::HALF || c.y > Fx::HALF {
            return Err(AnalysisError::CentroidOutside);
        }
        let mut r2 = Fx::ZERO;
        for p in self.rings.iter().flat_map(|r| r.iter()) {
            let q = self.normalized(*p);
            r2 = r2.max(q.x * q.x + q.y * q.y);
        }
        self.radius = r2.sqrt() + Fx(16);
        Ok(())
    }

    /// The field in normalised form: gains relative to the larger one, the wavelength in the
    /// normalised box's units.
    fn apply_field(&mut self, field: Field) -> Result<(), AnalysisError> {
        if field.gain_left <= Fx::ZERO || field.gain_right <= Fx::ZERO {
            return Err(AnalysisError::BadGain);
        }
        let kmax = field.gain_left.max(field.gain_right);
        self.k_left = field.gain_left / kmax;
        self.k_right = field.gain_right / kmax;
        self.symmetric = field.is_symmetric();
        self.law = match field.kind {
            FieldKind::Sign => Law::Sign,
            FieldKind::Linear => Law::Linear,
            FieldKind::Sine { wavelength } => {
                if wavelength <= Fx::ZERO {
                    return Err(AnalysisError::WavelengthTooShort);
                }
                let w = if self.shift >= 0 {
                    // Saturate: a wavelength beyond the range is "infinite" for this part.
                    let max_w = Fx::from_int(1 << 24).shl(-self.shift.min(24));
                    wavelength.min(max_w).shl(self.shift)
                } else {
                    wavelength.shl(self.shift)
                };
                if w < self.radius + self.radius {
                    return Err(AnalysisError::WavelengthTooShort);
                }
                Law::Sine { a: Fx::PI / w }
            }
        };
        Ok(())
    }

    /// Bounding-box-centred, scaled coordinates of an input point.
    #[inline]
    fn to_box(&self, p: Pt) -> Pt {
        Pt::new((p.x - self.origin.x).shl(self.shift), (p.y - self.origin.y).shl(self.shift))
    }

    /// Normalised coordinates of an input point: relative to the centroid, scaled by
    /// 2^[`Self::shift`].
    #[inline]
    pub fn normalized(&self, p: Pt) -> Pt {
        let q = self.to_box(p);
        Pt::new(q.x - self.centroid.x, q.y - self.centroid.y)
    }

    /// The power of two that scales mm to normalised units (normalised = mm · 2^shift).
    pub fn shift(&self) -> i32 {
        self.shift
    }

    /// The centroid in the input units (mm).
    pub fn centroid_mm(&self) -> Pt {
        Pt::new(
            self.origin.x + self.centroid.x.shl(-self.shift),
            self.origin.y + self.centroid.y.shl(-self.shift),
        )
    }

    /// Area in normalised units.
    pub fn area(&self) -> Fx {
        self.area
    }

    /// Radius about the centroid (normalised units, rounded up slightly).
    pub fn radius(&self) -> Fx {
        self.radius
    }

    /// Right- and left-side piece sums at orientation `theta`, centroid at x = `s`.
    pub fn side_sums(&self, theta: Bam, s: Fx) -> (PieceSums, PieceSums) {
        let (sn, cs) = fx::sincos(theta);
        let mut right = PieceSums::default();
        let mut left = PieceSums::default();
        let law = self.law;
        for ring in self.rings {
            let rot = |p: Pt| {
                let q = self.normalized(p);
                (cs * q.x - sn * q.y + s, sn * q.x + cs * q.y)
            };
            let (mut x0, mut y0) = rot(ring[ring.len() - 1]);
            for &p in ring.iter() {
                let (x1, y1) = rot(p);
                if x0 >= Fx::ZERO && x1 >= Fx::ZERO {
                    right.add(piece(law, x0, y0, x1, y1));
                } else if x0 <= Fx::ZERO && x1 <= Fx::ZERO {
                    left.add(piece(law, x0, y0, x1, y1));
                } else {
                    // Crosses the node strictly inside the edge.
                    let t = x0 / (x0 - x1);
                    let yc = y0 + t * (y1 - y0);
                    let a = piece(law, x0, y0, Fx::ZERO, yc);
                    let b = piece(law, Fx::ZERO, yc, x1, y1);
                    if x0 > Fx::ZERO {
                        right.add(a);
                        left.add(b);
                    } else {
                        left.add(a);
                        right.add(b);
                    }
                }
                (x0, y0) = (x1, y1);
            }
        }
        (right, left)
    }

    /// Force, ∂F/∂s and moment at orientation `theta`, centroid at x = `s`.
    pub fn force_moment(&self, theta: Bam, s: Fx) -> ForceMoment {
        let (r, l) = self.side_sums(theta, s);
        // Sign law: g = 1 was integrated, the left side's true g is −1.
        let kl = if self.law == Law::Sign { -self.k_left } else { self.k_left };
        ForceMoment {
            force: -(self.k_right * r.p) - kl * l.p,
            dforce: -(self.k_right * r.d) - kl * l.d,
            moment: self.k_right * r.q + kl * l.q,
        }
    }

    /// Balance offset and turn function at `theta`; `guess` is a starting offset.
    pub fn balance(&self, theta: Bam, guess: Fx) -> Balance {
        let (mut lo, mut hi) = (-self.radius, self.radius);
        let mut s = guess.max(lo).min(hi);
        let mut last = Balance { offset: s, turn: Fx::ZERO };
        for _ in 0..80 {
            let fm = self.force_moment(theta, s);
            last = Balance { offset: s, turn: fm.moment };
            if fm.force.is_zero() {
                break;
            }
            if fm.force > Fx::ZERO {
                lo = s;
            } else {
                hi = s;
            }
            let newton = if fm.dforce < Fx::ZERO { fm.force.checked_div(fm.dforce) } else { None };
            // A huge step (∂F/∂s ≈ 0) leaves the bracket anyway: bisect instead of overflowing.
            let next = match newton.and_then(|step| s.0.checked_sub(step.0)).map(Fx) {
                Some(n) if n > lo && n < hi => n,
                _ => Fx((lo.raw() >> 1) + (hi.raw() >> 1)),
            };
            if (next - s).abs() <= OFFSET_TOL || hi - lo <= OFFSET_TOL {
                break;
            }
            s = next;
        }
        last
    }

    /// t(θ) (balance found from scratch).
    pub fn turn(&self, theta: Bam) -> Fx {
        self.balance(theta, Fx::ZERO).turn
    }

    /// The stable orientation a part starting at `theta` settles in (see [`Analysis::align`]).
    pub fn align(&self, analysis: &Analysis, theta: Bam) -> Bam {
        analysis.align(theta, self.turn(theta).signum())
    }

    /// |t| at or below this counts as zero everywhere (neutral part): 2⁻²⁰ of the natural
    /// moment scale (A·R for the sign law, A·R² otherwise).
    pub fn neutral_threshold(&self) -> Fx {
        let scale = match self.law {
            Law::Sign => self.area * self.radius,
            _ => self.area * self.radius * self.radius,
        };
        scale.shl(-20).max(Fx(64))
    }

    /// Refines a sign change of t between `a` and `a + width` (t = `ta`, `tb` there).
    fn refine(&self, a: Bam, width: u64, ta: Fx, tb: Fx, guess: Fx) -> Bam {
        let (mut x0, mut f0, mut x1, mut f1) = (0u64, ta.raw(), width, tb.raw());
        let mut s = guess;
        let mut side = 0i8;
        for _ in 0..60 {
            if x1 - x0 <= ROOT_TOL {
                break;
            }
            let span = (x1 - x0) as i128;
            let x = (x0 + secant(span, f0, f1) as u64).clamp(x0 + 1, x1 - 1);
            let b = self.balance(a.wrapping_add(x as u32), s);
            s = b.offset;
            let fx = b.turn.raw();
            if fx == 0 {
                return a.wrapping_add(x as u32);
            }
            if (fx > 0) == (f0 > 0) {
                x0 = x;
                f0 = fx;
                if side == -1 {
                    f1 /= 2;
                }
                side = -1;
            } else {
                x1 = x;
                f1 = fx;
                if side == 1 {
                    f0 /= 2;
                }
                side = 1;
            }
        }
        a.wrapping_add((x0 + secant((x1 - x0) as i128, f0, f1) as u64) as u32)
    }

    /// All rest orientations over 360°.
    pub fn analyze(&self) -> Result<Analysis, AnalysisError> {
        let period: u64 = if self.symmetric { 1 << 31 } else { 1 << 32 };
        let step = period / SAMPLES as u64;
        let mut t = [Fx::ZERO; SAMPLES];
        let mut off = [Fx::ZERO; SAMPLES];
        let mut max_abs = Fx::ZERO;
        for i in 0..SAMPLES {
            let guess = match i {
                0 => Fx::ZERO,
                1 => off[0],
                _ => off[i - 1] + off[i - 1] - off[i - 2],
            };
            let b = self.balance((i as u64 * step) as u32, guess);
            t[i] = b.turn;
            off[i] = b.offset;
            max_abs = max_abs.max(b.turn.abs());
        }
        let field_order = if self.symmetric { 2 } else { 1 };
        if max_abs <= self.neutral_threshold() {
            return Ok(Analysis { rests: Vec::new(), neutral: true, order: field_order });
        }
        let mut rests: Vec<Rest, MAX_RESTS> = Vec::new();
        let mut push = |angle: Bam, stable: bool| -> Result<(), AnalysisError> {
            rests.push(Rest { angle, stable }).map_err(|_| AnalysisError::TooManyRests)?;
            if field_order == 2 {
                rests
                    .push(Rest { angle: angle.wrapping_add(HALF_TURN), stable })
                    .map_err(|_| AnalysisError::TooManyRests)?;
            }
            Ok(())
        };
        let at = |i: usize| (i % SAMPLES) as u64 * step;
        for i in 0..SAMPLES {
            let j = (i + 1) % SAMPLES;
            let prev = t[(i + SAMPLES - 1) % SAMPLES];
            if t[i].is_zero() {
                if prev.is_zero() {
                    continue; // inside a run of exact zeros, handled at its start
                }
                let mut end = i;
                while t[(end + 1) % SAMPLES].is_zero() {
                    end += 1;
                }
                let next = t[(end + 1) % SAMPLES];
                let mid = at(i) + (end - i) as u64 * step / 2;
                push(mid as u32, prev > Fx::ZERO && next < Fx::ZERO)?;
            } else if !t[j].is_zero() && (t[i] > Fx::ZERO) != (t[j] > Fx::ZERO) {
                let root = self.refine(at(i) as u32, step, t[i], t[j], off[i]);
                push(root, t[i] > Fx::ZERO)?;
            }
        }
        rests.sort_unstable_by_key(|r| r.angle);
        let order = symmetry_order(&rests).max(field_order);
        Ok(Analysis { rests, neutral: false, order })
    }
}

/// Where the secant through `(0, f0)` and `(span, f1)` crosses zero, within `[0, span]`.
/// The Illinois halving can take both ends' values down to 0 (|f| = 1 halves to 0): then, or
/// whenever the ends are equal, the midpoint (the old form divided by zero there). The ends
/// never have the same strict sign, so the clamp changes no other result: it only makes that
/// plain to the reader and to the fuzzer.
fn secant(span: i128, f0: i64, f1: i64) -> i128 {
    let den = f0 as i128 - f1 as i128;
    if den == 0 { span / 2 } else { (span * f0 as i128 / den).clamp(0, span) }
}

/// Largest m such that turning the rest pattern by 360°/m maps it onto itself (same kinds),
/// within 0.01°.
fn symmetry_order(rests: &[Rest]) -> u32 {
    let tol: u32 = (1u64 << 32).div_ceil(36_000) as u32;
    let ns = rests.iter().filter(|r| r.stable).count();
    let nu = rests.len() - ns;
    for m in (2..=ns.max(1)).rev() {
        if !ns.is_multiple_of(m) || !nu.is_multiple_of(m) {
            continue;
        }
        let shift = ((1u64 << 32) / m as u64) as u32;
        let ok = rests.iter().all(|r| {
            let target = r.angle.wrapping_add(shift);
            rests.iter().any(|o| {
                let d = o.angle.wrapping_sub(target);
                o.stable == r.stable && d.min(d.wrapping_neg()) <= tol
            })
        });
        if ok {
            return m as u32;
        }
    }
    1
}

#[cfg(test)]
mod tests;
