//! A part's contact geometry (docs/motion.md, "Contacts between parts"): its area cut into
//! convex pieces, and the contacts and overlaps of two placed parts, from `parry2d-f64`.
//!
//! The pieces: the outline with its holes bridged in (each hole joined to the outline by a
//! cut, so the polygon is one ring), ear-clipped into triangles, and the triangles merged
//! into convex polygons by Hertel–Mehlhorn (parry's `hertel_mehlhorn`; at most four times
//! the fewest pieces). The cut is exact: the pieces cover the part's area and nothing else.
//! Contacts between two parts are parry's contact manifolds between their pieces (up to two
//! points per pair of pieces, so an edge lying on an edge is held at both ends).
//!
//! Units: mm, rad; pieces are relative to the part's centroid, like [`Body::rings`].

use parry2d_f64::math::{Pose as PPose, Vector};
use parry2d_f64::query::ContactManifold;
use parry2d_f64::query::details::contact_manifold_pfm_pfm;
use parry2d_f64::shape::ConvexPolygon;
use parry2d_f64::transformation::hertel_mehlhorn;

use crate::model::pose::Pose;
use crate::motion::body::Body;

/// A part's area as convex pieces (relative to the centroid).
#[derive(Debug, Clone)]
pub struct Pieces {
    /// The convex pieces.
    pub convex: Vec<ConvexPolygon>,
    /// Each piece's bounding-circle centre (relative to the centroid) and radius (mm).
    pub circles: Vec<([f64; 2], f64)>,
}

/// One contact between two placed parts: the point (plate frame, mm), the unit normal from
/// the first part towards the second, and the signed distance (mm, negative: overlap).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PairContact {
    /// Contact point, midway between the two parts' surface points.
    pub point: [f64; 2],
    /// Unit normal from the first part to the second.
    pub normal: [f64; 2],
    /// Signed distance along the normal (negative when the parts overlap).
    pub dist: f64,
}

impl Pieces {
    /// The convex pieces of a body's area (outline minus holes).
    pub fn of(body: &Body) -> Pieces {
        let ring = bridged(&body.rings);
        let tris = ear_clip(&ring);
        let verts: Vec<Vector> = ring.iter().map(|p| Vector::new(p[0], p[1])).collect();
        let polys = hertel_mehlhorn(&verts, &tris);
        let mut convex = Vec::new();
        for poly in polys {
            if let Some(c) = ConvexPolygon::from_convex_polyline(poly) {
                convex.push(c);
            }
        }
        let circles = convex
            .iter()
            .map(|c| {
                let pts = c.points();
                let n = pts.len().max(1) as f64;
                let m = pts.iter().fold(Vector::ZERO, |a, p| a + *p) / n;
                let r = pts.iter().map(|p| (*p - m).length()).fold(0.0, f64::max);
                ([m.x, m.y], r)
            })
            .collect();
        Pieces { convex, circles }
    }
}

fn ppose(q: Pose) -> PPose {
    PPose::new(Vector::new(q.x, q.y), q.theta)
}

/// The contacts of two placed parts within `margin` (mm) of touching: every pair of pieces
/// whose bounding circles come that close, through parry's polygon contact manifolds.
pub fn contacts(a: &Pieces, qa: Pose, b: &Pieces, qb: Pose, margin: f64) -> Vec<PairContact> {
    let (pa, pb) = (ppose(qa), ppose(qb));
    let pab = pa.inv_mul(&pb);
    let mut out = Vec::new();
    for (i, ca) in a.convex.iter().enumerate() {
        let (oa, ra) = a.circles[i];
        let wa = pa.transform_point(Vector::new(oa[0], oa[1]));
        for (j, cb) in b.convex.iter().enumerate() {
            let (ob, rb) = b.circles[j];
            let wb = pb.transform_point(Vector::new(ob[0], ob[1]));
            if (wa - wb).length() > ra + rb + margin {
                continue;
            }
            let mut m: ContactManifold<(), ()> = ContactManifold::new();
            contact_manifold_pfm_pfm(&pab, ca, 0.0, None, cb, 0.0, None, margin, &mut m);
            let n = pa.rotation * m.local_n1;
            for c in &m.points {
                if c.dist > margin {
                    continue;
                }
                let p = 0.5 * (pa.transform_point(c.local_p1) + pb.transform_point(c.local_p2));
                out.push(PairContact { point: [p.x, p.y], normal: [n.x, n.y], dist: c.dist });
            }
        }
    }
    out
}

/// How deep two placed parts overlap (mm): the largest penetration of their contacts, 0 when
/// they are apart or just touch.
pub fn overlap(a: &Pieces, qa: Pose, b: &Pieces, qb: Pose) -> f64 {
    contacts(a, qa, b, qb, 0.0).iter().map(|c| -c.dist).fold(0.0, f64::max)
}

/// The outline with every hole joined in by a cut (a two-way edge) from the hole's
/// rightmost vertex to the nearest outline vertex it sees: one ring, counter-clockwise.
fn bridged(rings: &[Vec<[f64; 2]>]) -> Vec<[f64; 2]> {
    let mut ring = rings.first().cloned().unwrap_or_default();
    let mut holes: Vec<&Vec<[f64; 2]>> = rings.iter().skip(1).collect();
    // Rightmost holes first, so a later cut never crosses an earlier hole's area.
    holes.sort_by(|a, b| max_x(b).total_cmp(&max_x(a)));
    for (k, hole) in holes.iter().enumerate() {
        let Some(m) = (0..hole.len()).max_by(|&i, &j| hole[i][0].total_cmp(&hole[j][0])) else {
            continue;
        };
        let mp = hole[m];
        let others: Vec<&Vec<[f64; 2]>> = holes[k + 1..].to_vec();
        let visible = |i: usize| {
            let p = ring[i];
            let blocked_by = |r: &[[f64; 2]]| {
                (0..r.len()).any(|e| {
                    let (s, t) = (r[e], r[(e + 1) % r.len()]);
                    s != p && t != p && s != mp && t != mp && crosses(mp, p, s, t)
                })
            };
            !blocked_by(&ring) && !blocked_by(hole) && !others.iter().any(|h| blocked_by(h))
        };
        let d = |i: usize| (ring[i][0] - mp[0]).hypot(ring[i][1] - mp[1]);
        let mut order: Vec<usize> = (0..ring.len()).collect();
        order.sort_by(|&i, &j| d(i).total_cmp(&d(j)));
        let Some(&p) = order.iter().find(|&&i| visible(i)) else { continue };
        let mut joined = ring[..=p].to_vec();
        joined.extend((0..=hole.len()).map(|s| hole[(m + s) % hole.len()]));
        joined.extend_from_slice(&ring[p..]);
        ring = joined;
    }
    ring
}

fn max_x(r: &[[f64; 2]]) -> f64 {
    r.iter().map(|p| p[0]).fold(f64::NEG_INFINITY, f64::max)
}

fn cross(o: [f64; 2], a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Do the segments ab and cd cross (touching counts)?
fn crosses(a: [f64; 2], b: [f64; 2], c: [f64; 2], d: [f64; 2]) -> bool {
    let (d1, d2) = (cross(a, b, c), cross(a, b, d));
    let (d3, d4) = (cross(c, d, a), cross(c, d, b));
    d1 * d2 <= 0.0 && d3 * d4 <= 0.0 && !(d1 == 0.0 && d2 == 0.0)
}

/// Is p inside or on the triangle abc (counter-clockwise)?
fn in_triangle(p: [f64; 2], a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> bool {
    cross(a, b, p) >= 0.0 && cross(b, c, p) >= 0.0 && cross(c, a, p) >= 0.0
}

/// Ear clipping of a counter-clockwise ring (weakly simple: a cut's two copies of a vertex
/// are distinct indices): triangles as index triples, counter-clockwise.
fn ear_clip(ring: &[[f64; 2]]) -> Vec<[u32; 3]> {
    let mut idx: Vec<usize> = (0..ring.len()).collect();
    let mut tris = Vec::with_capacity(ring.len().saturating_sub(2));
    let scale = ring.iter().map(|p| p[0].abs().max(p[1].abs())).fold(1e-9, f64::max);
    let eps = 1e-12 * scale * scale;
    while idx.len() > 3 {
        let n = idx.len();
        let ear = (0..n).find(|&k| {
            let (a, b, c) = (ring[idx[(k + n - 1) % n]], ring[idx[k]], ring[idx[(k + 1) % n]]);
            cross(a, b, c) > eps
                && !idx.iter().any(|&v| {
                    let p = ring[v];
                    p != a && p != b && p != c && in_triangle(p, a, b, c)
                })
        });
        // A ring left with no ear is degenerate (collinear remains): drop its flattest vertex.
        let k = ear.unwrap_or_else(|| {
            (0..n)
                .min_by(|&i, &j| {
                    let area = |k: usize| {
                        cross(ring[idx[(k + n - 1) % n]], ring[idx[k]], ring[idx[(k + 1) % n]])
                            .abs()
                    };
                    area(i).total_cmp(&area(j))
                })
                .unwrap_or(0)
        });
        if ear.is_some() {
            tris.push([idx[(k + n - 1) % n] as u32, idx[k] as u32, idx[(k + 1) % n] as u32]);
        }
        idx.remove(k);
    }
    if idx.len() == 3 && cross(ring[idx[0]], ring[idx[1]], ring[idx[2]]) > eps {
        tris.push([idx[0] as u32, idx[1] as u32, idx[2] as u32]);
    }
    tris
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::geometry::signed_area;
    use crate::model::part::Part;

    fn plate_with_hole() -> Part {
        let outline = vec![[0.0, 0.0], [40.0, 0.0], [40.0, 30.0], [0.0, 30.0]];
        let hole: Vec<[f64; 2]> = (0..24)
            .map(|k| {
                let a = -(k as f64) * std::f64::consts::TAU / 24.0;
                [25.0 + 8.0 * a.cos(), 15.0 + 8.0 * a.sin()]
            })
            .collect();
        Part::new("h".into(), outline, vec![hole]).unwrap()
    }

    #[test]
    fn the_pieces_are_convex_and_cover_exactly_the_area_with_its_holes() {
        let l = Part::new(
            "l".into(),
            vec![[0.0, 0.0], [30.0, 0.0], [30.0, 8.0], [8.0, 8.0], [8.0, 25.0], [0.0, 25.0]],
            vec![],
        )
        .unwrap();
        for part in [l, plate_with_hole()] {
            let body = Body::new(&part);
            let pieces = Pieces::of(&body);
            let area: f64 = pieces
                .convex
                .iter()
                .map(|c| signed_area(&c.points().iter().map(|p| [p.x, p.y]).collect::<Vec<_>>()))
                .sum();
            assert!((area - body.area).abs() < 1e-9 * body.area, "{area} vs {}", body.area);
            assert!(pieces.convex.len() >= 2, "{}", pieces.convex.len());
            // The hole's centre is in no piece.
            let c = [25.0 - body.centroid[0], 15.0 - body.centroid[1]];
            if part.name == "h" {
                for p in &pieces.convex {
                    let pts: Vec<[f64; 2]> = p.points().iter().map(|p| [p.x, p.y]).collect();
                    assert!(!crate::model::geometry::inside(c, &pts));
                }
            }
        }
    }

    #[test]
    fn two_squares_report_their_overlap_and_their_touching_edge() {
        let sq =
            Part::new("s".into(), vec![[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]], vec![])
                .unwrap();
        let p = Pieces::of(&Body::new(&sq));
        let at = |x: f64| Pose { x, y: 0.0, theta: 0.0 };
        assert!((overlap(&p, at(0.0), &p, at(9.0)) - 1.0).abs() < 1e-9);
        assert_eq!(overlap(&p, at(0.0), &p, at(10.5)), 0.0);
        let c = contacts(&p, at(0.0), &p, at(10.0), 0.01);
        assert_eq!(c.len(), 2, "{c:?}");
        for k in c {
            assert!((k.normal[0] - 1.0).abs() < 1e-9 && k.dist.abs() < 1e-9, "{k:?}");
            assert!((k.point[0] - 5.0).abs() < 1e-9);
        }
    }
}
