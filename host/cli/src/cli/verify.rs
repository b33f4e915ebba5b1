//! `chladni verify PHOTO --plan plan.json --part P.json … --plate PLATE.toml`: the parts in a
//! photo of the plate after a run, against the plan's prediction (docs/plate.md, "Checking a
//! run from a photo"). Exit 0 when every part found is as planned, 1 when any is off (or none
//! was found), 2 for bad input. The judgement is the library's ([`chladni_media::vision::verify`]).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use chladni_core::model::part::Part;
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::motion::steps::{PlanStepsError, plan_steps};
use chladni_media::vision::verify::{self, Check, Outcome, Verification};
use clap::Args;

use super::check_plot;
use super::locate::{Failure, bad, see};

/// Arguments of `chladni verify`.
#[derive(Debug, Args)]
pub struct VerifyArgs {
    /// Photo of the plate after the run (PNG or JPEG; the format is read from the content).
    photo: PathBuf,
    /// The plan that was run (chladni plan --out): its predicted orientation and position.
    #[arg(long, value_name = "plan.json")]
    plan: PathBuf,
    /// The part(s) the plan was made for, in its order (JSON, SVG or DXF).
    #[arg(long = "part", value_name = "FILE", required = true)]
    parts: Vec<PathBuf>,
    /// The plate the plan was made for (TOML): its size and modes.
    #[arg(long, value_name = "PLATE.toml")]
    plate: PathBuf,
    /// Pixel positions of the plate's corners, as for `chladni locate` (bottom-left,
    /// bottom-right, top-right, top-left); found from the plate's contrast when not given.
    #[arg(
        long,
        num_args = 8,
        allow_negative_numbers = true,
        value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"]
    )]
    corners: Option<Vec<f64>>,
    /// Plate size W H (mm); the plate file's when not given, and it must agree with it.
    #[arg(long, num_args = 2, value_names = ["W", "H"])]
    size_mm: Option<Vec<f64>>,
    /// A part is oriented when within this of the predicted orientation (deg).
    #[arg(long, value_name = "D", default_value_t = verify::DEFAULT_TOL_DEG)]
    tol_deg: f64,
    /// A part is in place when its centroid is within this of a predicted position (mm).
    #[arg(long, value_name = "D", default_value_t = verify::DEFAULT_TOL_MM)]
    tol_mm: f64,
    /// Print one JSON object (also for failures).
    #[arg(long)]
    json: bool,
    /// Draw the found outlines over the rectified photo (PNG): green as planned, red off.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
}

/// A plate size given with --size-mm must be the plate file's to this (mm).
const SIZE_AGREEMENT_MM: f64 = 0.5;

impl VerifyArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        self.verify().map_err(|f| f.report(self.json))
    }

    /// The plate's size (checked against --size-mm) and the check of the plan for the parts.
    fn inputs(&self) -> Result<([f64; 2], Check), Failure> {
        let (size, check) =
            load_check(&self.plan, &self.parts, &self.plate, (self.tol_deg, self.tol_mm))?;
        if let Some(given) = &self.size_mm
            && (given[0] - size[0]).abs().max((given[1] - size[1]).abs()) > SIZE_AGREEMENT_MM
        {
            return Err(bad(
                "size_mismatch",
                format!(
                    "--size-mm {} {} is not the size of the plate {} ({} × {} mm): the plan's \
                     positions are on that plate; leave --size-mm out or photograph that plate",
                    given[0],
                    given[1],
                    self.plate.display(),
                    size[0],
                    size[1]
                ),
            ));
        }
        Ok((size, check))
    }

    fn verify(&self) -> Result<ExitCode, Failure> {
        let mut inputs: Vec<(&str, &Path)> = vec![
            ("photo", self.photo.as_path()),
            ("plan", self.plan.as_path()),
            ("plate", self.plate.as_path()),
        ];
        inputs.extend(self.parts.iter().map(|p| ("part", p.as_path())));
        check_plot("--plot", &self.plot, &["png"], &inputs)
            .map_err(|e| Failure { kind: "bad_input", error: e })?;
        let (size, check) = self.inputs()?;
        let seen = see(&self.photo, &self.parts, size, self.corners.as_deref())?;
        let v = check.judge(&seen.report);
        if let Some(path) = &self.plot {
            let fig = verify::draw(&seen.rectified, &seen.report, &v, &check.templates, size[1]);
            chladni_core::output::write_with(path, |p| fig.save(p).map_err(|e| e.to_string()))
                .map_err(|e| Failure { kind: "plot", error: super::output_error(e) })?;
        }
        if self.json {
            println!("{}", serde_json::to_string(&v).unwrap_or_default());
        } else {
            print_table(&v);
        }
        Ok(if v.result == Outcome::Ok { ExitCode::SUCCESS } else { ExitCode::from(1) })
    }
}

/// The verdict for people: a line per part, then the success rate.
fn print_table(v: &Verification) {
    for c in &v.parts {
        let l = &c.located;
        let verdict = match &c.reason {
            None => format!(
                "ok{}",
                c.orientation_error_deg.map_or(String::new(), |e| format!(" (θ off by {e:.2}°)"))
            ),
            Some(r) => format!("OFF: {r}"),
        };
        println!(
            "{:<16} x {:7.2} mm  y {:7.2} mm  θ {:7.2}°  {:<8} {verdict}",
            l.part,
            l.x_mm,
            l.y_mm,
            l.theta_deg,
            if l.flipped { "flipped" } else { "face up" }
        );
    }
    for u in &v.unseen {
        println!("not seen         {}", u.reason);
    }
    for u in &v.unknown {
        println!(
            "unknown blob at x {:.1} y {:.1} mm, {:.0} mm² (no given part; not counted)",
            u.x_mm, u.y_mm, u.area_mm2
        );
    }
    match v.success_rate {
        Some(rate) => println!(
            "success    {} of {} parts as planned ({:.1} %; within {}° and {} mm)",
            v.oriented,
            v.found,
            100.0 * rate,
            v.tolerance_deg,
            v.tolerance_mm
        ),
        None => println!("success    - (no part found on the plate)"),
    }
}

/// Loads the plate, the plan and the parts and checks that they belong together (the plan's
/// steps are modes of the plate, its entries the parts' faces): the plate's size and the
/// check photos are judged by. Every failure is bad input, named. `chladni serve
/// --verify-plan` loads its files here too.
pub(crate) fn load_check(
    plan_path: &Path,
    part_paths: &[PathBuf],
    plate_path: &Path,
    (tol_deg, tol_mm): (f64, f64),
) -> Result<([f64; 2], Check), Failure> {
    let plate = PlateModel::load(plate_path)
        .map_err(|e| bad("bad_plate", format!("--plate {}: {e}", plate_path.display())))?;
    let text = std::fs::read_to_string(plan_path)
        .map_err(|e| bad("bad_plan", format!("cannot read plan {}: {e}", plan_path.display())))?;
    let plan = PlanFile::parse(&text)
        .map_err(|e| bad("bad_plan", format!("plan {}: {e}", plan_path.display())))?;
    if let Err(PlanStepsError::NoMode(e)) = plan_steps(&plan, &plate) {
        return Err(bad(
            "plan_plate_mismatch",
            format!(
                "plan {} is not for the plate {}: {e}; give the plate the plan was made for",
                plan_path.display(),
                plate_path.display()
            ),
        ));
    }
    let mut parts = Vec::new();
    for p in part_paths {
        parts.push(
            Part::load(p).map_err(|e| bad("bad_part", format!("--part {}: {e}", p.display())))?,
        );
    }
    let check = Check::new(&plan, &parts, tol_deg, tol_mm)
        .map_err(|e| bad(e.name(), format!("plan {}: {e}", plan_path.display())))?;
    Ok((plate.size_mm, check))
}
