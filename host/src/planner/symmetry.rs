//! Symmetry: a part's rotational symmetry order and the period orientations are taken
//! modulo (docs/plan.md, "Equivalence").

use crate::model::part::Part;
use crate::model::plate::{Mode, PlateModel};
use crate::motion::sim::Body;

/// Rotational symmetry order of a part (largest m such that turning it by 360°/m about its
/// centroid maps it onto itself, vertex for vertex, within 10⁻⁶ of its size).
pub fn symmetry_order(part: &Part) -> u32 {
    body_symmetry_order(&Body::new(part))
}

/// [`symmetry_order`] of a prepared part.
pub(crate) fn body_symmetry_order(body: &Body) -> u32 {
    let n = body.rings[0].len();
    let tol = 1e-6 * body.radius.max(1e-9);
    for m in (2..=n).rev() {
        if !n.is_multiple_of(m) {
            continue;
        }
        let (s, c) = (std::f64::consts::TAU / m as f64).sin_cos();
        let ok = body.rings.iter().all(|r| {
            r.iter().all(|p| {
                let q = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
                body.rings.iter().any(|o| o.iter().any(|v| (v[0] - q[0]).hypot(v[1] - q[1]) < tol))
            })
        });
        if ok {
            return m as u32;
        }
    }
    1
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The period P = 360°/m orientations are taken modulo: m = the part's rotational symmetry
/// order, doubled (lcm with 2) when every mode is a straight node with equal gains.
pub fn plan_period(part: &Part, plate: &PlateModel) -> f64 {
    let m_part = symmetry_order(part);
    let all_sym = plate.modes.iter().all(Mode::is_symmetric_line);
    let m = if all_sym { m_part * 2 / gcd(m_part, 2) } else { m_part };
    360.0 / m as f64
}
