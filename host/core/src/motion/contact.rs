//! The plate's rim in the quasi-static model (docs/motion.md): a wall the part cannot pass,
//! with Coulomb friction, or an open edge the part falls off.
//!
//! The part has no inertia: its twist ξ = (vx, vy, ω) is the mobility W = μ·diag(1/A, 1/A, 1/J)
//! times the total wrench. A wall adds contact forces λₙ·n + λₜ·t at the outline's vertices
//! touching it, found so that the wall is never entered (n·v ≥ 0), never pulls (λₙ ≥ 0), does
//! no work where the part leaves it (λₙ·(n·v) = 0) and holds friction inside its cone
//! (|λₜ| ≤ μ_c·λₙ, opposing the slip). That linear complementarity problem is solved by
//! projected Gauss–Seidel on the contacts (a handful per part); positions are projected back
//! inside the plate after each integration step (a translation, so a step's overshoot into
//! the wall never accumulates).
//!
//! Vertices suffice against a straight wall: the points of a polygon nearest a line are its
//! vertices. Holes never touch the rim. A part that is further than its radius from every
//! edge has no contacts and moves exactly as without a rim (same arithmetic, same numbers).

#[cfg(test)]
use crate::model::plate::DEFAULT_FRICTION;
use crate::model::plate::{Edge, PlateModel, on_plate};
use crate::model::pose::Pose;
use crate::motion::body::Body;

/// Vertices within this fraction of the part's radius of the wall count as touching it (a
/// part resting flush ends within 10⁻⁴ rad of the wall's direction).
pub(crate) const CONTACT_GAP: f64 = 1e-4;

/// Gauss–Seidel sweeps at most per solve (a few contacts converge in tens).
const SWEEPS: usize = 200;

/// The plate's rim as the integrator sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rim {
    /// The plate [0, W] × [0, H] (mm).
    pub size_mm: [f64; 2],
    /// Wall or open edge.
    pub edge: Edge,
    /// Coulomb friction coefficient between part and wall.
    pub friction: f64,
}

impl Rim {
    /// The rim of a plate.
    pub fn of(plate: &PlateModel) -> Rim {
        Rim { size_mm: plate.size_mm, edge: plate.edge, friction: plate.friction }
    }

    /// The orientation (degrees, 0.5° apart) at which the part's bounding box is least
    /// over the plate, and by how much (mm, the larger of the two overshoots; ≤ 0 when the
    /// part fits inside the plate there). A part with no orientation that fits can never lie
    /// on the plate: the wall would have to hold it on two opposite sides at once.
    pub(crate) fn best_fit(&self, body: &Body) -> (f64, f64) {
        let [w, h] = self.size_mm;
        let over = |deg: f64| {
            let (s, c) = deg.to_radians().sin_cos();
            let mut lo = [f64::INFINITY; 2];
            let mut hi = [f64::NEG_INFINITY; 2];
            for p in body.rings.iter().flatten() {
                let q = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
                for k in 0..2 {
                    (lo[k], hi[k]) = (lo[k].min(q[k]), hi[k].max(q[k]));
                }
            }
            (hi[0] - lo[0] - w).max(hi[1] - lo[1] - h)
        };
        (0..360)
            .map(|k| (k as f64 * 0.5, over(k as f64 * 0.5)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0.0, 0.0))
    }

    /// Is the part's bounding circle clear of every edge by more than the contact gap?
    /// (Then nothing touches: the free path.)
    fn clear(&self, body: &Body, q: Pose) -> bool {
        let r = body.radius * (1.0 + 2.0 * CONTACT_GAP);
        let [w, h] = self.size_mm;
        q.x - r > 0.0 && q.y - r > 0.0 && q.x + r < w && q.y + r < h
    }

    /// Has the part fallen off an open edge (centroid off the plate)?
    pub fn lost(&self, q: Pose) -> bool {
        self.edge == Edge::Open && !on_plate(self.size_mm, [q.x, q.y])
    }

    /// The pose moved back inside a wall (by a translation), unchanged without one.
    pub fn project(&self, body: &Body, q: Pose) -> Pose {
        if self.edge != Edge::Wall || self.clear(body, q) {
            return q;
        }
        let (lo, hi) = extent(body, q);
        let shift = |lo: f64, hi: f64, size: f64| {
            if hi - lo >= size {
                0.5 * (size - lo - hi)
            } else if lo < 0.0 {
                -lo
            } else if hi > size {
                size - hi
            } else {
                0.0
            }
        };
        let [w, h] = self.size_mm;
        Pose { x: q.x + shift(lo[0], hi[0], w), y: q.y + shift(lo[1], hi[1], h), ..q }
    }

    /// The wall's contacts of the part at `q`: (vertex relative to the centroid in the plate
    /// frame, inward unit normal).
    pub fn contacts(&self, body: &Body, q: Pose) -> Vec<([f64; 2], [f64; 2])> {
        let mut out = Vec::new();
        if self.edge != Edge::Wall || self.clear(body, q) {
            return out;
        }
        let gap = CONTACT_GAP * body.radius;
        let [w, h] = self.size_mm;
        let (s, c) = q.theta.sin_cos();
        for p in body.rings.first().into_iter().flatten() {
            let r = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
            let (x, y) = (q.x + r[0], q.y + r[1]);
            for (d, n) in
                [(x, [1.0, 0.0]), (w - x, [-1.0, 0.0]), (y, [0.0, 1.0]), (h - y, [0.0, -1.0])]
            {
                if d <= gap {
                    out.push((r, n));
                }
            }
        }
        out
    }

    /// The twist of the part at `q` under the field's `free` twist (μF/A, μF/A, μM/J), with
    /// the wall's contact forces: projected Gauss–Seidel on the complementarity conditions.
    pub(crate) fn constrain(&self, body: &Body, speed: f64, q: Pose, free: [f64; 3]) -> [f64; 3] {
        let contacts = self.contacts(body, q);
        if contacts.is_empty() {
            return free;
        }
        let mob = [speed / body.area, speed / body.area, speed / body.polar];
        solve(&contacts, mob, self.friction, free)
    }
}

/// Lower-left and upper-right corners of the placed outline's bounding box.
fn extent(body: &Body, q: Pose) -> ([f64; 2], [f64; 2]) {
    let (s, c) = q.theta.sin_cos();
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in body.rings.first().into_iter().flatten() {
        let v = [q.x + c * p[0] - s * p[1], q.y + s * p[0] + c * p[1]];
        for k in 0..2 {
            lo[k] = lo[k].min(v[k]);
            hi[k] = hi[k].max(v[k]);
        }
    }
    (lo, hi)
}

/// Projected Gauss–Seidel for one body: contacts (r, n), diagonal mobility `mob`, friction
/// coefficient `mu`, the free twist. Returns the constrained twist.
pub fn solve(
    contacts: &[([f64; 2], [f64; 2])],
    mob: [f64; 3],
    mu: f64,
    free: [f64; 3],
) -> [f64; 3] {
    // Jacobian rows: the contact point's velocity along n and along t = (−n_y, n_x).
    let rows: Vec<([f64; 3], [f64; 3])> = contacts
        .iter()
        .map(|&(r, n)| {
            let t = [-n[1], n[0]];
            let cross = |a: [f64; 2]| r[0] * a[1] - r[1] * a[0];
            ([n[0], n[1], cross(n)], [t[0], t[1], cross(t)])
        })
        .collect();
    let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let eff = |j: [f64; 3]| j[0] * j[0] * mob[0] + j[1] * j[1] * mob[1] + j[2] * j[2] * mob[2];
    let mut xi = free;
    let mut lam = vec![[0.0f64; 2]; rows.len()];
    let scale = free[0].hypot(free[1]).max(1e-300);
    for _ in 0..SWEEPS {
        let mut change = 0.0f64;
        for (k, &(jn, jt)) in rows.iter().enumerate() {
            let apply = |j: [f64; 3], d: f64, xi: &mut [f64; 3]| {
                for i in 0..3 {
                    xi[i] += mob[i] * j[i] * d;
                }
            };
            let ln = (lam[k][0] - dot(jn, xi) / eff(jn)).max(0.0);
            apply(jn, ln - lam[k][0], &mut xi);
            change = change.max((ln - lam[k][0]).abs() * eff(jn));
            lam[k][0] = ln;
            let bound = mu * ln;
            let lt = (lam[k][1] - dot(jt, xi) / eff(jt)).clamp(-bound, bound);
            apply(jt, lt - lam[k][1], &mut xi);
            change = change.max((lt - lam[k][1]).abs() * eff(jt));
            lam[k][1] = lt;
        }
        if change < 1e-12 * scale {
            break;
        }
    }
    xi
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::field::Law;
    use crate::motion::field::FieldModel;
    use crate::motion::integrate::{SimParams, run};
    use crate::motion::testkit::{predicted_rest, quad, rect, uniform};

    const W: f64 = 300.0;
    const H: f64 = 200.0;

    fn rim(friction: f64) -> Rim {
        Rim { size_mm: [W, H], edge: Edge::Wall, friction }
    }

    #[test]
    fn a_part_fits_when_some_turn_of_its_box_fits_the_plate() {
        let bar = |l: f64, t: f64| {
            let ring = vec![[0.0, 0.0], [l, 0.0], [l, t], [0.0, t]];
            Body::new(&crate::model::part::Part::new("bar".into(), ring, vec![]).unwrap())
        };
        let r = rim(0.3);
        // On 300 × 200 mm: 290 × 30 fits lying along x, 320 × 20 only turned, 340 × 30 and
        // 400 × 30 (longer than the 361 mm diagonal) never.
        assert!(r.best_fit(&bar(290.0, 30.0)).1 <= 0.0);
        assert!(r.best_fit(&bar(340.0, 30.0)).1 > 0.0);
        let (deg, over) = r.best_fit(&bar(320.0, 20.0));
        assert!(over <= 0.0 && deg > 0.0 && deg < 90.0, "{deg} {over}");
        assert!(r.best_fit(&bar(400.0, 30.0)).1 > 0.0);
    }

    fn params(r: Option<Rim>) -> SimParams {
        SimParams { speed: 10.0, t_limit: 1e4, run_to_limit: false, rim: r }
    }

    #[test]
    fn a_part_pushed_against_the_wall_settles_on_the_stable_edge_push_alignment_predicts() {
        let body = Body::new(&quad());
        let f = uniform([1.0, 0.0]);
        for mu in [0.0, DEFAULT_FRICTION] {
            for k in 0..12 {
                let th0 = k as f64 * 0.52 + 0.1;
                let r =
                    run(&body, &f, params(Some(rim(mu))), Pose { x: 150.0, y: 100.0, theta: th0 });
                let want = predicted_rest(&body, th0);
                let err = (r.pose.theta - want).to_degrees();
                assert!(r.rested, "μ {mu}, θ0 {th0}: {r:?}");
                assert!(err.abs() < 0.2, "μ {mu}, θ0 {th0}: {} vs {}", r.pose.theta, want);
                let (lo, hi) = extent(&body, r.pose);
                // Touching: within the contact gap of the wall.
                let gap = CONTACT_GAP * body.radius;
                assert!(hi[0] <= W && hi[0] > W - gap && lo[0] > 0.0, "{lo:?} {hi:?}");
            }
        }
    }

    #[test]
    fn a_part_on_the_wall_holds_inside_the_friction_cone_and_slides_outside_it() {
        let body = Body::new(&rect());
        let mu = 0.5;
        // Flush against the right wall (long side vertical), pulled into it and along it.
        let at = Pose { x: W - 5.0, y: 100.0, theta: std::f64::consts::FRAC_PI_2 };
        for (tan, slides) in [(0.3, false), (0.49, false), (0.7, true), (1.5, true)] {
            let n = (1.0f64 + tan * tan).sqrt();
            let f = uniform([1.0 / n, tan / n]);
            let w = f.wrench(&body, at);
            let free = [10.0 * w.fx / body.area, 10.0 * w.fy / body.area, 10.0 * w.m / body.polar];
            let v = rim(mu).constrain(&body, 10.0, at, free);
            // Coulomb: the wall takes the normal pull and up to μ times it along the wall.
            let want_vy = if slides { 10.0 * (tan - mu) / n } else { 0.0 };
            assert!(v[0].abs() < 1e-9 && v[2].abs() < 1e-9, "tan {tan}: {v:?}");
            assert!((v[1] - want_vy).abs() < 1e-9, "tan {tan}: {v:?} want {want_vy}");
            let r = run(&body, &f, SimParams { t_limit: 1.0, ..params(Some(rim(mu))) }, at);
            let moved = (r.pose.y - at.y).abs() > 1e-6;
            assert_eq!(moved, slides, "tan {tan}: {:?}", r.pose);
        }
    }

    #[test]
    fn the_wall_never_feeds_energy_in() {
        // Field power F·v + M·ω ≥ 0 (the field's potential never rises) and the contact
        // forces' power ≤ 0, at poses touching the walls and corners, fields of all directions.
        let body = Body::new(&quad());
        let mob = [10.0 / body.area, 10.0 / body.area, 10.0 / body.polar];
        let mut touched = 0;
        for k in 0..400 {
            let a = k as f64 * 2.399;
            let f = uniform([a.cos(), a.sin()]);
            let q = Pose {
                x: (k as f64 * 0.618_034 % 1.0) * (W + 100.0) - 50.0,
                y: (k as f64 * 0.414_214 % 1.0) * (H + 100.0) - 50.0,
                theta: k as f64 * 0.77,
            };
            let q = rim(0.47).project(&body, q);
            let w = f.wrench(&body, q);
            let free = [mob[0] * w.fx, mob[1] * w.fy, mob[2] * w.m];
            let v = rim(0.47).constrain(&body, 10.0, q, free);
            touched += usize::from(v != free);
            let field = w.fx * v[0] + w.fy * v[1] + w.m * v[2];
            let contact: f64 = (0..3).map(|i| v[i] * (v[i] - free[i]) / mob[i]).sum();
            let scale = w.fx.hypot(w.fy) * free[0].hypot(free[1]);
            assert!(field >= -1e-9 * scale, "{q:?}: field power {field}");
            assert!(contact <= 1e-9 * scale, "{q:?}: contact power {contact}");
        }
        assert!(touched > 100, "{touched}");
    }

    #[test]
    fn far_from_the_rim_a_run_is_the_run_without_one_bit_for_bit() {
        let body = Body::new(&quad());
        let f = FieldModel::Line { xhat: [1.0, 0.0], c: 150.0, law: Law::Linear, k: [1.0, 1.3] };
        let q = Pose { x: 120.0, y: 100.0, theta: 0.4 };
        let (a, b) = (run(&body, &f, params(Some(rim(0.47))), q), run(&body, &f, params(None), q));
        assert_eq!(a.trace, b.trace);
        assert!(!a.lost);
    }

    #[test]
    fn an_open_edge_loses_the_part_and_a_wall_keeps_it() {
        let body = Body::new(&quad());
        let f = uniform([-1.0, 0.2]);
        let q = Pose { x: 100.0, y: 100.0, theta: 0.0 };
        let open = Rim { edge: Edge::Open, ..rim(0.47) };
        let r = run(&body, &f, params(Some(open)), q);
        assert!(r.lost && r.pose.x < 0.0, "{r:?}");
        let r = run(&body, &f, params(Some(rim(0.47))), q);
        assert!(!r.lost && r.rested, "{r:?}");
        for (_, p) in &r.trace {
            let (lo, hi) = extent(&body, *p);
            assert!(lo[0] >= -1e-9 && lo[1] >= -1e-9 && hi[0] <= W + 1e-9 && hi[1] <= H + 1e-9);
        }
    }
}
