//! `chladni plan PART --plate P` and `chladni simulate PART --plate P --plan PLAN`.

use chladni_core::motion::body::PLANNER_BODY_SAMPLES;
use chladni_media::shapes::plan::PartReport;
use chladni_media::shapes::{self, SimulateReport, TraceLine};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni_core::model::part::Part;
use chladni_core::model::part::mirror::{self, Face, FaceOf, Faces};
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::pose::Pose;
use chladni_core::motion::body::Body;
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::{self, Report, Setup, Stats, Trials};
use chladni_core::output::write_atomic;
use chladni_core::planner::capture::CaptureZone;
use chladni_core::planner::collide::EndOverlap;
use chladni_core::planner::feed::{self, FeedRegion};
use chladni_core::planner::whole::OnPlate;
use chladni_core::planner::{self, MapKind, Minimize, PlanFailure, PlanOptions, Synthesis};
use chladni_media::plot::plan as plan_plot;
use chladni_shared::icd::plan::DeviceLimits;
use clap::{Args, ValueEnum};

use super::parse::{f64_where, finite, positive};
use super::part::PartRead;
use super::progress::{Bar, LateBar, message_bar};
use super::{InputError, check_output, check_plot, output_error, plot_error};

mod copies;
mod together;

fn bad(msg: String) -> anyhow::Error {
    InputError(msg).into()
}

fn load_plate(path: &Path) -> anyhow::Result<PlateModel> {
    PlateModel::load(path).map_err(|e| bad(e.to_string()))
}

/// The `--feed X0 Y0 X1 Y1` region, checked against the plate.
fn feed_region(c: &Option<Vec<f64>>, plate: &PlateModel) -> anyhow::Result<Option<FeedRegion>> {
    let Some(c) = c else { return Ok(None) };
    let c: [f64; 4] = c
        .as_slice()
        .try_into()
        .map_err(|_| bad(format!("--feed takes 4 numbers X0 Y0 X1 Y1, got {}", c.len())))?;
    FeedRegion::new(c, plate).map(Some).map_err(|e| bad(format!("--feed: {e}")))
}

/// What `--minimize` makes the plan shortest in.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
enum MinimizeArg {
    /// Fewest steps (the first such plan found).
    Steps,
    /// Least total duration (sum of the simulated step durations).
    Time,
}

/// Sensorless plan: the shortest mode sequence bringing every start orientation to one.
#[derive(Debug, Args)]
pub struct PlanArgs {
    /// Part file(s) (.json, .svg or .dxf); several parts: one sequence orients each of them.
    #[arg(required = true, num_args = 1..)]
    part: Vec<PathBuf>,
    #[command(flatten)]
    read: PartRead,
    /// Plate model (TOML with [[mode]] entries; docs/plan.md).
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// Robustness margin: no predicted orientation closer than this to a basin boundary
    /// (deg, in [0, 45)); `auto`: each grid mode's margin from how far its boundaries move when
    /// its grid is resampled, 3° for the other modes (docs/plan.md, "Margins from evidence").
    #[arg(long, value_name = "D|auto", default_value = "auto", value_parser = margin_arg)]
    margin_deg: MarginArg,
    /// Step duration = slowest simulated settle time × this.
    #[arg(long, value_name = "X", default_value_t = 1.5,
          value_parser = f64_where("safety", "in (0, 100]", |v| v > 0.0 && v <= 100.0))]
    safety: f64,
    /// Print the plan as one JSON object.
    #[arg(long)]
    json: bool,
    /// Write the plan file (for `chladni simulate` and `chladni device run-file`).
    #[arg(long, value_name = "plan.json")]
    out: Option<PathBuf>,
    /// Draw the step-by-step plan figure (PNG, or SVG for a .svg name) for a few example starts.
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// Parts are dropped in this rectangle (mm): plan by tracking poses from it.
    #[arg(long, num_args = 4, value_names = ["X0", "Y0", "X1", "Y1"], allow_negative_numbers = true)]
    feed: Option<Vec<f64>>,
    /// Final orientation wanted (deg, modulo the part's period), one per part: among the
    /// shortest plans (or one step longer) one that ends there, within --margin-deg.
    #[arg(long, num_args = 1.., value_name = "θ", allow_negative_numbers = true,
          value_parser = finite("goal-deg"))]
    goal_deg: Option<Vec<f64>>,
    /// Only a plan that fixes the final position (checked by simulation).
    #[arg(long)]
    fix_position: bool,
    /// Among plans that fix the position, the one ending nearest to (X, Y) mm (one part).
    #[arg(long, num_args = 2, value_names = ["X", "Y"], allow_negative_numbers = true,
          value_parser = finite("goal-pos"))]
    goal_pos: Option<Vec<f64>>,
    /// What the plan is shortest in: steps, or time (the sum of the step durations).
    #[arg(long, value_enum, default_value_t = MinimizeArg::Steps)]
    minimize: MinimizeArg,
    /// Straight-node step maps: the static alignment function checked by simulation
    /// afterwards (static), the simulated approach from both sides of the node (dynamic), or
    /// static first and dynamic when that gives no plan (auto).
    #[arg(long, value_enum, default_value_t = Maps::Auto)]
    maps: Maps,
    /// Every part may land on either face: plan for it and its mirror image at once (as a
    /// part file's `"flips": true` does for that part; docs/plan.md, "Both faces").
    #[arg(long)]
    both_faces: bool,
    /// Bulk feeding: of the plans the planner offers (its own, one per other reachable
    /// orientation, the least in time), the one orienting the most of N copies dropped together
    /// per minute (docs/motion.md, "Bulk feeding"); one part on one face.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1000))]
    copies: Option<u32>,
    /// Give up after this many seconds of planning (failure `out_of_time`, naming the stage
    /// reached); a plan may overrun it by one step map at most.
    #[arg(long, value_name = "S", default_value_t = 120.0,
          value_parser = f64_where("max-time-s", "in (0, 86400]", |v| v > 0.0 && v <= 86400.0))]
    max_time_s: f64,
    /// Most orientation sets the search expands (a failure says when it stopped there).
    #[arg(long, value_name = "N", default_value_t = 200_000,
          value_parser = clap::value_parser!(u32).range(1..=50_000_000))]
    max_states: u32,
    /// With --feed: the longest mode sequence the feed-region search tries (default 6; at
    /// most 8: the sequences grow as (modes − 1)^N). The search over orientation sets has no
    /// step bound (--max-states bounds it).
    #[arg(long, value_name = "N",
          value_parser = clap::value_parser!(u32).range(1..=feed::MAX_DEPTH as i64))]
    max_steps: Option<u32>,
    /// Whole-plate plans on grid (solver) modes: how many times the step maps are refined with
    /// the drop points a plan does not hold from (docs/plan.md, "Whole-plate plans on grid
    /// modes"); 0: no whole-plate check.
    #[arg(long, value_name = "N", default_value_t = planner::whole::REFINE_ROUNDS as u32,
          value_parser = clap::value_parser!(u32).range(0..=20))]
    refine_rounds: u32,
}

/// `--maps`: which step maps straight-node modes use ([`MapKind`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum Maps {
    Auto,
    Static,
    Dynamic,
}

impl PlanArgs {
    /// One goal per part (or none), and the options the goal flags combine with: bad input
    /// before any work.
    fn goals(&self) -> anyhow::Result<Vec<Option<f64>>> {
        let n = self.part.len();
        if n > 1 && self.feed.is_some() {
            return Err(bad(format!(
                "--feed plans one part (on both faces when it flips); {n} parts were given"
            )));
        }
        self.one_part_flags(n, "parts were given")?;
        self.check_max_steps()?;
        let goal_flags = self.goal_deg.is_some() || self.fix_position || self.goal_pos.is_some();
        if self.feed.is_some() && (goal_flags || self.minimize != MinimizeArg::Steps) {
            return Err(bad(
                "--goal-deg, --fix-position, --goal-pos and --minimize plan over orientation \
                 sets: not with --feed"
                    .into(),
            ));
        }
        match &self.goal_deg {
            None => Ok(vec![None; n]),
            Some(g) if g.len() == n => Ok(g.iter().map(|&v| Some(v)).collect()),
            Some(g) => Err(bad(format!(
                "--goal-deg takes one angle per part: {n} part(s), {} angle(s) given",
                g.len()
            ))),
        }
    }

    /// The feed-region search's settings: `--max-steps` or the default depth.
    fn feed_search(&self) -> planner::FeedSearch {
        let depth = self.max_steps.map_or(planner::FeedSearch::DEFAULT_DEPTH, |n| n as usize);
        planner::FeedSearch { depth, ..Default::default() }
    }

    /// `--max-steps` bounds the feed-region search only: without `--feed` it is refused.
    fn check_max_steps(&self) -> anyhow::Result<()> {
        match self.max_steps {
            Some(n) if self.feed.is_none() => Err(bad(format!(
                "--max-steps {n} bounds the feed-region search: give --feed X0 Y0 X1 Y1 too \
                 (the search over orientation sets has no step bound; --max-states bounds it)"
            ))),
            _ => Ok(()),
        }
    }

    /// `--plot` and `--goal-pos` take one part (`what`: "parts were given", or "faces to
    /// plan" once both faces are counted); `--feed` takes one part on one face or both
    /// ([`Self::goals`]).
    fn one_part_flags(&self, n: usize, what: &str) -> anyhow::Result<()> {
        if n > 1 && self.plot.is_some() {
            return Err(bad(format!("--plot draws one part; {n} {what}")));
        }
        if n > 1 && self.goal_pos.is_some() {
            return Err(bad(format!("--goal-pos places one part; {n} {what}")));
        }
        Ok(())
    }

    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let mut inputs: Vec<(&str, &Path)> =
            self.part.iter().map(|p| ("part", p.as_path())).collect();
        inputs.push(("plate", self.plate.as_path()));
        check_plot("--plot", &self.plot, &chladni_media::plot::FIGURE_EXTENSIONS, &inputs)?;
        if let Some(out) = &self.out {
            check_output("--out", out, &inputs)?;
        }
        warn_safety(self.safety);
        let given_goals = self.goals()?;
        let (given, plate) = load_checked(&self.read, &self.part, &self.plate)?;
        let name = given.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join("+");
        let faces = mirror::faces(&given, self.both_faces);
        self.one_part_flags(faces.parts.len(), "faces to plan (both faces of a part that flips)")?;
        self.check_copies(faces.parts.len())?;
        note_self_mirrored(&faces);
        // A goal is the face-up one; a flipped face takes no goal.
        let goals: Vec<Option<f64>> = (faces.of.iter())
            .map(|o| if o.face == Some(Face::Flipped) { None } else { given_goals[o.source] })
            .collect();
        let parts = faces.parts.clone();
        if let (_, Some(warning)) = planner::plan_name(&name) {
            eprintln!("warning: {warning}");
        }
        let region = feed_region(&self.feed, &plate)?;
        let (zone, in_zone) = if region.is_none() { capture_zone(&parts, &plate) } else { NO_ZONE };
        let with_zone = |j| shapes::capture::with_zone(j, zone.as_ref(), &plate, in_zone);
        let opt = self.plan_options(region, &goals);
        let syn = match self.synthesize(&parts, &faces.of, &plate, region, &goals) {
            Ok(syn) => syn,
            Err(e) => {
                if self.json {
                    println!("{}", with_zone(shapes::plan_failure_json(&e)));
                }
                eprintln!("error: {e}");
                return Ok(ExitCode::from(1));
            }
        };
        let (syn, bulk) = self.for_copies(&parts, &plate, &opt, syn)?;
        let mut file = syn.to_file(&plate, &name);
        if let Some(preds) = &mut file.parts {
            for (p, o) in preds.iter_mut().zip(&faces.of) {
                p.face = o.face;
            }
        }
        let limit =
            warn_device_limits(&file).map_err(|e| anyhow::anyhow!("planned steps refused: {e}"))?;
        let overlaps = collisions(&parts, &faces, &syn);
        let mut json = file.to_json();
        if let Some(out) = &self.out {
            write_atomic(out, (serde_json::to_string_pretty(&json)? + "\n").as_bytes())
                .map_err(output_error)?;
        }
        if let Some(w) = &limit {
            let max = DeviceLimits::DEFAULT.max_total_ms;
            json["device_limit"] = shapes::plan::device_limit_json(w, &file, max);
        }
        if syn.parts.len() > 1 {
            json["end_overlaps"] = shapes::plan::end_overlaps_json(&parts, &overlaps);
        }
        if self.json {
            let json = with_zone(shapes::plan::with_whole_plate(json, syn.whole_plate.as_ref()));
            println!("{}", shapes::plan::with_margins(copies::with_bulk(json, &bulk), &syn.steps));
        } else {
            print_plan(&parts, &plate, &syn);
            print_margins(&syn);
            copies::print_bulk(&bulk);
            if let Some(out) = &self.out {
                println!("written    {}", out.display());
            }
        }
        if let Some(path) = &self.plot {
            plan_plot::synthesis_figure(path, &parts[0], &plate, &syn, region.as_ref())
                .map_err(plot_error)?;
            if !self.json {
                println!("plot       {}", path.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The planner's options from the flags (the first part's goal).
    fn plan_options(&self, region: Option<FeedRegion>, goals: &[Option<f64>]) -> PlanOptions {
        PlanOptions {
            margin_deg: self.margin_deg.0.unwrap_or(PlanOptions::default().margin_deg),
            margin_auto: self.margin_deg.0.is_none(),
            safety: self.safety,
            feed: region,
            maps: match self.maps {
                Maps::Auto => MapKind::Auto,
                Maps::Static => MapKind::Static,
                Maps::Dynamic => MapKind::Dynamic,
            },
            minimize: match self.minimize {
                MinimizeArg::Steps => Minimize::Steps,
                MinimizeArg::Time => Minimize::Time,
            },
            goal_deg: goals.first().copied().flatten(),
            fix_position: self.fix_position,
            goal_pos_mm: self.goal_pos.as_ref().map(|g| [g[0], g[1]]),
            deadline: Some(planner::Deadline::after_s(self.max_time_s)),
            max_states: self.max_states as usize,
            feed_search: self.feed_search(),
            refine_rounds: self.refine_rounds as usize,
            ..Default::default()
        }
    }

    /// The plan: over orientation sets (one part or several; `of[i]`: where part `i` comes
    /// from), or by tracking poses from the feed region.
    fn synthesize(
        &self,
        parts: &[Part],
        of: &[FaceOf],
        plate: &PlateModel,
        region: Option<FeedRegion>,
        goals: &[Option<f64>],
    ) -> Result<Synthesis, PlanFailure> {
        let opt = self.plan_options(region, goals);
        match &region {
            Some(r) => {
                let bar = Bar(message_bar(self.json));
                let syn = feed::plan_parts(parts, plate, &opt, r, &bar);
                bar.0.finish_and_clear();
                syn
            }
            None => {
                let bar = LateBar::new(self.json);
                let on = OnPlate::Faces(of);
                let syn = planner::plan_parts_progress(parts, on, plate, &opt, goals, &bar);
                bar.finish();
                syn
            }
        }
    }
}

/// No capture zone (a `--feed` plan): none, and no drop points in it.
const NO_ZONE: (Option<CaptureZone>, (usize, usize)) = (None, (0, 0));

/// The clamp's capture zone of a whole-plate plan ([`planner::capture`]), said up front on
/// stderr when it covers drop points of the whole-plate check: the zone, and (drop points in
/// it, drop points).
fn capture_zone(parts: &[Part], plate: &PlateModel) -> (Option<CaptureZone>, (usize, usize)) {
    let Some(zone) = planner::capture::zone_for_parts(plate, parts) else { return NO_ZONE };
    let body = Body::with_samples(&parts[0], PLANNER_BODY_SAMPLES);
    let drops = planner::whole::drops(&body, plate);
    let n = drops.iter().filter(|(p, _)| zone.contains(plate, *p)).count();
    if n > 0 {
        let feed = feed_hint(&zone, plate);
        eprintln!(
            "warning: {}: {n} of the {} drop points of the whole-plate check lie in it{feed}",
            zone.describe(plate),
            drops.len()
        );
    }
    (Some(zone), (n, drops.len()))
}

/// The `--feed` box the capture-zone warning offers: the plate past the clear line, where
/// one mode takes no sampled drop to the clamp, when there is one; else the plate outside the
/// zone.
fn feed_hint(zone: &CaptureZone, plate: &PlateModel) -> String {
    let (outside, clear) = (zone.outside_mm(plate), zone.clear_box_mm(plate));
    let farther = (zone.bands.iter()).filter(|b| b.clear_mm > b.width_mm).map(|b| b.clear_mm);
    let why = match farther.reduce(f64::max) {
        Some(c) if clear.is_some() => format!(
            "; from {c:.0} mm off the clamped edge on, one mode takes none of the zone's sampled \
             drops to the clamp, so a plan can start with it"
        ),
        _ => String::new(),
    };
    clear.or(outside).map_or(String::new(), |b| {
        format!("{why}; try --feed {:.0} {:.0} {:.0} {:.0}", b[0], b[1], b[2], b[3])
    })
}

/// The planned parts whose predicted end poses overlap (parts from different files: two faces
/// of one part are never on the plate together), each said on stderr: the planner plans each
/// part alone, the motion model keeps them apart, so those predictions cannot both hold.
fn collisions(parts: &[Part], faces: &Faces, syn: &Synthesis) -> Vec<EndOverlap> {
    let meet = |i: usize, j: usize| faces.of[i].source != faces.of[j].source;
    let found = planner::collide::end_overlaps(parts, &syn.parts, meet);
    for o in &found {
        eprintln!(
            "warning: {} and {} are predicted to end overlapping by {:.1} mm: the plan predicts \
             each part as if it were alone, and parts never pass through each other, so they \
             collide there and these predictions do not hold; `chladni simulate` drops them \
             together and measures what happens",
            parts[o.a].name, parts[o.b].name, o.depth_mm
        );
    }
    found
}

/// The given parts and the plate, each part checked against the plate (vertices, size and
/// fit: [`planner::check_input`]) before any work: `plan` and `simulate` refuse alike.
fn load_checked(
    read: &PartRead,
    parts: &[PathBuf],
    plate: &Path,
) -> anyhow::Result<(Vec<Part>, PlateModel)> {
    let given = parts.iter().map(|p| read.load(p)).collect::<anyhow::Result<Vec<_>>>()?;
    let plate = load_plate(plate)?;
    for part in &given {
        planner::check_input(part, &plate).map_err(|e| bad(e.to_string()))?;
    }
    Ok((given, plate))
}

/// Device limits apply at `device upload`: here they are a warning (research first).
/// Returns the warning (`plan --json` names it too).
fn warn_device_limits(
    file: &PlanFile,
) -> Result<Option<String>, chladni_core::model::plan_file::PlanFileError> {
    let w = file.device_limit_warning(&DeviceLimits::DEFAULT)?;
    if let Some(w) = &w {
        eprintln!("warning: {w}");
    }
    Ok(w)
}

/// `--margin-deg`: a number of degrees (every mode keeps it) or `auto` (`None`: margins from
/// evidence).
#[derive(Debug, Clone, Copy)]
pub(super) struct MarginArg(pub(super) Option<f64>);

/// Parses `--margin-deg D|auto`: D in [0, 45).
pub(super) fn margin_arg(s: &str) -> Result<MarginArg, String> {
    if s.trim().eq_ignore_ascii_case("auto") {
        return Ok(MarginArg(None));
    }
    match s.trim().parse::<f64>() {
        Ok(v) if (0.0..45.0).contains(&v) => Ok(MarginArg(Some(v))),
        _ => Err(format!("--margin-deg must be a number in [0, 45) or auto, got {s}")),
    }
}

/// The margin of each step, in words (after the step lines), unless every step kept the
/// default of maps without evidence (straight nodes: nothing to add).
fn print_margins(syn: &Synthesis) {
    use chladni_core::planner::mode_margin::MarginSource;
    if syn.steps.iter().all(|s| s.margin.source == MarginSource::Default) {
        return;
    }
    for (i, s) in syn.steps.iter().enumerate() {
        println!("margin {:<3} {}", i + 1, s.margin.describe());
    }
}

/// `--safety` below 1 makes steps shorter than the slowest simulated settle: allowed, said.
fn warn_safety(safety: f64) {
    if safety < 1.0 {
        eprintln!(
            "warning: --safety {safety} < 1: steps end before the slowest simulated start has \
             settled; check the plan with `chladni simulate`"
        );
    }
}

/// Says which flipping parts are their own mirror image turned (one face planned for them).
fn note_self_mirrored(faces: &Faces) {
    for (name, turn) in &faces.self_mirrored {
        eprintln!(
            "note: {name} is its own mirror image turned by {turn:.2}°: its flipped face rests \
             as the face up turned, so one face is planned and simulated"
        );
    }
}

/// The plan as a table: one line per step, the feed check, the final pose.
fn print_plan(parts: &[Part], plate: &PlateModel, syn: &Synthesis) {
    for (i, part) in parts.iter().enumerate() {
        let (_, period) = syn.predicted(i);
        println!("part       {} (symmetry period {period}°)", part.name);
    }
    println!("plate      {} ({} modes)", plate.name, plate.modes.len());
    for (i, s) in syn.steps.iter().enumerate() {
        let m = &plate.modes[s.mode];
        let after = s.after.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
        println!(
            "step {:<3}  {:<16} {:>8.3} Hz  amplitude {:.3}  {:>6} ms (settle {:.2} s)  → {{{after}}}",
            i + 1,
            m.name,
            m.freq_hz,
            m.amplitude,
            s.duration_ms,
            s.settle.settle_s
        );
        if s.settle.lingering > 0 {
            println!(
                "           ({} simulated start(s) lingered near an unstable rest; not counted)",
                s.settle.lingering
            );
        }
        if !s.settle.ends_on_edge.is_empty() {
            let at = s
                .settle
                .ends_on_edge
                .iter()
                .map(|p| format!("({:.0}, {:.0})", p[0], p[1]))
                .collect::<Vec<_>>()
                .join(", ");
            println!(
                "           reach      {} of {} simulated start points end on a node; from {at} mm the part ends on the plate edge (drop parts elsewhere, or plan for the drop region with --feed)",
                s.settle.points - s.settle.ends_on_edge.len(),
                s.settle.points
            );
        }
    }
    if let Some(f) = &syn.feed {
        println!(
            "feed       ({}, {})–({}, {}) mm: {} start poses tracked; the plan run from {} starts ends at most {:.2}° off",
            f.region.lo[0],
            f.region.lo[1],
            f.region.hi[0],
            f.region.hi[1],
            f.starts,
            f.checked,
            f.worst_error_deg
        );
    }
    if syn.parts.is_empty() {
        print_final(syn.final_orientation_deg, syn.period_deg, syn.goal_deg, syn.final_position_mm);
        print_reach(&syn.reachable_deg, syn.max_steps);
    } else {
        for p in &syn.parts {
            println!("--         {}", p.name);
            print_final(p.final_orientation_deg, p.period_deg, p.goal_deg, p.final_position_mm);
            print_reach(&p.reachable_deg, syn.max_steps);
        }
    }
    if let Some(w) = &syn.whole_plate {
        println!("whole plate  {}", w.describe());
    }
    if let Some(d) = syn.position_check_mm {
        println!("           (simulated from 40 starts: every final centroid within {d:.2} mm)");
    }
    let total: u64 = syn.steps.iter().map(|s| u64::from(s.duration_ms)).sum();
    println!("total      {:.1} s", total as f64 / 1000.0);
}

/// The final orientation (and goal) and position lines.
fn print_final(theta: f64, period: f64, goal: Option<f64>, pos: Option<[f64; 2]>) {
    let goal = goal.map(|g| format!(" (goal {g}°)")).unwrap_or_default();
    println!("final      θ = {theta:.3}° (mod {period}°){goal}");
    match pos {
        Some(p) => println!("position   ({:.2}, {:.2}) mm", p[0], p[1]),
        None => println!("position   not fixed by these nodes"),
    }
}

/// The final orientations plans of at most `max_steps` steps reach.
fn print_reach(reachable: &[f64], max_steps: usize) {
    if reachable.is_empty() {
        return;
    }
    let list = reachable.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
    println!("reachable  {{{list}}} in at most {max_steps} steps");
}

/// Monte Carlo simulation of a plan: success rate and final pose spread.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Part file(s) (.json, .svg or .dxf); a plan for several parts takes them in its order.
    #[arg(required = true, num_args = 1..)]
    part: Vec<PathBuf>,
    #[command(flatten)]
    read: PartRead,
    /// Plate model (TOML).
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// Plan file (chladni plan --out).
    #[arg(long, value_name = "plan.json")]
    plan: PathBuf,
    /// Random start poses.
    #[arg(long, default_value_t = 200, value_parser = clap::value_parser!(u32).range(1..=1_000_000))]
    trials: u32,
    /// Seed of the start poses.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// A trial succeeds when its final orientation is within this of the plan's prediction.
    #[arg(long, value_name = "D", default_value_t = 5.0, value_parser = positive("tol-deg"))]
    tol_deg: f64,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
    /// Draw traces of the first trials (PNG, or SVG for a .svg name); also FILE-plan.png
    /// (.svg), the step-by-step figure.
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// Draw the random start poses in this rectangle (mm), where a feed-region plan holds.
    #[arg(long, num_args = 4, value_names = ["X0", "Y0", "X1", "Y1"], allow_negative_numbers = true)]
    feed: Option<Vec<f64>>,
    /// Every part may land on either face: half of the trials drop it face up, half flipped
    /// (its mirror image), reported per face; the plan must have been made for both faces.
    #[arg(long)]
    both_faces: bool,
    /// Bulk feeding: drop N copies of the part together in each trial (random non-overlapping
    /// poses, contacts between them); reports the oriented fraction, the lost copies and the
    /// oriented parts per minute of plan time.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..=1000))]
    copies: Option<u32>,
    /// With --json: every trial's start pose, its pose after each step and its end pose
    /// (`poses`: trials and steps numbered from 1).
    #[arg(long, requires = "json")]
    poses: bool,
    /// Write every trial's trajectory, one JSON object per line (.jsonl).
    #[arg(long, value_name = "FILE.jsonl")]
    traces: Option<PathBuf>,
    /// Animate the first trials through the plan (GIF): plate, each step's node, the parts,
    /// a clock and the step.
    #[arg(long, value_name = "FILE.gif")]
    animate: Option<PathBuf>,
    /// Integrate grid (solver) modes by the reference wrench rule, not the fast one the
    /// planner uses: confirms a plan independently of the fast rule, at 1.2–3.5× the CPU.
    #[arg(long)]
    reference_wrench: bool,
}

/// The trials and seed of each face: a part dropped on both faces lands face up in the
/// first ⌈N/2⌉ trials and flipped in the other ⌊N/2⌋, each face from its own seed (drawn
/// from `seed`), so the faces' start poses are independent; any other part runs all N.
fn face_trials(faces: &Faces, trials: u32, seed: u64) -> Vec<(u32, u64)> {
    let mut rng = chladni_core::rng::Rng::seeded(seed);
    let flipped_seed = rng.next_u64();
    (faces.of.iter())
        .map(|o| match o.face {
            None => (trials, seed),
            Some(Face::Up) => (trials.div_ceil(2), seed),
            Some(Face::Flipped) => (trials / 2, flipped_seed),
        })
        .collect()
}

impl SimulateArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let (plate, faces) = self.inputs()?;
        note_self_mirrored(&faces);
        let parts = &faces.parts;
        let region = feed_region(&self.feed, &plate)?;
        let file = self.read_plan()?;
        let views = self.part_views(&file, parts, &faces)?;
        let runs = face_trials(&faces, self.trials, self.seed);
        let steps =
            chladni_core::motion::steps::plan_steps(&file, &plate).map_err(|e| match e {
                chladni_core::motion::steps::PlanStepsError::NoMode(e) => bad(format!(
                    "plan step {}: no mode of {} at {} Hz (modes: {})",
                    e.step,
                    self.plate.display(),
                    e.freq_hz,
                    e.modes
                )),
                other => bad(other.to_string()),
            })?;
        let rule = |f: FieldModel| if self.reference_wrench { f.reference() } else { f };
        let fields: Vec<FieldModel> =
            plate.modes.iter().map(|m| rule(FieldModel::new(m, &plate))).collect();
        let sim =
            together::Sim { plate: &plate, fields: &fields, steps: &steps, feed: region.as_ref() };
        if let Some(n) = self.copies {
            return self.run_copies(n, parts, &faces, &sim, &views);
        }
        let mut together = self.together(parts, &faces, &sim)?;
        let mut reports = Vec::new();
        let mut traces = Vec::new();
        for (k, ((part, view), &(trials, seed))) in parts.iter().zip(&views).zip(&runs).enumerate()
        {
            let body = Body::new(part);
            let setup = Setup {
                body: &body,
                plate: &plate,
                fields: &fields,
                steps: &steps,
                feed: region.as_ref(),
            };
            let sims = match together.as_mut() {
                Some(t) => std::mem::take(&mut t[k]),
                None => self.trials_of(&setup, trials, seed),
            };
            let stats = montecarlo::statistics(&sims, view, self.tol_deg);
            if !self.json {
                self.print(part, steps.len(), &stats, (trials, seed));
            }
            let report = Report::new(&stats, view, trials, seed, self.tol_deg);
            self.keep_data(&mut reports, &mut traces, (report, part, &sims));
            if let Some(path) = &self.plot {
                let target = view.final_orientation_deg.zip(view.period_deg);
                let fig = plan_plot::trials_figures(path, part, &setup, &sims, target)
                    .map_err(plot_error)?;
                if !self.json {
                    println!("plots      {} {}", path.display(), fig.display());
                }
            }
            self.write_animation(part, &setup, &sims)?;
        }
        self.write_traces(&traces)?;
        if self.json {
            self.print_json(&faces, reports)?;
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The flags, the parts and the plate checked before any work: the plate and the faces
    /// to simulate.
    fn inputs(&self) -> anyhow::Result<(PlateModel, Faces)> {
        let mut inputs: Vec<(&str, &Path)> =
            self.part.iter().map(|p| ("part", p.as_path())).collect();
        inputs.extend([("plate", self.plate.as_path()), ("plan", self.plan.as_path())]);
        check_plot("--plot", &self.plot, &chladni_media::plot::FIGURE_EXTENSIONS, &inputs)?;
        check_plot("--traces", &self.traces, &["jsonl"], &inputs)?;
        check_plot("--animate", &self.animate, &["gif"], &inputs)?;
        if let Some(path) = &self.plot {
            check_output("--plot", &plan_plot::trials_plan_path(path), &inputs)?;
            if self.part.len() > 1 {
                return Err(bad(format!("--plot draws one part; {} given", self.part.len())));
            }
        }
        let (given, plate) = load_checked(&self.read, &self.part, &self.plate)?;
        let faces = mirror::faces(&given, self.both_faces);
        if self.plot.is_some() && faces.parts.len() > 1 {
            return Err(bad(format!(
                "--plot draws one part; {} faces to simulate",
                faces.parts.len()
            )));
        }
        self.check_animate(faces.parts.len())?;
        if self.trials < 2 && faces.of.iter().any(|o| o.face.is_some()) {
            return Err(bad("--trials 1: both faces need at least 2 trials (half each)".into()));
        }
        Ok((plate, faces))
    }

    /// `--json`: one part, the report; several (or both faces), `{"parts": [{"part": name,
    /// "face"?: "up" | "flipped", ...report}]}`.
    fn print_json(&self, faces: &Faces, reports: Vec<SimulateReport>) -> anyhow::Result<()> {
        if faces.parts.len() == 1
            && let Some(r) = reports.first()
        {
            println!("{}", serde_json::to_string(r)?);
            return Ok(());
        }
        let entries: Vec<PartReport> = (faces.parts.iter().zip(&faces.of))
            .zip(reports)
            .map(|((p, o), report)| PartReport { face: o.face, part: &p.name, report })
            .collect();
        println!("{}", shapes::plan::parts_json(&entries));
        Ok(())
    }

    /// `trials` random trials of one part from `seed` (a progress bar for 100 or more, not
    /// with --json).
    fn trials_of(&self, setup: &Setup<'_>, trials: u32, seed: u64) -> Trials {
        let bar = if !self.json && trials >= 100 {
            indicatif::ProgressBar::new(trials as u64)
        } else {
            indicatif::ProgressBar::hidden()
        };
        let keep = montecarlo::Keep { poses: self.poses, traces: self.traces.is_some() };
        let trials = montecarlo::run_trials_keeping(setup, trials, seed, keep, &Bar(bar.clone()));
        bar.finish_and_clear();
        trials
    }

    /// The report with `--poses`, and the part's `--traces` lines.
    fn keep_data(
        &self,
        reports: &mut Vec<SimulateReport>,
        traces: &mut Vec<TraceLine>,
        (report, part, sims): (Report, &Part, &Trials),
    ) {
        let poses = self.poses.then(|| shapes::trial_poses(sims));
        reports.push(SimulateReport { report, poses });
        if self.traces.is_some() {
            traces.extend(shapes::trace_lines(sims, &part.name));
        }
    }

    /// `--animate` draws one part on one face (`n`: the parts or faces to simulate).
    fn check_animate(&self, n: usize) -> anyhow::Result<()> {
        if self.animate.is_some() && n > 1 {
            return Err(bad(format!(
                "--animate draws one part on one face; {n} parts or faces to simulate"
            )));
        }
        Ok(())
    }

    /// `--animate FILE.gif`: the first trials moving through the plan.
    fn write_animation(&self, part: &Part, setup: &Setup<'_>, sims: &Trials) -> anyhow::Result<()> {
        if let Some(path) = &self.animate {
            let frames = chladni_media::plot::animate::trials_animation(path, part, setup, sims)
                .map_err(plot_error)?;
            if !self.json {
                println!("animation  {} ({frames} frames)", path.display());
            }
        }
        Ok(())
    }

    /// `--traces FILE.jsonl`: every trial's trajectory, one line each.
    fn write_traces(&self, lines: &[TraceLine]) -> anyhow::Result<()> {
        if let Some(path) = &self.traces {
            shapes::write_jsonl(path, lines).map_err(super::output_error)?;
            if !self.json {
                println!("traces     {} ({} trials)", path.display(), lines.len());
            }
        }
        Ok(())
    }

    /// The plan as each part sees it (its own predictions): a plan for several parts needs
    /// as many parts, in its order; a one-part plan, one part.
    fn part_views(
        &self,
        file: &PlanFile,
        parts: &[Part],
        faces: &Faces,
    ) -> anyhow::Result<Vec<PlanFile>> {
        let preds = file.parts.as_deref().unwrap_or_default();
        let planned = file.parts.as_ref().map_or(1, Vec::len);
        if planned != parts.len() {
            let planned_faces = preds.iter().any(|p| p.face == Some(Face::Flipped));
            let hint = if planned_faces && faces.of.iter().all(|o| o.face != Some(Face::Flipped)) {
                "; it was planned for both faces: give --both-faces (or \"flips\": true)"
            } else {
                " (give the parts in the plan's order)"
            };
            return Err(bad(format!(
                "plan {} is for {planned} part(s) or face(s), {} given{hint}",
                self.plan.display(),
                parts.len()
            )));
        }
        // Each face against the plan's entry for that face.
        for (i, (p, o)) in preds.iter().zip(&faces.of).enumerate() {
            if p.face != o.face {
                let says = |f: Option<Face>| f.map_or("no face".to_string(), |f| f.to_string());
                return Err(bad(format!(
                    "plan {} entry {i} ({}) is for {}, the parts given make it {} ({}): plan and \
                     simulate with the same parts and --both-faces",
                    self.plan.display(),
                    p.name,
                    says(p.face),
                    says(o.face),
                    parts[i].name
                )));
            }
        }
        Ok((0..parts.len()).filter_map(|i| file.for_part(i)).collect())
    }

    /// Reads and checks the plan file: every problem is bad input.
    fn read_plan(&self) -> anyhow::Result<PlanFile> {
        let text = std::fs::read_to_string(&self.plan)
            .map_err(|e| bad(format!("cannot read plan {}: {e}", self.plan.display())))?;
        let file = PlanFile::parse(&text)
            .map_err(|e| bad(format!("plan {}: {e}", self.plan.display())))?;
        warn_device_limits(&file)
            .map_err(|e| bad(format!("plan {} refused: {e}", self.plan.display())))?;
        Ok(file)
    }

    /// The statistics as a table.
    fn print(&self, part: &Part, steps: usize, stats: &Stats, (trials, seed): (u32, u64)) {
        println!("part       {}", part.name);
        println!("plan       {steps} step(s), {trials} trials, seed {seed}");
        match (stats.success_rate, stats.orientation_error_deg) {
            (Some(s), Some(err)) => {
                println!(
                    "success    {:.1} % within {}° of the predicted orientation",
                    100.0 * s,
                    self.tol_deg
                );
                println!("θ error    rms {:.3}°, max {:.3}°", err.rms, err.max);
                print_misses(&stats.misses);
            }
            _ => println!("success    - (the plan file predicts no final orientation)"),
        }
        if let Some(err) = stats.position_error_mm {
            println!("position   error rms {:.3} mm, max {:.3} mm", err.rms, err.max);
        }
        let [mx, my] = stats.mean_position_mm;
        println!(
            "spread     centroid rms {:.3} mm about ({mx:.2}, {my:.2})",
            stats.position_spread_mm
        );
    }
}

/// Where the missed trials started.
fn print_misses(misses: &[Pose]) {
    if misses.is_empty() {
        return;
    }
    let range = |f: fn(&Pose) -> f64| {
        let lo = misses.iter().map(f).fold(f64::INFINITY, f64::min);
        let hi = misses.iter().map(f).fold(f64::NEG_INFINITY, f64::max);
        format!("[{lo:.0}, {hi:.0}]")
    };
    println!(
        "misses     {} started in x ∈ {} mm, y ∈ {} mm",
        misses.len(),
        range(|q| q.x),
        range(|q| q.y)
    );
}
