//! Sensorless plans made on the learned plate against plans made on the given plate, both run
//! on the true plate (issue 44: "plans made on the learned plate … the part ends as planned in
//! ≥ 95 % of drops, where plans made on the given plate do not"; docs/evidence/steer.md).
//!
//! A rig (a seed) is a true plate: the given plate (the free plate's first 12 solver modes,
//! `examples/plates/free-12-modes.toml`, at `steer_rig::SPEED_MM_S` (120 mm/s)) with each mode's nodes moved 4–8 mm
//! in a random direction and its speed ×0.4–×2.5 (log-uniform), drawn as the steer bench draws
//! them; a `slow` rig draws its factors from ×0.4–×0.6 (every mode slower than given). The true
//! plate is that plate with the true `shift_mm` and `speed_mm_s` in its modes
//! (`steer::Model::plate`), which the motion model reads as any plate. For each part and feed
//! region a plan is made as `chladni plan PART --feed …` makes it (both faces of a part that
//! flips) and run as `chladni simulate --feed …` runs it: random drops in the region, per face.
//! A drop ends as planned (`orient`) within [`TOL_DEG`] of the predicted orientation (what
//! `simulate` counts); `pose` also asks for [`TOL_MM`] of the predicted position when the plan
//! fixes one; `still`: the part has stopped at the plan's end (moves < 0.1 mm and 0.5° in 10 s
//! more of the last mode); `pos`: the median distance from the predicted position (mm).
//!
//! - Scan: the given plate's plan on every scanned rig's true plate (no learning needed), and
//!   with its steps ×[`STRETCH`] (the slowest factor's reciprocal): a failure that the longer
//!   steps mend is one of timing (steps timed for the given speed end before the part has
//!   settled), one they do not mend is one of the nodes.
//! - Learned rigs: the plate learned in process as the steer bench's `learn` section learns it
//!   (the learning policy's bursts of three parts on the true plate, with noise, 12 per mode,
//!   then `steer::learn`); the given plate's plan and the learned plate's plan, each on its own
//!   plate and on the true plate.
//!
//! `cargo bench -p chladni --bench learned_plans` (release). The cases: `LEARNED_PLANS_PARTS`
//! (comma-separated substrings of `examples/parts/ordinary/` names, `all`; default
//! [`DEFAULT_PARTS`]), `LEARNED_PLANS_FEEDS` (`left`, `corner`, `right`, `all`; [`FEEDS`]),
//! `LEARNED_PLANS_RIGS` (learned rigs: seeds, `slow` seeds, `a..b`; default [`DEFAULT_RIGS`]),
//! `LEARNED_PLANS_SCAN` (scanned rigs, empty for none; [`DEFAULT_SCAN`]),
//! `LEARNED_PLANS_TRIALS` and `LEARNED_PLANS_SCAN_TRIALS` (drops per face).

use std::path::Path;
use std::time::Instant;

use chladni_core::model::angle::signed_diff;
use chladni_core::model::part::Part;
use chladni_core::model::part::mirror;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::integrate::{SimParams, run};
use chladni_core::motion::montecarlo::{Setup, run_trials};
use chladni_core::motion::steps::{SimStep, plan_steps};
use chladni_core::planner::feed::{self, FeedRegion};
use chladni_core::planner::{PlanOptions, Synthesis};
use chladni_core::progress::Silent;
use chladni_core::rng::Rng;
use chladni_core::steer::cost::Piece;
use chladni_core::steer::sim::{Noise, Truth};
use chladni_core::steer::{Correction, Model, learn};

#[path = "support/steer_rig.rs"]
mod steer_rig;
use steer_rig::{record, true_corrections_in, twelve_modes};

/// Drops per face and plan.
const TRIALS: u32 = 200;
/// A drop ends as planned within this of the predicted orientation (`simulate`'s default).
const TOL_DEG: f64 = 5.0;
/// … and within this of the predicted position when the plan fixes one (the steering
/// tolerance of several parts).
const TOL_MM: f64 = 3.0;
/// The `long` variant's step stretch: 1 / the slowest true speed factor.
const STRETCH: f64 = 2.5;
/// Drops per face and plan on each scanned rig.
const SCAN_TRIALS: u32 = 50;
/// The cases run unless the environment picks others (module documentation).
const DEFAULT_PARTS: &str = "corner-bracket,house-key";
const DEFAULT_FEEDS: &str = "left";
const DEFAULT_RIGS: &str = "1,13,slow2";
const DEFAULT_SCAN: &str = "1..21,slow1..6";
/// The learning set of the steer bench: three parts small enough to keep apart.
const LEARNING_SET: [&str; 3] = [
    "examples/parts/ordinary/u-channel.json",
    "examples/parts/ordinary/keyed-gear.json",
    "examples/parts/ordinary/spring-clip.json",
];
/// Feed regions (mm, x0 y0 x1 y1): a hopper on the left side (`plates_table`'s), one in the
/// lower-left quarter and one on the right side.
const FEEDS: [(&str, [f64; 4]); 3] = [
    ("left", [40.0, 50.0, 90.0, 150.0]),
    ("corner", [60.0, 40.0, 100.0, 80.0]),
    ("right", [210.0, 50.0, 260.0, 150.0]),
];

/// One rig: its name, the true plate, its speed factors and (once learned) the learned plate.
struct Rig {
    name: String,
    truth: PlateModel,
    corrections: Vec<Correction>,
    learned: Option<PlateModel>,
}

/// The rig `name` (a seed; `slow` prefix: the slow draw), not yet learned.
fn rig(name: &str, given: &PlateModel) -> Rig {
    let (slow, seed) = name.strip_prefix("slow").map_or((false, name), |s| (true, s));
    let seed: u64 = seed.parse().expect("a rig is a seed, or slow and a seed");
    let factors = if slow { (0.4, 0.6) } else { (0.4, 2.5) };
    let corrections = true_corrections_in(&mut Rng::seeded(seed), given.modes.len(), factors);
    let truth = Model::with_corrections(given.clone(), &corrections).expect("corrections").plate();
    Rig { name: name.to_string(), truth, corrections, learned: None }
}

impl Rig {
    fn factors(&self) -> Vec<f64> {
        self.corrections.iter().map(|c| c.speed_factor).collect()
    }

    /// Learns the plate as the steer bench's `learn` section does (noise seeded by the rig).
    fn learn(&mut self, given: &PlateModel, pieces: &[Piece]) {
        let true_model = Model::with_corrections(given.clone(), &self.corrections).expect("ok");
        let seed =
            self.name.bytes().fold(7u64, |h, b| h.wrapping_mul(31).wrapping_add(u64::from(b)));
        let mut t = Truth::new(true_model, Noise::default(), seed);
        let t0 = Instant::now();
        let (bursts, _, _) = record(&mut t, &mut Model::new(given.clone()), pieces, 12);
        let learned = learn(given, pieces, &bursts, Default::default()).expect("learned");
        let err = |f: &dyn Fn(&Correction, &Correction) -> f64| {
            (learned.reports.iter().zip(&self.corrections))
                .map(|(r, c)| f(&r.correction, c))
                .fold(0.0, f64::max)
        };
        let shift =
            err(&|a, b| (a.shift_mm[0] - b.shift_mm[0]).hypot(a.shift_mm[1] - b.shift_mm[1]));
        let factor = err(&|a, b| (a.speed_factor / b.speed_factor - 1.0).abs());
        let fs: Vec<String> = self.factors().iter().map(|f| format!("{f:.2}")).collect();
        println!(
            "rig {}: true factors [{}]; learned in {:.0} s ({} bursts): shift error max {shift:.2} \
             mm, factor error max {:.0} %",
            self.name,
            fs.join(" "),
            t0.elapsed().as_secs_f64(),
            bursts.len(),
            100.0 * factor
        );
        self.learned = Some(learned.model.plate());
    }
}

/// A plan as `chladni plan PART --feed …` makes it: the faces of the part, planned together.
fn make_plan(
    part: &Part,
    plate: &PlateModel,
    region: FeedRegion,
) -> Result<(Vec<Part>, Synthesis, PlanFile), String> {
    let faces = mirror::faces(std::slice::from_ref(part), false);
    let opt = PlanOptions { feed: Some(region), ..Default::default() };
    let syn =
        feed::plan_parts(&faces.parts, plate, &opt, &region, &Silent).map_err(|e| e.to_string())?;
    let mut file = syn.to_file(plate, &part.name);
    if let Some(preds) = &mut file.parts {
        for (p, o) in preds.iter_mut().zip(&faces.of) {
            p.face = o.face;
        }
    }
    Ok((faces.parts, syn, file))
}

/// What the drops of one plan on one plate gave.
#[derive(Default)]
struct Outcome {
    drops: usize,
    orient: usize,
    pose: usize,
    still: usize,
    /// Distances of the final centroids from the predicted position (mm), when predicted.
    pos_err: Vec<f64>,
}

impl Outcome {
    fn pct(n: usize, of: usize) -> f64 {
        100.0 * n as f64 / of.max(1) as f64
    }

    fn cell(&self) -> String {
        let pos = if self.pos_err.is_empty() {
            "-".to_string()
        } else {
            let mut v = self.pos_err.clone();
            v.sort_by(f64::total_cmp);
            format!("{:.1}", v[v.len() / 2])
        };
        format!(
            "{:.1} {:.1} {:.1} {pos}",
            Self::pct(self.orient, self.drops),
            Self::pct(self.pose, self.drops),
            Self::pct(self.still, self.drops)
        )
    }
}

/// Whether `body` at `pose` stays put for another 10 s of `mode` on `plate`.
fn still(body: &Body, plate: &PlateModel, field: &FieldModel, mode: usize, pose: Pose) -> bool {
    let p = SimParams::under(&plate.modes[mode], plate, 10.0);
    let r = run(body, field, p, pose);
    let moved = (r.pose.x - pose.x).hypot(r.pose.y - pose.y);
    moved < 0.1 && (r.pose.theta - pose.theta).to_degrees().abs() < 0.5
}

/// Runs `file` (made for `parts`, one view per face) on `plate` from `TRIALS` drops per face
/// in `region`, each step's duration × `stretch`.
fn drops(
    parts: &[Part],
    file: &PlanFile,
    plate: &PlateModel,
    region: &FeedRegion,
    stretch: f64,
    trials: u32,
) -> Outcome {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let mut steps: Vec<SimStep> =
        plan_steps(file, plate).expect("the plan's modes are the plate's");
    for s in &mut steps {
        s.duration_s *= stretch;
    }
    let mut out = Outcome::default();
    for (i, part) in parts.iter().enumerate() {
        let view = file.for_part(i).expect("a view per face");
        let body = Body::new(part);
        let setup =
            Setup { body: &body, plate, fields: &fields, steps: &steps, feed: Some(region) };
        let sims = run_trials(&setup, trials, 1 + i as u64, &Silent);
        let (theta, period) = (view.final_orientation_deg, view.period_deg);
        let last = steps.last().map_or(0, |s| s.mode);
        for q in &sims.finals {
            let ok_deg = theta
                .zip(period)
                .is_some_and(|(t, p)| signed_diff(q.theta.to_degrees(), t, p).abs() <= TOL_DEG);
            let d = view.final_position_mm.map(|p| (q.x - p[0]).hypot(q.y - p[1]));
            out.drops += 1;
            out.orient += usize::from(ok_deg);
            out.pose += usize::from(ok_deg && d.is_none_or(|d| d <= TOL_MM));
            out.still += usize::from(still(&body, plate, &fields[last], last, *q));
            out.pos_err.extend(d);
        }
    }
    out
}

/// The plan's steps as `modes (s each)`, and its total duration (s).
fn describe(syn: &Synthesis, factors: &[f64]) -> (String, f64) {
    let total: f64 = syn.steps.iter().map(|s| f64::from(s.duration_ms) / 1e3).sum();
    let steps: Vec<String> = (syn.steps.iter())
        .map(|s| {
            format!(
                "{} (×{:.2}): {:.0}",
                s.mode + 1,
                factors[s.mode],
                f64::from(s.duration_ms) / 1e3
            )
        })
        .collect();
    (steps.join(", "), total)
}

/// A plan made on one plate, with the faces it was made for and its region.
struct Made {
    parts: Vec<Part>,
    syn: Synthesis,
    file: PlanFile,
    region: FeedRegion,
    wall_s: f64,
}

/// The plan `chladni plan PART --feed …` makes on `plate`, or why there is none.
fn plan_on(plate: &PlateModel, part: &Part, feed: [f64; 4]) -> Result<Made, String> {
    let region = FeedRegion::new(feed, plate).map_err(|e| e.to_string())?;
    let t = Instant::now();
    let (parts, syn, file) = make_plan(part, plate, region)?;
    Ok(Made { parts, syn, file, region, wall_s: t.elapsed().as_secs_f64() })
}

/// One plan's row: its steps and duration, its drops on the plate it was made on (`own`)
/// and on the true plate, and (`long`) those of its steps stretched × [`STRETCH`].
/// Returns the orientation success on the true plate and with the steps stretched (%).
fn report(
    head: &str,
    made: &Made,
    own: Option<&PlateModel>,
    rig: &Rig,
    long: bool,
    trials: u32,
) -> [f64; 2] {
    let (steps, total) = describe(&made.syn, &rig.factors());
    let t = Instant::now();
    let run = |plate: &PlateModel, stretch: f64| {
        drops(&made.parts, &made.file, plate, &made.region, stretch, trials)
    };
    let own = own.map_or(String::new(), |p| run(p, 1.0).cell());
    let o = run(&rig.truth, 1.0);
    let l = long.then(|| run(&rig.truth, STRETCH));
    let fixes = match made.file.for_part(0).and_then(|v| v.final_position_mm) {
        Some(p) => format!("at ({:.0}, {:.0})", p[0], p[1]),
        None => "-".into(),
    };
    println!(
        "| {head} | {} | {steps} | {total:.0} | {fixes} | {} | {} | {} | {:.0} + {:.0} |",
        made.syn.steps.len(),
        own,
        o.cell(),
        l.as_ref().map_or("".into(), Outcome::cell),
        made.wall_s,
        t.elapsed().as_secs_f64()
    );
    let long_pct = l.map_or(f64::NAN, |l| Outcome::pct(l.orient, l.drops));
    [Outcome::pct(o.orient, o.drops), long_pct]
}

/// Whether `name` passes the filter in `var` (comma-separated substrings; unset: `default`;
/// `all`: everything).
fn wanted(var: &str, default: &str, name: &str) -> bool {
    let f = std::env::var(var).unwrap_or_else(|_| default.into());
    f == "all" || f.split(',').any(|s| !s.trim().is_empty() && name.contains(s.trim()))
}

/// Rig names from `var` (unset: `default`): seeds, `a..b` ranges, `slow` prefixes.
fn names(var: &str, default: &str) -> Vec<String> {
    let v = std::env::var(var).unwrap_or_else(|_| default.into());
    v.split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .flat_map(|s| {
            let (pre, rest) = s.strip_prefix("slow").map_or(("", s), |r| ("slow", r));
            match rest.split_once("..") {
                Some((a, b)) => {
                    let (a, b): (u64, u64) = (a.parse().expect("seed"), b.parse().expect("seed"));
                    (a..b).map(|k| format!("{pre}{k}")).collect::<Vec<_>>()
                }
                None => vec![s.to_string()],
            }
        })
        .collect()
}

/// The table's header (both sections).
const HEADER: &str = "| rig | part | feed | plan on | steps | modes (× true speed): s | total s | \
    position | own plate: orient pose still pos | true plate: orient pose still pos | true, steps \
    ×2.5 | wall s (plan + drops) |";

/// The given plate's plan of one part and feed on every scanned rig's true plate (no
/// learning: the plan does not depend on it): how often it fails, and how often stretching
/// its steps mends it (a timing failure) or not (a node failure).
fn scan(made: &Made, given: &PlateModel, rigs: &[Rig], head: &str, trials: u32) {
    let (mut ok, mut timing, mut node) = (0, 0, 0);
    let own = drops(&made.parts, &made.file, given, &made.region, 1.0, trials);
    for r in rigs {
        let [pct, long] =
            report(&format!("{} | {head} | given", r.name), made, None, r, true, trials);
        if pct >= 95.0 {
            ok += 1;
        } else if long >= 95.0 {
            timing += 1;
        } else {
            node += 1;
        }
    }
    println!(
        "scan {head}: the given plate's plan ends as planned (orientation) in ≥ 95 % of drops \
         on {ok} of {} true plates; below: {timing} mended by steps ×{STRETCH} (timing), {node} \
         not (nodes); on the given plate itself: {}",
        rigs.len(),
        own.cell()
    );
}

fn main() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let trials: u32 =
        std::env::var("LEARNED_PLANS_TRIALS").ok().and_then(|v| v.parse().ok()).unwrap_or(TRIALS);
    let scan_trials: u32 = std::env::var("LEARNED_PLANS_SCAN_TRIALS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(SCAN_TRIALS);
    let given = twelve_modes(&root);
    let load = |p: &str| Part::load(&root.join(p)).expect("the part loads");
    let pieces: Vec<Piece> = LEARNING_SET.iter().map(|p| Piece::new(&load(p))).collect();
    let mut parts: Vec<String> = std::fs::read_dir(root.join("examples/parts/ordinary"))
        .expect("examples/parts/ordinary")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".json") && wanted("LEARNED_PLANS_PARTS", DEFAULT_PARTS, n))
        .collect();
    parts.sort();
    let start = Instant::now();
    let scanned: Vec<Rig> =
        names("LEARNED_PLANS_SCAN", DEFAULT_SCAN).iter().map(|n| rig(n, &given)).collect();
    let mut rigs: Vec<Rig> =
        names("LEARNED_PLANS_RIGS", DEFAULT_RIGS).iter().map(|n| rig(n, &given)).collect();
    for r in &mut rigs {
        r.learn(&given, &pieces);
    }
    println!("{HEADER}");
    for p in &parts {
        let part = load(&format!("examples/parts/ordinary/{p}"));
        for feed in FEEDS.iter().filter(|f| wanted("LEARNED_PLANS_FEEDS", DEFAULT_FEEDS, f.0)) {
            let head = format!("{} | {}", part.name, feed.0);
            let made = match plan_on(&given, &part, feed.1) {
                Ok(m) => m,
                Err(e) => {
                    println!("| - | {head} | given | no plan: {e} |");
                    continue;
                }
            };
            if !scanned.is_empty() {
                scan(&made, &given, &scanned, &head, scan_trials);
            }
            for r in &rigs {
                let on = |w: &str| format!("{} | {head} | {w}", r.name);
                report(&on("given"), &made, Some(&given), r, true, trials);
                let learned = r.learned.as_ref().expect("learned");
                match plan_on(learned, &part, feed.1) {
                    Ok(m) => drop(report(&on("learned"), &m, Some(learned), r, false, trials)),
                    Err(e) => println!("| {} | {head} | learned | no plan: {e} |", r.name),
                }
            }
        }
    }
    println!("total {:.0} s", start.elapsed().as_secs_f64());
}
