//! rapier2d-f64's solver against our own overdamped contact solve (docs/motion.md, "Decision:
//! …"): the same drop of copies of the triangle through its example plan on the four-lines
//! plate, run by [`chladni_core::motion::many`] and by rapier with high damping, from the same
//! seeded non-overlapping start poses. Printed: how far the final poses of the two agree, the
//! oriented fraction each gives, the deepest final overlap each leaves, and the wall time per
//! drop.
//!
//! rapier is made to reproduce the quasi-static law v = μ·F/A, ω = μ·M/J: each body gets mass
//! A and inertia J (density 1 per mm²), linear and angular damping C, and the field's wrench
//! times μ·C as its applied force and torque, so its terminal velocity F/(m·C) is the model's.
//! rapier's damping is implicit (v ← v/(1 + C·dt)), so with C·dt ≫ 1 the velocity after each
//! step is the terminal one: the inertia the model leaves out lasts 1/C = 0.1 ms. No gravity
//! (the plate is the plane), restitution 0, friction the plate's `friction` for walls and
//! pairs (rapier combines two equal coefficients to the same), no sleeping. The rim is four
//! fixed boxes outside the plate's rectangle.
//!
//! Outside the default build (rapier is an optional dependency):
//! `cargo bench -p chladni --features rapier-compare --bench rapier`

use std::time::Instant;

use chladni_core::model::pose::Pose;
use chladni_core::motion::bulk::{BulkReport, Drops, place};
use chladni_core::motion::contact::Rim;
use chladni_core::motion::many::{Group, simulate_plan_many};
use chladni_core::motion::montecarlo::Trials;
use chladni_core::motion::shape;
use chladni_core::rng::Rng;
use rapier2d_f64::prelude::*;

#[path = "support/drop_case.rs"]
mod drop_case;
#[path = "../tests/integration/support/examples.rs"]
mod examples;

use drop_case::DropCase;

/// rapier's damping (1/s): the model's missing inertia lasts 1/C.
const DAMPING: f64 = 1e4;
/// Repetitions of each timed drop.
const REPEAT: u32 = 3;

/// The same drop for both solvers.
type Setup = DropCase;

/// Final poses of one drop by rapier with time step `dt` (s).
fn rapier_drop(s: &Setup, start: &[Pose], dt: f64) -> Vec<Pose> {
    let friction = s.plate.friction;
    let mut world = PhysicsWorld::new();
    world.gravity = Vector::ZERO;
    world.integration_parameters.dt = dt;
    // Tolerances (allowed penetration, prediction distance) scale with the part, not metres.
    world.integration_parameters.length_unit = s.body.radius;
    let [w, h] = s.plate.size_mm;
    let t = 50.0;
    for (x, y, hx, hy) in
        [(-t, h / 2.0, t, h), (w + t, h / 2.0, t, h), (w / 2.0, -t, w, t), (w / 2.0, h + t, w, t)]
    {
        let wall = ColliderBuilder::cuboid(hx, hy)
            .translation(Vector::new(x, y))
            .friction(friction)
            .restitution(0.0);
        world.insert_collider(wall, None);
    }
    let shapes: Vec<(rapier2d_f64::math::Pose, SharedShape)> = (s.pieces.convex.iter())
        .map(|c| (rapier2d_f64::math::Pose::new(Vector::ZERO, 0.0), SharedShape::new(c.clone())))
        .collect();
    let handles: Vec<RigidBodyHandle> = start
        .iter()
        .map(|q| {
            let body = RigidBodyBuilder::dynamic()
                .translation(Vector::new(q.x, q.y))
                .rotation(q.theta)
                .linear_damping(DAMPING)
                .angular_damping(DAMPING)
                .can_sleep(false)
                .additional_mass_properties(MassProperties::new(
                    Vector::ZERO,
                    s.body.area,
                    s.body.polar,
                ));
            let coll = ColliderBuilder::compound(shapes.clone())
                .density(0.0)
                .friction(friction)
                .restitution(0.0);
            world.insert(body, coll).0
        })
        .collect();
    for step in &s.steps {
        let mode = &s.plate.modes[step.mode];
        let k = mode.speed_mm_s * step.amplitude_ratio * step.amplitude_ratio * DAMPING;
        let n = (step.duration_s / dt).round() as usize;
        for _ in 0..n {
            for &hd in &handles {
                let rb = &mut world.bodies[hd];
                let p = rb.translation();
                let q = Pose { x: p.x, y: p.y, theta: rb.rotation().angle() };
                let wr = s.fields[step.mode].wrench(&s.body, q);
                rb.reset_forces(false);
                rb.reset_torques(false);
                rb.add_force(Vector::new(k * wr.fx, k * wr.fy), false);
                rb.add_torque(k * wr.m, false);
            }
            world.step();
        }
    }
    handles
        .iter()
        .map(|&hd| {
            let rb = &world.bodies[hd];
            let p = rb.translation();
            Pose { x: p.x, y: p.y, theta: rb.rotation().angle() }
        })
        .collect()
}

/// Final poses of one drop by our solve (motion::many).
fn own_drop(s: &Setup, start: &[Pose]) -> Vec<Pose> {
    let n = start.len();
    let (b, p) = (vec![&s.body; n], vec![&s.pieces; n]);
    let rim = Rim::of(&s.plate);
    let g = Group { bodies: &b, pieces: &p, rim: Some(rim), friction: rim.friction };
    simulate_plan_many(&g, &s.plate, &s.fields, &s.steps, start).poses
}

/// Wall time per run of `f` (s, mean of [`REPEAT`]) and its last result.
fn timed(f: impl Fn() -> Vec<Pose>) -> (f64, Vec<Pose>) {
    let t = Instant::now();
    let mut out = Vec::new();
    for _ in 0..REPEAT {
        out = f();
    }
    (t.elapsed().as_secs_f64() / f64::from(REPEAT), out)
}

/// Oriented fraction (5°) and deepest overlap (mm) of final poses.
fn judged(s: &Setup, start: &[Pose], finals: &[Pose]) -> (Option<f64>, f64) {
    let per_body = (start.iter().zip(finals))
        .map(|(&a, &b)| Trials {
            starts: vec![a],
            finals: vec![b],
            lost: vec![false],
            ..Default::default()
        })
        .collect();
    let mut deepest = 0.0f64;
    for i in 0..finals.len() {
        for j in i + 1..finals.len() {
            deepest = deepest.max(shape::overlap(&s.pieces, finals[i], &s.pieces, finals[j]));
        }
    }
    let drops = Drops { per_body, max_overlap_mm: deepest };
    (BulkReport::new(&drops, &s.plan, &s.steps, 1, 5.0).oriented, deepest)
}

/// Largest and mean |Δposition| (mm) and |Δθ| (deg) between two sets of final poses.
fn agreement(a: &[Pose], b: &[Pose]) -> ([f64; 2], [f64; 2]) {
    let n = a.len() as f64;
    let (mut dp, mut dt) = ([0.0f64, 0.0], [0.0f64, 0.0]);
    for (p, q) in a.iter().zip(b) {
        let d = (p.x - q.x).hypot(p.y - q.y);
        let t = chladni_core::model::angle::signed_diff(
            p.theta.to_degrees(),
            q.theta.to_degrees(),
            360.0,
        )
        .abs();
        dp = [dp[0].max(d), dp[1] + d / n];
        dt = [dt[0].max(t), dt[1] + t / n];
    }
    (dp, dt)
}

fn main() {
    let s = DropCase::triangle_four_lines();
    for n in [2usize, 10] {
        let (b, p) = (vec![&s.body; n], vec![&s.pieces; n]);
        let d = s.drop(&b, &p);
        let start = place(&mut Rng::seeded(1), &d).expect("the copies fit");
        let (t_own, own) = timed(|| own_drop(&s, &start));
        let (o_own, ov_own) = judged(&s, &start, &own);
        println!(
            "{n} triangles, own solve: {t_own:.3} s/drop, oriented {o_own:?}, overlap {ov_own:.4} mm"
        );
        for dt in [0.01, 0.002] {
            let (t_r, rap) = timed(|| rapier_drop(&s, &start, dt));
            let (o_r, ov_r) = judged(&s, &start, &rap);
            let (dp, da) = agreement(&own, &rap);
            println!(
                "{n} triangles, rapier dt {dt} s: {t_r:.3} s/drop, oriented {o_r:?}, overlap \
                 {ov_r:.4} mm; against own: position max {:.3} mean {:.3} mm, θ max {:.2} \
                 mean {:.2}°",
                dp[0], dp[1], da[0], da[1]
            );
        }
    }
}
