//! The feed region: the rectangle of the plate where parts are dropped (`plan --feed`,
//! `simulate --feed`), checked against the plate.

use crate::model::plate::PlateModel;
use chladni_shared::icd::units::Given;

/// A rectangle of the plate (mm) where parts are dropped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FeedRegion {
    /// Lower-left corner (x0, y0).
    pub lo: [f64; 2],
    /// Upper-right corner (x1, y1).
    pub hi: [f64; 2],
}

/// A feed region that cannot be used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FeedError {
    /// A coordinate is NaN or infinite.
    #[error("feed region {} mm: every coordinate must be a finite number", show(.0))]
    NotFinite([f64; 4]),
    /// X1 ≤ X0 or Y1 ≤ Y0.
    #[error("feed region {} mm is empty: X0 < X1 and Y0 < Y1 are required", show(.0))]
    Empty([f64; 4]),
    /// Part of the region lies off the plate.
    #[error("feed region {} mm is not inside the {} × {} mm plate", show(.0), .1[0], .1[1])]
    OutsidePlate([f64; 4], [f64; 2]),
}

/// The coordinates as given ([`Given`]: huge ones in exponent form).
fn show(c: &[f64; 4]) -> String {
    c.iter().map(|&v| Given(v).to_string()).collect::<Vec<_>>().join(" ")
}

impl FeedRegion {
    /// The region X0 Y0 X1 Y1 (mm), checked against the plate.
    pub fn new(c: [f64; 4], plate: &PlateModel) -> Result<FeedRegion, FeedError> {
        if !c.iter().all(|v| v.is_finite()) {
            return Err(FeedError::NotFinite(c));
        }
        if c[2] <= c[0] || c[3] <= c[1] {
            return Err(FeedError::Empty(c));
        }
        let [w, h] = plate.size_mm;
        if c[0] < 0.0 || c[1] < 0.0 || c[2] > w || c[3] > h {
            return Err(FeedError::OutsidePlate(c, plate.size_mm));
        }
        Ok(FeedRegion { lo: [c[0], c[1]], hi: [c[2], c[3]] })
    }

    /// The point at fractions (u, v) of the region, kept at least `r` (the part's radius) from
    /// the plate's edges, as `chladni simulate` keeps its random starts: a centroid nearer the
    /// edge would leave the part overhanging it.
    pub fn at(&self, u: f64, v: f64, r: f64, plate: &PlateModel) -> [f64; 2] {
        let keep = |x: f64, size: f64| {
            let r = r.min(size / 2.0);
            x.clamp(r, size - r)
        };
        let x = self.lo[0] + u * (self.hi[0] - self.lo[0]);
        let y = self.lo[1] + v * (self.hi[1] - self.lo[1]);
        [keep(x, plate.size_mm[0]), keep(y, plate.size_mm[1])]
    }
}

#[cfg(test)]
mod tests {
    use super::FeedError;

    #[test]
    fn refusals_echo_the_region_as_given_and_readable() {
        let far = FeedError::OutsidePlate([0.0, 0.0, 1e308, 10.0], [300.0, 200.0]);
        assert_eq!(
            far.to_string(),
            "feed region 0 0 1e308 10 mm is not inside the 300 × 200 mm plate"
        );
        let thin = FeedError::Empty([10.5, 3e-9, 10.5, 20.0]);
        assert_eq!(
            thin.to_string(),
            "feed region 10.5 3e-9 10.5 20 mm is empty: X0 < X1 and Y0 < Y1 are required"
        );
        let nan = FeedError::NotFinite([f64::NAN, 0.0, f64::INFINITY, 1.0]);
        assert_eq!(
            nan.to_string(),
            "feed region NaN 0 inf 1 mm: every coordinate must be a finite number"
        );
    }
}
