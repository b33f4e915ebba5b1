//! The integrator of the quasi-static motion (docs/motion.md): velocity = μ·F/area, angular
//! velocity = μ·M/J (J = polar moment of area about the centroid), integrated by Heun's
//! method with an error-controlled step until F and M vanish or the time limit.
//!
//! Units: mm, s, rad.

use crate::model::plate::{Mode, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;

/// One simulated run.
#[derive(Debug, Clone)]
pub struct Run {
    /// Final pose.
    pub pose: Pose,
    /// Time at which the pose last left the settle band around the final pose (s).
    pub settle_s: f64,
    /// Simulated time (s).
    pub t_end: f64,
    /// (t, pose) samples.
    pub trace: Vec<(f64, Pose)>,
    /// Came to rest (|F|, |M| below tolerance) before the time limit.
    pub rested: bool,
    /// Integration steps taken.
    pub steps: usize,
    /// Fell off an open edge (centroid off the plate); the run stopped there.
    pub lost: bool,
}

/// Simulation settings.
#[derive(Debug, Clone, Copy)]
pub struct SimParams {
    /// Settle speed μ (mm/s per unit force per area).
    pub speed: f64,
    /// Stop at this time (s) even if still moving; `None`: until at rest.
    pub t_limit: f64,
    /// Keep running to `t_limit` after coming to rest (plans: step durations are fixed).
    pub run_to_limit: bool,
    /// The plate's rim ([`Rim::of`]); `None`: an unbounded plane (the field alone).
    pub rim: Option<Rim>,
}

/// A run to rest stops at this many T₀ ([`t0`]): the limit of simulated maps, feed-region runs
/// and dynamic maps' crossings. A part not at rest by then is creeping or cycling.
pub const REST_LIMIT_T0: f64 = 5000.0;

/// T₀ (s), the time scale of every run: how long a part of radius `radius` (mm) takes to travel
/// one radius at the field's full pull at settle speed `speed`.
pub fn t0(radius: f64, speed: f64, field: &FieldModel) -> f64 {
    radius / (speed * field.max_gain().max(1e-9))
}

impl SimParams {
    /// A run under `mode` on `plate`, stopped at `t_limit` (s) or at rest: the mode's own
    /// speed inside the plate's rim (as `simulate_plan` runs a step at the mode's amplitude).
    pub fn under(mode: &Mode, plate: &PlateModel, t_limit: f64) -> SimParams {
        SimParams {
            speed: mode.speed_mm_s,
            t_limit,
            run_to_limit: false,
            rim: Some(Rim::of(plate)),
        }
    }

    /// A run of `body` to rest under `mode` (its `field`) on `plate`: [`SimParams::under`]
    /// stopped at [`REST_LIMIT_T0`] T₀.
    pub fn to_rest(body: &Body, mode: &Mode, field: &FieldModel, plate: &PlateModel) -> SimParams {
        SimParams::under(mode, plate, REST_LIMIT_T0 * t0(body.radius, mode.speed_mm_s, field))
    }
}

/// Local error allowed per integration step, as a fraction of the part's radius R (angles
/// count as arc length at R). Heun's method is second order, so its error per step is about
/// its difference from the Euler step. At 10⁻³ R the feed-region and orientation-set plans
/// of docs/plan.md keep their modes and final orientations (within 0.01°) against the fixed
/// 2 %-of-R steps this replaced, with a third to a half fewer steps; settle times of runs
/// creeping along a node moved towards those of a converged integration (10⁻⁴ R).
pub const STEP_TOL: f64 = 1e-3;

/// How many integration steps [`run_while`] takes between two questions to its caller.
pub(crate) const GO_EVERY: usize = 64;

/// The velocity field of one run: the field's wrench turned into velocities, with the rim's
/// walls and contact forces when there is a rim.
struct Flow<'a> {
    body: &'a Body,
    field: &'a FieldModel,
    p: SimParams,
    /// Part radius R (mm), T₀ (s: one radius at full pull) and the rest tolerances.
    r: f64,
    t0: f64,
    v_tol: f64,
    w_tol: f64,
}

/// A velocity (mm/s, mm/s, rad/s).
type Vel = (f64, f64, f64);

impl Flow<'_> {
    fn vel(&self, q: Pose) -> Vel {
        let (p, body) = (self.p, self.body);
        let w = self.field.wrench(body, q);
        let free =
            (p.speed * w.fx / body.area, p.speed * w.fy / body.area, p.speed * w.m / body.polar);
        match p.rim {
            Some(rim) => {
                let v = rim.constrain(body, p.speed, q, [free.0, free.1, free.2]);
                (v[0], v[1], v[2])
            }
            None => free,
        }
    }

    fn keep(&self, q: Pose) -> Pose {
        self.p.rim.map_or(q, |rim| rim.project(self.body, q))
    }

    fn fell(&self, q: Pose) -> bool {
        self.p.rim.is_some_and(|rim| rim.lost(q))
    }

    /// One accepted Heun step from `pose` (velocity `v0`) trying `dt` first: the step taken,
    /// the new pose and its velocity, and the next step to try. The pose comes back unchanged
    /// when the part chatters about a non-smooth rest (it is at rest).
    fn step(&self, pose: Pose, v0: Vel, mut dt: f64, tol: f64) -> (f64, Pose, Vel, f64) {
        let (r, t0, v_tol, w_tol) = (self.r, self.t0, self.v_tol, self.w_tol);
        let speed = norm(v0.0, v0.1);
        let mut tries = 0;
        loop {
            let pred = self.keep(Pose {
                x: pose.x + dt * v0.0,
                y: pose.y + dt * v0.1,
                theta: pose.theta + dt * v0.2,
            });
            let vp = self.vel(pred);
            let overshoot = (speed > v_tol && vp.0 * v0.0 + vp.1 * v0.1 < -0.25 * speed * speed)
                || (v0.2.abs() > w_tol && vp.2 * v0.2 < -0.25 * v0.2 * v0.2);
            if overshoot && dt * speed < 1e-4 * r && dt * v0.2.abs() < 1e-5 && speed < 0.02 * r / t0
            {
                // Chattering about a non-smooth rest (an edge lying on the node): at rest.
                return (dt, pose, v0, dt);
            }
            // Euler vs Heun: 0.5·dt·|v(pred) − v(pose)|, angles as arc length at R.
            let (ex, ey, er) = (vp.0 - v0.0, vp.1 - v0.1, r * (vp.2 - v0.2));
            let err = 0.5 * dt * (ex * ex + ey * ey + er * er).sqrt();
            if (overshoot || err > tol) && tries < 30 {
                dt *= if overshoot { 0.5 } else { (0.9 * (tol / err).sqrt()).clamp(0.2, 0.5) };
                tries += 1;
                continue;
            }
            // Second order: the error scales as dt², so the next step aims at 0.9·tol.
            let dt_next = dt * (0.9 * (tol / err.max(1e-300)).sqrt()).min(2.0);
            let q = self.keep(Pose {
                x: pose.x + 0.5 * dt * (v0.0 + vp.0),
                y: pose.y + 0.5 * dt * (v0.1 + vp.1),
                theta: pose.theta + 0.5 * dt * (v0.2 + vp.2),
            });
            return (dt, q, self.vel(q), dt_next);
        }
    }
}

/// Integrates the quasi-static motion from `start`: Heun's method (second order) with the
/// step chosen from its embedded error estimate (Euler vs Heun position, at most
/// [`STEP_TOL`]·R per step), halved on overshoot (the velocity reverses across a node).
/// With a rim, every pose is kept inside a wall and the velocity is the field's with the
/// wall's contact forces ([`crate::motion::contact`]); a part off an open edge is lost.
pub fn run(body: &Body, field: &FieldModel, p: SimParams, start: Pose) -> Run {
    run_while(body, field, p, start, &|| true).expect("a run that is never called off ends")
}

/// [`run`], called off (`None`) as soon as `go` says no (asked every [`GO_EVERY`] steps): a
/// caller whose answer no longer depends on the run (a step map's start point already found
/// outside the mode's reach) stops paying for it, e.g. for a run creeping for its whole step
/// budget where the pull vanishes.
pub(crate) fn run_while(
    body: &Body,
    field: &FieldModel,
    p: SimParams,
    start: Pose,
    go: &dyn Fn() -> bool,
) -> Option<Run> {
    run_stuck_after(body, field, p, start, go, STUCK_STEPS)
}

/// [`run_while`] ending a run after `stuck_steps` consecutive steps that move the part only
/// by rounding (`usize::MAX`: never; the tests compare the two).
fn run_stuck_after(
    body: &Body,
    field: &FieldModel,
    p: SimParams,
    start: Pose,
    go: &dyn Fn() -> bool,
    stuck_steps: usize,
) -> Option<Run> {
    let r = body.radius.max(1e-6);
    let t0 = t0(r, p.speed, field);
    // Curved nodes let a part creep slowly along them: a creep below 10⁻³ R per T0 counts as rest.
    let flow = Flow { body, field, p, r, t0, v_tol: 1e-3 * r / t0, w_tol: 1e-4 / t0 };
    let tol = STEP_TOL * r;
    let mut dt_next = 0.05 * t0;
    let mut pose = flow.keep(start);
    let mut t = 0.0;
    let mut lost = flow.fell(pose);
    let mut trace = vec![(0.0, pose)];
    let mut v0 = flow.vel(pose);
    let mut rested = false;
    let mut steps = 0;
    let mut stuck = 0;
    while t < p.t_limit && steps < 20_000 && !lost {
        if steps % GO_EVERY == 0 && !go() {
            return None;
        }
        steps += 1;
        let speed = norm(v0.0, v0.1);
        if speed < flow.v_tol && v0.2.abs() < flow.w_tol {
            rested = true;
            break;
        }
        // Never more than 10 T₀, a quarter radius or 0.1 rad per step, whatever the estimate
        // says: a node narrower than that could be stepped over without a velocity change.
        let dt = dt_next
            .min(10.0 * t0)
            .min(0.25 * r / speed.max(1e-30))
            .min(0.1 / v0.2.abs().max(1e-30))
            .min(p.t_limit - t);
        let (dt, next, v1, dt_after) = flow.step(pose, v0, dt, tol);
        if next == pose {
            rested = true;
            break;
        }
        stuck = if moved_by_rounding(pose, next, r) { stuck + 1 } else { 0 };
        if stuck >= stuck_steps {
            // The step has collapsed to the rounding scale (a contact switching on and off
            // within an ulp): the run cannot advance; it ends where it is, not at rest, as it
            // would at the step cap, with the pose moved by ~1e-13 mm per remaining step.
            break;
        }
        dt_next = dt_after;
        t += dt;
        pose = next;
        v0 = v1;
        trace.push((t, pose));
        lost = flow.fell(pose);
    }
    if p.run_to_limit && t < p.t_limit && !lost {
        t = p.t_limit;
        trace.push((t, pose));
    }
    let settle = settle_time(&trace, pose, 0.02 * r / t0);
    Some(Run { pose, settle_s: settle, t_end: t, trace, rested, steps, lost })
}

/// √(a² + b²) without `hypot`'s guard against overflow, a libm call that was 13 % of a Monte
/// Carlo run's CPU: speeds and steps here are far from overflowing.
fn norm(a: f64, b: f64) -> f64 {
    (a * a + b * b).sqrt()
}

/// Consecutive steps that move the part only by rounding (`moved_by_rounding`) after which
/// [`run_while`] ends the run, not at rest: such a run would otherwise creep by one ulp per
/// step to the 20 000-step cap (measured: runs pushed along a wall on the cantilever's grid
/// modes, 3 Heun evaluations per step, steps of 10⁻¹⁵ T₀; docs/plan.md, "Planning time").
pub(crate) const STUCK_STEPS: usize = 64;

/// Did a step from `a` to `b` move a part of radius `r` by no more than rounding (10⁻⁹ R in
/// position and 10⁻⁹ rad)? A run still coming to rest moves ≥ 10⁻⁶ R per step (speed above
/// the rest tolerance 10⁻³ R/T₀) takes steps that grow by up to 2× each when accepted, so
/// it never stays 64 steps at the rounding scale.
fn moved_by_rounding(a: Pose, b: Pose, r: f64) -> bool {
    norm(b.x - a.x, b.y - a.y) <= 1e-9 * r && (b.theta - a.theta).abs() <= 1e-9
}

/// Settle time: the last time the part was still moving across its node (speed above
/// `v_move`, 2 % of R per T0; a slow creep along a curved node does not count) or its
/// orientation was more than 0.5° from the final one.
fn settle_time(trace: &[(f64, Pose)], end: Pose, v_move: f64) -> f64 {
    let band_th = 0.5f64.to_radians();
    for k in (1..trace.len()).rev() {
        let ((ta, a), (tb, b)) = (trace[k - 1], trace[k]);
        let v = if tb > ta { norm(b.x - a.x, b.y - a.y) / (tb - ta) } else { 0.0 };
        if v > v_move || (b.theta - end.theta).abs() > band_th {
            return tb;
        }
    }
    0.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::grid::Grid;
    use crate::model::part::Part;
    use crate::model::plate::Node;
    use crate::model::plate::PlateModel;
    use crate::motion::testkit::{mode, plate, rect};

    #[test]
    fn a_run_stuck_at_the_rounding_scale_ends_where_the_step_cap_would_end_it() {
        // The crank lever on the cantilever's first solver mode, dropped at the inset corner:
        // pushed along the bottom wall, the step collapses to 10⁻¹⁵ T₀ (a contact switching
        // within an ulp) and, without the stop, creeps one ulp per step to the step cap.
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let part = Part::load(&dir.join("examples/parts/ordinary/crank-lever.json")).unwrap();
        let plate = PlateModel::load(&dir.join("examples/plates/cantilever-6-modes.toml")).unwrap();
        let body = Body::with_samples(&part, 160);
        let mode = &plate.modes[0];
        let f = FieldModel::new(mode, &plate);
        let rim = Rim::of(&plate);
        let p = SimParams::to_rest(&body, mode, &f, &plate);
        let t0 = t0(body.radius, mode.speed_mm_s, &f);
        let start = rim.project(&body, Pose { x: 264.87, y: 35.13, theta: 65.2f64.to_radians() });
        let run = |n| run_stuck_after(&body, &f, p, start, &|| true, n).unwrap();
        let (cut, full) = (run(STUCK_STEPS), run(usize::MAX));
        eprintln!(
            "stuck: {} steps (t {:.3e} s) against {} (t {:.3e} s)",
            cut.steps, cut.t_end, full.steps, full.t_end
        );
        assert_eq!(full.steps, 20_000, "the case no longer gets stuck: choose another");
        assert!(cut.steps < 2_000, "{}", cut.steps);
        assert!(!cut.rested && !full.rested && !cut.lost && !full.lost);
        let d = (cut.pose.x - full.pose.x).hypot(cut.pose.y - full.pose.y);
        assert!(
            d < 1e-6 && (cut.pose.theta - full.pose.theta).abs() < 1e-9,
            "{:?} {:?}",
            cut.pose,
            full.pose
        );
        assert!((cut.settle_s - full.settle_s).abs() < 1e-9 * t0);
    }

    #[test]
    fn a_symmetric_part_turned_by_its_symmetry_runs_the_same() {
        // sampled_map simulates a part of symmetry order m from 360°/m of start orientations
        // only: the run from θ + 180° of a rectangle must be the run from θ, turned.
        let body = Body::with_samples(&rect(), 160);
        let m = mode(
            "freq_hz = 50.0\nnode = { kind = \"hyperbola\", center_mm = [60.0, 100.0], angle_deg = 0.0, a_mm = 70.0, b_mm = 60.0 }",
        );
        let f = FieldModel::new(&m, &plate(&m));
        let p = SimParams { speed: 100.0, t_limit: 1e3, run_to_limit: false, rim: None };
        for th in [25.3f64, 140.0] {
            let q = |t: f64| Pose { x: 20.6, y: 20.6, theta: t.to_radians() };
            let (r0, r1) = (run(&body, &f, p, q(th)), run(&body, &f, p, q(th + 180.0)));
            assert_eq!(r0.rested, r1.rested);
            assert!((r0.pose.x - r1.pose.x).abs() < 1e-6 && (r0.pose.y - r1.pose.y).abs() < 1e-6);
            let dth = (r1.pose.theta - r0.pose.theta).to_degrees() - 180.0;
            assert!(dth.abs() < 1e-6, "{th}: {dth}");
        }
    }

    #[test]
    fn rectangle_settles_long_side_on_a_vertical_node() {
        let body = Body::new(&rect());
        let m = mode(
            "freq_hz = 50.0\nfield = \"sign\"\nnode = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }",
        );
        let f = FieldModel::new(&m, &plate(&m));
        let p = SimParams { speed: 10.0, t_limit: 1e4, run_to_limit: false, rim: None };
        let r = run(&body, &f, p, Pose { x: 100.0, y: 80.0, theta: 0.3 });
        eprintln!("line: {} steps, t = {}, rested {}", r.steps, r.t_end, r.rested);
        assert!(r.rested);
        assert!((r.pose.x - 150.0).abs() < 0.05, "{:?}", r.pose);
        assert!((r.pose.y - 80.0).abs() < 1e-9);
        assert!((r.pose.theta.to_degrees() - 90.0).abs() < 0.5, "{:?}", r.pose);
        assert!(r.settle_s > 4.0 && r.settle_s < r.t_end + 1e-9);
    }

    #[test]
    fn hyperbola_and_grid_pull_parts_onto_their_nodes() {
        let body = Body::new(&rect());
        let m = mode(
            "freq_hz = 50.0\nnode = { kind = \"hyperbola\", center_mm = [100.0, 100.0], angle_deg = 0.0, a_mm = 50.0, b_mm = 50.0 }",
        );
        let f = FieldModel::new(&m, &plate(&m));
        let p = SimParams { speed: 10.0, t_limit: 1e4, run_to_limit: false, rim: None };
        let r = run(&body, &f, p, Pose { x: 200.0, y: 120.0, theta: 0.0 });
        eprintln!("hyperbola: {} steps, t = {}, rested {}", r.steps, r.t_end, r.rested);
        let (u, v) = (r.pose.x - 100.0, r.pose.y - 100.0);
        let on = (u / 50.0).powi(2) - (v / 50.0).powi(2);
        assert!((on - 1.0).abs() < 0.2, "{:?} {on}", r.pose);
        // φ = cos(πx/W): node at x = W/2.
        let (nx, ny) = (31, 21);
        let values = (0..ny)
            .flat_map(|_| {
                (0..nx).map(move |i| (std::f64::consts::PI * i as f64 / (nx - 1) as f64).cos())
            })
            .collect();
        let g = Grid { nx, ny, size_mm: [300.0, 200.0], values };
        let mut m = m.clone();
        m.node = Node::Grid(g);
        let f = FieldModel::new(&m, &plate(&m));
        let r = run(&body, &f, p, Pose { x: 120.0, y: 100.0, theta: 0.3 });
        eprintln!("grid: {} steps, t = {}, rested {}", r.steps, r.t_end, r.rested);
        assert!((r.pose.x - 150.0).abs() < 1.0, "{:?}", r.pose);
        assert!((r.pose.theta.to_degrees().rem_euclid(180.0) - 90.0).abs() < 2.0, "{:?}", r.pose);
    }
}
