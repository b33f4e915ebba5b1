//! Angles on a circle: the one home for circular distance and the signed wrap (degrees or
//! any unit; `p` is the circumference: 360°, or a part's symmetry period).

/// An angle in degrees wrapped to [0°, 360°).
pub fn wrap_deg(deg: f64) -> f64 {
    deg.rem_euclid(360.0)
}

/// The circular mean of `angles` (deg) modulo `period` (deg), in [0, period): each angle taken
/// to 360° · θ / period on the circle, averaged as unit vectors, taken back; 0 when there are
/// none (or their mean vector has length 0).
pub fn circular_mean(angles: impl IntoIterator<Item = f64>, period: f64) -> f64 {
    let s = std::f64::consts::TAU / period;
    let (c, n) = angles.into_iter().fold((0.0, 0.0), |(c, n), deg| {
        let a = deg * s;
        (c + a.cos(), n + a.sin())
    });
    (n.atan2(c) / s).rem_euclid(period)
}

/// Circular distance between `a` and `b` on a circle of circumference `p` (in [0, p/2]).
pub fn cdist(a: f64, b: f64, p: f64) -> f64 {
    let d = (a - b).rem_euclid(p);
    d.min(p - d)
}

/// The signed difference `a − b` wrapped to (−p/2, p/2] on a circle of circumference `p`.
pub fn signed_diff(a: f64, b: f64, p: f64) -> f64 {
    let d = (a - b).rem_euclid(p);
    if d > p / 2.0 { d - p } else { d }
}

#[cfg(test)]
mod tests {
    use super::{cdist, signed_diff};

    #[test]
    fn wraps_to_the_half_open_interval() {
        assert_eq!(signed_diff(10.0, 350.0, 360.0), 20.0);
        assert_eq!(signed_diff(350.0, 10.0, 360.0), -20.0);
        // The half-way point is +p/2, never −p/2.
        assert_eq!(signed_diff(180.0, 0.0, 360.0), 180.0);
        assert_eq!(signed_diff(0.0, 180.0, 360.0), 180.0);
        assert_eq!(signed_diff(91.0, 0.0, 90.0), 1.0);
        assert_eq!(signed_diff(-1.0, 0.0, 90.0), -1.0);
        assert_eq!(cdist(-1.0, 89.0, 90.0), 0.0);
        assert_eq!(cdist(10.0, 350.0, 360.0), 20.0);
    }
}
