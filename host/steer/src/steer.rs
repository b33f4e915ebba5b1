//! `chladni steer`: parts to goal poses in closed loop (docs/steer.md).
//!
//! Each cycle: a frame → the parts located and followed → the model's correction of the mode
//! just driven refitted from what it did ([`Corrector`]) → identical parts given the goals
//! nearest them now ([`assign_goals`]) → the command (mode, burst) predicted to bring all
//! parts nearest their goals ([`choose()`], with look-ahead; [`Stall`] turns to the worst part
//! when the total stops falling) → the burst. Until every part is within tolerance, or the
//! time limit. The same cycle as the in-process rig's (`chladni_core::steer::sim`), which the
//! benches measure.

use std::time::{Duration, Instant, UNIX_EPOCH};

use chladni_core::model::pose::Pose;
use chladni_core::steer::choose::Stall;
use chladni_core::steer::cost::{PartGoal, angle_error_deg, distance_mm};
use chladni_core::steer::{
    Burst, Corrector, Menu, Model, assign_goals, choose, reachable_orientation,
};
use serde::Serialize;

use crate::LoopError;
use crate::parts::{self, Kind, Tracked};
use crate::session::Session;

/// What to steer and how.
#[derive(Debug, Clone)]
pub struct SteerJob {
    /// The part kinds.
    pub kinds: Vec<Kind>,
    /// Each part given: its kind and its goal (mm, rad).
    pub parts: Vec<(usize, Pose)>,
    /// Position tolerance (mm).
    pub tol_mm: f64,
    /// Orientation tolerance (deg).
    pub tol_deg: f64,
    /// Give up after this long.
    pub time_limit: Duration,
    /// The commands to choose from.
    pub menu: Menu,
}

/// One part at the end.
#[derive(Debug, Clone, Serialize)]
pub struct PartResult {
    /// Part name.
    pub part: String,
    /// Its goal [x mm, y mm, θ deg].
    pub goal: [f64; 3],
    /// Where it is (mm).
    pub x_mm: f64,
    /// Where it is (mm).
    pub y_mm: f64,
    /// Its orientation (deg).
    pub theta_deg: f64,
    /// Distance from the goal (mm).
    pub error_mm: f64,
    /// Orientation error modulo the part's symmetry (deg).
    pub error_deg: f64,
    /// Within both tolerances.
    pub reached: bool,
}

/// The outcome of `steer`.
#[derive(Debug, Clone, Serialize)]
pub struct SteerReport {
    /// Every part within tolerance.
    pub reached: bool,
    /// Each part, in the order given.
    pub parts: Vec<PartResult>,
    /// Control cycles run (bursts driven).
    pub cycles: u32,
    /// Wall time from the first frame (s).
    pub elapsed_s: f64,
    /// Goals no mode holds a part at, said before steering: (part index, the nearest rest
    /// [x, y, θ deg] some mode holds there).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unheld_goals: Vec<(usize, [f64; 3])>,
}

/// One cycle, for `--log`.
#[derive(Debug, Clone, Serialize)]
pub struct CycleRecord {
    /// Cycle number from 0.
    pub cycle: u32,
    /// When the frame was taken (Unix s).
    pub frame_time: f64,
    /// How long the frame and locating took (ms).
    pub look_ms: f64,
    /// Each part's pose seen [x mm, y mm, θ deg].
    pub seen: Vec<[f64; 3]>,
    /// What the last command predicted for this frame, and the error of that prediction (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub predicted_error_mm: Option<Vec<f64>>,
    /// The command: mode index, its frequency, burst asked and driven (s); none in the cycle
    /// that ends the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub command: Option<CommandRecord>,
    /// Each part's pose predicted after the command.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub predicted: Vec<[f64; 3]>,
    /// How long choosing the command took (ms).
    pub choose_ms: f64,
}

/// A command as logged.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct CommandRecord {
    /// Mode index.
    pub mode: usize,
    /// Its drive frequency (Hz).
    pub freq_hz: f64,
    /// Burst asked (s).
    pub burst_s: f64,
    /// Burst the controller drove, ramps included (s).
    pub driven_s: f64,
}

/// `[x, y, θ deg]` of a pose.
pub fn triple(p: Pose) -> [f64; 3] {
    [p.x, p.y, p.theta.to_degrees()]
}

/// Steers `job`'s parts to their goals on `model` (corrected as it goes) through `session`.
/// `on_cycle` sees every cycle (the log, a progress line).
pub fn steer(
    session: &mut Session,
    model: &mut Model,
    job: &SteerJob,
    mut on_cycle: impl FnMut(&CycleRecord),
) -> Result<SteerReport, LoopError> {
    let start = Instant::now();
    let (mut sighting, _) = session.look()?;
    let given: Vec<usize> = job.parts.iter().map(|p| p.0).collect();
    let mut tracked = parts::first(&job.kinds, &given, &sighting.parts)?;
    let mut goals = goals_assigned(job, &tracked)?;
    let unheld_goals = unheld(model, job, &tracked, &goals)?;
    let mut stall = Stall::new();
    let mut corrector = Corrector::new(model.mode_count());
    let mut last: Option<(Burst, Vec<Pose>)> = None;
    let mut cycles = 0u32;
    loop {
        let mut record = record_of(cycles, &sighting, &tracked);
        if let Some((mut burst, predicted)) = last.take() {
            let errors =
                predicted.iter().zip(&tracked).map(|(p, t)| distance_mm(*p, t.pose)).collect();
            record.predicted_error_mm = Some(errors);
            for (k, (_, _, after)) in burst.parts.iter_mut().enumerate() {
                *after = tracked[k].pose;
            }
            let pieces = pieces_of(job, &tracked);
            corrector.observe(model, &pieces, burst).map_err(LoopError::Steer)?;
        }
        goals = goals_assigned(job, &tracked)?;
        let goal_of = |i: usize| part_goal(job, &tracked[i], goals[i]);
        let within =
            (0..tracked.len()).all(|i| goal_of(i).within(tracked[i].pose, job.tol_mm, job.tol_deg));
        if within || start.elapsed() >= job.time_limit {
            on_cycle(&record);
            return Ok(report(job, &tracked, &goals, within, cycles, start, unheld_goals));
        }
        let chosen = Instant::now();
        let pg: Vec<PartGoal> = (0..tracked.len()).map(goal_of).collect();
        let command = choose(model, &stall.weigh(&pg), &job.menu).map_err(LoopError::Steer)?;
        record.choose_ms = chosen.elapsed().as_secs_f64() * 1e3;
        let mode = model.mode(command.mode).map_err(LoopError::Steer)?.clone();
        let driven = session.burst(&mode, command.burst_s)?;
        record.command = Some(CommandRecord {
            mode: command.mode,
            freq_hz: mode.freq_hz,
            burst_s: command.burst_s,
            driven_s: driven.driven_s,
        });
        record.predicted = command.predicted.iter().map(|p| triple(*p)).collect();
        on_cycle(&record);
        let before: Vec<(usize, Pose, Pose)> =
            tracked.iter().enumerate().map(|(k, t)| (k, t.pose, t.pose)).collect();
        last = Some((
            Burst { mode: command.mode, burst_s: driven.driven_s, parts: before },
            command.predicted,
        ));
        cycles += 1;
        sighting = session.look()?.0;
        tracked = parts::follow(&job.kinds, &tracked, &sighting.parts)?;
    }
}

/// A followed part and its goal; orientation counts for nothing when any orientation is
/// within tolerance (`--tol-deg` of half the part's symmetry period or more).
fn part_goal<'a>(job: &'a SteerJob, t: &Tracked, goal: Pose) -> PartGoal<'a> {
    let piece = job.kinds[t.kind].piece(t.flipped);
    let mut g = PartGoal::new(piece, t.pose, goal);
    if job.tol_deg >= piece.period_deg / 2.0 {
        g.mm_per_deg = 0.0;
    }
    g
}

/// The pieces of the followed parts, by the face each lies on.
fn pieces_of(job: &SteerJob, tracked: &[Tracked]) -> Vec<chladni_core::steer::cost::Piece> {
    tracked.iter().map(|t| job.kinds[t.kind].piece(t.flipped).clone()).collect()
}

/// Each part's goal: identical parts (one kind) share their kind's goals by least total cost.
fn goals_assigned(job: &SteerJob, tracked: &[Tracked]) -> Result<Vec<Pose>, LoopError> {
    let mut goals: Vec<Pose> = job.parts.iter().map(|p| p.1).collect();
    for kind in 0..job.kinds.len() {
        let members: Vec<usize> = (0..tracked.len()).filter(|&i| tracked[i].kind == kind).collect();
        let kind_goals: Vec<Pose> = members.iter().map(|&i| job.parts[i].1).collect();
        let pg: Vec<PartGoal> =
            members.iter().map(|&i| part_goal(job, &tracked[i], job.parts[i].1)).collect();
        let assigned = assign_goals(&pg, &kind_goals).map_err(LoopError::Steer)?;
        for (&i, a) in members.iter().zip(assigned) {
            goals[i] = a.goal;
        }
    }
    Ok(goals)
}

/// The goals no mode holds a part at: each with the nearest rest that is held there.
fn unheld(
    model: &Model,
    job: &SteerJob,
    tracked: &[Tracked],
    goals: &[Pose],
) -> Result<Vec<(usize, [f64; 3])>, LoopError> {
    let mut out = Vec::new();
    for (i, (t, goal)) in tracked.iter().zip(goals).enumerate() {
        let piece = job.kinds[t.kind].piece(t.flipped);
        let reach = reachable_orientation(model, piece, *goal, job.tol_mm, job.tol_deg)
            .map_err(LoopError::Steer)?;
        if !reach.reachable {
            out.push((i, triple(reach.rest)));
        }
    }
    Ok(out)
}

fn record_of(cycle: u32, sighting: &crate::session::Sighting, tracked: &[Tracked]) -> CycleRecord {
    let frame_time = sighting.taken.duration_since(UNIX_EPOCH).map_or(0.0, |d| d.as_secs_f64());
    CycleRecord {
        cycle,
        frame_time,
        look_ms: sighting.took.as_secs_f64() * 1e3,
        seen: tracked.iter().map(|t| triple(t.pose)).collect(),
        predicted_error_mm: None,
        command: None,
        predicted: Vec::new(),
        choose_ms: 0.0,
    }
}

fn report(
    job: &SteerJob,
    tracked: &[Tracked],
    goals: &[Pose],
    reached: bool,
    cycles: u32,
    start: Instant,
    unheld_goals: Vec<(usize, [f64; 3])>,
) -> SteerReport {
    let parts = tracked
        .iter()
        .zip(goals)
        .map(|(t, g)| {
            let piece = job.kinds[t.kind].piece(t.flipped);
            let (error_mm, error_deg) =
                (distance_mm(t.pose, *g), angle_error_deg(t.pose, *g, piece.period_deg));
            PartResult {
                part: job.kinds[t.kind].part.name.clone(),
                goal: triple(*g),
                x_mm: t.pose.x,
                y_mm: t.pose.y,
                theta_deg: t.pose.theta.to_degrees(),
                error_mm,
                error_deg,
                reached: error_mm <= job.tol_mm && error_deg <= job.tol_deg,
            }
        })
        .collect();
    SteerReport { reached, parts, cycles, elapsed_s: start.elapsed().as_secs_f64(), unheld_goals }
}
