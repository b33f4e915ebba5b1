//! `chladni plate ...`: plate modes from theory (Rayleigh–Ritz) and node lines from photos.

use crate::cli::progress::Bar;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use super::parse::usize_in;
use super::{InputError, check_output, output_error, plot_error};
use chladni_core::model::modes_file;
use chladni_core::model::plate_file::{ModeEntry, Plate, PlateFile, PlateTable};
use chladni_core::output::write_atomic;
use chladni_core::planner::PlanOptions;
use chladni_core::plate::contour::{line_count, node_lines, total_length};
use chladni_core::plate::photo::job::{PhotoGrid, PhotoRequest};
use chladni_core::plate::{drive, photo, rocking, solver, suggest};
use chladni_media::plot::plate as plot;
use chladni_media::shapes::plate::{ModeJson, ModesJson, photo_json, suggest_json};

#[derive(Debug, Subcommand)]
pub enum PlateCommand {
    /// Natural frequencies, node lines (Chladni figures) and `[[mode]]` entries of a plate.
    Modes(ModesArgs),
    /// Node lines and curves from a photo of sand gathered on the nodes of a vibrating plate.
    FromPhoto(FromPhotoArgs),
    /// Fit a mode's settle speed (speed_mm_s) to observed parts and write it to the plate file.
    CalibrateSpeed(super::calibrate::CalibrateArgs),
    /// Try drive points and clamp positions and report which give a part a plan.
    Suggest(SuggestArgs),
    /// Learn what each mode really does from bursts seen by a camera; write a learned plate.
    Learn(super::steer::LearnArgs),
}

impl PlateCommand {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            PlateCommand::Modes(a) => a.run(),
            PlateCommand::FromPhoto(a) => a.run(),
            PlateCommand::CalibrateSpeed(a) => a.run(),
            PlateCommand::Suggest(a) => a.run(),
            PlateCommand::Learn(a) => a.run(),
        }
    }
}

#[derive(Debug, Args)]
pub struct ModesArgs {
    /// Plate file (TOML with a `[plate]` table; see docs/plate.md).
    plate: PathBuf,
    /// Number of elastic modes (rigid-body modes are left out; at most a quarter of the Ritz
    /// unknowns, terms² / 4).
    #[arg(long, default_value_t = 6)]
    count: usize,
    /// Print `{"modes": [{"freq_hz": f, "lambda": λ}, ...]}` instead of a table.
    #[arg(long)]
    json: bool,
    /// Write one node-line figure per mode (mode-01.png, ...) into this directory.
    #[arg(long, value_name = "DIR")]
    plot: Option<PathBuf>,
    /// The `--plot` figures' format: png, or svg (mode-01.svg, ...).
    #[arg(long, value_name = "png|svg", default_value = "png", value_parser = ["png", "svg"])]
    plot_format: String,
    /// Write a plate file: the input's `[plate]` table plus one `[[mode]]` per mode, with the
    /// mode shape sampled on a grid (`node = { kind = "grid", ... }`).
    #[arg(long, value_name = "FILE")]
    write_modes: Option<PathBuf>,
    /// Grid points along x for `--write-modes` (y follows the aspect ratio).
    #[arg(long, default_value_t = 41, value_parser = usize_in("grid", *solver::GRID_X_POINTS.start(), *solver::GRID_X_POINTS.end()))]
    grid: usize,
    /// Legendre polynomials per direction in the Ritz basis (terms² unknowns).
    #[arg(long, default_value_t = solver::DEFAULT_TERMS, value_parser = usize_in("terms", 4, 30))]
    terms: usize,
    /// Hinged-rod plates: drive frequency (Hz) of the rigid rocking about the hinge that the
    /// rod forces below the first elastic mode (the paper's setup 2 ran it at 10 Hz); written
    /// by `--write-modes` as a straight `line` node on the hinge, ahead of the elastic modes.
    /// Default 10 Hz; refused for other boundaries.
    #[arg(long, value_name = "HZ")]
    rocking_hz: Option<f64>,
}

impl ModesArgs {
    fn run(&self) -> anyhow::Result<ExitCode> {
        let file = PlateFile::load(&self.plate).map_err(|e| InputError(e.to_string()))?;
        let plate = file.plate.mechanics().map_err(|e| InputError(e.to_string()))?;
        let available = self.terms * self.terms / 4;
        if self.count == 0 || self.count > available {
            return Err(InputError(format!(
                "--count must be in 1..={available} (a quarter of the Ritz unknowns), got {}",
                self.count
            ))
            .into());
        }
        self.check_outputs()?;
        let spinner =
            ProgressBar::new_spinner().with_message(format!("solving ({0}×{0} terms)", self.terms));
        spinner.enable_steady_tick(std::time::Duration::from_millis(120));
        let all = solver::solve_all(&plate, self.terms);
        spinner.finish_and_clear();
        let shown = self.resonances(&plate, &all)?;
        let sol = &shown.sol;
        if let Some(dir) = &self.plot {
            plot_modes(dir, &self.plot_format, &plate, &shown)?;
        }
        let rocking = rocking::rocking_mode(&plate, sol, self.rocking_hz)
            .map_err(|e| InputError(e.to_string()))?;
        if let Some(out) = &self.write_modes {
            let (nx, ny) = solver::grid_dims(self.grid, plate.size_mm);
            let entries = rocking
                .iter()
                .cloned()
                .chain(sol.modes.iter().enumerate().map(|(k, m)| {
                    modes_file::grid_mode(
                        &shown.labels[k],
                        m.freq_hz,
                        m.lambda,
                        &sol.sample(k, nx, ny),
                    )
                }))
                .collect();
            write(out, &modes_file::render(&file.plate, entries)?)?;
        }
        if self.json {
            let modes = sol.modes.iter().enumerate().map(|(k, m)| ModeJson {
                freq_hz: m.freq_hz,
                lambda: m.lambda,
                name: shown.labels[k].clone(),
                excitation: shown.excitation.get(k).copied(),
            });
            println!("{}", serde_json::to_string(&ModesJson { modes: modes.collect() })?);
        } else {
            self.print(&plate, &shown, rocking.is_some());
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The modes to show and write: the first `--count` free modes, or with `[plate]
    /// drive_mm` the forced response at each resonance among them (unexcited ones dropped
    /// with a warning naming them). Without a drive point a degenerate pair has no one shape,
    /// so `--write-modes` is refused (the planner would refuse the file: one frequency is one
    /// mode), naming the modes and the fix.
    fn resonances(&self, plate: &Plate, all: &solver::ModalSolution) -> Result<Shown, InputError> {
        let Some(d) = plate.drive_mm else {
            let pairs: Vec<Vec<usize>> =
                drive::first_groups(all, self.count).into_iter().filter(|g| g.len() > 1).collect();
            if let (Some(g), Some(_)) = (pairs.first(), &self.write_modes) {
                return Err(InputError(format!(
                    "{} of this plate share {:.3} Hz (a degenerate pair, as a symmetric plate \
                     has): the shape the plate takes there depends on where it is driven, and \
                     the planner refuses two modes at one frequency; set [plate] drive_mm = \
                     [x, y] (where the shaker drives the plate) in {}",
                    drive::members_label(g),
                    all.modes[g[0]].freq_hz,
                    self.plate.display()
                )));
            }
            let mut sol = all.clone();
            sol.modes.truncate(self.count);
            let labels = (1..=sol.modes.len()).map(|k| format!("mode {k}")).collect();
            return Ok(Shown { sol, labels, excitation: vec![] });
        };
        let forced = drive::forced(all, self.count, d, plate.damping_ratio);
        for r in &forced.dropped {
            eprintln!(
                "warning: {} ({:.2} Hz) is not excited from drive_mm = {d:?} (response there \
                 {:.1} % of its peak, under {:.0} %: a node at the drive point): left out",
                drive::members_label(&r.members),
                r.freq_hz,
                100.0 * r.excitation,
                100.0 * drive::MIN_EXCITATION
            );
        }
        if forced.resonances.is_empty() {
            return Err(InputError(format!(
                "[plate] drive_mm = {d:?} mm excites none of the first {} modes (it lies on their \
                 nodes): move the drive point off the nodes (`chladni plate suggest` tries some)",
                self.count
            )));
        }
        let labels = forced.resonances.iter().map(|r| drive::members_label(&r.members)).collect();
        let excitation = forced.resonances.iter().map(|r| r.excitation).collect();
        Ok(Shown { sol: forced.as_solution(all), labels, excitation })
    }

    /// Refuses, before solving, outputs that would overwrite the plate file.
    fn check_outputs(&self) -> anyhow::Result<()> {
        let inputs = [("plate", self.plate.as_path())];
        if let Some(out) = &self.write_modes {
            check_output("--write-modes", out, &inputs)?;
        }
        if let Some(dir) = &self.plot {
            for k in 0..self.count {
                check_output("--plot", &dir.join(mode_figure_name(k, &self.plot_format)), &inputs)?;
            }
        }
        Ok(())
    }

    /// The modes as a table, and the forced rocking of a hinged-rod plate.
    fn print(&self, plate: &Plate, shown: &Shown, rocking: bool) {
        let sol = &shown.sol;
        println!(
            "{} ({}, {:.0}×{:.0} mm):",
            plate.name,
            plate.boundary.key(),
            plate.size_mm[0],
            plate.size_mm[1]
        );
        if let Some(d) = plate.drive_mm {
            println!(
                "forced response to a point drive at ({:.1}, {:.1}) mm, ζ = {}; excitation = \
                 response at the drive point / its peak",
                d[0], d[1], plate.damping_ratio
            );
        }
        println!(
            "{:>10} {:>12} {:>10} {:>8} {:>16} {:>10}",
            "mode", "freq (Hz)", "lambda", "lines", "node length (mm)", "excitation"
        );
        let (nx, ny) = solver::grid_dims(121, plate.size_mm);
        for (k, m) in sol.modes.iter().enumerate() {
            let lines = node_lines(&sol.sample(k, nx, ny));
            let exc = shown.excitation.get(k).map_or("-".into(), |e| format!("{e:.3}"));
            println!(
                "{:>10} {:>12.2} {:>10.4} {:>8} {:>16.1} {:>10}",
                shown.labels[k].trim_start_matches("mode ").trim_start_matches("modes "),
                m.freq_hz,
                m.lambda,
                line_count(&lines),
                total_length(&lines) + 0.0,
                exc
            );
        }
        if rocking {
            println!(
                "forced: rigid rocking about the hinge at {} Hz, node = the hinge line x = {:.1} mm (linear field){}",
                self.rocking_hz.unwrap_or(rocking::DEFAULT_ROCKING_HZ),
                plate.hinge_x_mm,
                if self.write_modes.is_some() { ", written as the first mode" } else { "" }
            );
        }
    }
}

/// The file name of mode `k`'s figure (0-based) in the `--plot` directory, `ext` "png" or
/// "svg".
fn mode_figure_name(k: usize, ext: &str) -> String {
    format!("mode-{:02}.{ext}", k + 1)
}

/// The modes `plate modes` shows and writes, with their names and, for a drive point, their
/// excitation.
struct Shown {
    sol: solver::ModalSolution,
    labels: Vec<String>,
    excitation: Vec<f64>,
}

/// One Chladni figure per mode in `dir`, as `ext` ("png" or "svg").
fn plot_modes(dir: &Path, ext: &str, plate: &Plate, shown: &Shown) -> anyhow::Result<()> {
    let sol = &shown.sol;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let bar = ProgressBar::new(sol.modes.len() as u64).with_style(
        ProgressStyle::with_template("plotting {bar:30} {pos}/{len}")
            .unwrap_or(ProgressStyle::default_bar()),
    );
    let (nx, ny) = solver::grid_dims(121, plate.size_mm);
    for (k, m) in sol.modes.iter().enumerate() {
        let grid = sol.sample(k, nx, ny);
        let lines = node_lines(&grid);
        let title = format!(
            "{} — {}: {:.1} Hz, λ = {:.3}",
            plate.name, shown.labels[k], m.freq_hz, m.lambda
        );
        plot::chladni_figure(&dir.join(mode_figure_name(k, ext)), &title, plate, &grid, &lines)
            .map_err(plot_error)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(())
}

/// Writes a text file atomically.
fn write(path: &Path, text: &str) -> anyhow::Result<()> {
    write_atomic(path, text.as_bytes()).map_err(output_error)
}

#[derive(Debug, Args)]
pub struct FromPhotoArgs {
    /// Photo of the plate, cropped to the plate's edges (PNG), +y up = top of the image.
    image: PathBuf,
    /// Plate size W H (mm): the image's width and height.
    #[arg(long, num_args = 2, value_names = ["W", "H"], required = true)]
    size_mm: Vec<f64>,
    /// Drive frequency the photo was taken at (written as freq_hz).
    #[arg(long)]
    freq_hz: Option<f64>,
    /// Print the recovered lines and curves as JSON.
    #[arg(long)]
    json: bool,
    /// Write a plate file (`[plate]` name and size, then one `[[mode]]` entry: a `line` node
    /// for one straight node, a `lines` node for several, or, when curved nodes were found
    /// (or with --as-grid), a `grid` node for all of them).
    #[arg(long, value_name = "FILE")]
    out: Option<PathBuf>,
    /// Add the entry to the plate file given by --out instead of replacing it (one photo
    /// per drive frequency calibrates a plate mode by mode); its size must match --size-mm.
    /// Lines at the frequency of an existing line entry are merged into it (one frequency is
    /// one mode); any other entry at that frequency is refused.
    #[arg(long, requires = "out")]
    append: bool,
    /// Describe the nodes by one grid entry (signed distance to them) even if all are
    /// straight.
    #[arg(long)]
    as_grid: bool,
    /// Grid points along x for the grid entry (y follows the aspect ratio).
    #[arg(long, default_value_t = 121)]
    grid: usize,
    /// Photo taken at an angle: pixel positions (x right, y down) of the plate's corners
    /// (0, 0), (W, 0), (W, H), (0, H) — bottom-left, bottom-right, top-right, top-left.
    /// The photo is rectified to the square-on view first.
    #[arg(long, num_args = 8, value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"])]
    corners: Option<Vec<f64>>,
    /// Diameter (mm) of coarse grains such as lentils (the paper's are ≈ 4 mm); above 2 px
    /// in the photo the nodes are found as bands of separate grains. 0: sand.
    #[arg(long, value_name = "MM", default_value_t = 0.0)]
    grain_mm: f64,
    /// Write the rectified photo (PNG) to check the corners.
    #[arg(long, value_name = "FILE", requires = "corners")]
    save_rectified: Option<PathBuf>,
}

impl FromPhotoArgs {
    /// The request the library runs, or the bad argument (exit 2).
    fn request(&self) -> Result<PhotoRequest, InputError> {
        let c = self.corners.as_deref();
        let req = PhotoRequest {
            size_mm: [self.size_mm[0], self.size_mm[1]],
            corners: c.map(|c| [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]]),
            grain_mm: self.grain_mm,
            freq_hz: self.freq_hz,
            as_grid: self.as_grid,
            grid: self.grid,
        };
        req.check().map_err(InputError)?;
        if self.out.is_some() && self.freq_hz.is_none() {
            return Err(InputError(
                "--out needs --freq-hz: the planner drives each mode at its frequency; give the \
                 drive frequency the photo was taken at"
                    .into(),
            ));
        }
        Ok(req)
    }

    fn run(&self) -> anyhow::Result<ExitCode> {
        let req = self.request()?;
        let inputs = [("photo", self.image.as_path())];
        for (flag, out) in [("--out", &self.out), ("--save-rectified", &self.save_rectified)] {
            if let Some(out) = out {
                check_output(flag, out, &inputs)?;
            }
        }
        let img = photo::input::read(&self.image).map_err(|e| InputError(e.to_string()))?;
        let outcome = req.run(img).map_err(InputError)?;
        if let (Some(path), Some(r)) = (&self.save_rectified, &outcome.rectified) {
            write_output(path, |p| r.save(p).map_err(anyhow::Error::from))?;
        }
        let confident = outcome.found.check_confidence();
        let entries = req.entries(&outcome);
        let writable = confident.is_ok() && !entries.is_empty();
        if let Some(out) = self.out.as_ref().filter(|_| writable) {
            let text = self.plate_text(out, &req, entries)?;
            write_output(out, |p| std::fs::write(p, &text).map_err(anyhow::Error::from))?;
        }
        if self.json {
            println!("{}", photo_json(&outcome.found, outcome.grid.as_ref()));
        } else {
            print_photo(&outcome.found, outcome.grid.as_ref());
        }
        confident.map_err(|e| anyhow::anyhow!("{}: {e}", self.image.display()))?;
        if let Some(out) = self.out.as_ref().filter(|_| !writable) {
            anyhow::bail!(
                "no node found in {}: nothing written to {} (is the sand visible against the plate?)",
                self.image.display(),
                out.display()
            );
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The plate file to write: a new one, or `out` with the entries appended.
    fn plate_text(
        &self,
        out: &Path,
        req: &PhotoRequest,
        entries: Vec<ModeEntry>,
    ) -> anyhow::Result<String> {
        let size = req.size_mm;
        let file = if self.append && out.exists() {
            let mut file = PlateFile::load(out).map_err(|e| InputError(e.to_string()))?;
            if file.plate.size_mm != Some(size) {
                let had =
                    file.plate.size_mm.map_or("size-less".into(), |[w, h]| format!("{w} × {h} mm"));
                return Err(InputError(format!(
                    "--append: {} is a {had} plate, the photo is {} × {} mm; give --size-mm {had_args} \
                     or write to another file",
                    out.display(),
                    size[0],
                    size[1],
                    had_args = file.plate.size_mm.map_or("W H".into(), |[w, h]| format!("{w} {h}")),
                ))
                .into());
            }
            for entry in entries {
                let name = entry.name.clone().unwrap_or_default();
                match modes_file::add_entry(&mut file.mode, entry)
                    .map_err(|e| InputError(format!("--append to {}: {e}", out.display())))?
                {
                    modes_file::Added::New => {}
                    modes_file::Added::Merged(k) => eprintln!(
                        "note: {name}: merged into [[mode]] {} ({}) at the same frequency (one \
                         frequency is one mode)",
                        k + 1,
                        file.mode[k].name.as_deref().unwrap_or("unnamed")
                    ),
                }
            }
            file
        } else {
            let stem = self.image.file_stem().map_or("photo".into(), |s| s.to_string_lossy());
            let plate = PlateTable {
                name: format!("from photo {stem}"),
                size_mm: Some(size),
                ..PlateTable::default()
            };
            PlateFile { plate, mode: entries, learned: None }
        };
        Ok(modes_file::render(&file.plate, file.mode)?)
    }
}

/// The one place from-photo writes files (--out, --save-rectified): atomically, so a crash
/// never leaves half a file (the outputs were checked against the photo before any work).
fn write_output(path: &Path, save: impl FnOnce(&Path) -> anyhow::Result<()>) -> anyhow::Result<()> {
    chladni_core::output::write_with(path, |p| save(p).map_err(|e| format!("{e:#}")))
        .map_err(output_error)
}

fn print_photo(found: &photo::Found, grid: Option<&PhotoGrid>) {
    println!(
        "threshold {} ({} sand), {} skeleton pixels, {} on no line or curve",
        found.threshold,
        if found.sand_is_dark { "dark" } else { "light" },
        found.skeleton_pixels,
        found.unexplained_pixels
    );
    for (k, l) in found.lines.iter().enumerate() {
        println!(
            "line {}: angle {:.2}°, offset {:+.2} mm, length {:.0} mm, rms {:.2} mm",
            k + 1,
            l.angle_deg,
            l.offset_mm,
            l.length_mm,
            l.rms_mm
        );
    }
    for (k, c) in found.curves.iter().enumerate() {
        let (a, b) = (c.points[0], c.points[c.points.len() - 1]);
        println!(
            "curve {}: {} points from ({:.1}, {:.1}) to ({:.1}, {:.1}) mm, length {:.0} mm, \
             rms {:.2} mm",
            k + 1,
            c.points.len(),
            a[0],
            a[1],
            b[0],
            b[1],
            c.length_mm,
            c.rms_mm
        );
    }
    if found.lines.is_empty() && found.curves.is_empty() {
        println!("no node line found");
    }
    match grid {
        None => {}
        Some(Ok(f)) if f.signed => println!(
            "grid node {}×{}: signed distance, {} regions",
            f.grid.nx, f.grid.ny, f.regions
        ),
        Some(Ok(f)) => println!(
            "grid node {}×{}: UNSIGNED distance ({})",
            f.grid.nx,
            f.grid.ny,
            f.note.as_deref().unwrap_or("regions not 2-colourable")
        ),
        Some(Err(e)) => println!("no grid node: {e}"),
    }
}

#[derive(Debug, Args)]
pub struct SuggestArgs {
    /// Plate file with the solver's keys (`[plate]` material and boundary; docs/plate.md).
    plate: PathBuf,
    /// The part to plan for (.json, .svg or .dxf).
    part: PathBuf,
    #[command(flatten)]
    read: super::part::PartRead,
    /// Solver modes per candidate (as `plate modes --count`).
    #[arg(long, default_value_t = 6, value_parser = usize_in("count", 1, 12))]
    count: usize,
    /// Robustness margin of the plans, as `plan --margin-deg`: a number of degrees in [0, 45)
    /// for every mode, or `auto` (each grid mode's margin from evidence, docs/plan.md).
    #[arg(long, value_name = "D|auto", default_value = "auto", value_parser = super::plan::margin_arg)]
    margin_deg: super::plan::MarginArg,
    /// No new candidate starts after this many seconds (the rest are reported "not tried",
    /// but for those with the plate file of a row tried), and the plan under way stops there
    /// (its row says so; not the first candidate that is planned).
    #[arg(long, default_value_t = 60, value_parser = usize_in("budget-s", 1, 3600))]
    budget_s: usize,
    /// The whole-plate check of every plan found, as `plan --refine-rounds`: how many times the
    /// step maps are refined with the drop points a plan does not hold from (docs/plan.md,
    /// "Whole-plate plans on grid modes"); a plan no round makes hold is a `not_whole_plate`
    /// row; 0: no check (a plan row may then be one `plan` refuses).
    #[arg(long, value_name = "N", default_value_t = chladni_core::planner::whole::REFINE_ROUNDS,
          value_parser = usize_in("refine-rounds", 0, 20))]
    refine_rounds: usize,
    /// Print the rows as JSON.
    #[arg(long)]
    json: bool,
}

impl SuggestArgs {
    fn run(&self) -> anyhow::Result<ExitCode> {
        let file = PlateFile::load(&self.plate).map_err(|e| InputError(e.to_string()))?;
        let plate = file.plate.mechanics().map_err(|e| InputError(e.to_string()))?;
        let part = self.read.load(&self.part)?;
        let set = suggest::Settings {
            count: self.count,
            terms: solver::DEFAULT_TERMS,
            grid: 41,
            budget: std::time::Duration::from_secs(self.budget_s as u64),
            plan: PlanOptions {
                margin_deg: self.margin_deg.0.unwrap_or(PlanOptions::default().margin_deg),
                margin_auto: self.margin_deg.0.is_none(),
                maps: chladni_core::planner::MapKind::Static,
                refine_rounds: self.refine_rounds,
                ..Default::default()
            },
        };
        let n = suggest::candidates(plate.size_mm).len() as u64;
        let bar = ProgressBar::new(n).with_style(
            ProgressStyle::with_template("trying {bar:30} {pos}/{len} candidates ({elapsed})")
                .unwrap_or(ProgressStyle::default_bar()),
        );
        if self.json {
            bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
        }
        let rows = suggest::run(&file, &plate, &part, &set, &Bar(bar.clone()));
        bar.finish_and_clear();
        let found = rows.iter().filter(|r| matches!(r.outcome, suggest::Outcome::Plan(_))).count();
        if self.json {
            println!("{}", suggest_json(&part.name, &plate.name, &rows));
        } else {
            print_suggest(&rows);
        }
        if found == 0 {
            eprintln!(
                "error: no candidate drive point or clamp set gives {} a plan on {}",
                part.name,
                self.plate.display()
            );
            return Ok(ExitCode::from(1));
        }
        Ok(ExitCode::SUCCESS)
    }
}

/// The suggest table: drive point, clamps, plan found, plan length, predicted orientation,
/// the whole-plate check's drops held, time, and why not; then each failing row's reason.
fn print_suggest(rows: &[suggest::Row]) {
    println!(
        "{:>3} {:>12} {:<24} {:>5} {:>4} {:>5} {:>8} {:>14} {:>7} {:>7}  why not",
        "row",
        "drive (mm)",
        "clamps (mm)",
        "modes",
        "plan",
        "steps",
        "total s",
        "final θ (deg)",
        "held",
        "wall s"
    );
    let pt = |c: &[f64; 2]| format!("({:.0}, {:.0})", c[0], c[1]);
    for (k, r) in rows.iter().enumerate() {
        let c = &r.candidate;
        let clamps = if c.clamps_mm.is_empty() {
            "none".to_string()
        } else {
            c.clamps_mm.iter().map(pt).collect::<Vec<_>>().join(" ")
        };
        let [plan, steps, total, theta, held, why] = suggest_cells(&r.outcome);
        let why = match r.same_as {
            Some(j) => format!("{why} (same modes as row {})", j + 1).trim_start().to_string(),
            None => why,
        };
        println!(
            "{:>3} {:>12} {clamps:<24} {:>5} {plan:>4} {steps:>5} {total:>8} {theta:>14} {held:>7} {:>7.1}  {why}",
            k + 1,
            pt(&c.drive_mm),
            r.modes,
            r.wall_s
        );
    }
    for (k, r) in rows.iter().enumerate().filter(|(_, r)| r.same_as.is_none()) {
        if let suggest::Outcome::NoPlan { reason, .. } = &r.outcome {
            println!("row {}: {reason}", k + 1);
        }
    }
}

/// A suggest row's outcome cells: plan y/n/?, steps, total s, final θ, the drops over the
/// plate the plan held from ("48/48"; "-" when not checked), and why not.
fn suggest_cells(outcome: &suggest::Outcome) -> [String; 6] {
    let dash = || "-".to_string();
    match outcome {
        suggest::Outcome::Plan(f) => {
            let held = match &f.whole_plate {
                Some(w) if w.checked => format!("{}/{}", w.held, w.drops),
                _ => dash(),
            };
            [
                "y".into(),
                f.steps.to_string(),
                format!("{:.1}", f.total_s),
                format!("{:.2} mod {}", f.final_orientation_deg, f.period_deg),
                held,
                String::new(),
            ]
        }
        suggest::Outcome::NoPlan { why, .. } => {
            let held = match why {
                suggest::Why::NotWholePlate(h) => format!("{}/{}", h.held, h.drops),
                _ => dash(),
            };
            ["n".into(), dash(), dash(), dash(), held, why.name().to_string()]
        }
        suggest::Outcome::NotTried => {
            ["?".into(), dash(), dash(), dash(), dash(), "not tried (budget)".into()]
        }
    }
}
