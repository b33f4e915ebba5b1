//! `chladni demo --steer`: the feeder with a camera, without hardware (docs/demo.md).
//!
//! The controller runs in QEMU (as for `chladni demo`) and a virtual rig follows it
//! ([`rig::VirtualRig`]: `chladni rig --seed 1` in-process): three triangles on a true plate,
//! the given plate warped, seen by a snapshot camera. Then, each step a paragraph of output
//! (the printing is `cli::demo`'s):
//! 1. **learn** what each mode really does, as `chladni plate learn` does ([`SteerDemo::learn`]),
//!    and write `learned.toml`;
//! 2. **steer** the three parts to [`GOALS`] on the learned plate, within [`TOL_MM`] in any
//!    orientation ([`SteerDemo::steer`]);
//! 3. **plan** on the learned plate for each part as if fed where step 2 left it (a small box
//!    around its seen position), and keep the shortest plan ([`SteerDemo::plan`]). A
//!    sensorless plan holds where parts are fed: on the free plate no plan holds over the
//!    whole plate (every mode is centrally symmetric, so a pose and its twin turned 180° about
//!    the centre move alike), and a plan from a box of a few mm is minutes shorter than one
//!    from a larger region; step 2 is the feeder that put the parts there;
//! 4. **verify**: the plan runs on the controller (open loop, at the planner's amplitudes: the
//!    rig moves parts by the amplitude output) while the rig moves all three parts; one frame
//!    then shows them, and the part at the plan's predicted position is judged against the
//!    prediction by `chladni_media::vision::verify` with its default tolerances
//!    ([`SteerDemo::verify`]). The other two were not fed where the plan holds: they are
//!    shown, not judged.
//!
//! Every failure stops the drive: the loop's sessions stop it before they report an error and
//! when dropped, Ctrl-C stops the plan, and QEMU is killed when the demo ends.

pub mod rig;

use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, SystemTime};

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_edit::set_learned;
use chladni_core::model::plate_file::{Learned as LearnedTable, PlateFile};
use chladni_core::model::pose::Pose;
use chladni_core::output::{OutputGuard, write_atomic, write_with};
use chladni_core::planner::feed::FeedRegion;
use chladni_core::planner::{self, Deadline, PlanOptions, Synthesis};
use chladni_core::steer::{Menu, Model};
use chladni_device::client::DeviceClient;
use chladni_media::vision::verify::{self, Check, Verification};
use chladni_media::vision::{self, Located, Report, Template};
use chladni_rig::ModeTruth;
use chladni_shared::icd::link::Telemetry;
use chladni_shared::icd::plan::{DeviceLimits, Plan};
use chladni_shared::icd::store::PlanSummary;
use chladni_steer::camera::{Camera, CameraOptions, CameraSource};
use chladni_steer::learn::{LearnJob, LearnOutcome, learn_plate};
use chladni_steer::parts::Kind;
use chladni_steer::session::{Session, SessionConfig};
use chladni_steer::steer::{CycleRecord, SteerJob, SteerReport, steer};
use serde::Serialize;

use super::{Controller, DemoError, RunReport, STORED_NAME, run_plan, start_emulator, upload};
use rig::VirtualRig;

/// The given plate: the free plate's first 12 solver modes.
pub const PLATE: &str = "examples/plates/free-12-modes.toml";
/// Bursts per mode while learning: the fewest that hold one out (every 4th) to score the fit
/// before and after; `chladni plate learn` records 8 by default.
pub const BURSTS_PER_MODE: usize = 4;
/// Learning stops recording after this and fits what it has.
pub const LEARN_LIMIT: Duration = Duration::from_secs(600);
/// Steering gives up after this.
pub const STEER_LIMIT: Duration = Duration::from_secs(300);
/// The seed of the rig (its warp, drops, noise and frames), as `chladni rig --seed`.
pub const RIG_SEED: u64 = 1;
/// Where the three triangles lie at the start (x mm, y mm, θ deg).
pub const STARTS: [[f64; 3]; 3] = [[80.0, 60.0, 10.0], [150.0, 150.0, 120.0], [230.0, 60.0, 250.0]];
/// The three goals (mm), at least 60 mm apart.
pub const GOALS: [[f64; 2]; 3] = [[70.0, 140.0], [150.0, 60.0], [230.0, 140.0]];
/// A part is at its goal within this (mm), in any orientation.
pub const TOL_MM: f64 = 3.0;
/// A plan is made for a part fed where the camera saw it ± this (mm).
pub const FEED_HALF_MM: f64 = 2.0;
/// The part judged after the plan is the one nearest its predicted position, within this (mm).
pub const FED_RADIUS_MM: f64 = 30.0;
/// How long parts take to settle after the drive stops (`--settle-ms` of `plate learn`).
pub const SETTLE: Duration = Duration::from_millis(150);
/// The planner's time limit (s), as `chladni plan`'s default.
pub const PLAN_MAX_S: f64 = 120.0;
/// QEMU is killed after this whatever happens (s).
const EMULATOR_LIMIT_S: u64 = 3600;

/// What `--steer` takes from the command line.
#[derive(Debug, Clone)]
pub struct SteerConfig {
    /// The part (three copies go on the plate).
    pub part: PathBuf,
    /// The given plate.
    pub plate: PathBuf,
    /// The output folder (created).
    pub out: PathBuf,
}

/// The files `--steer` writes into the output folder.
#[derive(Debug, Clone, Serialize)]
pub struct SteerFiles {
    /// The rig's true plate (what the learning does not see).
    pub true_plate: PathBuf,
    /// The learned plate.
    pub learned: PathBuf,
    /// Every steering cycle, one JSON line each (as `chladni steer --log`).
    pub steer_log: PathBuf,
    /// The plan made on the learned plate.
    pub plan: PathBuf,
    /// The frame after the plan.
    pub frame: PathBuf,
    /// That frame rectified, the parts outlined: green as planned, red off.
    pub verify_figure: PathBuf,
    /// The QEMU controller's flash bank.
    pub flash: PathBuf,
    /// Its decoded log.
    pub firmware_log: PathBuf,
}

impl SteerFiles {
    fn in_dir(out: &Path) -> Self {
        SteerFiles {
            true_plate: out.join("true-plate.toml"),
            learned: out.join("learned.toml"),
            steer_log: out.join("steer-log.jsonl"),
            plan: out.join("steer-plan.json"),
            frame: out.join("steer-frame.png"),
            verify_figure: out.join("steer-verify.png"),
            flash: out.join("steer-flash.bin"),
            firmware_log: out.join("steer-firmware.log"),
        }
    }

    fn all(&self) -> [&Path; 8] {
        [
            &self.true_plate,
            &self.learned,
            &self.steer_log,
            &self.plan,
            &self.frame,
            &self.verify_figure,
            &self.flash,
            &self.firmware_log,
        ]
    }
}

/// The controller, the rig, and what the steps need of each other.
pub struct SteerDemo {
    /// The files written.
    pub files: SteerFiles,
    /// The part.
    pub part: Part,
    /// The given plate.
    pub given: PlateModel,
    /// The given plate's file as written.
    given_text: String,
    /// Where it was read from.
    given_path: PathBuf,
    /// The learned plate, once learned.
    learned: Option<PlateModel>,
    interrupted: Option<&'static AtomicBool>,
    // Dropped in this order: the rig follows the controller's link, so it stops first.
    /// The virtual rig.
    pub rig: VirtualRig,
    /// The controller in QEMU.
    pub controller: Controller,
}

impl SteerDemo {
    /// Checks the outputs, loads the part and the plate, starts QEMU and the rig (three parts
    /// at [`STARTS`]) and writes the rig's true plate.
    pub fn start(
        config: &SteerConfig,
        interrupted: Option<&'static AtomicBool>,
    ) -> Result<SteerDemo, DemoError> {
        super::preflight_qemu()?;
        let files = SteerFiles::in_dir(&config.out);
        let guard = OutputGuard::new().input("part", &config.part).input("plate", &config.plate);
        for path in files.all() {
            guard.check("--out", path)?;
        }
        let input = |e: String| DemoError::Input(e);
        let part = Part::load(&config.part)
            .map_err(|e| input(format!("{}: {e}", config.part.display())))?;
        let given_text = std::fs::read_to_string(&config.plate)
            .map_err(|e| input(format!("{}: {e}", config.plate.display())))?;
        let given_file = PlateFile::load(&config.plate)
            .map_err(|e| input(format!("{}: {e}", config.plate.display())))?;
        let given = PlateModel::load(&config.plate).map_err(|e| input(e.to_string()))?;
        std::fs::create_dir_all(&config.out)
            .map_err(|e| input(format!("cannot create --out {}: {e}", config.out.display())))?;
        let (true_plate, rig_seed, frame_seed) = rig::true_plate(&given_file, RIG_SEED)?;
        let text = true_plate.to_toml().map_err(DemoError::Rig)?;
        write_atomic(&files.true_plate, text.as_bytes())?;
        let name = client_name();
        let controller =
            start_emulator(&files.flash, &files.firmware_log, EMULATOR_LIMIT_S, &name)?;
        let seeds = (rig_seed, frame_seed);
        let rig = VirtualRig::start(true_plate, &part, &STARTS, seeds, &controller.port)?;
        Ok(SteerDemo {
            files,
            part,
            given,
            given_text,
            given_path: config.plate.clone(),
            learned: None,
            interrupted,
            rig,
            controller,
        })
    }

    /// A camera loop's session on the controller and the rig's camera.
    fn session(&self) -> Result<Session, DemoError> {
        let source: CameraSource = self.rig.url.parse().map_err(DemoError::Camera)?;
        let camera = Camera::open(source, CameraOptions::default()).map_err(DemoError::Camera)?;
        let port = &self.controller.port;
        let client = DeviceClient::open(port, &client_name())
            .map_err(|source| DemoError::PortUnreachable { port: port.clone(), source })?;
        let config = SessionConfig { size_mm: self.given.size_mm, corners: None, settle: SETTLE };
        let flag = self.interrupted;
        let interrupted = Box::new(move || flag.is_some_and(|f| f.load(Ordering::SeqCst)));
        Ok(Session::new(client, camera, std::slice::from_ref(&self.part), config, interrupted))
    }

    /// The part kind and the parts on the plate, as the loops take them.
    pub fn kinds(&self) -> (Vec<Kind>, Vec<usize>) {
        (vec![Kind::new(self.part.clone())], vec![0; STARTS.len()])
    }

    /// Records bursts of every mode and fits the given plate to them (`job`: `chladni plate
    /// learn`'s, for [`Self::kinds`]); `progress(recorded, wanted)`.
    pub fn learn(
        &mut self,
        job: &LearnJob,
        progress: impl FnMut(usize, usize),
    ) -> Result<LearnOutcome, DemoError> {
        let mut session = self.session()?;
        let model = Model::new(self.given.clone());
        learn_plate(&mut session, &model, job, progress)
            .map_err(|source| DemoError::Loop { stage: "learning the plate", source })
    }

    /// Where the given plate was read from (the learned table names it).
    pub fn given_path(&self) -> &Path {
        &self.given_path
    }

    /// Writes the learned plate (the given one corrected by `table`) and keeps it for the next
    /// steps.
    pub fn write_learned(&mut self, table: &LearnedTable) -> Result<(), DemoError> {
        let text =
            set_learned(&self.given_text, table).map_err(|e| DemoError::Learned(e.to_string()))?;
        write_atomic(&self.files.learned, text.as_bytes())?;
        let learned =
            PlateModel::load(&self.files.learned).map_err(|e| DemoError::Learned(e.to_string()))?;
        self.learned = Some(learned);
        Ok(())
    }

    /// The learned plate, or the given one before learning.
    pub fn plate(&self) -> &PlateModel {
        self.learned.as_ref().unwrap_or(&self.given)
    }

    /// Steers the parts to [`GOALS`] on the learned plate; every cycle goes to the log file and
    /// to `on_cycle`.
    pub fn steer(
        &mut self,
        mut on_cycle: impl FnMut(&CycleRecord),
    ) -> Result<SteerReport, DemoError> {
        let (kinds, parts) = self.kinds();
        let goals = GOALS.iter().map(|g| Pose { x: g[0], y: g[1], theta: 0.0 });
        let job = SteerJob {
            kinds,
            parts: parts.into_iter().zip(goals).collect(),
            tol_mm: TOL_MM,
            tol_deg: 180.0,
            time_limit: STEER_LIMIT,
            menu: Menu::default(),
        };
        let mut log = std::fs::File::create(&self.files.steer_log).map_err(|e| {
            DemoError::Input(format!("cannot write {}: {e}", self.files.steer_log.display()))
        })?;
        let mut model = Model::new(self.plate().clone());
        let mut session = self.session()?;
        steer(&mut session, &mut model, &job, |c| {
            if let Ok(line) = serde_json::to_string(c) {
                let _ = writeln!(log, "{line}");
            }
            on_cycle(c);
        })
        .map_err(|source| DemoError::Loop { stage: "steering the parts", source })
    }

    /// Plans on the learned plate for each steered part as if fed where it lies (its seen
    /// position ± [`FEED_HALF_MM`]; the planner's default options otherwise) and keeps the
    /// shortest plan, written to the plan file; the plan the controller stores is its steps in
    /// open loop, named [`STORED_NAME`]. `progress(planned, parts)` before each.
    pub fn plan(
        &self,
        steered: &SteerReport,
        mut progress: impl FnMut(usize, usize),
    ) -> Result<FedPlan, DemoError> {
        let plate = self.plate();
        let (mut best, mut failure): (Option<FedPlan>, Option<DemoError>) = (None, None);
        let mut totals_s = Vec::new();
        for (i, p) in steered.parts.iter().enumerate() {
            progress(i, steered.parts.len());
            let [x, y] = [p.x_mm, p.y_mm].map(|v| (v * 10.0).round() / 10.0);
            let box_mm = [x - FEED_HALF_MM, y - FEED_HALF_MM, x + FEED_HALF_MM, y + FEED_HALF_MM];
            match self.plan_from(plate, i, box_mm) {
                Ok(plan) => {
                    let total = plan.device.total_ms();
                    totals_s.push(Some(total as f64 / 1000.0));
                    if best.as_ref().is_none_or(|b| total < b.device.total_ms()) {
                        best = Some(plan);
                    }
                }
                Err(e) => {
                    totals_s.push(None);
                    failure = Some(e);
                }
            }
        }
        let Some(mut plan) = best else {
            return Err(failure.unwrap_or(DemoError::Input("no part was steered".into())));
        };
        plan.totals_s = totals_s;
        let text = serde_json::to_string_pretty(&plan.file.to_json()).unwrap_or_default() + "\n";
        write_atomic(&self.files.plan, text.as_bytes())?;
        Ok(plan)
    }

    /// The plan for part `part` fed into `box_mm` on `plate`.
    fn plan_from(
        &self,
        plate: &PlateModel,
        part: usize,
        box_mm: [f64; 4],
    ) -> Result<FedPlan, DemoError> {
        let region = FeedRegion::new(box_mm, plate).map_err(|e| DemoError::Input(e.to_string()))?;
        let options = PlanOptions {
            feed: Some(region),
            deadline: Some(Deadline::after_s(PLAN_MAX_S)),
            ..PlanOptions::default()
        };
        let syn = planner::plan(&self.part, plate, &options)
            .map_err(|source| DemoError::FedPlan { region: feed_text(box_mm), source })?;
        let file = syn.to_file(plate, &self.part.name);
        let stored = PlanFile { name: STORED_NAME.to_string(), ..file.clone() };
        let device = stored.to_plan(&DeviceLimits::DEFAULT).map_err(DemoError::DevicePlan)?;
        let steps = fed_steps(plate, &syn, &file);
        Ok(FedPlan { part, box_mm, syn, file, device, steps, totals_s: Vec::new() })
    }

    /// Stores the plan on the controller and runs it to its end (`on_sample`: each telemetry
    /// sample; `Break` stops it).
    pub fn run(
        &mut self,
        plan: &FedPlan,
        on_sample: impl FnMut(&Telemetry) -> std::ops::ControlFlow<()>,
    ) -> Result<(PlanSummary, RunReport), DemoError> {
        let stored = upload(&mut self.controller, &plan.device, |_, _| {})?;
        let report = run_plan(&mut self.controller, &plan.device, on_sample)?;
        Ok((stored, report))
    }

    /// One frame of the rig after the parts settled, the parts located in it and the part at
    /// the plan's predicted position judged against the prediction; the frame and the figure
    /// written.
    pub fn verify(&self, plan: &FedPlan) -> Result<Verified, DemoError> {
        let source: CameraSource = self.rig.url.parse().map_err(DemoError::Camera)?;
        let mut camera =
            Camera::open(source, CameraOptions::default()).map_err(DemoError::Camera)?;
        let frame = camera.frame_after(SystemTime::now() + SETTLE).map_err(DemoError::Camera)?;
        write_with(&self.files.frame, |p| frame.image.save(p).map_err(|e| e.to_string()))?;
        let templates = vec![Template::new(&self.part)];
        let size = self.plate().size_mm;
        let (report, rectified) =
            vision::locate(&frame.image, &templates, size, None).map_err(DemoError::Locate)?;
        let check = Check::new(
            &plan.file,
            std::slice::from_ref(&self.part),
            verify::DEFAULT_TOL_DEG,
            verify::DEFAULT_TOL_MM,
        )
        .map_err(DemoError::Verify)?;
        let (fed, others) = fed_part(&report, plan.syn.final_position_mm);
        let verification = check.judge(&fed);
        let figure = verify::draw(&rectified, &fed, &verification, &templates, size[1]);
        write_with(&self.files.verify_figure, |p| figure.save(p).map_err(|e| e.to_string()))?;
        Ok(Verified { verification, others })
    }
}

/// The session name the demo's links carry.
fn client_name() -> String {
    format!("chladni demo --steer (pid {})", std::process::id())
}

/// A feed box as said: `(x0, y0)–(x1, y1) mm`.
pub fn feed_text(b: [f64; 4]) -> String {
    format!("({}, {})–({}, {}) mm", b[0], b[1], b[2], b[3])
}

/// The plan made on the learned plate.
#[derive(Debug, Clone)]
pub struct FedPlan {
    /// The part it is for (index among the steered parts).
    pub part: usize,
    /// The feed box (x0, y0, x1, y1 mm).
    pub box_mm: [f64; 4],
    /// The planner's answer.
    pub syn: Synthesis,
    /// As written.
    pub file: PlanFile,
    /// As stored on the controller.
    pub device: Plan,
    /// Its steps, for people.
    pub steps: Vec<FedStep>,
    /// How long the plan from each part's place lasts (s; `None`: no plan from there).
    pub totals_s: Vec<Option<f64>>,
}

/// One step of the plan.
#[derive(Debug, Clone, Serialize)]
pub struct FedStep {
    /// The mode's name.
    pub mode: String,
    /// Drive frequency (Hz).
    pub freq_hz: f64,
    /// Amplitude (fraction of full scale, open loop).
    pub amplitude: f64,
    /// Duration (ms).
    pub duration_ms: u32,
}

/// The plan's steps with their modes' names.
fn fed_steps(plate: &PlateModel, syn: &Synthesis, file: &PlanFile) -> Vec<FedStep> {
    (file.steps.iter().enumerate())
        .map(|(i, s)| FedStep {
            mode: (syn.steps.get(i).and_then(|p| plate.modes.get(p.mode)))
                .map_or_else(|| format!("step {}", i + 1), |m| m.name.clone()),
            freq_hz: s.freq_hz,
            amplitude: s.amplitude.unwrap_or(1.0),
            duration_ms: s.duration_ms,
        })
        .collect()
}

/// The verdict after the plan.
#[derive(Debug, Clone, Serialize)]
pub struct Verified {
    /// The fed part judged against the plan's prediction.
    pub verification: Verification,
    /// The other parts found: not fed into the box, not judged.
    pub others: Vec<Located>,
}

/// `report` split into the part fed into the plan's box and the others: with a predicted
/// position, the fed part is the located part nearest it within [`FED_RADIUS_MM`] (none: the
/// part is not where the plan puts it), with the blobs within that radius (a cluster there
/// hides it); without one, every part is judged.
pub fn fed_part(report: &Report, at: Option<[f64; 2]>) -> (Report, Vec<Located>) {
    let Some([x, y]) = at else { return (report.clone(), Vec::new()) };
    let off = |px: f64, py: f64| (px - x).hypot(py - y);
    let nearest = (report.parts.iter().enumerate())
        .map(|(i, l)| (off(l.x_mm, l.y_mm), i))
        .filter(|(d, _)| *d <= FED_RADIUS_MM)
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, i)| i);
    let mut fed = report.clone();
    fed.parts = nearest.map(|i| report.parts[i].clone()).into_iter().collect();
    fed.unknown.retain(|u| off(u.x_mm, u.y_mm) <= FED_RADIUS_MM);
    let others = (report.parts.iter().enumerate())
        .filter(|(i, _)| Some(*i) != nearest)
        .map(|(_, l)| l.clone())
        .collect();
    (fed, others)
}

/// How close the learned plate came to the rig's true one, over the modes learned.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AgainstTruth {
    /// Median and largest |learned speed / true speed − 1|.
    pub speed_off: [f64; 2],
    /// Median and largest distance of the learned node shift from the true one (mm).
    pub shift_off_mm: [f64; 2],
}

/// The learned table against the rig's true modes (matched by frequency); `None` when no
/// mode matches.
pub fn against_truth(table: &LearnedTable, truth: &[ModeTruth]) -> Option<AgainstTruth> {
    let (mut speed, mut shift) = (Vec::new(), Vec::new());
    for m in &table.mode {
        let Some(t) = truth.iter().find(|t| (t.freq_hz - m.freq_hz).abs() < 1e-3) else {
            continue;
        };
        if let Some(f) = t.speed_factor.filter(|f| *f > 0.0) {
            speed.push((m.speed_factor / f - 1.0).abs());
        }
        shift.push((m.shift_mm[0] - t.shift_mm[0]).hypot(m.shift_mm[1] - t.shift_mm[1]));
    }
    Some(AgainstTruth { speed_off: median_max(&mut speed)?, shift_off_mm: median_max(&mut shift)? })
}

/// The median and the largest of `v` (`None` when empty).
fn median_max(v: &mut [f64]) -> Option<[f64; 2]> {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    let median = match n {
        0 => return None,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    };
    Some([median, v[n - 1]])
}

#[cfg(test)]
mod tests;
