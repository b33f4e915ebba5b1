//! Polygon and polyline helpers in f64 mm, shared by parts, the analysis, the planner, the
//! simulator and the plots: signed area, area centroid of a set of rings, point in ring,
//! orientation and segment tests, the nearest point on a segment, bounding boxes. A ring is a closed polygon given by its
//! vertices (the closing edge from the last vertex back to the first is implied).

/// Nearest point to `p` on the segment `a`–`b` and its distance (a point if `a == b`).
pub(crate) fn segment_foot(p: [f64; 2], a: [f64; 2], b: [f64; 2]) -> ([f64; 2], f64) {
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let len2 = dx * dx + dy * dy;
    let t = if len2 > 0.0 {
        (((p[0] - a[0]) * dx + (p[1] - a[1]) * dy) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let f = [a[0] + t * dx, a[1] + t * dy];
    (f, (p[0] - f[0]).hypot(p[1] - f[1]))
}

/// Signed area (counter-clockwise positive, mm²).
pub(crate) fn signed_area(ring: &[[f64; 2]]) -> f64 {
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            a[0] * b[1] - b[0] * a[1]
        })
        .sum::<f64>()
        / 2.0
}

/// Area and centroid of a region given by its rings (outline and holes in opposite windings,
/// as a validated part has them): shoelace sums, one pass.
pub fn area_centroid<'a>(rings: impl IntoIterator<Item = &'a [[f64; 2]]>) -> (f64, [f64; 2]) {
    let (mut a, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for r in rings {
        for (i, &p) in r.iter().enumerate() {
            let q = r[(i + 1) % r.len()];
            let c = p[0] * q[1] - q[0] * p[1];
            a += c / 2.0;
            sx += (p[0] + q[0]) * c / 6.0;
            sy += (p[1] + q[1]) * c / 6.0;
        }
    }
    (a, [sx / a, sy / a])
}

/// Centroid of a region given by its rings (see [`area_centroid`]).
pub fn centroid<'a>(rings: impl IntoIterator<Item = &'a [[f64; 2]]>) -> [f64; 2] {
    area_centroid(rings).1
}

/// Point strictly inside a ring (even–odd rule).
// Inlined into its callers' code: the photo renderer (chladni-media, optimised in debug
// builds) asks it for every pixel.
#[inline]
pub fn inside(p: [f64; 2], ring: &[[f64; 2]]) -> bool {
    let n = ring.len();
    let mut c = false;
    for i in 0..n {
        let (a, b) = (ring[i], ring[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                c = !c;
            }
        }
    }
    c
}

/// Twice the signed area of triangle abc (positive when a, b, c turn counter-clockwise).
pub fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// `p` lies in the bounding box of segment ab (for collinear points: on the segment).
fn on_segment(a: [f64; 2], b: [f64; 2], p: [f64; 2]) -> bool {
    p[0] >= a[0].min(b[0])
        && p[0] <= a[0].max(b[0])
        && p[1] >= a[1].min(b[1])
        && p[1] <= a[1].max(b[1])
}

/// Do closed segments ab and cd share a point?
pub fn segments_meet(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (orient(c, d, a), orient(c, d, b));
    let (d3, d4) = (orient(a, b, c), orient(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on_segment(c, d, a))
        || (d2 == 0.0 && on_segment(c, d, b))
        || (d3 == 0.0 && on_segment(a, b, c))
        || (d4 == 0.0 && on_segment(a, b, d))
}

/// Bounding box `(min, max)` of points (infinite and inverted when there are none).
pub fn bounds<'a>(points: impl IntoIterator<Item = &'a [f64; 2]>) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in points {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn square_with_a_hole() {
        let outer = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]];
        let hole = [[1.0, 1.0], [1.0, 2.0], [2.0, 2.0], [2.0, 1.0]];
        assert_eq!(signed_area(&outer), 16.0);
        assert_eq!(signed_area(&hole), -1.0);
        let c = centroid([&outer[..], &hole[..]]);
        assert!((c[0] - (16.0 * 2.0 - 1.5) / 15.0).abs() < 1e-12, "{c:?}");
        assert!(inside([3.0, 3.0], &outer) && !inside([5.0, 1.0], &outer));
        assert!(segments_meet([0.0, 0.0], [2.0, 2.0], [0.0, 2.0], [2.0, 0.0]));
        assert!(!segments_meet([0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [1.0, 1.0]));
        assert_eq!(bounds(&outer), ([0.0, 0.0], [4.0, 4.0]));
    }
}
