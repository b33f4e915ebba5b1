//! `chladni analyze PART --field …`: rest orientations of a part at a straight node.

use std::path::PathBuf;
use std::process::ExitCode;

use chladni_core::analysis::samples::{deg, offset_mm, turn_samples};
use chladni_core::model::field::{LawError, MAX_WAVELENGTH_MM};
use chladni_core::model::part::Part;
use chladni_media::plot::analysis::{self, PlotData};
use chladni_media::shapes::analyze::AnalyzeJson;
use chladni_media::shapes::write_csv;
use chladni_shared::analysis::field::Field;
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::rest::{Analysis, AnalysisError, Analyzer};
use clap::Args;

use super::parse::{FieldArg, f64_where, usize_in};
use super::part::PartArgs;
use super::{InputError, check_plot, plot_error};

/// Rest orientations of a part at a straight node (the plate's y-axis).
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    #[command(flatten)]
    part: PartArgs,
    /// Field law.
    #[arg(long, value_enum)]
    field: FieldArg,
    /// Sine field: distance from the node to the next antinode (mm).
    #[arg(long, value_name = "MM",
          value_parser = f64_where("wavelength", "in (0, 1e7] mm", |w| w > 0.0 && w <= MAX_WAVELENGTH_MM))]
    wavelength: Option<f64>,
    /// Gain on the left side of the node (x < 0).
    #[arg(long, value_name = "G", default_value_t = 1.0, value_parser = gain("gain-left"))]
    gain_left: f64,
    /// Gain on the right side of the node (x > 0).
    #[arg(long, value_name = "G", default_value_t = 1.0, value_parser = gain("gain-right"))]
    gain_right: f64,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// Draw the part at rest, t(θ) and a(θ) to this file (.png or .svg).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// With --json: add N samples of t(θ) and a(θ), θ evenly over [0°, 360°], as `samples`.
    #[arg(long, value_name = "N", value_parser = usize_in("samples", 2, 1_000_000))]
    samples: Option<usize>,
    /// Write the samples of t(θ) and a(θ) as CSV (theta_deg,turn,alignment_deg; N from
    /// --samples, else 721: every 0.5°).
    #[arg(long, value_name = "FILE")]
    csv: Option<PathBuf>,
}

/// Samples of t(θ) and a(θ) written by `--csv` unless `--samples` says how many.
const CSV_SAMPLES: usize = 721;

/// A field gain: a number in (0, 1e6].
fn gain(
    name: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    f64_where(name, "a number in (0, 1e6]", |g| g.is_finite() && g > 0.0 && g <= 1e6)
}

fn bad(msg: String) -> anyhow::Error {
    InputError(msg).into()
}

impl AnalyzeArgs {
    fn field(&self) -> anyhow::Result<Field> {
        // The law's own check, worded for the command line.
        let law = self.field.with_wavelength(self.wavelength).map_err(|e| {
            bad(match e {
                LawError::NeedsWavelength => "--field sine needs --wavelength MM".into(),
                LawError::WavelengthNotSine(_) => {
                    format!("--wavelength only applies to --field sine, not {}", self.field.name())
                }
                e => format!("--wavelength: {e}"),
            })
        })?;
        let kind = law.to_fixed();
        Ok(Field {
            kind,
            gain_left: Fx::from_f64(self.gain_left),
            gain_right: Fx::from_f64(self.gain_right),
        })
    }

    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let field = self.field()?;
        check_plot("--plot", &self.plot, &analysis::EXTENSIONS, &[("part", self.part.path())])?;
        check_plot("--csv", &self.csv, &["csv"], &[("part", self.part.path())])?;
        if self.samples.is_some() && !self.json && self.csv.is_none() {
            return Err(
                bad("--samples goes with --json or --csv (it adds samples to them)".into()),
            );
        }
        let part = self.part.load()?;
        let rings = part.to_fixed();
        let slices: Vec<&[chladni_shared::analysis::geometry::Pt]> =
            rings.iter().map(Vec::as_slice).collect();
        let an = Analyzer::new(&slices, field).map_err(|e| match e {
            AnalysisError::WavelengthTooShort => {
                let diameter = 2.0 * radius_mm(&part);
                bad(format!(
                    "--wavelength {} mm is too short for {}: the part must fit between node and \
                     antinode on either side, so the wavelength must be at least its diameter \
                     about the centroid, {diameter:.3} mm",
                    self.wavelength.unwrap_or(0.0),
                    part.name
                ))
            }
            other => bad(format!("{}: cannot analyse: {other:?}", self.part.path().display())),
        })?;
        let analysis = an.analyze().map_err(|e| anyhow::anyhow!("analysis failed: {e:?}"))?;
        let stable: Vec<f64> =
            analysis.rests.iter().filter(|r| r.stable).map(|r| deg(r.angle)).collect();
        let unstable: Vec<f64> =
            analysis.rests.iter().filter(|r| !r.stable).map(|r| deg(r.angle)).collect();
        let period = 360.0 / analysis.order as f64;
        if self.json {
            let report = AnalyzeJson {
                field: self.field.name(),
                neutral: analysis.neutral,
                part: &part.name,
                period_deg: period,
                samples: self.samples.map(|n| turn_samples(&an, &analysis, n)),
                stable_deg: stable,
                unstable_deg: unstable,
            };
            println!("{}", serde_json::to_string(&report)?);
        } else {
            self.print_table(&part, &an, &analysis, period);
        }
        if let Some(path) = &self.csv {
            let rows = turn_samples(&an, &analysis, self.samples.unwrap_or(CSV_SAMPLES));
            write_csv(path, &rows).map_err(super::output_error)?;
            if !self.json {
                println!("csv        {} ({} samples)", path.display(), rows.len());
            }
        }
        if let Some(path) = &self.plot {
            let (field, desc) = (self.field.name(), self.describe_field());
            let title = format!(
                "{} — {} field{}",
                part.name,
                field,
                desc.strip_prefix(field).unwrap_or("")
            );
            let data = PlotData::of(&part, &an, &analysis, title);
            analysis::write(path, &data).map_err(plot_error)?;
            if !self.json {
                println!("plot       {}", path.display());
            }
        }
        Ok(ExitCode::SUCCESS)
    }

    fn describe_field(&self) -> String {
        let mut s = self.field.name().to_string();
        if let Some(w) = self.wavelength {
            s += &format!(" (w = {w} mm)");
        }
        if self.gain_left != self.gain_right {
            s += &format!(", gains left {} / right {}", self.gain_left, self.gain_right);
        }
        s
    }

    fn print_table(&self, part: &Part, an: &Analyzer<'_>, a: &Analysis, period: f64) {
        println!(
            "part       {} ({} vertices, {} hole(s), area {:.3} mm²)",
            part.name,
            part.vertex_count(),
            part.holes.len(),
            part.area()
        );
        println!("field      {}", self.describe_field());
        if a.neutral {
            println!("result     neutral: every orientation is at rest");
            return;
        }
        println!("period     {period}°");
        println!("{:>12}  {:<9}  {:>18}", "θ (deg)", "kind", "node offset (mm)");
        for r in &a.rests {
            let s = offset_mm(an, an.balance(r.angle, Fx::ZERO).offset);
            let kind = if r.stable { "stable" } else { "unstable" };
            println!("{:>12.6}  {:<9}  {:>18.6}", deg(r.angle), kind, s);
        }
    }
}

fn radius_mm(part: &Part) -> f64 {
    let [cx, cy] = part.centroid();
    part.rings().flatten().map(|p| (p[0] - cx).hypot(p[1] - cy)).fold(0.0, f64::max)
}
