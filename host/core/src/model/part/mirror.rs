//! Both faces of a flat part (docs/physics.md, "Faces"). A part dropped on the plate lands
//! on either face; the plate only sees its contact surface, so the part lying on its other
//! face is its **mirror image**.
//!
//! Convention: the part as drawn in its file is seen from above the plate, so the face
//! *up* is the one the drawing shows (pose θ = 0 is the drawing). Turned over about its
//! local y axis (the line through the centroid c parallel to the drawing's y axis), every
//! point (x, y) of the drawing appears, seen from above, at (2·c_x − x, y): the *flipped*
//! face, whose pose θ = 0 is that mirror image. Turning the part over about any other axis
//! in its plane gives the same shape turned about c, so the choice only fixes where the
//! flipped face's θ = 0 lies.
//!
//! A part with a mirror axis (an isosceles triangle, a rectangle, a key drawn symmetric)
//! is its own mirror image turned by some angle: its flipped face rests exactly as the face
//! up, turned, and needs no plan of its own ([`flip_turn_deg`]).

use crate::model::angle::wrap_deg;
use std::collections::HashMap;

use super::Part;

/// Appended to a part's name for its flipped face.
pub const FLIPPED_SUFFIX: &str = " (flipped)";

/// Which face of a part lies on the plate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Face {
    /// The face the drawing shows is up (the part as drawn).
    Up,
    /// The part turned over: its mirror image ([`Part::mirrored`]).
    Flipped,
}

impl std::fmt::Display for Face {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Face::Up => "face up",
            Face::Flipped => "flipped",
        })
    }
}

impl Part {
    /// The part turned over (its flipped face, see the module docs): every ring reflected
    /// across the vertical line through the centroid, x → 2·c_x − x, and reversed so the
    /// outline stays counter-clockwise and holes clockwise. Same centroid, area and polar
    /// moment; named `NAME (flipped)`.
    pub fn mirrored(&self) -> Part {
        let cx = self.centroid()[0];
        let flip = |ring: &Vec<[f64; 2]>| -> Vec<[f64; 2]> {
            ring.iter().rev().map(|p| [2.0 * cx - p[0], p[1]]).collect()
        };
        Part {
            name: format!("{}{FLIPPED_SUFFIX}", self.name),
            outline: flip(&self.outline),
            holes: self.holes.iter().map(flip).collect(),
            flips: false,
        }
    }
}

/// When the part's mirror image is the part itself turned about its centroid: the smallest
/// such turn (degrees CCW, in [0, 360)), with every vertex within 10⁻⁶ of the part's radius
/// of a vertex of the other shape (the tolerance of the planner's rotational symmetry test).
/// `None` for a part without a mirror axis, whose flipped face is a different shape.
///
/// A flipped face at pose (x, y, θ) is then the face up at (x, y, θ + turn).
pub fn flip_turn_deg(part: &Part) -> Option<f64> {
    let c = part.centroid();
    let rel = |r: &Vec<[f64; 2]>| -> Vec<[f64; 2]> {
        r.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect()
    };
    let own: Vec<[f64; 2]> = part.rings().flat_map(rel).collect();
    let mirror: Vec<[f64; 2]> = own.iter().map(|p| [-p[0], p[1]]).collect();
    let radius = own.iter().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
    let tol = 1e-6 * radius.max(1e-9);
    let grid = VertexGrid::new(&own, tol);
    // The mirror's farthest outline vertex must land on an own outline vertex as far out.
    let outline = part.outline.len();
    let far = (0..outline).max_by(|&a, &b| {
        mirror[a][0].hypot(mirror[a][1]).total_cmp(&mirror[b][0].hypot(mirror[b][1]))
    })?;
    let m0 = mirror[far];
    let r0 = m0[0].hypot(m0[1]);
    let mut turns: Vec<f64> = own[..outline]
        .iter()
        .filter(|v| (v[0].hypot(v[1]) - r0).abs() <= tol)
        .map(|v| (v[1].atan2(v[0]) - m0[1].atan2(m0[0])).rem_euclid(std::f64::consts::TAU))
        .filter(|&phi| {
            let (s, co) = phi.sin_cos();
            mirror.iter().all(|p| grid.has([co * p[0] - s * p[1], s * p[0] + co * p[1]]))
        })
        // φ turns the mirror onto the part, so the mirror is the part turned by −φ.
        .map(|phi| wrap_deg(-phi.to_degrees()))
        .map(|d| if 360.0 - d < 1e-6 || d < 1e-9 { 0.0 } else { d })
        .collect();
    turns.sort_by(f64::total_cmp);
    turns.first().copied()
}

/// A part's vertices hashed by cells of the match tolerance: "is there a vertex within
/// `tol` of q" in O(1), so the mirror test is linear in the vertex count.
struct VertexGrid {
    cell: f64,
    tol: f64,
    cells: HashMap<(i64, i64), Vec<[f64; 2]>>,
}

impl VertexGrid {
    fn new(points: &[[f64; 2]], tol: f64) -> Self {
        let cell = 2.0 * tol;
        let mut cells: HashMap<(i64, i64), Vec<[f64; 2]>> = HashMap::new();
        for &p in points {
            cells.entry(Self::key(p, cell)).or_default().push(p);
        }
        VertexGrid { cell, tol, cells }
    }

    fn key(p: [f64; 2], cell: f64) -> (i64, i64) {
        ((p[0] / cell).floor() as i64, (p[1] / cell).floor() as i64)
    }

    fn has(&self, q: [f64; 2]) -> bool {
        let (i, j) = Self::key(q, self.cell);
        (i - 1..=i + 1).any(|a| {
            (j - 1..=j + 1).any(|b| {
                self.cells.get(&(a, b)).is_some_and(|ps| {
                    ps.iter().any(|p| (p[0] - q[0]).hypot(p[1] - q[1]) <= self.tol)
                })
            })
        })
    }
}

/// One face to plan or simulate: which given part it comes from and which face it is.
#[derive(Debug, Clone, PartialEq)]
pub struct FaceOf {
    /// Index of the part as given.
    pub source: usize,
    /// Which face (only parts that flip have a [`Face::Flipped`] entry).
    pub face: Option<Face>,
}

/// The faces of some parts: what the planner and the simulation take.
#[derive(Debug, Clone, Default)]
pub struct Faces {
    /// The parts to plan: each given part, followed by its mirror image when it flips and
    /// has no mirror axis.
    pub parts: Vec<Part>,
    /// For each entry of `parts`, where it comes from.
    pub of: Vec<FaceOf>,
    /// Parts that flip but are their own mirror image turned: (name, turn in degrees).
    pub self_mirrored: Vec<(String, f64)>,
}

/// The faces of `given`: a part flips when its file says so (`"flips": true`) or when
/// `both` (`--both-faces`); a flipping part without a mirror axis brings its mirror image as
/// one more part, right after it; one with a mirror axis is planned once (and listed in
/// [`Faces::self_mirrored`]).
pub fn faces(given: &[Part], both: bool) -> Faces {
    let mut out = Faces::default();
    for (source, part) in given.iter().enumerate() {
        if !(both || part.flips) {
            out.parts.push(part.clone());
            out.of.push(FaceOf { source, face: None });
            continue;
        }
        if let Some(turn) = flip_turn_deg(part) {
            out.self_mirrored.push((part.name.clone(), turn));
            out.parts.push(part.clone());
            out.of.push(FaceOf { source, face: None });
            continue;
        }
        out.parts.push(part.clone());
        out.of.push(FaceOf { source, face: Some(Face::Up) });
        out.parts.push(part.mirrored());
        out.of.push(FaceOf { source, face: Some(Face::Flipped) });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn part(outline: Vec<[f64; 2]>, holes: Vec<Vec<[f64; 2]>>) -> Part {
        Part::new("p".into(), outline, holes).unwrap()
    }

    fn turned(p: &Part, deg: f64) -> Part {
        let (s, c) = deg.to_radians().sin_cos();
        let t = |r: &Vec<[f64; 2]>| {
            r.iter().map(|q| [c * q[0] - s * q[1], s * q[0] + c * q[1]]).collect()
        };
        part(t(&p.outline), p.holes.iter().map(t).collect())
    }

    #[test]
    fn the_mirror_keeps_the_centroid_and_area_and_reverses_no_winding() {
        let p = part(
            vec![[0.0, 0.0], [40.0, 0.0], [31.0, 16.0], [5.0, 26.0]],
            vec![vec![[10.0, 5.0], [14.0, 12.0], [20.0, 5.0]]],
        );
        let m = p.mirrored();
        assert_eq!(m.name, "p (flipped)");
        assert!((m.area() - p.area()).abs() < 1e-9);
        let (a, b) = (p.centroid(), m.centroid());
        assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
        // Still a valid part with the same winding: Part::new keeps it as it is.
        let again = Part::new("m".into(), m.outline.clone(), m.holes.clone()).unwrap();
        assert_eq!(again.outline, m.outline);
        assert_eq!(again.holes, m.holes);
        // Twice turned over is the part again (to rounding).
        let back = m.mirrored();
        for (u, v) in back.outline.iter().zip(&p.outline) {
            assert!((u[0] - v[0]).abs() < 1e-9 && (u[1] - v[1]).abs() < 1e-9);
        }
        assert_eq!(flip_turn_deg(&p), None);
    }

    #[test]
    fn a_part_with_a_mirror_axis_is_its_own_flipped_face_turned() {
        let iso = part(vec![[0.0, 0.0], [30.0, 0.0], [15.0, 20.0]], vec![]);
        assert_eq!(flip_turn_deg(&iso), Some(0.0));
        // Drawn turned by 25°: the mirror is the part turned by −50°.
        let t = flip_turn_deg(&turned(&iso, 25.0)).unwrap();
        assert!((t - 310.0).abs() < 1e-6, "{t}");
        // A rectangle with an off-centre hole on its axis: mirror axis kept.
        let holed = part(
            vec![[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [0.0, 10.0]],
            vec![vec![[18.0, 2.0], [22.0, 2.0], [22.0, 4.0], [18.0, 4.0]]],
        );
        assert_eq!(flip_turn_deg(&holed), Some(0.0));
        // The same hole moved off the axis: no mirror axis.
        let off = part(
            holed.outline.clone(),
            vec![vec![[8.0, 2.0], [12.0, 2.0], [12.0, 4.0], [8.0, 4.0]]],
        );
        // The hole off the axis (and off the centre): no turn maps the mirror onto it.
        assert_eq!(flip_turn_deg(&off), None);
        let tri = part(vec![[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]], vec![]);
        assert_eq!(flip_turn_deg(&tri), None);
    }

    #[test]
    fn faces_add_the_mirror_only_for_parts_that_flip_without_a_mirror_axis() {
        let tri = part(vec![[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]], vec![]);
        let iso = part(vec![[0.0, 0.0], [30.0, 0.0], [15.0, 20.0]], vec![]);
        let f = faces(&[tri.clone(), iso.clone()], false);
        assert_eq!(f.parts.len(), 2);
        assert!(f.self_mirrored.is_empty());
        let f = faces(&[tri.clone(), iso.clone()], true);
        assert_eq!(f.parts.len(), 3);
        assert_eq!(f.parts[1], tri.mirrored());
        let faces_of: Vec<_> = f.of.iter().map(|o| (o.source, o.face)).collect();
        assert_eq!(faces_of, vec![(0, Some(Face::Up)), (0, Some(Face::Flipped)), (1, None)]);
        assert_eq!(f.self_mirrored, vec![("p".to_string(), 0.0)]);
        let flips = Part::from_json(
            r#"{"name": "t", "outline": [[0, 0], [30, 0], [8, 20]], "flips": true}"#,
            "t",
        )
        .unwrap();
        assert!(flips.flips && !tri.flips);
        assert_eq!(faces(&[flips], false).parts.len(), 2);
    }
}
