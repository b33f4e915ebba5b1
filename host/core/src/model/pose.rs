//! The pose of a part on the plate, the one pose type of the motion model, the observations
//! file and the figures. It lives in `model` so that a file schema below `motion` can hold one.

/// A pose: centroid (x, y) in mm, orientation θ in radians.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose {
    /// Centroid x (mm).
    pub x: f64,
    /// Centroid y (mm).
    pub y: f64,
    /// Orientation (rad).
    pub theta: f64,
}
