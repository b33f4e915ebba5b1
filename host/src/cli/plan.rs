//! `chladni plan PART --plate P` and `chladni simulate PART --plate P --plan PLAN`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni::model::part::Part;
use chladni::model::plan_file::PlanFile;
use chladni::model::plate::PlateModel;
use chladni::motion::sim::{Body, FieldModel, Pose, SimStep, run_plan};
use chladni::planner::feed::{self, FeedRegion};
use chladni::planner::{self, PlanOptions};
use chladni::plot::plan as plan_plot;
use chladni_shared::plan::DeviceLimits;
use clap::Args;

use super::InputError;

fn bad(msg: String) -> anyhow::Error {
    InputError(msg).into()
}

fn load_part(path: &Path) -> anyhow::Result<Part> {
    Part::load(path).map_err(|e| bad(format!("{}: {e}", path.display())))
}

fn load_plate(path: &Path) -> anyhow::Result<PlateModel> {
    PlateModel::load(path).map_err(bad)
}

fn check_png(path: &Option<PathBuf>) -> anyhow::Result<()> {
    if let Some(p) = path
        && p.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref()
            != Some("png")
    {
        return Err(bad(format!("--plot file must end in .png: {}", p.display())));
    }
    Ok(())
}

/// Small deterministic generator (SplitMix64): seeded Monte Carlo without extra crates.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// A random pose on the plate, or in the feed region when given (centroid at least the
/// part's radius from the plate's edges).
fn random_pose(rng: &mut Rng, body: &Body, plate: &PlateModel, feed: Option<&FeedRegion>) -> Pose {
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let (u, v) = (rng.next(), rng.next());
    let [x, y] = match feed {
        Some(f) => f.at(u, v, r, plate),
        None => [r + (w - 2.0 * r) * u, r + (h - 2.0 * r) * v],
    };
    Pose { x, y, theta: std::f64::consts::TAU * rng.next() }
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
    /// Part file (.json or .svg).
    part: PathBuf,
    /// Plate model (TOML with [[mode]] entries; docs/plan.md).
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// Robustness margin: no predicted orientation closer than this to a basin boundary.
    #[arg(long, value_name = "D", default_value_t = 3.0)]
    margin_deg: f64,
    /// Step duration = slowest simulated settle time × this.
    #[arg(long, value_name = "X", default_value_t = 1.5)]
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
        if !(self.margin_deg.is_finite() && (0.0..45.0).contains(&self.margin_deg)) {
            return Err(bad(format!("--margin-deg must be in [0, 45), got {}", self.margin_deg)));
        }
        if !(self.safety.is_finite() && (1.0..=100.0).contains(&self.safety)) {
            return Err(bad(format!("--safety must be in [1, 100], got {}", self.safety)));
        }
        check_png(&self.plot)?;
        let part = load_part(&self.part)?;
        let plate = load_plate(&self.plate)?;
        planner::check_input(&part, &plate).map_err(|e| bad(e.to_string()))?;
        if let (_, Some(warning)) = planner::plan_name(&part.name) {
            eprintln!("warning: {warning}");
        }
        let region = feed_region(&self.feed, &plate)?;
        let opt = PlanOptions {
            margin_deg: self.margin_deg,
            safety: self.safety,
            feed: region,
            ..Default::default()
        };
        let syn = match &region {
            Some(r) => {
                let bar = search_bar(self.json);
                let syn = feed::plan(&part, &plate, &opt, r, &bar);
                bar.finish_and_clear();
                syn
            }
            None => planner::plan(&part, &plate, &opt),
        }
        .map_err(|e| anyhow::anyhow!("{}: {e}", part.name))?;
        let file = syn.to_file(&plate, &part.name);
        file.to_plan(&DeviceLimits::DEFAULT)
            .map_err(|e| anyhow::anyhow!("planned steps refused: {e}"))?;
        let json = file.to_json();
        if let Some(out) = &self.out {
            std::fs::write(out, serde_json::to_string_pretty(&json)? + "\n")
                .map_err(|e| anyhow::anyhow!("cannot write {}: {e}", out.display()))?;
        }
        if self.json {
            println!("{json}");
        } else {
            println!("part       {} (symmetry period {}°)", part.name, syn.period_deg);
            println!("plate      {} ({} modes)", plate.name, plate.modes.len());
            for (i, s) in syn.steps.iter().enumerate() {
                let m = &plate.modes[s.mode];
                let after =
                    s.after.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
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
            if let Some(out) = &self.out {
                println!("written    {}", out.display());
            }
        }
        if let Some(path) = &self.plot {
            let body = Body::new(&part);
            let fields: Vec<FieldModel> =
                plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
            let steps: Vec<SimStep> = syn.sim_steps();
            let mut rng = Rng(1);
            let examples: Vec<Vec<Pose>> = (0..3)
                .map(|_| {
                    let start = random_pose(&mut rng, &body, &plate, region.as_ref());
                    run_plan(&body, &plate, &fields, &steps, start).0
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
            plan_plot::plan_figure(path, &title, &body, &plate, &modes, &examples)?;
            if !self.json {
                println!("plot       {}", path.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }
}

/// Missed trials listed by `chladni simulate --json` (all are counted).
const MAX_LISTED_MISSES: usize = 100;

/// Monte Carlo simulation of a plan: success rate and final pose spread.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Part file (.json or .svg).
    part: PathBuf,
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
    #[arg(long, value_name = "D", default_value_t = 5.0)]
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

impl SimulateArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        check_png(&self.plot)?;
        if !(self.tol_deg.is_finite() && self.tol_deg > 0.0) {
            return Err(bad(format!("--tol-deg must be positive, got {}", self.tol_deg)));
        }
        let part = load_part(&self.part)?;
        let plate = load_plate(&self.plate)?;
        planner::check_input(&part, &plate).map_err(|e| bad(e.to_string()))?;
        let region = feed_region(&self.feed, &plate)?;
        let text = std::fs::read_to_string(&self.plan)
            .map_err(|e| bad(format!("cannot read plan {}: {e}", self.plan.display())))?;
        let file = PlanFile::parse(&text)
            .map_err(|e| bad(format!("plan {}: {e}", self.plan.display())))?;
        file.to_plan(&DeviceLimits::DEFAULT)
            .map_err(|e| bad(format!("plan {} refused: {e}", self.plan.display())))?;
        let mut steps = Vec::new();
        for (i, s) in file.steps.iter().enumerate() {
            let k =
                plate.modes.iter().position(|m| (m.freq_hz - s.freq_hz).abs() < 1e-3).ok_or_else(
                    || {
                        let list = plate
                            .modes
                            .iter()
                            .map(|m| format!("{} Hz", m.freq_hz))
                            .collect::<Vec<_>>()
                            .join(", ");
                        bad(format!(
                            "plan step {i}: no mode of {} at {} Hz (modes: {list})",
                            self.plate.display(),
                            s.freq_hz
                        ))
                    },
                )?;
            steps.push(SimStep {
                mode: k,
                duration_s: s.duration_ms as f64 / 1000.0,
                amplitude_ratio: s.amplitude / plate.modes[k].amplitude,
            });
        }
        let steps: Vec<SimStep> = (0..file.repeat).flat_map(|_| steps.iter().copied()).collect();
        let body = Body::new(&part);
        let fields: Vec<FieldModel> =
            plate.modes.iter().map(|m| FieldModel::new(m, &plate)).collect();
        let mut rng = Rng(self.seed);
        let bar = if !self.json && self.trials >= 100 {
            indicatif::ProgressBar::new(self.trials as u64)
        } else {
            indicatif::ProgressBar::hidden()
        };
        let mut starts = Vec::with_capacity(self.trials as usize);
        let mut finals = Vec::with_capacity(self.trials as usize);
        let mut traces = Vec::new();
        let mut examples = Vec::new();
        let mut ends = Vec::new();
        for i in 0..self.trials {
            let start = random_pose(&mut rng, &body, &plate, region.as_ref());
            let (poses, trace, e) = run_plan(&body, &plate, &fields, &steps, start);
            starts.push(start);
            finals.push(*poses.last().unwrap_or(&start));
            if i < 6 {
                traces.push(trace);
                ends = e;
            }
            if i < 3 {
                examples.push(poses);
            }
            bar.inc(1);
        }
        bar.finish_and_clear();
        let target = file.final_orientation_deg.zip(file.period_deg);
        let n = finals.len() as f64;
        // Start poses of the trials that missed the predicted orientation: where a plan's
        // feed region ends (e.g. near a cantilever's clamp) shows in them.
        let mut misses: Vec<Pose> = Vec::new();
        let (success, orient) = match target {
            Some((t, p)) => {
                let errs: Vec<f64> = finals
                    .iter()
                    .map(|q| {
                        let d = (q.theta.to_degrees() - t).rem_euclid(p);
                        if d > p / 2.0 { d - p } else { d }
                    })
                    .collect();
                misses = starts
                    .iter()
                    .zip(&errs)
                    .filter(|(_, e)| e.abs() > self.tol_deg)
                    .map(|(s, _)| *s)
                    .collect();
                let ok = 1.0 - misses.len() as f64 / n;
                let rms = (errs.iter().map(|e| e * e).sum::<f64>() / n).sqrt();
                let max = errs.iter().fold(0.0f64, |m, e| m.max(e.abs()));
                (Some(ok), Some((rms, max)))
            }
            None => (None, None),
        };
        let pos = file.final_position_mm.map(|p| {
            let d: Vec<f64> = finals.iter().map(|q| (q.x - p[0]).hypot(q.y - p[1])).collect();
            (
                (d.iter().map(|e| e * e).sum::<f64>() / n).sqrt(),
                d.iter().fold(0.0f64, |m, e| m.max(*e)),
            )
        });
        let (mx, my) = (
            finals.iter().map(|q| q.x).sum::<f64>() / n,
            finals.iter().map(|q| q.y).sum::<f64>() / n,
        );
        let spread = (finals.iter().map(|q| (q.x - mx).powi(2) + (q.y - my).powi(2)).sum::<f64>()
            / n)
            .sqrt();
        let r6 = |v: f64| (v * 1e6).round() / 1e6;
        if self.json {
            let v = serde_json::json!({
                "trials": self.trials,
                "seed": self.seed,
                "tolerance_deg": self.tol_deg,
                "success_rate": success.map(r6),
                "final_orientation_deg": target.map(|t| t.0),
                "period_deg": target.map(|t| t.1),
                "orientation_error_deg": orient.map(|(rms, max)| serde_json::json!({"rms": r6(rms), "max": r6(max)})),
                "position_error_mm": pos.map(|(rms, max)| serde_json::json!({"rms": r6(rms), "max": r6(max)})),
                "position_spread_mm": r6(spread),
                "missed": misses.len(),
                "missed_starts": misses.iter().take(MAX_LISTED_MISSES).map(|q| [r6(q.x), r6(q.y), r6(q.theta.to_degrees())]).collect::<Vec<_>>(),
            });
            println!("{v}");
        } else {
            println!("part       {}", part.name);
            println!(
                "plan       {} step(s), {} trials, seed {}",
                steps.len(),
                self.trials,
                self.seed
            );
            match (success, orient) {
                (Some(s), Some((rms, max))) => {
                    println!(
                        "success    {:.1} % within {}° of the predicted orientation",
                        100.0 * s,
                        self.tol_deg
                    );
                    println!("θ error    rms {rms:.3}°, max {max:.3}°");
                    if !misses.is_empty() {
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
                }
                _ => println!("success    - (the plan file predicts no final orientation)"),
            }
            if let Some((rms, max)) = pos {
                println!("position   error rms {rms:.3} mm, max {max:.3} mm");
            }
            println!("spread     centroid rms {spread:.3} mm about ({mx:.2}, {my:.2})");
        }
        if let Some(path) = &self.plot {
            let modes: Vec<usize> = steps.iter().map(|s| s.mode).collect();
            let title = format!(
                "{} on {}: simulated plan ({} trials shown)",
                part.name,
                plate.name,
                traces.len()
            );
            plan_plot::traces_figure(path, &title, &body, &plate, &modes, &traces, &ends, target)?;
            let stem = path.with_extension("");
            let fig = PathBuf::from(format!("{}-plan.png", stem.display()));
            let title = format!("{}: plan step by step", part.name);
            plan_plot::plan_figure(&fig, &title, &body, &plate, &modes, &examples)?;
            if !self.json {
                println!("plots      {} {}", path.display(), fig.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }
}
