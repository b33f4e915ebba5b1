//! A part prepared for the motion model: its rings about the centroid, area, polar moment of
//! area and interior samples, and the pose type every motion module uses.
//!
//! Units: mm, rad (degrees only where named).

use crate::model::geometry::{self, inside};
use crate::model::part::Part;

/// Target number of interior sample points for numerical force integration.
pub const BODY_SAMPLES: usize = 400;
/// The planner's coarser resolution: its many short runs (step maps, settle times, tracked
/// feed poses) take 160 samples, and its tests compare against runs made the same way.
/// Grid modes integrate along the outline and use neither.
pub const PLANNER_BODY_SAMPLES: usize = 160;

pub use crate::model::pose::Pose;

/// A part prepared for simulation: rings about the centroid, area, polar moment, samples.
#[derive(Debug, Clone)]
pub struct Body {
    /// Rings relative to the centroid (outline CCW, holes CW).
    pub rings: Vec<Vec<[f64; 2]>>,
    /// Centroid of the part as drawn (mm).
    pub centroid: [f64; 2],
    /// Area (mm²).
    pub area: f64,
    /// Polar moment of area about the centroid (mm⁴).
    pub polar: f64,
    /// Radius about the centroid (mm).
    pub radius: f64,
    /// Interior sample points (relative to the centroid) and their weights (mm²).
    pub samples: Vec<([f64; 2], f64)>,
    /// Per ring: the moment rule of a hole ([`HoleRule`]); `None` for the outline.
    pub holes: Vec<Option<HoleRule>>,
}

/// A hole's area integral by four points: the hole's centroid ± a along its first principal
/// axis and ± b along the second, a quarter of its area each, with a² = 2·I₁/A and b² = 2·I₂/A
/// (I₁, I₂ its principal second moments of area). The rule has the hole's area, centroid and
/// second moments, so it integrates every polynomial of degree 2 over the hole exactly, and of
/// degree 3 over a centrally symmetric hole (a round one). Where a field varies little across
/// a hole (a hole small against a grid cell), the grid wrench takes it instead of the hole's
/// outline integral (`motion::field`, the grid's fast rule).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HoleRule {
    /// Largest distance from the hole's centroid to its outline (mm).
    pub radius: f64,
    /// The four points, relative to the part's centroid (mm).
    pub points: [[f64; 2]; 4],
    /// The weight of each point: a quarter of the hole's area (mm²).
    pub weight: f64,
}

impl HoleRule {
    /// The rule of a ring (either winding), relative to the same origin as its points.
    pub fn of(ring: &[[f64; 2]]) -> HoleRule {
        let (a, c) = geometry::area_centroid([ring]);
        // Second moments about the centroid (signed like `a`, so the ratios are positive).
        let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
        for (i, &p) in ring.iter().enumerate() {
            let q = ring[(i + 1) % ring.len()];
            let (p, q) = ([p[0] - c[0], p[1] - c[1]], [q[0] - c[0], q[1] - c[1]]);
            let cr = p[0] * q[1] - q[0] * p[1];
            sxx += cr * (p[0] * p[0] + p[0] * q[0] + q[0] * q[0]) / 12.0;
            syy += cr * (p[1] * p[1] + p[1] * q[1] + q[1] * q[1]) / 12.0;
            sxy += cr * (p[0] * q[1] + 2.0 * p[0] * p[1] + 2.0 * q[0] * q[1] + q[0] * p[1]) / 24.0;
        }
        let (ixx, iyy, ixy) = (sxx / a, syy / a, sxy / a);
        // Principal axes of [[ixx, ixy], [ixy, iyy]] (per unit area).
        let half = 0.5 * (ixx - iyy);
        let root = half.hypot(ixy);
        let (l1, l2) = (0.5 * (ixx + iyy) + root, (0.5 * (ixx + iyy) - root).max(0.0));
        let phi = 0.5 * (2.0 * ixy).atan2(ixx - iyy);
        let (s, co) = phi.sin_cos();
        let (ra, rb) = ((2.0 * l1).sqrt(), (2.0 * l2).sqrt());
        let at = |u: f64, v: f64| [c[0] + u * co - v * s, c[1] + u * s + v * co];
        let radius = ring.iter().map(|p| (p[0] - c[0]).hypot(p[1] - c[1])).fold(0.0, f64::max);
        HoleRule {
            radius,
            points: [at(ra, 0.0), at(-ra, 0.0), at(0.0, rb), at(0.0, -rb)],
            weight: 0.25 * a.abs(),
        }
    }
}

impl Body {
    /// Prepares a validated part ([`BODY_SAMPLES`] interior samples).
    pub fn new(part: &Part) -> Body {
        Body::with_samples(part, BODY_SAMPLES)
    }

    /// Prepares a validated part with about `target` interior samples.
    pub fn with_samples(part: &Part, target: usize) -> Body {
        let (a, centroid) = geometry::area_centroid(part.rings().map(|r| r.as_slice()));
        let rings: Vec<Vec<[f64; 2]>> = part
            .rings()
            .map(|r| r.iter().map(|p| [p[0] - centroid[0], p[1] - centroid[1]]).collect())
            .collect();
        let mut polar = 0.0;
        for r in &rings {
            for i in 0..r.len() {
                let (p, q) = (r[i], r[(i + 1) % r.len()]);
                let c = p[0] * q[1] - q[0] * p[1];
                polar += c
                    * (p[0] * p[0]
                        + p[0] * q[0]
                        + q[0] * q[0]
                        + p[1] * p[1]
                        + p[1] * q[1]
                        + q[1] * q[1])
                    / 12.0;
            }
        }
        let radius = rings.iter().flatten().map(|p| p[0].hypot(p[1])).fold(0.0, f64::max);
        // Interior samples: cell centres of a square grid inside the outline and outside holes.
        let (lo, hi) = geometry::bounds(rings.iter().flatten());
        let target = target.max(16);
        let mut h = (a / target as f64).sqrt();
        let mut samples = Vec::new();
        for _ in 0..4 {
            samples.clear();
            let (nx, ny) =
                (((hi[0] - lo[0]) / h).ceil() as usize, ((hi[1] - lo[1]) / h).ceil() as usize);
            for j in 0..ny {
                for i in 0..nx {
                    let p = [lo[0] + (i as f64 + 0.5) * h, lo[1] + (j as f64 + 0.5) * h];
                    if inside(p, &rings[0]) && !rings[1..].iter().any(|r| inside(p, r)) {
                        samples.push(p);
                    }
                }
            }
            if samples.len() >= target / 2 {
                break;
            }
            h *= 0.7;
        }
        // Weights: total area split evenly; shift so the samples' centroid is exact.
        let n = samples.len().max(1) as f64;
        let (mx, my) = (
            samples.iter().map(|p| p[0]).sum::<f64>() / n,
            samples.iter().map(|p| p[1]).sum::<f64>() / n,
        );
        let samples = samples.into_iter().map(|p| ([p[0] - mx, p[1] - my], a / n)).collect();
        let holes = (0..rings.len()).map(|i| (i > 0).then(|| HoleRule::of(&rings[i]))).collect();
        Body { rings, centroid, area: a, polar, radius, samples, holes }
    }

    /// The part's rings at a pose (plate frame).
    pub fn placed(&self, pose: Pose) -> Vec<Vec<[f64; 2]>> {
        let (s, c) = pose.theta.sin_cos();
        self.rings
            .iter()
            .map(|r| {
                r.iter()
                    .map(|p| [pose.x + c * p[0] - s * p[1], pose.y + s * p[0] + c * p[1]])
                    .collect()
            })
            .collect()
    }
}
