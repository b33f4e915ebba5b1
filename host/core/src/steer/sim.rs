//! An in-process rig for tests and benches: a "true" plate (the given one with known
//! corrections, moving parts by the same motion model, plus noise) and the closed loop run
//! against it (assign, choose, drive, observe, correct), with no camera and no controller.
//!
//! Goals are poses a part can hold: a random drop run to rest under a random mode of the true
//! plate ([`Truth::random_goal`]), so every goal is a rest of some mode near where it lies.

use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::rng::Rng;
use crate::steer::SteerError;
use crate::steer::assign::assign_goals;
use crate::steer::choose::{Menu, Stall, choose};
use crate::steer::correct::Corrector;
use crate::steer::cost::{MM_PER_DEG, PartGoal, Piece, angle_error_deg, distance_mm};
use crate::steer::fit::Burst;
use crate::steer::model::Model;

/// How the true plate's parts stray from the motion model: a diffusion over the time driven
/// (a burst of t s moves a part off its predicted pose by σ·√t along each axis), bounces at
/// random times (a Poisson process), and a camera-sized error on every burst (added to the
/// pose the loop is shown, which is the pose the next burst starts from).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Diffusion: standard deviation of each coordinate's error after 1 s of drive (mm).
    pub mm: f64,
    /// Diffusion: standard deviation of the orientation error after 1 s of drive (deg).
    pub deg: f64,
    /// Bounces per second of drive, per part.
    pub bounces_per_s: f64,
    /// A bounce moves the part by up to this (mm, uniform direction).
    pub bounce_mm: f64,
    /// Standard deviation of each coordinate's error per burst whatever its length (mm):
    /// about `locate`'s on rendered photos (0.04 mm).
    pub camera_mm: f64,
}

impl Default for Noise {
    /// 0.2 mm and 0.5° per √s, a bounce of up to 8 mm every 50 s of drive per part, 0.05 mm
    /// from the camera.
    fn default() -> Self {
        Noise { mm: 0.2, deg: 0.5, bounces_per_s: 0.02, bounce_mm: 8.0, camera_mm: 0.05 }
    }
}

/// The true plate: what really moves the parts.
#[derive(Debug, Clone)]
pub struct Truth {
    /// The true plate (the given one with the true corrections).
    pub model: Model,
    /// Its noise.
    pub noise: Noise,
    rng: Rng,
}

/// A normal deviate (Box–Muller) from the project's generator.
pub fn normal(rng: &mut Rng) -> f64 {
    let u = rng.uniform().max(1e-300);
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * rng.uniform()).cos()
}

impl Truth {
    /// A true plate with `noise`, its randomness from `seed`.
    pub fn new(model: Model, noise: Noise, seed: u64) -> Truth {
        Truth { model, noise, rng: Rng::seeded(seed) }
    }

    /// The parts' poses after mode `mode` is driven for `burst_s`: each part's run under the
    /// true plate, plus noise, kept inside the rim.
    pub fn burst(
        &mut self,
        parts: &[(&Body, Pose)],
        mode: usize,
        burst_s: f64,
    ) -> Result<Vec<Pose>, SteerError> {
        let mut out = Vec::with_capacity(parts.len());
        for (body, pose) in parts {
            let q = self.model.predict(body, *pose, mode, burst_s)?;
            let n = self.noise;
            let s = (n.mm * n.mm * burst_s + n.camera_mm * n.camera_mm).sqrt();
            let (mut dx, mut dy) = (s * normal(&mut self.rng), s * normal(&mut self.rng));
            if self.rng.uniform() < 1.0 - (-n.bounces_per_s * burst_s).exp() {
                let (a, r) =
                    (self.rng.range(0.0, std::f64::consts::TAU), self.rng.range(0.0, n.bounce_mm));
                (dx, dy) = (dx + r * a.cos(), dy + r * a.sin());
            }
            let moved = Pose {
                x: q.x + dx,
                y: q.y + dy,
                theta: q.theta + n.deg.to_radians() * burst_s.sqrt() * normal(&mut self.rng),
            };
            out.push(crate::motion::contact::Rim::of(self.model.given()).project(body, moved));
        }
        Ok(out)
    }

    /// A random pose of `body` on the plate, its bounding circle `margin` mm inside the rim.
    pub fn random_pose(&mut self, body: &Body, margin: f64) -> Pose {
        let [w, h] = self.model.given().size_mm;
        let r = body.radius + margin;
        Pose {
            x: self.rng.range(r, (w - r).max(r)),
            y: self.rng.range(r, (h - r).max(r)),
            theta: self.rng.range(0.0, std::f64::consts::TAU),
        }
    }

    /// A goal `body` can hold: a random drop run to rest under a random mode, kept when it
    /// rests with its bounding circle `margin` mm inside the rim (up to 50 drops; `None`).
    pub fn random_goal(&mut self, body: &Body, margin: f64) -> Option<Pose> {
        let [w, h] = self.model.given().size_mm;
        let n = self.model.mode_count();
        for _ in 0..50 {
            let drop = self.random_pose(body, margin);
            let mode = ((self.rng.uniform() * n as f64) as usize).min(n.saturating_sub(1));
            let run = self.model.run_to_rest(body, drop, mode);
            let r = body.radius + margin;
            let q = run.pose;
            if run.rested && q.x > r && q.y > r && q.x < w - r && q.y < h - r {
                return Some(q);
            }
        }
        None
    }
}

/// How a trial runs.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialOptions {
    /// Position tolerance (mm).
    pub tol_mm: f64,
    /// Orientation tolerance (deg).
    pub tol_deg: f64,
    /// Drive-time limit (s): the sum of the bursts driven.
    pub time_limit_s: f64,
    /// Cycle limit.
    pub max_cycles: usize,
    /// Orientations count (cost and tolerance); `false`: positions only.
    pub orientation: bool,
    /// The commands.
    pub menu: Menu,
    /// Correct the model online from each burst.
    pub correct: bool,
}

/// How a trial ended.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialResult {
    /// Every part within tolerance of its goal at the end.
    pub reached: bool,
    /// Cycles run (one command each).
    pub cycles: usize,
    /// Drive time (s).
    pub drive_s: f64,
    /// Each part's goal (after assignment) and final pose.
    pub goals: Vec<Pose>,
    /// Each part's final pose.
    pub poses: Vec<Pose>,
    /// Each part's final position error (mm).
    pub error_mm: Vec<f64>,
    /// Each part's final orientation error (deg).
    pub error_deg: Vec<f64>,
}

/// The closed loop against `truth`: identical parts (`piece` at each of `starts`), each
/// cycle assigned to `goals` ([`assign_goals`]), weighed by the loop's progress ([`Stall`]),
/// then choose → drive
/// → observe (→ correct `model`) until every part is within tolerance or the drive time is
/// spent.
pub fn steer_trial(
    truth: &mut Truth,
    model: &mut Model,
    piece: &Piece,
    starts: &[Pose],
    goals: &[Pose],
    opt: &TrialOptions,
) -> Result<TrialResult, SteerError> {
    let mm_per_deg = if opt.orientation { MM_PER_DEG } else { 0.0 };
    let tol_deg = if opt.orientation { opt.tol_deg } else { 360.0 };
    let mut parts: Vec<PartGoal> =
        starts.iter().map(|s| PartGoal { mm_per_deg, ..PartGoal::new(piece, *s, *s) }).collect();
    let pieces = std::slice::from_ref(piece);
    let mut corrector = Corrector::new(model.mode_count());
    let (mut cycles, mut drive_s) = (0, 0.0);
    let within = |parts: &[PartGoal]| parts.iter().all(|p| p.within(p.pose, opt.tol_mm, tol_deg));
    let mut stall = Stall::new();
    loop {
        // Identical parts: each cycle, the goals go to the parts that are nearest them now.
        parts = assign_goals(&parts, goals)?;
        if within(&parts) || drive_s >= opt.time_limit_s || cycles >= opt.max_cycles {
            break;
        }
        let cmd = choose(model, &stall.weigh(&parts), &opt.menu)?;
        let before: Vec<(&Body, Pose)> = parts.iter().map(|p| (&p.piece.body, p.pose)).collect();
        let after = truth.burst(&before, cmd.mode, cmd.burst_s)?;
        if opt.correct {
            let seen = before.iter().zip(&after).map(|((_, b), a)| (0, *b, *a)).collect();
            corrector.observe(
                model,
                pieces,
                Burst { mode: cmd.mode, burst_s: cmd.burst_s, parts: seen },
            )?;
        }
        for (p, q) in parts.iter_mut().zip(after) {
            p.pose = q;
        }
        cycles += 1;
        drive_s += cmd.burst_s;
    }
    Ok(TrialResult {
        reached: within(&parts),
        cycles,
        drive_s,
        goals: parts.iter().map(|p| p.goal).collect(),
        poses: parts.iter().map(|p| p.pose).collect(),
        error_mm: parts.iter().map(|p| distance_mm(p.pose, p.goal)).collect(),
        error_deg: parts
            .iter()
            .map(|p| angle_error_deg(p.pose, p.goal, p.piece.period_deg))
            .collect(),
    })
}
