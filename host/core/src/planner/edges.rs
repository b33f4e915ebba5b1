//! The plate's edges as the planner meets them: which edge ([`PlateEdge`]), a straight node
//! lying along the rim ([`rim_line`]), a part touching the rim (`on_plate_edge`). A leaf of
//! the planner: every module that reasons about the rim reads it, and it reads none of them.

use crate::model::plate::{Mode, Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;

/// One of the plate's four edges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlateEdge {
    /// x = 0.
    Left,
    /// x = W.
    Right,
    /// y = 0.
    Bottom,
    /// y = H.
    Top,
}

impl PlateEdge {
    pub(crate) fn name(self) -> &'static str {
        match self {
            PlateEdge::Left => "left (x = 0)",
            PlateEdge::Right => "right (x = W)",
            PlateEdge::Bottom => "bottom (y = 0)",
            PlateEdge::Top => "top (y = H)",
        }
    }
}

/// Does a straight node lie where a part of radius `radius` cannot rest across it: the node
/// line misses the plate inset by the radius (a node along or beyond an edge, as a clamped
/// edge is)? Then the field pushes the part into the rim, not onto the node, and the static
/// alignment function (balance on the node, then rotate) does not apply: the planner maps
/// such a mode by simulation with the rim ([`sampled_map`](super::sampled_map)), where the wall's reaction turns
/// the part to a stable edge (push alignment).
pub fn rim_line(radius: f64, mode: &Mode, plate: &PlateModel) -> bool {
    let Node::Line { angle_deg, offset_mm } = mode.node else { return false };
    let [w, h] = plate.size_mm;
    let r = radius.min(w / 2.0).min(h / 2.0);
    let (s, c) = angle_deg.to_radians().sin_cos();
    let ctr = plate.center();
    let xi = |p: [f64; 2]| -s * (p[0] - ctr[0]) + c * (p[1] - ctr[1]) - offset_mm;
    let d = [[r, r], [w - r, r], [w - r, h - r], [r, h - r]].map(xi);
    d.iter().all(|&x| x > 0.0) || d.iter().all(|&x| x < 0.0)
}

/// Does a part that ended at `q` sit on the plate's edge (centroid within its radius of
/// it) rather than on an interior node?
pub(crate) fn on_plate_edge(body: &Body, plate: &PlateModel, q: Pose) -> bool {
    let [w, h] = plate.size_mm;
    let edge = body.radius;
    q.x < edge || q.y < edge || q.x > w - edge || q.y > h - edge
}
