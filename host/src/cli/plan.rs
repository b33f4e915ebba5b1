//! `chladni plan PART --plate P` and `chladni simulate PART --plate P --plan PLAN`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni::model::part::Part;
use chladni::model::plan_file::PlanFile;
use chladni::model::plate::PlateModel;
use chladni::motion::montecarlo::{self, Report, Setup, Stats, Trials};
use chladni::motion::sim::{self, Body, FieldModel, Pose, SimStep, simulate_plan};
use chladni::output::write_atomic;
use chladni::planner::feed::{self, FeedRegion};
use chladni::planner::{self, PlanOptions, Synthesis};
use chladni::plot::plan::{self as plan_plot, TracesFigure};
use chladni::rng::Rng;
use chladni_shared::icd::plan::DeviceLimits;
use clap::Args;

use super::parse::{f64_where, positive};
use super::part::PartArgs;
use super::{InputError, check_output, check_plot, output_error, plot_error};

fn bad(msg: String) -> anyhow::Error {
    InputError(msg).into()
}

fn load_plate(path: &Path) -> anyhow::Result<PlateModel> {
    PlateModel::load(path).map_err(bad)
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

/// The feed-region search's progress bar (hidden for JSON output).
fn search_bar(hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(0);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("{msg} {wide_bar} {pos}/{len} [{elapsed}]")
    {
        bar.set_style(style);
    }
    bar
}

/// Sensorless plan: the shortest mode sequence bringing every start orientation to one.
#[derive(Debug, Args)]
pub struct PlanArgs {
    #[command(flatten)]
    part: PartArgs,
    /// Plate model (TOML with [[mode]] entries; docs/plan.md).
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// Robustness margin: no predicted orientation closer than this to a basin boundary.
    #[arg(long, value_name = "D", default_value_t = 3.0,
          value_parser = f64_where("margin-deg", "in [0, 45)", |v| (0.0..45.0).contains(&v)))]
    margin_deg: f64,
    /// Step duration = slowest simulated settle time × this.
    #[arg(long, value_name = "X", default_value_t = 1.5,
          value_parser = f64_where("safety", "in [1, 100]", |v| (1.0..=100.0).contains(&v)))]
    safety: f64,
    /// Print the plan as one JSON object.
    #[arg(long)]
    json: bool,
    /// Write the plan file (for `chladni simulate` and `chladni device run-file`).
    #[arg(long, value_name = "plan.json")]
    out: Option<PathBuf>,
    /// Draw the step-by-step plan figure (PNG) for a few example starts.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Parts are dropped in this rectangle (mm): plan by tracking poses from it.
    #[arg(long, num_args = 4, value_names = ["X0", "Y0", "X1", "Y1"], allow_negative_numbers = true)]
    feed: Option<Vec<f64>>,
}

impl PlanArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let inputs = [("part", self.part.path()), ("plate", self.plate.as_path())];
        check_plot("--plot", &self.plot, &["png"], &inputs)?;
        if let Some(out) = &self.out {
            check_output("--out", out, &inputs)?;
        }
        let part = self.part.load()?;
        let plate = load_plate(&self.plate)?;
        planner::check_input(&part, &plate).map_err(|e| bad(e.to_string()))?;
        if let (_, Some(warning)) = planner::plan_name(&part.name) {
            eprintln!("warning: {warning}");
        }
        let region = feed_region(&self.feed, &plate)?;
        let syn = self.synthesize(&part, &plate, region)?;
        let file = syn.to_file(&plate, &part.name);
        file.to_plan(&DeviceLimits::DEFAULT)
            .map_err(|e| anyhow::anyhow!("planned steps refused: {e}"))?;
        let json = file.to_json();
        if let Some(out) = &self.out {
            write_atomic(out, (serde_json::to_string_pretty(&json)? + "\n").as_bytes())
                .map_err(output_error)?;
        }
        if self.json {
            println!("{json}");
        } else {
            print_plan(&part, &plate, &syn);
            if let Some(out) = &self.out {
                println!("written    {}", out.display());
            }
        }
        if let Some(path) = &self.plot {
            plot_plan(path, &part, &plate, &syn, region.as_ref())?;
            if !self.json {
                println!("plot       {}", path.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The plan: over orientation sets, or by tracking poses from the feed region.
    fn synthesize(
        &self,
        part: &Part,
        plate: &PlateModel,
        region: Option<FeedRegion>,
    ) -> anyhow::Result<Synthesis> {
        let opt = PlanOptions {
            margin_deg: self.margin_deg,
            safety: self.safety,
            feed: region,
            ..Default::default()
        };
        match &region {
            Some(r) => {
                let bar = search_bar(self.json);
                let syn = feed::plan(part, plate, &opt, r, &bar);
                bar.finish_and_clear();
                syn
            }
            None => planner::plan(part, plate, &opt),
        }
        .map_err(|e| anyhow::anyhow!("{}: {e}", part.name))
    }
}

/// The plan as a table: one line per step, the feed check, the final pose.
fn print_plan(part: &Part, plate: &PlateModel, syn: &Synthesis) {
    println!("part       {} (symmetry period {}°)", part.name, syn.period_deg);
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
    println!("final      θ = {:.3}° (mod {}°)", syn.final_orientation_deg, syn.period_deg);
    match syn.final_position_mm {
        Some(p) => println!("position   ({:.2}, {:.2}) mm", p[0], p[1]),
        None => println!("position   not fixed by these nodes"),
    }
}

/// The step-by-step figure for three example starts (seed 1).
fn plot_plan(
    path: &Path,
    part: &Part,
    plate: &PlateModel,
    syn: &Synthesis,
    region: Option<&FeedRegion>,
) -> anyhow::Result<()> {
    let body = Body::new(part);
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let steps: Vec<SimStep> = syn.sim_steps();
    let mut rng = Rng::seeded(1);
    let examples: Vec<Vec<Pose>> = (0..3)
        .map(|_| {
            let start = montecarlo::random_pose(&mut rng, &body, plate, region);
            simulate_plan(&body, plate, &fields, &steps, start).0
        })
        .collect();
    let modes: Vec<usize> = syn.steps.iter().map(|s| s.mode).collect();
    let title = format!(
        "{}: {}-step plan, final θ = {:.1}° (mod {}°)",
        part.name,
        modes.len(),
        syn.final_orientation_deg,
        syn.period_deg
    );
    plan_plot::plan_figure(path, &title, &body, plate, &modes, &examples).map_err(plot_error)
}

/// Monte Carlo simulation of a plan: success rate and final pose spread.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    #[command(flatten)]
    part: PartArgs,
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
    /// Draw traces of the first trials (PNG); also FILE-plan.png, the step-by-step figure.
    #[arg(long, value_name = "FILE.png")]
    plot: Option<PathBuf>,
    /// Draw the random start poses in this rectangle (mm), where a feed-region plan holds.
    #[arg(long, num_args = 4, value_names = ["X0", "Y0", "X1", "Y1"], allow_negative_numbers = true)]
    feed: Option<Vec<f64>>,
}

/// The step-by-step figure beside `--plot F.png`: `F-plan.png`.
fn plan_figure_path(plot: &Path) -> PathBuf {
    PathBuf::from(format!("{}-plan.png", plot.with_extension("").display()))
}

impl SimulateArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let inputs = [
            ("part", self.part.path()),
            ("plate", self.plate.as_path()),
            ("plan", self.plan.as_path()),
        ];
        check_plot("--plot", &self.plot, &["png"], &inputs)?;
        if let Some(path) = &self.plot {
            check_output("--plot", &plan_figure_path(path), &inputs)?;
        }
        let part = self.part.load()?;
        let plate = load_plate(&self.plate)?;
        planner::check_input(&part, &plate).map_err(|e| bad(e.to_string()))?;
        let region = feed_region(&self.feed, &plate)?;
        let file = self.read_plan()?;
        let steps = sim::plan_steps(&file, &plate).map_err(|e| match e {
            sim::PlanStepsError::NoMode(e) => bad(format!(
                "plan step {}: no mode of {} at {} Hz (modes: {})",
                e.step,
                self.plate.display(),
                e.freq_hz,
                e.modes
            )),
            other => bad(other.to_string()),
        })?;
        let body = Body::new(&part);
        let fields: Vec<FieldModel> =
            plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
        let setup = Setup {
            body: &body,
            plate: &plate,
            fields: &fields,
            steps: &steps,
            feed: region.as_ref(),
        };
        let bar = if !self.json && self.trials >= 100 {
            indicatif::ProgressBar::new(self.trials as u64)
        } else {
            indicatif::ProgressBar::hidden()
        };
        let trials = montecarlo::run_trials(&setup, self.trials, self.seed, || bar.inc(1));
        bar.finish_and_clear();
        let stats = montecarlo::statistics(&trials, &file, self.tol_deg);
        if self.json {
            let report = Report::new(&stats, &file, self.trials, self.seed, self.tol_deg);
            println!("{}", serde_json::to_string(&report)?);
        } else {
            self.print(&part, steps.len(), &stats);
        }
        if let Some(path) = &self.plot {
            let target = file.final_orientation_deg.zip(file.period_deg);
            let fig = plot_trials(path, &part, &setup, &trials, target)?;
            if !self.json {
                println!("plots      {} {}", path.display(), fig.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }

    /// Reads and checks the plan file: every problem is bad input.
    fn read_plan(&self) -> anyhow::Result<PlanFile> {
        let text = std::fs::read_to_string(&self.plan)
            .map_err(|e| bad(format!("cannot read plan {}: {e}", self.plan.display())))?;
        let file = PlanFile::parse(&text)
            .map_err(|e| bad(format!("plan {}: {e}", self.plan.display())))?;
        file.to_plan(&DeviceLimits::DEFAULT)
            .map_err(|e| bad(format!("plan {} refused: {e}", self.plan.display())))?;
        Ok(file)
    }

    /// The statistics as a table.
    fn print(&self, part: &Part, steps: usize, stats: &Stats) {
        println!("part       {}", part.name);
        println!("plan       {steps} step(s), {} trials, seed {}", self.trials, self.seed);
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

/// The traces figure at `path` and the step-by-step figure beside it; returns the latter's
/// path.
fn plot_trials(
    path: &Path,
    part: &Part,
    setup: &Setup<'_>,
    trials: &Trials,
    target: Option<(f64, f64)>,
) -> anyhow::Result<PathBuf> {
    let modes: Vec<usize> = setup.steps.iter().map(|s| s.mode).collect();
    let title = format!(
        "{} on {}: simulated plan ({} trials shown)",
        part.name,
        setup.plate.name,
        trials.traces.len()
    );
    let fig = TracesFigure {
        title: &title,
        body: setup.body,
        plate: setup.plate,
        modes: &modes,
        traces: &trials.traces,
        step_ends: &trials.step_ends,
        target,
    };
    plan_plot::traces_figure(path, &fig).map_err(plot_error)?;
    let fig = plan_figure_path(path);
    let title = format!("{}: plan step by step", part.name);
    plan_plot::plan_figure(&fig, &title, setup.body, setup.plate, &modes, &trials.examples)
        .map_err(plot_error)?;
    Ok(fig)
}
