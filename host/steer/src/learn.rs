//! `chladni plate learn`: what each mode really does, from bursts seen by the camera
//! (docs/steer.md).
//!
//! The loop drives the modes in turn (the one with fewest bursts so far first, each burst as
//! long as keeps the parts on the plate and apart: [`next_learning_step`]), brings the parts
//! home when they gather or near the rim, and records every burst with each part's pose before
//! and after. Recovery bursts are recorded too: a burst is a burst. At the end, every mode's
//! correction is fitted to its bursts with every 4th held out to score it ([`learn()`]).

use std::time::{Duration, Instant};

use chladni_core::model::pose::Pose;
use chladni_core::steer::cost::Piece;
use chladni_core::steer::learn::LearnOptions;
use chladni_core::steer::policy::{LearnStep, Rules, next_learning_step};
use chladni_core::steer::{Burst, Learned, Menu, Model, learn};

use crate::LoopError;
use crate::parts::{self, Kind, Tracked};
use crate::session::Session;

/// What to learn from and for how long.
#[derive(Debug, Clone)]
pub struct LearnJob {
    /// The part kinds.
    pub kinds: Vec<Kind>,
    /// The kind of each part on the plate.
    pub parts: Vec<usize>,
    /// Bursts to record per mode (held-out ones included).
    pub bursts_per_mode: usize,
    /// Stop recording after this long, and fit what there is.
    pub time_limit: Duration,
    /// Burst lengths to choose from.
    pub menu: Menu,
    /// When to bring parts home, how far a burst may move them.
    pub rules: Rules,
    /// The fit's options (hold-out share, iterations).
    pub fit: LearnOptions,
}

/// What `learn` recorded and fitted.
#[derive(Debug, Clone)]
pub struct LearnOutcome {
    /// The fit.
    pub learned: Learned,
    /// Every burst recorded.
    pub bursts: Vec<Burst>,
    /// How many were recoveries (bringing parts home).
    pub recoveries: usize,
    /// Wall time (s).
    pub elapsed_s: f64,
    /// The time limit ended the recording before every mode had its bursts.
    pub timed_out: bool,
}

/// Records bursts through `session` and fits `model`'s plate to them. `progress(recorded,
/// wanted)` after each burst.
pub fn learn_plate(
    session: &mut Session,
    model: &Model,
    job: &LearnJob,
    mut progress: impl FnMut(usize, usize),
) -> Result<LearnOutcome, LoopError> {
    let start = Instant::now();
    let (sighting, _) = session.look()?;
    let mut tracked = parts::first(&job.kinds, &job.parts, &sighting.parts)?;
    let pieces: Vec<Piece> =
        tracked.iter().map(|t| job.kinds[t.kind].piece(t.flipped).clone()).collect();
    let faces: Vec<bool> = tracked.iter().map(|t| t.flipped).collect();
    let modes = model.mode_count();
    let wanted = modes * job.bursts_per_mode;
    let mut counts = vec![0usize; modes];
    let (mut bursts, mut recoveries) = (Vec::new(), 0);
    let timed_out = loop {
        if counts.iter().all(|&c| c >= job.bursts_per_mode) {
            break false;
        }
        if start.elapsed() >= job.time_limit {
            break true;
        }
        let now: Vec<(&Piece, Pose)> =
            pieces.iter().zip(&tracked).map(|(p, t)| (p, t.pose)).collect();
        let step = next_learning_step(model, &now, &counts, &job.menu, &job.rules)?;
        let (mode, burst_s) = match step {
            LearnStep::Burst { mode, burst_s } => (mode, burst_s),
            LearnStep::Recover(c) => {
                recoveries += 1;
                (c.mode, c.burst_s)
            }
        };
        let driven = session.burst(model.mode(mode)?, burst_s)?;
        let before = tracked.clone();
        tracked = parts::follow(&job.kinds, &tracked, &session.look()?.0.parts)?;
        bursts.push(recorded(mode, driven.driven_s, &before, &tracked, &faces));
        counts[mode] += 1;
        progress(counts.iter().map(|&c| c.min(job.bursts_per_mode)).sum(), wanted);
    };
    let learned = learn(model.given(), &pieces, &bursts, job.fit)?;
    Ok(LearnOutcome {
        learned,
        bursts,
        recoveries,
        elapsed_s: start.elapsed().as_secs_f64(),
        timed_out,
    })
}

/// A burst as recorded: each part that lies on the face it lay on at the start (the piece the
/// fit predicts it with), before and after.
fn recorded(
    mode: usize,
    burst_s: f64,
    before: &[Tracked],
    after: &[Tracked],
    faces: &[bool],
) -> Burst {
    let parts = (0..before.len())
        .filter(|&k| before[k].flipped == faces[k] && after[k].flipped == faces[k])
        .map(|k| (k, before[k].pose, after[k].pose))
        .collect();
    Burst { mode, burst_s, parts }
}
