//! `chladni steer` and `chladni plate learn`: the feeder with a camera (docs/steer.md). Thin:
//! parse, open the link and the camera, run `chladni_steer`'s loop, print; every failure
//! after the link opened has stopped the drive.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

use anyhow::Context;
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_edit::set_learned;
use chladni_core::model::plate_file::Learned as LearnedTable;
use chladni_core::model::pose::Pose;
use chladni_core::output::write_atomic;
use chladni_core::steer::learn::LearnOptions;
use chladni_core::steer::policy::Rules;
use chladni_core::steer::{Menu, Model};
use chladni_device::client::DeviceClient;
use chladni_steer::LoopError;
use chladni_steer::camera::{Camera, CameraOptions, CameraSource};
use chladni_steer::learn::{LearnJob, LearnOutcome, learn_plate};
use chladni_steer::parts::Kind;
use chladni_steer::session::{Session, SessionConfig};
use chladni_steer::steer::{SteerJob, SteerReport, steer};
use clap::Args;

use super::device::render::print_json;
use super::device::watch::{EXIT_INTERRUPTED, interrupt_flag};
use super::parse::positive;
use super::progress::message_bar;
use super::{Failure, InputError, check_output, output_error};

/// Exit code of a run that ended by the time limit with parts off their goals.
const EXIT_NOT_REACHED: u8 = 1;

/// What both commands take: the controller, the camera, the plate and the parts.
#[derive(Debug, Args)]
pub struct LoopArgs {
    /// The controller: serial device or tcp://HOST:PORT (`chladni emulator` prints it).
    #[arg(long, short)]
    port: String,
    /// The camera: http://… or https://… (each GET one JPEG or PNG frame) or dir:PATH (the
    /// newest image in a folder); docs/camera.md.
    #[arg(long, value_name = "URL")]
    camera: String,
    /// The plate file (TOML).
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// A part on the plate (JSON, SVG or DXF); give a file once per part, the same file several
    /// times for identical parts.
    #[arg(long = "part", value_name = "P.json", required = true)]
    parts: Vec<PathBuf>,
    /// The plate's corners in the frames (px): bottom-left, bottom-right, top-right, top-left;
    /// found in the first frame when not given.
    #[arg(long, num_args = 8, allow_negative_numbers = true,
          value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"])]
    corners: Option<Vec<f64>>,
    /// How long parts take to settle after the drive stops, before a frame counts (ms).
    #[arg(long, value_name = "MS", default_value_t = 150)]
    settle_ms: u64,
    /// How long a frame may take to come (s).
    #[arg(long, value_name = "S", default_value_t = 5.0, value_parser = positive("camera-timeout-s"))]
    camera_timeout_s: f64,
    /// Stop after this long (s).
    #[arg(long, value_name = "S", value_parser = positive("time-limit-s"))]
    time_limit_s: Option<f64>,
    /// Print one JSON object at the end (also for failures).
    #[arg(long)]
    json: bool,
}

/// The loaded inputs.
struct Loaded {
    plate: PlateModel,
    kinds: Vec<Kind>,
    /// Each part's kind.
    parts: Vec<usize>,
}

impl LoopArgs {
    /// Loads the plate and parts: identical files are one kind.
    fn load(&self) -> Result<Loaded, Failure> {
        let bad = |kind: &'static str, msg: String| Failure { kind, error: InputError(msg).into() };
        let plate = PlateModel::load(&self.plate)
            .map_err(|e| bad("bad_plate", format!("--plate {}: {e}", self.plate.display())))?;
        if plate.modes.is_empty() {
            return Err(bad(
                "bad_plate",
                format!(
                    "--plate {}: no [[mode]]: the loop needs modes to drive",
                    self.plate.display()
                ),
            ));
        }
        let (mut kinds, mut paths, mut parts) =
            (Vec::<Kind>::new(), Vec::<PathBuf>::new(), Vec::new());
        for p in &self.parts {
            let key = std::fs::canonicalize(p).unwrap_or_else(|_| p.clone());
            let index = match paths.iter().position(|q| *q == key) {
                Some(i) => i,
                None => {
                    let part = Part::load(p)
                        .map_err(|e| bad("bad_part", format!("--part {}: {e}", p.display())))?;
                    paths.push(key);
                    kinds.push(Kind::new(part));
                    kinds.len() - 1
                }
            };
            parts.push(index);
        }
        Ok(Loaded { plate, kinds, parts })
    }

    /// Opens the camera and the controller's link into a session.
    fn session(&self, loaded: &Loaded, command: &str) -> Result<Session, Failure> {
        let bad = |kind: &'static str, msg: String| Failure { kind, error: InputError(msg).into() };
        let source: CameraSource =
            self.camera.parse().map_err(|e: chladni_steer::camera::CameraError| {
                bad(e.name(), format!("--camera: {e}"))
            })?;
        let options = CameraOptions {
            timeout: Duration::from_secs_f64(self.camera_timeout_s),
            ..CameraOptions::default()
        };
        let camera = Camera::open(source, options)
            .map_err(|e| Failure { kind: e.name(), error: e.into() })?;
        let name = format!("chladni {command} (pid {})", std::process::id());
        let client = DeviceClient::open(&self.port, &name)
            .with_context(|| format!("connecting to {}", self.port))
            .map_err(|error| Failure { kind: "controller", error })?;
        let corners =
            self.corners.as_ref().map(|c| [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]]);
        let config = SessionConfig {
            size_mm: loaded.plate.size_mm,
            corners,
            settle: Duration::from_millis(self.settle_ms),
        };
        let flag = interrupt_flag().map_err(|error| Failure { kind: "failed", error })?;
        let interrupted = Box::new(move || flag.load(Ordering::SeqCst));
        let kinds: Vec<Part> = loaded.kinds.iter().map(|k| k.part.clone()).collect();
        Ok(Session::new(client, camera, &kinds, config, interrupted))
    }
}

/// A loop failure as the command's end: Ctrl-C is exit 130 (the one `--json` failure object
/// printed, the message on stderr), anything else a failure.
fn loop_end(e: LoopError, json: bool) -> Result<ExitCode, Failure> {
    if matches!(e, LoopError::Interrupted) {
        let error = Failure { kind: e.name(), error: e.into() }.report(json);
        eprintln!("{error:#}");
        return Ok(ExitCode::from(EXIT_INTERRUPTED));
    }
    Err(Failure { kind: e.name(), error: e.into() })
}

/// Drive parts to goal poses with the camera in the loop; exit 1 if the time runs out first.
#[derive(Debug, Args)]
pub struct SteerArgs {
    #[command(flatten)]
    rig: LoopArgs,
    /// A goal pose X Y THETA (mm, mm, degrees) for each --part, in the same order.
    #[arg(long, num_args = 3, allow_negative_numbers = true, value_names = ["X", "Y", "THETA"], required = true)]
    goal: Vec<f64>,
    /// Position tolerance (mm).
    #[arg(long, value_name = "MM", default_value_t = 2.0, value_parser = positive("tol-mm"))]
    tol_mm: f64,
    /// Orientation tolerance (degrees).
    #[arg(long, value_name = "DEG", default_value_t = 3.0, value_parser = positive("tol-deg"))]
    tol_deg: f64,
    /// Every cycle as one JSON line: frame time, poses seen, command, predicted and observed.
    #[arg(long, value_name = "F.jsonl")]
    log: Option<PathBuf>,
}

impl SteerArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let json = self.rig.json;
        self.steer().map_err(|f| f.report(json))
    }

    fn steer(&self) -> Result<ExitCode, Failure> {
        let bad = |msg: String| Failure { kind: "bad_input", error: InputError(msg).into() };
        let loaded = self.rig.load()?;
        let goals = self.goals(&loaded).map_err(bad)?;
        if let Some(log) = &self.log {
            check_output("--log", log, &[("--plate", &self.rig.plate)])
                .map_err(|error| Failure { kind: "bad_input", error })?;
        }
        let mut log = match &self.log {
            Some(p) => Some(
                std::fs::File::create(p).map_err(|e| bad(format!("--log {}: {e}", p.display())))?,
            ),
            None => None,
        };
        let job = SteerJob {
            kinds: loaded.kinds.clone(),
            parts: loaded.parts.iter().copied().zip(goals).collect(),
            tol_mm: self.tol_mm,
            tol_deg: self.tol_deg,
            time_limit: Duration::from_secs_f64(self.rig.time_limit_s.unwrap_or(120.0)),
            menu: Menu::default(),
        };
        let mut model = Model::new(loaded.plate.clone());
        let mut session = self.rig.session(&loaded, "steer")?;
        let bar = message_bar(self.rig.json);
        bar.set_message("steering");
        let result = steer(&mut session, &mut model, &job, |c| {
            if let Some(f) = log.as_mut()
                && let Ok(line) = serde_json::to_string(c)
            {
                let _ = writeln!(f, "{line}");
            }
            let worst = c
                .predicted_error_mm
                .as_ref()
                .map_or(0.0, |e| e.iter().copied().fold(0.0, f64::max));
            bar.set_message(format!("cycle {}, last prediction off by ≤ {worst:.1} mm", c.cycle));
            bar.tick();
        });
        bar.finish_and_clear();
        let report = match result {
            Ok(r) => r,
            Err(e) => return loop_end(e, self.rig.json),
        };
        self.print(&report).map_err(|error| Failure { kind: "failed", error })?;
        Ok(if report.reached { ExitCode::SUCCESS } else { ExitCode::from(EXIT_NOT_REACHED) })
    }

    /// The goals, one per part, θ in radians; each a pose on the plate.
    fn goals(&self, loaded: &Loaded) -> Result<Vec<Pose>, String> {
        let n = self.goal.len() / 3;
        if n != loaded.parts.len() {
            return Err(format!(
                "{} --part but {n} --goal: give each part a goal X Y THETA, in the same order",
                loaded.parts.len()
            ));
        }
        let [w, h] = loaded.plate.size_mm;
        self.goal
            .chunks(3)
            .map(|g| {
                if !(g.iter().all(|v| v.is_finite())
                    && (0.0..=w).contains(&g[0])
                    && (0.0..=h).contains(&g[1]))
                {
                    return Err(format!(
                        "--goal {} {} {}: the goal must lie on the {w} × {h} mm plate",
                        g[0], g[1], g[2]
                    ));
                }
                Ok(Pose { x: g[0], y: g[1], theta: g[2].to_radians() })
            })
            .collect()
    }

    fn print(&self, r: &SteerReport) -> anyhow::Result<()> {
        if self.rig.json {
            return print_json(r);
        }
        for line in steer_lines(r) {
            println!("{line}");
        }
        Ok(())
    }
}

/// The end of a steering run for people: goals no mode holds, each part against its goal, and
/// whether all reached them (`chladni steer`, `chladni demo --steer`).
pub(crate) fn steer_lines(r: &SteerReport) -> Vec<String> {
    let mut lines: Vec<String> = (r.unheld_goals.iter())
        .map(|(i, rest)| {
            format!(
                "note: no mode holds part {i} at its goal; the nearest rest held there is x {:.1} \
                 y {:.1} θ {:.1}°",
                rest[0], rest[1], rest[2]
            )
        })
        .collect();
    lines.extend(r.parts.iter().map(|p| {
        let verdict = if p.reached { "reached" } else { "off" };
        format!(
            "{:<16} goal ({:.1}, {:.1}, {:.1}°)  at ({:.1}, {:.1}, {:.1}°)  off {:.2} mm {:.2}°  \
             {verdict}",
            p.part,
            p.goal[0],
            p.goal[1],
            p.goal[2],
            p.x_mm,
            p.y_mm,
            p.theta_deg,
            p.error_mm,
            p.error_deg
        )
    }));
    let what = if r.reached {
        "every part reached its goal"
    } else {
        "time limit: not every part reached its goal"
    };
    lines.push(format!("{what} in {} cycles, {:.1} s", r.cycles, r.elapsed_s));
    lines
}

/// Learn what each mode really does from bursts seen by the camera; write a learned plate.
#[derive(Debug, Args)]
pub struct LearnArgs {
    #[command(flatten)]
    rig: LoopArgs,
    /// Bursts to record per mode (a quarter are held out to score the fit).
    #[arg(long, value_name = "N", default_value_t = 8)]
    bursts_per_mode: usize,
    /// The learned plate: the given one with each mode's speed_mm_s and shift_mm measured and
    /// a [learned] table.
    #[arg(long, value_name = "LEARNED.toml")]
    out: PathBuf,
}

impl LearnArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let json = self.rig.json;
        self.learn().map_err(|f| f.report(json))
    }

    fn learn(&self) -> Result<ExitCode, Failure> {
        let bad = |msg: String| Failure { kind: "bad_input", error: InputError(msg).into() };
        check_output("--out", &self.out, &[("--plate", &self.rig.plate)])
            .map_err(|error| Failure { kind: "bad_input", error })?;
        if !(1..=1000).contains(&self.bursts_per_mode) {
            return Err(bad(format!(
                "--bursts-per-mode {}: give 1 to 1000 (4 or more to hold some out)",
                self.bursts_per_mode
            )));
        }
        let text = std::fs::read_to_string(&self.rig.plate)
            .map_err(|e| bad(format!("--plate {}: {e}", self.rig.plate.display())))?;
        let loaded = self.rig.load()?;
        let job = learn_job(
            loaded.kinds.clone(),
            loaded.parts.clone(),
            self.bursts_per_mode,
            Duration::from_secs_f64(self.rig.time_limit_s.unwrap_or(600.0)),
        );
        let model = Model::new(loaded.plate.clone());
        let mut session = self.rig.session(&loaded, "plate learn")?;
        let bar = message_bar(self.rig.json);
        bar.set_message("bursts");
        let outcome = learn_plate(&mut session, &model, &job, |done, wanted| {
            bar.set_length(wanted as u64);
            bar.set_position(done as u64);
        });
        bar.finish_and_clear();
        let outcome = match outcome {
            Ok(o) => o,
            Err(e) => return loop_end(e, self.rig.json),
        };
        drop(session);
        let table = learned_table(&outcome, &self.rig.plate, &self.rig.camera);
        let written =
            set_learned(&text, &table).map_err(|e| Failure { kind: "failed", error: e.into() })?;
        write_atomic(&self.out, written.as_bytes())
            .map_err(|e| Failure { kind: "failed", error: output_error(e) })?;
        self.print(&outcome, &table).map_err(|error| Failure { kind: "failed", error })?;
        Ok(ExitCode::SUCCESS)
    }

    fn print(&self, o: &LearnOutcome, t: &LearnedTable) -> anyhow::Result<()> {
        if self.rig.json {
            let modes: Vec<serde_json::Value> =
                t.mode.iter().map(|m| serde_json::json!(m)).collect();
            return print_json(&serde_json::json!({
                "out": self.out, "bursts": o.bursts.len(), "recoveries": o.recoveries,
                "held_out": t.held_out, "elapsed_s": o.elapsed_s, "timed_out": o.timed_out,
                "modes": modes,
            }));
        }
        for line in learned_lines(t) {
            println!("{line}");
        }
        let note = if o.timed_out { " (time limit: some modes have fewer bursts)" } else { "" };
        println!(
            "{} bursts ({} bringing parts home) in {:.0} s{note}; wrote {}",
            o.bursts.len(),
            o.recoveries,
            o.elapsed_s,
            self.out.display()
        );
        Ok(())
    }
}

/// The learning job of `chladni plate learn` (and `chladni demo --steer`): every mode in
/// bursts of 0.15–1.2 s, one step of look-ahead when bringing parts home, the default rules
/// and fit.
pub(crate) fn learn_job(
    kinds: Vec<Kind>,
    parts: Vec<usize>,
    bursts_per_mode: usize,
    time_limit: Duration,
) -> LearnJob {
    LearnJob {
        kinds,
        parts,
        bursts_per_mode,
        time_limit,
        menu: Menu { bursts_s: vec![0.15, 0.3, 0.5, 0.8, 1.2], lookahead: 1, to_go_mm_per_s: None },
        rules: Rules::default(),
        fit: LearnOptions::default(),
    }
}

/// The `[learned]` table of a learning run from the plate file `given`, seen by `camera`.
pub(crate) fn learned_table(o: &LearnOutcome, given: &Path, camera: &str) -> LearnedTable {
    let rows = o.learned.rows();
    LearnedTable {
        given: given.display().to_string(),
        at: utc_now(),
        camera: camera.to_string(),
        bursts: rows.iter().map(|r| r.bursts).sum(),
        held_out: rows.iter().map(|r| r.held_out).sum(),
        mode: rows,
    }
}

/// The per-mode table for people, header first: bursts, the measured speed factor and node
/// shift, and the held-out error of a burst's prediction before and after.
pub(crate) fn learned_lines(t: &LearnedTable) -> Vec<String> {
    let mut lines = vec![format!(
        "{:>9} {:>7} {:>5} {:>7} {:>14} {:>17} {:>17}",
        "freq (Hz)", "bursts", "held", "speed×", "shift (mm)", "before (mm, °)", "after (mm, °)"
    )];
    lines.extend(t.mode.iter().map(|m| {
        format!(
            "{:>9.2} {:>7} {:>5} {:>7.2} {:>6.1} {:>6.1} {:>8.2} {:>7.1} {:>8.2} {:>7.1}",
            m.freq_hz,
            m.bursts,
            m.held_out,
            m.speed_factor,
            m.shift_mm[0],
            m.shift_mm[1],
            m.before_mm,
            m.before_deg,
            m.after_mm,
            m.after_deg
        )
    }));
    lines
}

/// Now, UTC, RFC 3339 to the second.
fn utc_now() -> String {
    jiff::Timestamp::now()
        .round(jiff::Unit::Second)
        .map_or_else(|_| String::new(), |t| t.to_string())
}
