//! `chladni plate calibrate-speed PLATE.toml --mode NAME --observations obs.csv`: fits the
//! mode's `speed_mm_s` to observed parts (`chladni_core::plate::calibrate`) and writes it into the
//! plate file (docs/plate.md, "Calibrating the settle speed").

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni_core::model::observations;
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::model::plate_edit;
use chladni_core::output::write_atomic;
use chladni_core::plate::calibrate::{self, CalPart, DEFAULT_WITHIN_MM, Fit, FitError};
use chladni_media::shapes::plate::{Calibrated, calibrate_json};
use chladni_media::vision::series::{self as photos, PhotoSeriesError, Sighting};
use clap::Args;

use super::parse::positive;
use super::{InputError, output_error};

/// Fit a mode's settle speed (speed_mm_s) to observed parts and write it to the plate file.
#[derive(Debug, Args)]
pub struct CalibrateArgs {
    /// Plate file (TOML); its `speed_mm_s` of the mode is replaced in place, the rest kept.
    plate: PathBuf,
    /// The mode observed (its name in the plate file, as `chladni plan` prints it).
    #[arg(long, value_name = "NAME")]
    mode: String,
    /// Observations (CSV: part,x_mm,y_mm,theta_deg,t_s[,end_x_mm,end_y_mm,end_theta_deg]).
    #[arg(
        long,
        value_name = "obs.csv",
        required_unless_present = "photos",
        conflicts_with = "photos"
    )]
    observations: Option<PathBuf>,
    /// Instead of a CSV: a directory of timestamped photos (PNG, the time in each file name,
    /// e.g. t012.500.png or run_12500ms.png) of one part (--part) moving on the plate.
    #[arg(long, value_name = "DIR")]
    photos: Option<PathBuf>,
    /// With --photos: the plate's size W H in the photos (mm); default the plate file's.
    #[arg(long, num_args = 2, value_names = ["W", "H"], requires = "photos")]
    size_mm: Option<Vec<f64>>,
    /// With --photos: the plate's corners in every photo (px, as `chladni locate` takes them);
    /// found in each photo when not given.
    #[arg(
        long,
        num_args = 8,
        allow_negative_numbers = true,
        requires = "photos",
        value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"]
    )]
    corners: Option<Vec<f64>>,
    /// Part files the CSV's `part` column may name (by path, file name or part name); other
    /// names are part files relative to the CSV's directory. With --photos: the one part
    /// photographed.
    #[arg(long, value_name = "P.json", num_args = 1..)]
    part: Vec<PathBuf>,
    /// A part counts as on the node when its centroid is this close to where it comes to
    /// rest (mm): the end of a time-to-node observation.
    #[arg(long, value_name = "MM", default_value_t = DEFAULT_WITHIN_MM, value_parser = positive("within-mm"))]
    within_mm: f64,
    /// Fit and report, but leave the plate file as it is.
    #[arg(long)]
    dry_run: bool,
    /// Print one JSON object (also for failures).
    #[arg(long)]
    json: bool,
}

/// What a fit runs on: the parts, the observations and (from photos) the sightings.
type Series = (Vec<CalPart>, Vec<calibrate::Observation>, Vec<Sighting>);

/// A failure and its `--json` name.
use super::Failure;

fn bad(msg: String) -> Failure {
    Failure { kind: "bad_input", error: InputError(msg).into() }
}

/// A fit that failed: undetermined (or no rows) is the observations' fault, bad input.
fn fit_failure(e: FitError) -> Failure {
    let (kind, input) = match e {
        FitError::Undetermined(_) => ("undetermined", true),
        FitError::Empty => ("empty", true),
        FitError::NoRest { .. } => ("no_rest", false),
        FitError::AtBound { .. } => ("at_bound", false),
    };
    let error = if input { InputError(e.to_string()).into() } else { e.into() };
    Failure { kind, error }
}

impl CalibrateArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        self.calibrate().map_err(|f| f.report(self.json))
    }

    fn calibrate(&self) -> Result<ExitCode, Failure> {
        let plate = PlateModel::load(&self.plate).map_err(|e| bad(e.to_string()))?;
        let Some(mode) = plate.modes.iter().position(|m| m.name == self.mode) else {
            let names: Vec<String> =
                plate.modes.iter().map(|m| format!("\"{}\"", m.name)).collect();
            return Err(bad(format!(
                "--mode {:?}: no such mode in {} (modes: {})",
                self.mode,
                self.plate.display(),
                names.join(", ")
            )));
        };
        let (cal, obs, sightings) = match &self.photos {
            Some(dir) => self.photo_series(&plate, dir)?,
            None => {
                let (parts, obs) = self.observations(&plate)?;
                (parts.iter().map(CalPart::new).collect(), obs, Vec::new())
            }
        };
        let fit = calibrate::fit(&cal, &plate, mode, &obs, self.within_mm).map_err(fit_failure)?;
        let m = &plate.modes[mode];
        let written =
            if self.dry_run { None } else { Some(self.write(m.freq_hz, fit.speed_mm_s)?) };
        if self.json {
            let calibrated = Calibrated {
                plate: &self.plate,
                mode: m,
                within_mm: self.within_mm,
                fit: &fit,
                written: written.as_deref(),
                photos: self.photos.is_some().then_some(&sightings),
            };
            println!("{}", calibrate_json(&calibrated));
        } else {
            print_sightings(&sightings);
            self.print(&plate, mode, &fit, written.as_deref());
        }
        Ok(ExitCode::SUCCESS)
    }

    /// The CSV's rows, the parts they name and the observations (every problem bad input).
    fn observations(
        &self,
        plate: &PlateModel,
    ) -> Result<(Vec<Part>, Vec<calibrate::Observation>), Failure> {
        let Some(csv) = &self.observations else {
            return Err(bad("give --observations obs.csv or --photos DIR".into()));
        };
        let label = csv.display();
        let given = (self.part.iter())
            .map(|p| {
                Part::load(p)
                    .map(|part| (p.clone(), part))
                    .map_err(|e| bad(format!("--part {}: {e}", p.display())))
            })
            .collect::<Result<Vec<_>, _>>()?;
        let rows = observations::load(csv).map_err(|e| bad(format!("{label}: {e}")))?;
        observations::check_on_plate(&rows, plate.size_mm)
            .map_err(|e| bad(format!("{label}: {e}")))?;
        let dir = csv.parent().unwrap_or(Path::new("."));
        observations::resolve(&rows, dir, &given).map_err(|e| bad(format!("{label}: {e}")))
    }

    /// The one part, its observations and sightings from the photos in `dir` (every problem
    /// bad input, named by [`PhotoSeriesError::name`]).
    fn photo_series(&self, plate: &PlateModel, dir: &Path) -> Result<Series, Failure> {
        let [path] = &self.part[..] else {
            return Err(bad(format!(
                "--photos needs exactly one --part (the part photographed), got {}",
                self.part.len()
            )));
        };
        let part = Part::load(path).map_err(|e| bad(format!("--part {}: {e}", path.display())))?;
        let size = self.size_mm.as_deref().map_or(plate.size_mm, |s| [s[0], s[1]]);
        let corners = self
            .corners
            .as_deref()
            .map(|c| [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]]);
        let series = |e: PhotoSeriesError| Failure {
            kind: e.name(),
            error: InputError(e.to_string()).into(),
        };
        let files = photos::list(dir).map_err(series)?;
        files.note.iter().for_each(|n| eprintln!("note: {n}"));
        let sightings = photos::locate_all(&files, &part, size, corners).map_err(series)?;
        let flipped = sightings.first().is_some_and(|s| s.located.flipped);
        let mut cal = CalPart::new(&if flipped { part.mirrored() } else { part.clone() });
        cal.name = part.name.clone();
        Ok((vec![cal], photos::observations(&sightings), sightings))
    }

    /// Writes the speed into the plate file (atomically; everything else kept).
    fn write(&self, freq_hz: f64, speed: f64) -> Result<String, Failure> {
        let text = std::fs::read_to_string(&self.plate)
            .map_err(|e| bad(format!("cannot read {}: {e}", self.plate.display())))?;
        let failed = |error: anyhow::Error| Failure { kind: "write", error };
        let out = plate_edit::set_speed(&text, freq_hz, speed).map_err(|e| failed(e.into()))?;
        write_atomic(&self.plate, out.as_bytes()).map_err(|e| failed(output_error(e)))?;
        Ok(self.plate.display().to_string())
    }

    fn print(&self, plate: &PlateModel, mode: usize, fit: &Fit, written: Option<&str>) {
        let m = &plate.modes[mode];
        let (times, poses) = fit
            .residuals
            .iter()
            .fold((0, 0), |(t, p), r| if r.kind == "time" { (t + 1, p) } else { (t, p + 1) });
        println!(
            "plate      {}, mode \"{}\" ({} Hz, amplitude {})",
            plate.name, m.name, m.freq_hz, m.amplitude
        );
        println!(
            "observed   {times} time(s) to the node (centroid within {} mm of its rest), {poses} pose(s) after a time",
            self.within_mm
        );
        println!(
            "fit        speed_mm_s = {} mm/s ({}; the file had {})",
            fit.speed_mm_s, fit.method, m.speed_mm_s
        );
        println!(
            "{:<6} {:<20} {:>10} {:>10} {:>10}",
            "line", "part", "observed", "model", "residual"
        );
        for r in &fit.residuals {
            let (obs, model, unit) = match (r.observed_s, r.model_s, r.model_pose) {
                (Some(o), Some(md), _) => (format!("{o:.2} s"), format!("{md:.2} s"), "s"),
                (_, _, Some(q)) => ("pose".into(), format!("({:.1}, {:.1})", q[0], q[1]), "mm"),
                _ => (String::new(), String::new(), ""),
            };
            println!(
                "{:<6} {:<20} {obs:>10} {model:>10} {:>+8.3} {unit}",
                r.line, r.part, r.residual
            );
        }
        if let Some(t) = fit.rms_time_s {
            println!("rms        time {t:.3} s");
        }
        if let Some(p) = fit.rms_pose_mm {
            println!("rms        pose {p:.3} mm");
        }
        match written {
            Some(path) => println!("written    {path} (speed_mm_s of mode \"{}\")", m.name),
            None => println!("written    nothing (--dry-run)"),
        }
    }
}

/// The photos' sightings (nothing for a CSV): the residuals' `line` is the photo's number.
fn print_sightings(sightings: &[Sighting]) {
    for (k, s) in sightings.iter().enumerate() {
        let l = &s.located;
        println!(
            "photo {:<4} {:>9.3} s  x {:7.2} mm  y {:7.2} mm  θ {:7.2}°  score {:.2}  {}",
            k + 1,
            s.t_s,
            l.x_mm,
            l.y_mm,
            l.theta_deg,
            l.score,
            s.file.display()
        );
    }
}
