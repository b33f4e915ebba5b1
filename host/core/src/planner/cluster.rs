//! Clustering of simulated final orientations into rests: the one type both simulated maps
//! ([`super::sampled_map`]) and dynamic maps ([`super::dynamic`]) use.

use crate::model::angle::{cdist, signed_diff};

/// Clustering tolerance of simulated final orientations (deg): well above the simulation's
/// rest tolerance, well below the distance between distinct rests of the example parts.
pub(crate) const CLUSTER_DEG: f64 = 2.0;

/// Rests found so far: running means of final orientations (deg, modulo a period); a new
/// orientation joins the first rest whose mean is within the tolerance, else starts one.
#[derive(Debug, Clone)]
pub(crate) struct Clusters {
    /// (first member, sum of the members' signed offsets from it, count).
    reps: Vec<(f64, f64, usize)>,
    period: f64,
    tol_deg: f64,
}

impl Clusters {
    /// No rests yet; orientations are taken modulo `period` and merged within `tol_deg`.
    pub(crate) fn new(period: f64, tol_deg: f64) -> Self {
        Clusters { reps: Vec::new(), period, tol_deg }
    }

    /// How many rests.
    pub(crate) fn len(&self) -> usize {
        self.reps.len()
    }

    /// Mean of rest `k` (deg, in [0, period)).
    pub(crate) fn mean(&self, k: usize) -> f64 {
        let r = self.reps[k];
        (r.0 + r.1 / r.2 as f64).rem_euclid(self.period)
    }

    /// Every rest's mean, in label order.
    pub(crate) fn means(&self) -> Vec<f64> {
        (0..self.len()).map(|k| self.mean(k)).collect()
    }

    /// Does orientation `theta` (deg) belong to rest `k`?
    pub(crate) fn holds(&self, k: usize, theta: f64) -> bool {
        cdist(self.mean(k), theta, self.period) < self.tol_deg
    }

    /// The rest of a final orientation (deg), a new one if none is within the tolerance.
    pub(crate) fn label(&mut self, theta: f64) -> usize {
        let fc = theta.rem_euclid(self.period);
        match (0..self.len()).find(|&k| self.holds(k, fc)) {
            Some(k) => {
                let r = &mut self.reps[k];
                r.1 += signed_diff(fc, r.0, self.period);
                r.2 += 1;
                k
            }
            None => {
                self.reps.push((fc, 0.0, 1));
                self.reps.len() - 1
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::Clusters;

    #[test]
    fn merges_across_the_period_and_keeps_apart_beyond_the_tolerance() {
        let mut c = Clusters::new(180.0, 2.0);
        assert_eq!(c.label(179.5), 0);
        assert_eq!(c.label(0.5), 0); // 1° apart across the period's end
        assert_eq!(c.label(90.0), 1);
        assert_eq!(c.label(93.0), 2);
        assert_eq!(c.len(), 3);
        assert!(c.mean(0) < 1e-9 || (c.mean(0) - 180.0).abs() < 1e-9, "{}", c.mean(0));
        assert!(c.holds(1, 271.0)); // 271 mod 180 = 91
    }
}
