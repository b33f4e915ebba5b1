//! The simulated plate: parts that move by the project's motion model on the true plate, for
//! the stretches of drive the controller reports ([`crate::drive`]), with bouncing noise.

use chladni_core::model::part::Part;
use chladni_core::model::plate::on_plate;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::bulk::{Drop, place};
use chladni_core::motion::contact::Rim;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::many::{Group, simulate_plan_many};
use chladni_core::motion::shape::{self, Pieces};
use chladni_core::motion::steps::{SimStep, simulate_plan};
use chladni_core::rng::Rng;
use chladni_media::vision::synth::Placed;
use chladni_shared::icd::link::StatusReport;
use serde::Serialize;

use crate::RigError;
use crate::camera::{Camera, Format};
use crate::drive::{Stretch, stretches};
use crate::truth::{ModeTruth, TruePlate};

/// A drive frequency within this share of a mode's (or [`MODE_TOL_HZ`], the larger) drives
/// that mode.
pub const MODE_TOL: f64 = 0.005;
/// A drive frequency within this many Hz of a mode's drives it (see [`MODE_TOL`]).
pub const MODE_TOL_HZ: f64 = 0.5;

/// The longest stretch of drive the parts are moved by at once: how often they are sorted
/// again into those that may touch and those that may not (the poll period).
pub const CHUNK_S: f64 = 0.02;
/// The reach of a part within a chunk beyond 3× its distance at its present speed (mm): parts
/// farther apart than their reaches run alone.
pub const REACH_SLACK_MM: f64 = 1.0;

/// Bouncing noise while the drive is on: a random walk of σ = `mm`·√(t / 1 s) on each axis
/// of the position and `deg`·√(t / 1 s) in the angle.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Noise {
    /// Position, mm per √s.
    pub mm: f64,
    /// Angle, degrees per √s.
    pub deg: f64,
}

/// The default noise: parts wander 0.15 mm and 0.5° in a second of drive.
pub const DEFAULT_NOISE: Noise = Noise { mm: 0.15, deg: 0.5 };

/// What a rig is made of.
#[derive(Debug, Clone)]
pub struct RigConfig {
    /// The plate the parts move on.
    pub plate: TruePlate,
    /// The part kinds.
    pub kinds: Vec<Part>,
    /// Each part on the plate: its kind (index into `kinds`).
    pub parts: Vec<usize>,
    /// Start poses, one per part; `None`: random drops, none overlapping another.
    pub at: Option<Vec<Pose>>,
    /// Seed of the drops and the noise.
    pub seed: u64,
    /// Bouncing noise.
    pub noise: Noise,
}

/// One part's true pose, as `/truth` reports it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartTruth {
    /// Fell off an open edge (no longer in the picture).
    pub lost: bool,
    /// The part's name.
    pub part: String,
    /// Orientation (deg CCW, in [0, 360)).
    pub theta_deg: f64,
    /// Centroid x (mm).
    pub x_mm: f64,
    /// Centroid y (mm).
    pub y_mm: f64,
}

/// The rig's state, as `GET /truth` answers it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Truth {
    /// The controller's sample clock at the state (samples).
    pub clock: u64,
    /// Drive time on a mode of the true plate so far (s).
    pub drive_s: f64,
    /// The true plate's modes.
    pub modes: Vec<ModeTruth>,
    /// Each part.
    pub parts: Vec<PartTruth>,
}

/// The virtual plate with its parts.
#[derive(Debug, Clone)]
pub struct Rig {
    plate: TruePlate,
    fields: Vec<FieldModel>,
    kinds: Vec<Part>,
    kind_of: Vec<usize>,
    bodies: Vec<Body>,
    pieces: Vec<Pieces>,
    poses: Vec<Pose>,
    lost: Vec<bool>,
    rng: Rng,
    noise: Noise,
    drive_s: f64,
    clock: u64,
}

impl Rig {
    /// The plate with its parts at their start poses.
    pub fn new(config: RigConfig) -> Result<Rig, RigError> {
        let RigConfig { plate, kinds, parts, at, seed, noise } = config;
        if parts.is_empty() {
            return Err(RigError::NoParts);
        }
        if let Some((i, &kind)) = parts.iter().enumerate().find(|(_, k)| **k >= kinds.len()) {
            return Err(RigError::NoSuchKind { part: i + 1, kind, kinds: kinds.len() });
        }
        let fields = plate.model.modes.iter().map(|m| FieldModel::new(m, &plate.model)).collect();
        let bodies: Vec<Body> = parts.iter().map(|&k| Body::new(&kinds[k])).collect();
        let pieces: Vec<Pieces> = bodies.iter().map(Pieces::of).collect();
        let mut rng = Rng::seeded(seed);
        let poses = match at {
            Some(at) => check_at(&plate, &bodies, &pieces, at)?,
            None => {
                let (b, p): (Vec<&Body>, Vec<&Pieces>) = bodies.iter().zip(&pieces).unzip();
                let drop = Drop {
                    bodies: &b,
                    pieces: &p,
                    plate: &plate.model,
                    fields: &[],
                    steps: &[],
                    feed: None,
                };
                place(&mut rng, &drop)?
            }
        };
        let lost = vec![false; poses.len()];
        let (kind_of, drive_s, clock) = (parts, 0.0, 0);
        Ok(Rig {
            plate,
            fields,
            kinds,
            kind_of,
            bodies,
            pieces,
            poses,
            lost,
            rng,
            noise,
            drive_s,
            clock,
        })
    }

    /// The true plate.
    pub fn plate(&self) -> &TruePlate {
        &self.plate
    }

    /// Each part's pose.
    pub fn poses(&self) -> &[Pose] {
        &self.poses
    }

    /// Which parts fell off an open edge.
    pub fn lost(&self) -> &[bool] {
        &self.lost
    }

    /// Moves the parts for what the controller drove between two polls of its status
    /// ([`stretches`]); returns those stretches.
    pub fn step(&mut self, before: &StatusReport, after: &StatusReport) -> Vec<Stretch> {
        let driven = stretches(before, after);
        for s in &driven {
            self.drive(s);
        }
        self.clock = after.clock;
        driven
    }

    /// Moves the parts for one stretch of drive: by the motion model under the true plate's
    /// mode at its frequency (if any), at a speed scaled by (amplitude / the mode's
    /// amplitude)², then the bouncing noise for its time (no noise without output).
    pub fn drive(&mut self, s: &Stretch) {
        if !(s.seconds > 0.0 && s.amplitude > 0.0) {
            return;
        }
        if let Some(k) = self.mode_at(f64::from(s.freq_mhz) / 1000.0) {
            let ratio = s.amplitude / self.plate.model.modes[k].amplitude;
            self.advance(SimStep { mode: k, duration_s: s.seconds, amplitude_ratio: ratio });
            self.drive_s += s.seconds;
        }
        self.jitter(s.seconds);
    }

    /// The true plate's mode driven at `freq_hz`: the nearest within [`MODE_TOL`] or
    /// [`MODE_TOL_HZ`].
    pub fn mode_at(&self, freq_hz: f64) -> Option<usize> {
        let off = |f: f64| (f - freq_hz).abs();
        (self.plate.model.modes.iter().enumerate())
            .filter(|(_, m)| off(m.freq_hz) <= (MODE_TOL * m.freq_hz).max(MODE_TOL_HZ))
            .min_by(|a, b| off(a.1.freq_hz).total_cmp(&off(b.1.freq_hz)))
            .map(|(k, _)| k)
    }

    /// Runs the motion model for one step, in chunks of at most [`CHUNK_S`]: in each, the
    /// parts that cannot touch another run alone (`integrate::run`, through `simulate_plan`),
    /// those that may run together with their contacts (`many`).
    fn advance(&mut self, step: SimStep) {
        let chunks = (step.duration_s / CHUNK_S).ceil().max(1.0);
        let chunk = SimStep { duration_s: step.duration_s / chunks, ..step };
        for _ in 0..chunks as usize {
            for cluster in self.clusters(&chunk) {
                self.advance_cluster(&cluster, chunk);
            }
        }
    }

    /// The parts (not lost) in groups that may touch within `step`: bounding circles closer
    /// than each part's reach, [`REACH_SLACK_MM`] plus 3× its distance at its present speed.
    fn clusters(&self, step: &SimStep) -> Vec<Vec<usize>> {
        let speed = self.plate.model.modes[step.mode].speed_mm_s * step.amplitude_ratio.powi(2);
        let field = &self.fields[step.mode];
        let reach: Vec<f64> = (self.bodies.iter().zip(&self.poses))
            .map(|(b, &q)| {
                let w = field.wrench(b, q);
                REACH_SLACK_MM + 3.0 * speed * w.fx.hypot(w.fy) / b.area * step.duration_s
            })
            .collect();
        let n = self.poses.len();
        let mut root: Vec<usize> = (0..n).collect();
        let find = |root: &[usize], mut i: usize| {
            while root[i] != i {
                i = root[i];
            }
            i
        };
        for i in (0..n).filter(|&i| !self.lost[i]) {
            for j in (0..i).filter(|&j| !self.lost[j]) {
                let (a, b) = (self.poses[i], self.poses[j]);
                let limit = self.bodies[i].radius + self.bodies[j].radius + reach[i] + reach[j];
                if (a.x - b.x).hypot(a.y - b.y) <= limit {
                    let (ri, rj) = (find(&root, i), find(&root, j));
                    root[ri.max(rj)] = ri.min(rj);
                }
            }
        }
        let mut out: Vec<Vec<usize>> = Vec::new();
        for i in (0..n).filter(|&i| !self.lost[i]) {
            let r = find(&root, i);
            match out.iter_mut().find(|c| find(&root, c[0]) == r) {
                Some(c) => c.push(i),
                None => out.push(vec![i]),
            }
        }
        out
    }

    /// Runs one cluster of parts for `step`.
    fn advance_cluster(&mut self, cluster: &[usize], step: SimStep) {
        let plate = &self.plate.model;
        let rim = Rim::of(plate);
        if let [i] = *cluster {
            let (poses, _, _) =
                simulate_plan(&self.bodies[i], plate, &self.fields, &[step], self.poses[i]);
            self.poses[i] = poses.last().copied().unwrap_or(self.poses[i]);
            self.lost[i] = rim.lost(self.poses[i]);
            return;
        }
        let bodies: Vec<&Body> = cluster.iter().map(|&i| &self.bodies[i]).collect();
        let pieces: Vec<&Pieces> = cluster.iter().map(|&i| &self.pieces[i]).collect();
        let start: Vec<Pose> = cluster.iter().map(|&i| self.poses[i]).collect();
        let g = Group { bodies: &bodies, pieces: &pieces, rim: Some(rim), friction: rim.friction };
        let run = simulate_plan_many(&g, plate, &self.fields, &[step], &start);
        for (k, &i) in cluster.iter().enumerate() {
            self.poses[i] = run.poses[k];
            self.lost[i] = run.lost[k];
        }
    }

    /// The bouncing noise of `seconds` of drive, then the poses kept inside the rim and apart.
    fn jitter(&mut self, seconds: f64) {
        let (s_mm, s_rad) =
            (self.noise.mm * seconds.sqrt(), (self.noise.deg * seconds.sqrt()).to_radians());
        if s_mm == 0.0 && s_rad == 0.0 {
            return;
        }
        for (q, &lost) in self.poses.iter_mut().zip(&self.lost) {
            if !lost {
                q.x += s_mm * gaussian(&mut self.rng);
                q.y += s_mm * gaussian(&mut self.rng);
                q.theta += s_rad * gaussian(&mut self.rng);
            }
        }
        let bodies: Vec<&Body> = self.bodies.iter().collect();
        let pieces: Vec<&Pieces> = self.pieces.iter().collect();
        let rim = Rim::of(&self.plate.model);
        let g = Group { bodies: &bodies, pieces: &pieces, rim: Some(rim), friction: rim.friction };
        g.separate(&mut self.poses, &self.lost);
        for (q, lost) in self.poses.iter().zip(self.lost.iter_mut()) {
            *lost |= rim.lost(*q);
        }
    }

    /// The robot's pick: the part (not lost) whose centroid lies nearest `[x, y]` (mm), within
    /// `radius_mm`, leaves the plate; its state just before. `None`: no part there.
    pub fn pick(&mut self, x: f64, y: f64, radius_mm: f64) -> Option<PartTruth> {
        let d = |q: &Pose| (q.x - x).hypot(q.y - y);
        let k = (0..self.poses.len())
            .filter(|&i| !self.lost[i] && d(&self.poses[i]) <= radius_mm)
            .min_by(|&a, &b| d(&self.poses[a]).total_cmp(&d(&self.poses[b])))?;
        let picked = self.part_truth(k);
        self.kind_of.remove(k);
        self.bodies.remove(k);
        self.pieces.remove(k);
        self.poses.remove(k);
        self.lost.remove(k);
        Some(picked)
    }

    /// Part `k`'s state, as `/truth` reports it.
    fn part_truth(&self, k: usize) -> PartTruth {
        let q = self.poses[k];
        PartTruth {
            lost: self.lost[k],
            part: self.kinds[self.kind_of[k]].name.clone(),
            theta_deg: q.theta.to_degrees().rem_euclid(360.0),
            x_mm: q.x,
            y_mm: q.y,
        }
    }

    /// The parts in the picture (those on the plate), as the camera draws them.
    pub fn placed(&self) -> Vec<Placed> {
        (self.poses.iter().zip(&self.kind_of).zip(&self.lost))
            .filter(|(_, lost)| !**lost)
            .map(|((q, &kind), _)| Placed {
                part: kind,
                c: [q.x, q.y],
                theta_deg: q.theta.to_degrees(),
                flipped: false,
            })
            .collect()
    }

    /// The state as `/truth` reports it.
    pub fn truth(&self) -> Truth {
        let parts = (0..self.poses.len()).map(|k| self.part_truth(k)).collect();
        Truth { clock: self.clock, drive_s: self.drive_s, modes: self.plate.modes.clone(), parts }
    }

    /// The camera over this plate and these part kinds.
    pub fn camera(&self) -> Camera {
        Camera::standard(self.plate.model.size_mm, self.kinds.clone())
    }

    /// A frame of the parts now, its sensor noise from `seed`.
    pub fn render(&self, seed: u64, format: Format) -> Result<Vec<u8>, RigError> {
        self.camera().frame(self.placed(), seed, format)
    }
}

/// A standard normal number (Box–Muller, from two uniforms).
fn gaussian(rng: &mut Rng) -> f64 {
    let u = 1.0 - rng.uniform();
    let v = rng.uniform();
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// Start poses as given: one per part, each inside the plate's rim, none overlapping another.
fn check_at(
    plate: &TruePlate,
    bodies: &[Body],
    pieces: &[Pieces],
    at: Vec<Pose>,
) -> Result<Vec<Pose>, RigError> {
    if at.len() != bodies.len() {
        return Err(RigError::AtCount { given: at.len(), parts: bodies.len() });
    }
    let rim = Rim::of(&plate.model);
    for (i, (b, &q)) in bodies.iter().zip(&at).enumerate() {
        if !on_plate(plate.model.size_mm, [q.x, q.y]) || rim.project(b, q) != q {
            return Err(RigError::AtOffPlate { part: i + 1, at: q, size_mm: plate.model.size_mm });
        }
        for j in 0..i {
            if shape::overlap(&pieces[i], q, &pieces[j], at[j]) > 0.0 {
                return Err(RigError::AtOverlap { first: j + 1, second: i + 1 });
            }
        }
    }
    Ok(at)
}

#[cfg(test)]
mod tests;
