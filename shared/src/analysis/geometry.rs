//! Polygon geometry in fixed point: areas, centroids, first and second moments, clipping.
//!
//! A *shape* is a slice of rings: ring 0 is the outline, counter-clockwise; the others are
//! holes, clockwise. With that winding every integral below is a plain sum over all rings
//! (holes contribute negatively by their winding). Coordinates are [`Fx`]; callers keep them
//! O(1) (see [`crate::analysis::rest`], which normalises parts by a power of two) so that products of
//! up to four coordinates stay well inside Q31.32.

use crate::analysis::fx::Fx;

/// A point (or vector) in the plane.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Pt {
    /// x.
    pub x: Fx,
    /// y.
    pub y: Fx,
}

impl Pt {
    /// A point from its coordinates.
    pub const fn new(x: Fx, y: Fx) -> Pt {
        Pt { x, y }
    }
    /// A point from integer coordinates.
    pub const fn int(x: i32, y: i32) -> Pt {
        Pt { x: Fx::from_int(x), y: Fx::from_int(y) }
    }
}

/// Area and moments of a region: `area = ∫dA`, `sx = ∫x dA`, `sxx = ∫x² dA`, `sxy = ∫xy dA`, …
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Moments {
    /// ∫ dA (signed by winding for a single ring).
    pub area: Fx,
    /// ∫ x dA.
    pub sx: Fx,
    /// ∫ y dA.
    pub sy: Fx,
    /// ∫ x² dA.
    pub sxx: Fx,
    /// ∫ y² dA.
    pub syy: Fx,
    /// ∫ xy dA.
    pub sxy: Fx,
}

impl core::ops::Add for Moments {
    type Output = Moments;
    /// Sum of two regions' moments.
    fn add(self, o: Moments) -> Moments {
        Moments {
            area: self.area + o.area,
            sx: self.sx + o.sx,
            sy: self.sy + o.sy,
            sxx: self.sxx + o.sxx,
            syy: self.syy + o.syy,
            sxy: self.sxy + o.sxy,
        }
    }
}

impl Moments {
    /// Centroid `(sx/area, sy/area)`; `None` for zero area.
    pub fn centroid(&self) -> Option<Pt> {
        Some(Pt::new(self.sx.checked_div(self.area)?, self.sy.checked_div(self.area)?))
    }
}

/// Edges of a ring as (start, end) pairs, closing the ring.
pub fn edges(ring: &[Pt]) -> impl Iterator<Item = (Pt, Pt)> + '_ {
    let n = ring.len();
    (0..n).map(move |i| (ring[i], ring[(i + 1) % n]))
}

/// Signed area of a ring (positive when counter-clockwise), shoelace formula.
pub fn ring_area(ring: &[Pt]) -> Fx {
    let mut twice = Fx::ZERO;
    for (a, b) in edges(ring) {
        twice += a.x * b.y - b.x * a.y;
    }
    twice.half()
}

/// Area and moments of one ring (signed by its winding), exact polygon formulas up to
/// the rounding of each product.
pub fn ring_moments(ring: &[Pt]) -> Moments {
    edge_moments(edges(ring))
}

/// Area and moments of the region bounded by closed chains of edges (Green's theorem):
/// [`ring_moments`] of mapped points without storing them.
pub fn edge_moments(edges: impl Iterator<Item = (Pt, Pt)>) -> Moments {
    // Accumulate 2A, 6 Sx, 6 Sy, 12 Sxx, 12 Syy, 24 Sxy; divide once at the end.
    let (mut a2, mut sx6, mut sy6, mut sxx12, mut syy12, mut sxy24) =
        (Fx::ZERO, Fx::ZERO, Fx::ZERO, Fx::ZERO, Fx::ZERO, Fx::ZERO);
    for (p, q) in edges {
        let cr = p.x * q.y - q.x * p.y;
        a2 += cr;
        sx6 += (p.x + q.x) * cr;
        sy6 += (p.y + q.y) * cr;
        sxx12 += (p.x * p.x + p.x * q.x + q.x * q.x) * cr;
        syy12 += (p.y * p.y + p.y * q.y + q.y * q.y) * cr;
        let two = Fx::from_int(2);
        sxy24 += (p.x * q.y + two * p.x * p.y + two * q.x * q.y + q.x * p.y) * cr;
    }
    Moments {
        area: a2.half(),
        sx: sx6.div_int(6),
        sy: sy6.div_int(6),
        sxx: sxx12.div_int(12),
        syy: syy12.div_int(12),
        sxy: sxy24.div_int(24),
    }
}

/// Moments of a shape (outline counter-clockwise, holes clockwise).
pub fn shape_moments(rings: &[&[Pt]]) -> Moments {
    rings.iter().fold(Moments::default(), |m, r| m + ring_moments(r))
}

/// The closed half-plane `nx·x + ny·y ≥ d`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HalfPlane {
    /// Normal, x.
    pub nx: Fx,
    /// Normal, y.
    pub ny: Fx,
    /// Offset.
    pub d: Fx,
}

impl HalfPlane {
    /// Signed value `nx·x + ny·y − d` (≥ 0 inside).
    pub fn eval(&self, p: Pt) -> Fx {
        self.nx * p.x + self.ny * p.y - self.d
    }
}

/// The output buffer of [`clip_ring`] was too small.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BufferTooSmall;

/// Clips one ring by a half-plane (Sutherland–Hodgman), writing the result into `out` and
/// returning its length. The result keeps the winding; for a non-convex ring it may contain
/// zero-width bridges along the cut line, which do not change any integral. Clip every ring
/// of a shape separately: the moments of the pieces add up to those of the clipped shape.
/// `out` needs at most `2 · ring.len()` points (fewer in practice).
pub fn clip_ring(ring: &[Pt], hp: HalfPlane, out: &mut [Pt]) -> Result<usize, BufferTooSmall> {
    let mut n = 0;
    let mut push = |p: Pt, n: &mut usize| -> Result<(), BufferTooSmall> {
        *out.get_mut(*n).ok_or(BufferTooSmall)? = p;
        *n += 1;
        Ok(())
    };
    for (a, b) in edges(ring) {
        let (da, db) = (hp.eval(a), hp.eval(b));
        let (ina, inb) = (da >= Fx::ZERO, db >= Fx::ZERO);
        if ina {
            push(a, &mut n)?;
        }
        if ina != inb && da != Fx::ZERO && db != Fx::ZERO {
            // Crossing strictly inside the edge: a + t (b − a), t = da / (da − db).
            let t = da / (da - db);
            push(Pt::new(a.x + t * (b.x - a.x), a.y + t * (b.y - a.y)), &mut n)?;
        }
    }
    Ok(n)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(x: Fx) -> f64 {
        x.raw() as f64 / 4294967296.0
    }

    #[test]
    fn rectangle_moments() {
        // [0,2]×[0,1], counter-clockwise.
        let r = [Pt::int(0, 0), Pt::int(2, 0), Pt::int(2, 1), Pt::int(0, 1)];
        let m = ring_moments(&r);
        assert_eq!(m.area, Fx::from_int(2));
        assert!((f(m.sx) - 2.0).abs() < 1e-9);
        assert!((f(m.sy) - 1.0).abs() < 1e-9);
        assert!((f(m.sxx) - 8.0 / 3.0).abs() < 1e-9);
        assert!((f(m.syy) - 2.0 / 3.0).abs() < 1e-9);
        assert!((f(m.sxy) - 1.0).abs() < 1e-9);
        let c = m.centroid().unwrap();
        assert_eq!(c, Pt::new(Fx::ONE, Fx::HALF));
        // Clockwise: negative.
        let mut rev = r;
        rev.reverse();
        assert_eq!(ring_area(&rev), -Fx::from_int(2));
    }

    #[test]
    fn clip_square_by_diagonal_half_plane() {
        let r = [Pt::int(0, 0), Pt::int(2, 0), Pt::int(2, 2), Pt::int(0, 2)];
        // x ≥ 1: right half.
        let hp = HalfPlane { nx: Fx::ONE, ny: Fx::ZERO, d: Fx::ONE };
        let mut out = [Pt::default(); 8];
        let n = clip_ring(&r, hp, &mut out).unwrap();
        assert_eq!(ring_area(&out[..n]), Fx::from_int(2));
        // x + y ≥ 2: the upper-right triangle, area 2.
        let hp = HalfPlane { nx: Fx::ONE, ny: Fx::ONE, d: Fx::from_int(2) };
        let n = clip_ring(&r, hp, &mut out).unwrap();
        assert_eq!(ring_area(&out[..n]), Fx::from_int(2));
        let mut tiny = [Pt::default(); 2];
        assert_eq!(clip_ring(&r, hp, &mut tiny), Err(BufferTooSmall));
    }
}
