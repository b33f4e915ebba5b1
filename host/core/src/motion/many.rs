//! Several parts in one field (docs/motion.md, "Contacts between parts"): the quasi-static
//! model of [`crate::motion::integrate`] for a group of bodies that touch each other and the
//! plate's rim.
//!
//! Each body's twist is its mobility W = μ·diag(1/A, 1/A, 1/J) times its total wrench: the
//! field's plus the contact forces. Contacts are the rim's (a vertex on a wall,
//! [`Rim::contacts`]) and the parts' (parry's contact manifolds between their convex pieces,
//! [`shape::contacts`]); every one has a normal force λₙ ≥ 0 (push, never pull), no
//! penetration (the contact's normal separation speed ≥ 0), no work where it opens
//! (λₙ·vₙ = 0) and Coulomb friction |λₜ| ≤ μ_c·λₙ against the slip (`[plate] friction`, the
//! wall's coefficient). One projected Gauss–Seidel solve takes walls and pairs together.
//! After each integration step the poses are projected: into the plate (the wall's
//! translation) and apart (overlapping pairs pushed apart along their normal, each by its
//! share of the mobility), so a step's overshoot never accumulates.
//!
//! One body is [`integrate::run`](crate::motion::integrate::run), unchanged: a group of one never comes here.
//!
//! Units: mm, s, rad.

use crate::model::plate::PlateModel;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::{CONTACT_GAP, Rim};
use crate::motion::field::FieldModel;
use crate::motion::integrate::STEP_TOL;
use crate::motion::shape::{self, Pieces};
use crate::motion::steps::SimStep;

/// Gauss–Seidel sweeps at most per solve.
const SWEEPS: usize = 100;
/// Passes of the pairwise separation after a step.
const SEPARATION_PASSES: usize = 10;
/// Integration steps at most per run.
const MAX_STEPS: usize = 20_000;

/// The parts simulated together.
#[derive(Debug, Clone, Copy)]
pub struct Group<'a> {
    /// The bodies.
    pub bodies: &'a [&'a Body],
    /// Their convex pieces, in the same order.
    pub pieces: &'a [&'a Pieces],
    /// The plate's rim; `None`: an unbounded plane.
    pub rim: Option<Rim>,
    /// Coulomb friction between parts (the plate's `friction`).
    pub friction: f64,
}

/// A run of a group.
#[derive(Debug, Clone)]
pub struct ManyRun {
    /// Final poses.
    pub poses: Vec<Pose>,
    /// Which bodies fell off an open edge (frozen where they fell).
    pub lost: Vec<bool>,
    /// (t, poses) samples.
    pub trace: Vec<(f64, Vec<Pose>)>,
    /// Simulated time (s).
    pub t_end: f64,
    /// Every body came to rest before the time limit.
    pub rested: bool,
    /// Integration steps taken.
    pub steps: usize,
}

/// One row of the contact problem: the bodies it acts on and their Jacobian rows along the
/// normal and the tangent (the contact point's velocity, relative for a pair).
#[derive(Debug, Clone)]
struct Row {
    on: Vec<(usize, [f64; 3], [f64; 3])>,
}

fn row_of(body: usize, r: [f64; 2], n: [f64; 2], sign: f64) -> (usize, [f64; 3], [f64; 3]) {
    let t = [-n[1], n[0]];
    let cross = |a: [f64; 2]| r[0] * a[1] - r[1] * a[0];
    let s = sign;
    (body, [s * n[0], s * n[1], s * cross(n)], [s * t[0], s * t[1], s * cross(t)])
}

impl Group<'_> {
    fn radius(&self, i: usize) -> f64 {
        self.bodies[i].radius.max(1e-6)
    }

    /// The contact rows at `qs` (lost bodies take no part).
    fn rows(&self, qs: &[Pose], lost: &[bool]) -> Vec<Row> {
        let mut rows = Vec::new();
        for (i, b) in self.bodies.iter().enumerate() {
            if lost[i] {
                continue;
            }
            if let Some(rim) = self.rim {
                for (r, n) in rim.contacts(b, qs[i]) {
                    rows.push(Row { on: vec![row_of(i, r, n, 1.0)] });
                }
            }
        }
        for i in 0..qs.len() {
            for j in i + 1..qs.len() {
                if lost[i] || lost[j] || !self.near(i, j, qs) {
                    continue;
                }
                let gap = self.gap(i, j);
                for c in shape::contacts(self.pieces[i], qs[i], self.pieces[j], qs[j], gap) {
                    let ri = [c.point[0] - qs[i].x, c.point[1] - qs[i].y];
                    let rj = [c.point[0] - qs[j].x, c.point[1] - qs[j].y];
                    let on = vec![row_of(j, rj, c.normal, 1.0), row_of(i, ri, c.normal, -1.0)];
                    rows.push(Row { on });
                }
            }
        }
        rows
    }

    /// Contact distance of a pair: [`CONTACT_GAP`] of their mean radius.
    fn gap(&self, i: usize, j: usize) -> f64 {
        CONTACT_GAP * 0.5 * (self.radius(i) + self.radius(j))
    }

    /// Can bodies i and j touch (bounding circles within the gap)?
    fn near(&self, i: usize, j: usize, qs: &[Pose]) -> bool {
        // Squared: this test runs for every pair at every stage, and `hypot` is a libm call.
        let (dx, dy) = (qs[i].x - qs[j].x, qs[i].y - qs[j].y);
        let reach = self.radius(i) + self.radius(j) + self.gap(i, j);
        dx * dx + dy * dy <= reach * reach
    }

    /// Each body's mobility W = μ·diag(1/A, 1/A, 1/J).
    fn mobility(&self, speed: f64) -> Vec<[f64; 3]> {
        self.bodies.iter().map(|b| [speed / b.area, speed / b.area, speed / b.polar]).collect()
    }

    /// The field's free twists and the constrained twists at `qs` (lost bodies: zero).
    pub fn twists(
        &self,
        field: &FieldModel,
        speed: f64,
        qs: &[Pose],
        lost: &[bool],
    ) -> (Vec<[f64; 3]>, Vec<[f64; 3]>) {
        let mob = self.mobility(speed);
        let free: Vec<[f64; 3]> = (self.bodies.iter().zip(qs).enumerate())
            .map(|(i, (b, &q))| {
                if lost[i] {
                    return [0.0; 3];
                }
                let w = field.wrench(b, q);
                [mob[i][0] * w.fx, mob[i][1] * w.fy, mob[i][2] * w.m]
            })
            .collect();
        let rows = self.rows(qs, lost);
        let xi = solve(&rows, &mob, self.friction, &free);
        (free, xi)
    }

    /// Moves the poses into the plate and apart: the wall's translation, then passes of
    /// pushing each overlapping pair apart along its deepest contact's normal, each body by
    /// its share of the pair's mobility (1/A).
    pub fn separate(&self, qs: &mut [Pose], lost: &[bool]) {
        let keep = |i: usize, q: Pose| self.rim.map_or(q, |rim| rim.project(self.bodies[i], q));
        for (i, q) in qs.iter_mut().enumerate() {
            *q = keep(i, *q);
        }
        for _ in 0..SEPARATION_PASSES {
            let mut moved = false;
            for i in 0..qs.len() {
                for j in i + 1..qs.len() {
                    if lost[i] || lost[j] || !self.near(i, j, qs) {
                        continue;
                    }
                    let cs = shape::contacts(self.pieces[i], qs[i], self.pieces[j], qs[j], 0.0);
                    let Some(c) = cs.iter().min_by(|a, b| a.dist.total_cmp(&b.dist)) else {
                        continue;
                    };
                    if c.dist >= 0.0 {
                        continue;
                    }
                    let (mi, mj) = (1.0 / self.bodies[i].area, 1.0 / self.bodies[j].area);
                    let d = -c.dist;
                    let (si, sj) = (d * mi / (mi + mj), d * mj / (mi + mj));
                    let n = c.normal;
                    qs[i] =
                        keep(i, Pose { x: qs[i].x - si * n[0], y: qs[i].y - si * n[1], ..qs[i] });
                    qs[j] =
                        keep(j, Pose { x: qs[j].x + sj * n[0], y: qs[j].y + sj * n[1], ..qs[j] });
                    moved = true;
                }
            }
            if !moved {
                break;
            }
        }
    }

    /// The deepest overlap of any two bodies at `qs` (mm).
    pub(crate) fn max_overlap(&self, qs: &[Pose], lost: &[bool]) -> f64 {
        let mut worst = 0.0f64;
        for i in 0..qs.len() {
            for j in i + 1..qs.len() {
                if !lost[i] && !lost[j] && self.near(i, j, qs) {
                    worst = worst.max(shape::overlap(self.pieces[i], qs[i], self.pieces[j], qs[j]));
                }
            }
        }
        worst
    }
}

/// Picks a row entry's normal or tangent Jacobian.
type Pick = fn(&(usize, [f64; 3], [f64; 3])) -> [f64; 3];

/// Projected Gauss–Seidel on the contact rows: diagonal mobilities `mob`, friction `mu`, the
/// free twists. Returns the constrained twists.
fn solve(rows: &[Row], mob: &[[f64; 3]], mu: f64, free: &[[f64; 3]]) -> Vec<[f64; 3]> {
    let mut xi = free.to_vec();
    if rows.is_empty() {
        return xi;
    }
    let eff = |on: &[(usize, [f64; 3], [f64; 3])], pick: Pick| {
        on.iter()
            .map(|e| {
                let j = pick(e);
                (0..3).map(|k| j[k] * j[k] * mob[e.0][k]).sum::<f64>()
            })
            .sum::<f64>()
            .max(1e-300)
    };
    let normal = |e: &(usize, [f64; 3], [f64; 3])| e.1;
    let tangent = |e: &(usize, [f64; 3], [f64; 3])| e.2;
    let effs: Vec<(f64, f64)> =
        rows.iter().map(|r| (eff(&r.on, normal), eff(&r.on, tangent))).collect();
    let scale = free.iter().map(|f| f[0].hypot(f[1])).fold(1e-300, f64::max);
    let mut lam = vec![[0.0f64; 2]; rows.len()];
    for _ in 0..SWEEPS {
        let mut change = 0.0f64;
        for (k, row) in rows.iter().enumerate() {
            let speed = |xi: &[[f64; 3]], pick: Pick| {
                row.on
                    .iter()
                    .map(|e| (0..3).map(|c| pick(e)[c] * xi[e.0][c]).sum::<f64>())
                    .sum::<f64>()
            };
            let apply = |xi: &mut [[f64; 3]], d: f64, pick: Pick| {
                for e in &row.on {
                    let j = pick(e);
                    for c in 0..3 {
                        xi[e.0][c] += mob[e.0][c] * j[c] * d;
                    }
                }
            };
            let ln = (lam[k][0] - speed(&xi, normal) / effs[k].0).max(0.0);
            apply(&mut xi, ln - lam[k][0], normal);
            change = change.max((ln - lam[k][0]).abs() * effs[k].0);
            lam[k][0] = ln;
            let bound = mu * ln;
            let lt = (lam[k][1] - speed(&xi, tangent) / effs[k].1).clamp(-bound, bound);
            apply(&mut xi, lt - lam[k][1], tangent);
            change = change.max((lt - lam[k][1]).abs() * effs[k].1);
            lam[k][1] = lt;
        }
        if change < 1e-9 * scale {
            break;
        }
    }
    xi
}

/// Integrates the group's quasi-static motion from `start` under one mode: Heun's method with
/// the error-controlled step of [`crate::motion::integrate::run`] (each body's error at most
/// [`STEP_TOL`] of its radius; one step for all), the poses separated after every stage.
pub(crate) fn run_many(
    g: &Group<'_>,
    field: &FieldModel,
    speed: f64,
    t_limit: f64,
    run_to_limit: bool,
    start: &[Pose],
    lost_in: &[bool],
) -> ManyRun {
    let n = start.len();
    let gain = field.max_gain().max(1e-9);
    let r: Vec<f64> = (0..n).map(|i| g.radius(i)).collect();
    let t0: Vec<f64> = r.iter().map(|r| r / (speed * gain)).collect();
    let t0_min = t0.iter().copied().fold(f64::INFINITY, f64::min);
    let mut lost = lost_in.to_vec();
    let fell = |q: Pose| g.rim.is_some_and(|rim| rim.lost(q));
    let mut qs = start.to_vec();
    g.separate(&mut qs, &lost);
    let vel = |qs: &[Pose], lost: &[bool]| g.twists(field, speed, qs, lost).1;
    let mut v0 = vel(&qs, &lost);
    let (mut t, mut steps, mut rested) = (0.0, 0, false);
    let mut dt_next = 0.05 * t0_min;
    let mut trace = vec![(0.0, qs.clone())];
    while t < t_limit && steps < MAX_STEPS {
        steps += 1;
        let moving = |i: usize, v: [f64; 3]| {
            !lost[i] && (v[0].hypot(v[1]) >= 1e-3 * r[i] / t0[i] || v[2].abs() >= 1e-4 / t0[i])
        };
        if !(0..n).any(|i| moving(i, v0[i])) {
            rested = true;
            break;
        }
        let mut dt = (dt_next.min(10.0 * t0_min)).min(t_limit - t);
        for i in (0..n).filter(|&i| !lost[i]) {
            let s = v0[i][0].hypot(v0[i][1]);
            dt = dt.min(0.25 * r[i] / s.max(1e-30)).min(0.1 / v0[i][2].abs().max(1e-30));
        }
        let scales = Scales { r: &r, t0: &t0 };
        let (next, v1, taken) =
            advance(g, field, speed, (&qs, &v0), &lost, scales, dt, &mut dt_next);
        if next == qs {
            rested = true;
            break;
        }
        t += taken;
        qs = next;
        v0 = v1;
        for i in 0..n {
            if !lost[i] && fell(qs[i]) {
                lost[i] = true;
                v0[i] = [0.0; 3];
            }
        }
        trace.push((t, qs.clone()));
        if lost.iter().all(|&l| l) {
            break;
        }
    }
    if run_to_limit && t < t_limit {
        t = t_limit;
        trace.push((t, qs.clone()));
    }
    ManyRun { poses: qs, lost, trace, t_end: t, rested, steps }
}

/// Per-body length and time scales of a run: the radius (mm) and T₀, the time to travel one
/// radius at full pull (s).
#[derive(Clone, Copy)]
struct Scales<'a> {
    r: &'a [f64],
    t0: &'a [f64],
}

/// One accepted step of [`run_many`] from poses `qs` with velocities `v0` (the pair `now`):
/// Heun's method with the contacts resolved after each stage, the step `dt` shrunk on an
/// overshoot or an error over [`STEP_TOL`] (at most 30 times), and `dt_next` set for the
/// next step. Returns the new poses, their velocities and the step taken (s: the clock must
/// advance by what was integrated, not by what was offered); the same poses when the bodies
/// chatter in place (at rest against a contact).
#[allow(clippy::too_many_arguments)]
fn advance(
    g: &Group<'_>,
    field: &FieldModel,
    speed: f64,
    now: (&[Pose], &[[f64; 3]]),
    lost: &[bool],
    scales: Scales<'_>,
    mut dt: f64,
    dt_next: &mut f64,
) -> (Vec<Pose>, Vec<[f64; 3]>, f64) {
    let (qs, v0) = now;
    let (n, r, t0) = (qs.len(), scales.r, scales.t0);
    let vel = |qs: &[Pose]| g.twists(field, speed, qs, lost).1;
    let step = |qs: &[Pose], v: &[[f64; 3]], dt: f64| -> Vec<Pose> {
        let mut out: Vec<Pose> = (qs.iter().zip(v))
            .map(|(q, v)| Pose {
                x: q.x + dt * v[0],
                y: q.y + dt * v[1],
                theta: q.theta + dt * v[2],
            })
            .collect();
        g.separate(&mut out, lost);
        out
    };
    let mut tries = 0;
    loop {
        let pred = step(qs, v0, dt);
        let vp = vel(&pred);
        let mut overshoot = false;
        let mut chatter = true;
        let mut err = 0.0f64;
        for i in (0..n).filter(|&i| !lost[i]) {
            let (a, b) = (v0[i], vp[i]);
            let s = a[0].hypot(a[1]);
            let v_tol = 1e-3 * r[i] / t0[i];
            let o = (s > v_tol && b[0] * a[0] + b[1] * a[1] < -0.25 * s * s)
                || (a[2].abs() > 1e-4 / t0[i] && b[2] * a[2] < -0.25 * a[2] * a[2]);
            overshoot |= o;
            if o {
                chatter &=
                    dt * s < 1e-4 * r[i] && dt * a[2].abs() < 1e-5 && s < 0.02 * r[i] / t0[i];
            }
            let e = 0.5 * dt * (b[0] - a[0]).hypot(b[1] - a[1]).hypot(r[i] * (b[2] - a[2]));
            err = err.max(e / (STEP_TOL * r[i]));
        }
        if overshoot && chatter {
            return (qs.to_vec(), v0.to_vec(), dt);
        }
        if (overshoot || err > 1.0) && tries < 30 {
            dt *= if overshoot { 0.5 } else { (0.9 * (1.0 / err).sqrt()).clamp(0.2, 0.5) };
            tries += 1;
            continue;
        }
        *dt_next = dt * (0.9 * (1.0 / err.max(1e-300)).sqrt()).min(2.0);
        let mean: Vec<[f64; 3]> = (v0.iter().zip(&vp))
            .map(|(a, b)| [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), 0.5 * (a[2] + b[2])])
            .collect();
        let q = step(qs, &mean, dt);
        let v = vel(&q);
        return (q, v, dt);
    }
}

/// A whole plan for a group from `start`: the final poses, which bodies were lost, and the
/// trace (times continue across steps).
pub fn simulate_plan_many(
    g: &Group<'_>,
    plate: &PlateModel,
    fields: &[FieldModel],
    steps: &[SimStep],
    start: &[Pose],
) -> ManyRun {
    let mut lost: Vec<bool> = start.iter().map(|&q| g.rim.is_some_and(|rim| rim.lost(q))).collect();
    let mut poses = start.to_vec();
    let mut trace = vec![(0.0, poses.clone())];
    let (mut t0, mut total_steps, mut rested) = (0.0, 0, true);
    for s in steps {
        let mode = &plate.modes[s.mode];
        let speed = mode.speed_mm_s * s.amplitude_ratio * s.amplitude_ratio;
        let r = run_many(g, &fields[s.mode], speed, s.duration_s, true, &poses, &lost);
        trace.extend(r.trace.iter().skip(1).map(|(t, q)| (t0 + t, q.clone())));
        t0 += s.duration_s;
        poses = r.poses;
        lost = r.lost;
        total_steps += r.steps;
        rested &= r.rested;
    }
    ManyRun { poses, lost, trace, t_end: t0, rested, steps: total_steps }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::plate::{DEFAULT_FRICTION, Edge};
    use crate::motion::testkit::{predicted_rest, quad, rect, uniform};

    const W: f64 = 300.0;
    const H: f64 = 200.0;

    fn rim(mu: f64) -> Rim {
        Rim { size_mm: [W, H], edge: Edge::Wall, friction: mu }
    }

    /// Runs `bodies` from `start` under `field` until at rest (speed 10).
    fn settle(bodies: &[&Body], field: &FieldModel, mu: f64, start: &[Pose]) -> (ManyRun, f64) {
        let pieces: Vec<Pieces> = bodies.iter().map(|b| Pieces::of(b)).collect();
        let refs: Vec<&Pieces> = pieces.iter().collect();
        let g = Group { bodies, pieces: &refs, rim: Some(rim(mu)), friction: mu };
        let r = run_many(&g, field, 10.0, 1e4, false, start, &vec![false; start.len()]);
        let worst = (r.trace.iter()).map(|(_, q)| g.max_overlap(q, &r.lost)).fold(0.0, f64::max);
        (r, worst)
    }

    #[test]
    fn parts_far_apart_move_as_each_alone_however_the_time_is_cut() {
        // Two parts far apart on a horizontal sign-law node at y = 120:
        // the group's run must put each where its lone run does, in one run or in ten pieces
        // (the clock counts the steps taken, not those offered and then shrunk).
        let m = crate::motion::testkit::mode(
            "freq_hz = 60\nfield = \"sign\"\nnode = { kind = \"line\", angle_deg = 0.0, offset_mm = 20.0 }",
        );
        let field = FieldModel::new(&m, &crate::motion::testkit::plate(&m));
        let (a, b) = (Body::new(&crate::motion::testkit::holed_part()), Body::new(&quad()));
        let start =
            [Pose { x: 90.0, y: 70.0, theta: 0.3 }, Pose { x: 220.0, y: 150.0, theta: 1.0 }];
        let pieces = [Pieces::of(&a), Pieces::of(&b)];
        let refs: Vec<&Pieces> = pieces.iter().collect();
        let bodies = [&a, &b];
        let g = Group { bodies: &bodies, pieces: &refs, rim: Some(rim(0.0)), friction: 0.0 };
        let alone = |body: &Body, q: Pose| {
            let p = crate::motion::integrate::SimParams {
                speed: 15.0,
                t_limit: 1.5,
                run_to_limit: true,
                rim: Some(rim(0.0)),
            };
            crate::motion::integrate::run(body, &field, p, q).pose
        };
        let want = [alone(&a, start[0]), alone(&b, start[1])];
        for pieces_of_time in [1, 10] {
            let mut qs = start.to_vec();
            for _ in 0..pieces_of_time {
                let dt = 1.5 / pieces_of_time as f64;
                qs = run_many(&g, &field, 15.0, dt, true, &qs, &[false, false]).poses;
            }
            for (q, w) in qs.iter().zip(&want) {
                let d = (q.x - w.x).hypot(q.y - w.y);
                assert!(d < 0.05, "{pieces_of_time} pieces: {q:?} against {w:?} ({d} mm)");
            }
        }
    }

    #[test]
    fn two_parts_pushed_together_by_a_uniform_field_never_overlap() {
        // A quadrilateral and a holed part pushed into the right wall and into each other,
        // from several orientations, frictionless and with friction.
        let (a, b) = (Body::new(&quad()), Body::new(&crate::motion::testkit::holed_part()));
        for mu in [0.0, DEFAULT_FRICTION] {
            for k in 0..6 {
                let th = k as f64 * 1.1;
                let start = [
                    Pose { x: 120.0, y: 100.0 + 3.0 * k as f64, theta: th },
                    Pose { x: 200.0, y: 96.0, theta: -th },
                ];
                let (r, worst) = settle(&[&a, &b], &uniform([1.0, 0.0]), mu, &start);
                assert!(r.rested, "μ {mu}, k {k}: {} steps", r.steps);
                // Penetration tolerance: 10⁻³ of the parts' mean radius.
                let tol = 1e-3 * 0.5 * (a.radius + b.radius);
                assert!(worst <= tol, "μ {mu}, k {k}: overlap {worst} mm > {tol}");
                // They ended touching: the first part rests on the second, not on the wall.
                let pieces = [Pieces::of(&a), Pieces::of(&b)];
                let c = shape::contacts(&pieces[0], r.poses[0], &pieces[1], r.poses[1], 0.05);
                assert!(!c.is_empty(), "μ {mu}, k {k}: {:?}", r.poses);
            }
        }
    }

    #[test]
    fn a_part_pushed_against_a_flat_part_settles_on_the_edge_push_alignment_predicts() {
        // A long bar flush against the right wall is the fence; the quadrilateral pushed
        // into it turns as against the wall (the contact test of motion::contact).
        let bar = Body::new(
            &crate::model::part::Part::new(
                "bar".into(),
                vec![[0.0, 0.0], [10.0, 0.0], [10.0, 180.0], [0.0, 180.0]],
                vec![],
            )
            .unwrap(),
        );
        let q = Body::new(&quad());
        for mu in [0.0, DEFAULT_FRICTION] {
            for k in 0..8 {
                let th0 = k as f64 * 0.78 + 0.1;
                let start = [
                    Pose { x: W - 5.0, y: 100.0, theta: 0.0 },
                    Pose { x: 150.0, y: 100.0, theta: th0 },
                ];
                let (r, worst) = settle(&[&bar, &q], &uniform([1.0, 0.0]), mu, &start);
                let want = predicted_rest(&q, th0);
                let err = (r.poses[1].theta - want).to_degrees();
                assert!(r.rested, "μ {mu}, θ0 {th0}");
                assert!(err.abs() < 0.3, "μ {mu}, θ0 {th0}: {} vs {want}", r.poses[1].theta);
                assert!((r.poses[0].theta).abs() < 1e-6 && (r.poses[0].x - (W - 5.0)).abs() < 1e-3);
                assert!(worst <= 1e-3 * q.radius, "{worst}");
            }
        }
    }

    #[test]
    fn a_part_resting_on_another_holds_inside_the_friction_cone_and_slides_outside_it() {
        // Two rectangles stacked against the right wall (long sides vertical, flush), pulled
        // into the wall and along it: inside the cone nothing moves; outside, the stack slides
        // as one at μ·(F_t − μ_c·F_n)/A (no slip between them, so their friction is static).
        let body = Body::new(&rect());
        let pieces = [Pieces::of(&body), Pieces::of(&body)];
        let refs = [&pieces[0], &pieces[1]];
        let mu = 0.5;
        let g = Group { bodies: &[&body, &body], pieces: &refs, rim: Some(rim(mu)), friction: mu };
        let up = std::f64::consts::FRAC_PI_2;
        let at =
            [Pose { x: W - 5.0, y: 100.0, theta: up }, Pose { x: W - 15.0, y: 100.0, theta: up }];
        for (tan, slides) in [(0.3, false), (0.49, false), (0.7, true), (1.5, true)] {
            let n = (1.0f64 + tan * tan).sqrt();
            let f = uniform([1.0 / n, tan / n]);
            let (_, v) = g.twists(&f, 10.0, &at, &[false, false]);
            let want_vy = if slides { 10.0 * (tan - mu) / n } else { 0.0 };
            for vi in &v {
                assert!(vi[0].abs() < 1e-7 && vi[2].abs() < 1e-7, "tan {tan}: {v:?}");
                assert!((vi[1] - want_vy).abs() < 1e-7, "tan {tan}: {v:?} want {want_vy}");
            }
        }
        // The outer rectangle alone on the inner one (the inner held by the wall): its own
        // cone decides.
        let f = uniform([1.0 / 1.04f64.sqrt(), 0.2 / 1.04f64.sqrt()]);
        let r = run_many(&g, &f, 10.0, 1.0, true, &at, &[false, false]);
        assert!(
            (r.poses[1].y - 100.0).abs() < 1e-9 && (r.poses[0].y - 100.0).abs() < 1e-9,
            "{:?}",
            r.poses
        );
    }

    #[test]
    fn contacts_between_parts_never_feed_energy_in() {
        // At poses where three parts and the walls touch, under fields of all directions: the
        // field's power is never negative and the contact forces' power never positive; and
        // over a run the field's potential (−Σ F·x for a uniform pull) never rises.
        let (a, b) = (Body::new(&quad()), Body::new(&rect()));
        let bodies = [&a, &b, &a];
        let pieces: Vec<Pieces> = bodies.iter().map(|x| Pieces::of(x)).collect();
        let refs: Vec<&Pieces> = pieces.iter().collect();
        let g = Group { bodies: &bodies, pieces: &refs, rim: Some(rim(0.47)), friction: 0.47 };
        let lost = [false; 3];
        let mut touched = 0;
        for k in 0..200 {
            let a = k as f64 * 2.399;
            let f = uniform([a.cos(), a.sin()]);
            let base = [(k as f64 * 0.618_034 % 1.0) * W, (k as f64 * 0.414_214 % 1.0) * H];
            let mut qs: Vec<Pose> = (0..3)
                .map(|i| Pose {
                    x: base[0] + 18.0 * i as f64,
                    y: base[1] + 7.0 * i as f64,
                    theta: k as f64 * 0.77 + i as f64,
                })
                .collect();
            g.separate(&mut qs, &lost);
            let (free, v) = g.twists(&f, 10.0, &qs, &lost);
            let mob = g.mobility(10.0);
            touched += usize::from(v != free);
            let (mut field, mut contact, mut scale) = (0.0, 0.0, 0.0f64);
            for i in 0..3 {
                let w = f.wrench(bodies[i], qs[i]);
                field += w.fx * v[i][0] + w.fy * v[i][1] + w.m * v[i][2];
                contact +=
                    (0..3).map(|c| v[i][c] * (v[i][c] - free[i][c]) / mob[i][c]).sum::<f64>();
                scale = scale.max(w.fx.hypot(w.fy) * free[i][0].hypot(free[i][1]));
            }
            assert!(field >= -1e-7 * scale, "{qs:?}: field power {field}");
            assert!(contact <= 1e-7 * scale, "{qs:?}: contact power {contact}");
        }
        assert!(touched > 50, "{touched}");
        // A run into the bottom-right corner: the potential never rises by more than the
        // separation's pushes (10⁻³ R of force × distance).
        let dir = [0.8, -0.6];
        let f = uniform(dir);
        let start = [
            Pose { x: 100.0, y: 120.0, theta: 0.3 },
            Pose { x: 160.0, y: 90.0, theta: 1.0 },
            Pose { x: 220.0, y: 60.0, theta: 2.0 },
        ];
        let r = run_many(&g, &f, 10.0, 1e4, false, &start, &lost);
        let u = |qs: &[Pose]| -> f64 {
            (0..3).map(|i| -bodies[i].area * (dir[0] * qs[i].x + dir[1] * qs[i].y)).sum()
        };
        let slack = 1e-3 * a.radius * (a.area + b.area + a.area);
        for w in r.trace.windows(2) {
            assert!(u(&w[1].1) <= u(&w[0].1) + slack, "{} -> {}", u(&w[0].1), u(&w[1].1));
        }
        assert!(u(&r.poses) < u(&start) - 1000.0);
    }
}
