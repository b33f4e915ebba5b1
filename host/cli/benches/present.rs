//! Presenting parts to a robot in the in-process rig (`chladni_core::steer::sim`,
//! `chladni_core::steer::present`): parts dropped at random on a true plate that is the given
//! plate with each mode's field shifted 4–8 mm (random direction) and its speed off by
//! ×0.4–×2.5 (log-uniform), as in the steer bench; the loop starts from the given plate and
//! corrects it online, and keeps its corrections from one part to the next.
//!
//! A session: "present a part at the pick pose" → the part chosen ([`choose_part`], soonest)
//! → cycles of the present objective ([`objective`]: the part to the pick pose, the others out
//! of the pick zone) chosen by `choose` (look-ahead 3, [`Stall`]), driven on the true plate
//! (`Truth::burst`), the driven mode corrected (`Corrector`) → "ready" once the part is within
//! 2 mm and 3° and no other part reaches into the zone → the robot picks for [`PICK_S`] and
//! the part is gone → the next request, until no part is left or [`SESSION_LIMIT_S`].
//! A present that is not ready within [`PRESENT_LIMIT_S`] is given up (counted, and the next
//! request chooses again).
//!
//! Time is counted as the live loop spends it: each cycle its burst's drive time plus
//! [`CYCLE_OVERHEAD_S`] (stop, settle, frame, locate: measured on the rig) plus this bench's
//! own measured choice and correction time; the pick's [`PICK_S`] after each ready.
//!
//! Sections (stdout, one line per result):
//! - `rate`: sessions of 1, 3 and 10 parts (the u-channel), one pick pose: parts presented per
//!   minute, present→ready median and p95, presents given up;
//! - `choice`: the first present of 10 parts, the part chosen by the soonest estimate and by
//!   nearness, on the same rigs and drops: present→ready median and p95 of each;
//! - `two`: two part types (5 u-channels, 5 keyed gears), each to its own pick pose, the
//!   requests alternating: each type's rate.
//!
//! Pick poses are rests some mode of the true plate holds (`Truth::random_goal`), their pick
//! zone inside the plate: a part steered to a rest converges there and stays, where a pose no
//! mode holds is only passed through (the steer bench's goals are chosen alike).
//!
//! `cargo bench -p chladni --bench present`; `PRESENT_SECTIONS=rate,choice` picks sections,
//! `PRESENT_TRIALS=3` the sessions (rigs) per case (default 8).

use std::path::Path;
use std::time::Instant;

use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::rng::Rng;
use chladni_core::steer::choose::Stall;
use chladni_core::steer::cost::{Piece, angle_error_deg, distance_mm};
use chladni_core::steer::present::{
    Estimate, OnPlate, Pick, choose_part, in_zone, objective, presented,
};
use chladni_core::steer::sim::{Noise, Truth};
use chladni_core::steer::{Burst, Corrector, Menu, Model, choose};

#[path = "support/steer_rig.rs"]
mod steer_rig;
use steer_rig::{true_corrections, twelve_modes};

/// The robot's pick: the part is gone this long after "ready" (s).
const PICK_S: f64 = 2.0;
/// What a live cycle costs besides its burst (s): on the rig a cycle took 2.9 s for a 2.0 s
/// burst (docs/evidence/steer.md): the stop and the controller's idle report, the 150 ms
/// settle (`--settle-ms`), the frame and locating the parts (0.68 s), the choice (9 ms).
const CYCLE_OVERHEAD_S: f64 = 0.9;
/// A present not ready within this (s, drive and overhead) is given up.
const PRESENT_LIMIT_S: f64 = 120.0;
/// A session ends after this (s).
const SESSION_LIMIT_S: f64 = 1200.0;
/// The pick zone's radius (mm): a gripper's jaws around the part.
const ZONE_MM: f64 = 15.0;

const U_CHANNEL: &str = "examples/parts/ordinary/u-channel.json";
const KEYED_GEAR: &str = "examples/parts/ordinary/keyed-gear.json";

/// The `q` quantile of `v` (nearest rank); NaN when empty.
fn quantile(v: &[f64], q: f64) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    v[((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1]
}

/// One session's rig: the true plate, the loop's model and its corrector, the parts.
struct Cell<'a> {
    truth: Truth,
    model: Model,
    corrector: Corrector,
    pieces: &'a [Piece],
    parts: Vec<OnPlate<'a>>,
    /// Time so far (s).
    clock: f64,
    /// Where it went: cycles, drive, choice and correction, picks (s).
    spent: Spent,
}

/// Where a session's time went.
#[derive(Default, Clone, Copy)]
struct Spent {
    cycles: usize,
    drive_s: f64,
    compute_s: f64,
    pick_s: f64,
}

/// How one present ended.
struct Presented {
    ready: bool,
    /// Present→ready (or given up) time (s).
    took_s: f64,
}

impl<'a> Cell<'a> {
    /// A rig of seed `seed` with `counts[k]` parts of `pieces[k]` dropped apart at random.
    fn new(plate: &PlateModel, pieces: &'a [Piece], counts: &[usize], seed: u64) -> Cell<'a> {
        let mut rng = Rng::seeded(5000 + seed);
        let truth_c = true_corrections(&mut rng, plate.modes.len());
        let truth_m = Model::with_corrections(plate.clone(), &truth_c).expect("corrections");
        let mut truth = Truth::new(truth_m, Noise::default(), seed);
        let mut parts: Vec<OnPlate> = Vec::new();
        for (kind, (&n, piece)) in counts.iter().zip(pieces).enumerate() {
            for _ in 0..n {
                let mut pose = truth.random_pose(&piece.body, 5.0);
                for _ in 0..200 {
                    let clear = parts.iter().all(|o| {
                        distance_mm(o.pose, pose) > o.piece.body.radius + piece.body.radius
                    });
                    if clear {
                        break;
                    }
                    pose = truth.random_pose(&piece.body, 5.0);
                }
                parts.push(OnPlate { piece, kind, pose });
            }
        }
        let model = Model::new(plate.clone());
        let corrector = Corrector::new(model.mode_count());
        Cell { truth, model, corrector, pieces, parts, clock: 0.0, spent: Spent::default() }
    }

    /// A pick pose for parts of `kind`: a rest of the true plate, its zone inside the plate
    /// and `apart` mm from every pose of `others`.
    fn pick_pose(&mut self, kind: usize, others: &[Pose], apart: f64) -> Option<Pick> {
        let body = &self.pieces[kind].body;
        for _ in 0..50 {
            let rest = self.truth.random_goal(body, ZONE_MM)?;
            if others.iter().all(|o| distance_mm(*o, rest) >= apart) {
                return Some(Pick::new(rest, kind, ZONE_MM));
            }
        }
        None
    }

    /// One present at `pick`: choose, steer until ready or the limit, then the pick.
    fn present(&mut self, pick: &Pick, how: Estimate, menu: &Menu) -> Option<Presented> {
        let start = self.clock;
        let choice = choose_part(&self.model, &self.parts, pick, how).ok()?;
        let chosen = choice.part;
        let mut stall = Stall::new();
        loop {
            let clear = in_zone(&self.parts, chosen, pick).is_empty();
            if presented(&self.parts, chosen, pick) && clear {
                let took_s = self.clock - start;
                self.clock += PICK_S;
                self.spent.pick_s += PICK_S;
                self.parts.remove(chosen);
                return Some(Presented { ready: true, took_s });
            }
            if self.clock - start >= PRESENT_LIMIT_S {
                let c = self.parts[chosen];
                println!(
                    "  given up: the part {:.1} mm / {:.1} deg off, {} other(s) in the zone",
                    distance_mm(c.pose, pick.pose),
                    angle_error_deg(c.pose, pick.pose, c.piece.period_deg),
                    in_zone(&self.parts, chosen, pick).len()
                );
                return Some(Presented { ready: false, took_s: self.clock - start });
            }
            let computed = Instant::now();
            self.cycle(chosen, pick, &mut stall, menu);
            let compute_s = computed.elapsed().as_secs_f64();
            self.clock += CYCLE_OVERHEAD_S + compute_s;
            self.spent.cycles += 1;
            self.spent.compute_s += compute_s;
        }
    }

    /// One cycle: the command for the present objective, the burst on the true plate, the
    /// driven mode corrected from what the parts did. Adds the drive time to the clock.
    fn cycle(&mut self, chosen: usize, pick: &Pick, stall: &mut Stall, menu: &Menu) {
        let goals = objective(&self.parts, chosen, pick);
        let cmd = choose(&self.model, &stall.weigh(&goals), menu).expect("a command");
        let before: Vec<(&Body, Pose)> =
            self.parts.iter().map(|p| (&p.piece.body, p.pose)).collect();
        let after = self.truth.burst(&before, cmd.mode, cmd.burst_s).expect("a burst");
        let seen = self.parts.iter().zip(&after).map(|(p, a)| (p.kind, p.pose, *a)).collect();
        let burst = Burst { mode: cmd.mode, burst_s: cmd.burst_s, parts: seen };
        self.corrector.observe(&mut self.model, self.pieces, burst).expect("a correction");
        for (p, q) in self.parts.iter_mut().zip(after) {
            p.pose = q;
        }
        self.clock += cmd.burst_s;
        self.spent.drive_s += cmd.burst_s;
    }
}

/// What a case's sessions gave.
#[derive(Default)]
struct Tally {
    /// Parts presented, per type.
    presented: Vec<usize>,
    given_up: usize,
    /// Session time (s).
    time_s: f64,
    /// Present→ready times (s) of the presents that were ready.
    ready_s: Vec<f64>,
    spent: Spent,
}

impl Spent {
    fn add(&mut self, o: &Spent) {
        self.cycles += o.cycles;
        self.drive_s += o.drive_s;
        self.compute_s += o.compute_s;
        self.pick_s += o.pick_s;
    }

    /// One line: cycles, and the session time split into drive, overhead, computing, picks.
    fn line(&self) -> String {
        format!(
            "{} cycles (mean burst {:.2} s); time: drive {:.0} s, cycle overhead {:.0} s, choice and correction {:.0} s, picks {:.0} s",
            self.cycles,
            self.drive_s / self.cycles.max(1) as f64,
            self.drive_s,
            self.cycles as f64 * CYCLE_OVERHEAD_S,
            self.compute_s,
            self.pick_s
        )
    }
}

impl Tally {
    fn add(&mut self, kind: usize, p: &Presented) {
        if self.presented.len() <= kind {
            self.presented.resize(kind + 1, 0);
        }
        if p.ready {
            self.presented[kind] += 1;
            self.ready_s.push(p.took_s);
        } else {
            self.given_up += 1;
        }
    }
}

/// Sessions of `counts` parts (per type) presented at one pick pose per type, the requests
/// cycling through the types that have parts left.
fn sessions(plate: &PlateModel, pieces: &[Piece], counts: &[usize], trials: u64) -> Tally {
    let mut tally = Tally::default();
    let menu = Menu::default();
    for seed in 0..trials {
        let mut cell = Cell::new(plate, pieces, counts, seed);
        let mut picks: Vec<Pick> = Vec::new();
        for kind in 0..counts.len() {
            let taken: Vec<Pose> = picks.iter().map(|p| p.pose).collect();
            match cell.pick_pose(kind, &taken, 4.0 * ZONE_MM) {
                Some(p) => picks.push(p),
                None => break,
            }
        }
        if picks.len() < counts.len() {
            println!("session {seed}: no pick poses found");
            continue;
        }
        let mut next = 0;
        while cell.clock < SESSION_LIMIT_S {
            let left = |k: usize| cell.parts.iter().any(|p| p.kind == k);
            let Some(kind) =
                (0..counts.len()).map(|k| (next + k) % counts.len()).find(|&k| left(k))
            else {
                break;
            };
            next = kind + 1;
            let Some(p) = cell.present(&picks[kind], Estimate::Soonest, &menu) else { break };
            tally.add(kind, &p);
        }
        tally.time_s += cell.clock;
        tally.spent.add(&cell.spent);
        println!(
            "session {seed}: {} presented, {} left, {:.0} s",
            counts.iter().sum::<usize>() - cell.parts.len(),
            cell.parts.len(),
            cell.clock
        );
    }
    tally
}

fn rate_section(plate: &PlateModel, piece: &Piece, trials: u64) {
    let pieces = std::slice::from_ref(piece);
    for n in [1, 3, 10] {
        let t = sessions(plate, pieces, &[n], trials);
        let done: usize = t.presented.iter().sum();
        println!(
            "rate, {n} part(s): {done} presented in {:.0} s: {:.2} per minute; present→ready median {:.1} s, p95 {:.1} s; {} given up",
            t.time_s,
            done as f64 * 60.0 / t.time_s.max(1e-9),
            quantile(&t.ready_s, 0.5),
            quantile(&t.ready_s, 0.95),
            t.given_up
        );
        println!("  {}", t.spent.line());
    }
}

fn two_section(plate: &PlateModel, pieces: &[Piece], trials: u64) {
    let t = sessions(plate, pieces, &[5, 5], trials);
    let per_min = |k: usize| t.presented.get(k).copied().unwrap_or(0) as f64 * 60.0 / t.time_s;
    println!(
        "two types, 5 + 5 parts, two pick poses: u-channel {:.2} per minute, keyed gear {:.2} per minute (together {:.2}); present→ready median {:.1} s, p95 {:.1} s; {} given up",
        per_min(0),
        per_min(1),
        per_min(0) + per_min(1),
        quantile(&t.ready_s, 0.5),
        quantile(&t.ready_s, 0.95),
        t.given_up
    );
    println!("  {}", t.spent.line());
}

/// The first present of 10 parts, by each estimate, on the same rigs and drops.
fn choice_section(plate: &PlateModel, piece: &Piece, trials: u64) {
    let pieces = std::slice::from_ref(piece);
    let menu = Menu::default();
    for how in [Estimate::Soonest, Estimate::Nearest] {
        let (mut times, mut given_up) = (Vec::new(), 0);
        for seed in 0..trials {
            let mut cell = Cell::new(plate, pieces, &[10], seed);
            let Some(pick) = cell.pick_pose(0, &[], 0.0) else { continue };
            match cell.present(&pick, how, &menu) {
                Some(p) if p.ready => times.push(p.took_s),
                _ => given_up += 1,
            }
        }
        println!(
            "choice by {how:?}, first of 10 parts: present→ready median {:.1} s, p95 {:.1} s, mean {:.1} s over {} ready; {given_up} given up",
            quantile(&times, 0.5),
            quantile(&times, 0.95),
            times.iter().sum::<f64>() / times.len().max(1) as f64,
            times.len()
        );
    }
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let sections = std::env::var("PRESENT_SECTIONS").unwrap_or_else(|_| "rate,choice,two".into());
    let trials: u64 =
        std::env::var("PRESENT_TRIALS").ok().and_then(|v| v.parse().ok()).unwrap_or(8);
    let plate = twelve_modes(&root);
    let load = |p: &str| Piece::new(&Part::load(&root.join(p)).expect("the part loads"));
    let pieces = [load(U_CHANNEL), load(KEYED_GEAR)];
    let on = |s: &str| sections.split(',').any(|x| x == s);
    if on("rate") {
        rate_section(&plate, &pieces[0], trials);
    }
    if on("choice") {
        choice_section(&plate, &pieces[0], trials);
    }
    if on("two") {
        two_section(&plate, &pieces, trials);
    }
}
