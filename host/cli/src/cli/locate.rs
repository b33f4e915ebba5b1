//! `chladni locate PHOTO --part P.json … --size-mm W H`: the parts in a photo of the plate,
//! with their poses, faces and match scores (docs/plate.md, "Parts in a photo").

use std::path::PathBuf;
use std::process::ExitCode;

use chladni_core::model::part::Part;
use chladni_core::plate::photo;
use chladni_media::vision::{self, Report, Template};
use clap::Args;

use super::{InputError, check_plot, output_error};

/// Arguments of `chladni locate`.
#[derive(Debug, Args)]
pub struct LocateArgs {
    /// Photo of the plate (PNG; the format is read from the content).
    photo: PathBuf,
    /// A part kind to look for (JSON, SVG or DXF); repeat for several kinds.
    #[arg(long = "part", value_name = "FILE", required = true)]
    parts: Vec<PathBuf>,
    /// Plate size W H (mm).
    #[arg(long, num_args = 2, value_names = ["W", "H"], required = true)]
    size_mm: Vec<f64>,
    /// Pixel positions (x right, y down) of the plate's corners (0, 0), (W, 0), (W, H), (0, H):
    /// bottom-left, bottom-right, top-right, top-left. Found from the plate's contrast with
    /// its surroundings when not given.
    #[arg(
        long,
        num_args = 8,
        allow_negative_numbers = true,
        value_names = ["X0", "Y0", "X1", "Y1", "X2", "Y2", "X3", "Y3"]
    )]
    corners: Option<Vec<f64>>,
    /// Print one JSON object (also for failures).
    #[arg(long)]
    json: bool,
    /// Draw the found outlines over the rectified photo (PNG).
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
}

pub(crate) use super::Failure;

pub(crate) fn bad(kind: &'static str, msg: String) -> Failure {
    Failure { kind, error: InputError(msg).into() }
}

/// The parts, photo and located poses: what `locate` and `verify` share.
pub(crate) struct Seen {
    pub templates: Vec<Template>,
    pub report: Report,
    pub rectified: image::GrayImage,
}

/// Loads the parts and the photo and locates the parts; every failure is bad input.
pub(crate) fn see(
    photo_path: &std::path::Path,
    parts: &[PathBuf],
    size_mm: [f64; 2],
    corners: Option<&[f64]>,
) -> Result<Seen, Failure> {
    let mut templates = Vec::new();
    for p in parts {
        let part =
            Part::load(p).map_err(|e| bad("bad_part", format!("--part {}: {e}", p.display())))?;
        templates.push(Template::new(&part));
    }
    let img = photo::input::read(photo_path).map_err(|e| {
        let kind = if matches!(e, photo::PhotoError::TooLarge { .. }) {
            "too_large"
        } else {
            "not_a_photo"
        };
        bad(kind, e.to_string())
    })?;
    let corners = corners.map(|c| [[c[0], c[1]], [c[2], c[3]], [c[4], c[5]], [c[6], c[7]]]);
    let (report, rectified) = vision::locate(&img, &templates, size_mm, corners)
        .map_err(|e| bad(e.name(), e.to_string()))?;
    Ok(Seen { templates, report, rectified })
}

/// Writes the `--plot` figure.
pub(crate) fn write_plot(path: &std::path::Path, seen: &Seen, h_mm: f64) -> Result<(), Failure> {
    let fig = vision::plot::draw(&seen.rectified, &seen.report, &seen.templates, h_mm);
    chladni_core::output::write_with(path, |p| fig.save(p).map_err(|e| e.to_string()))
        .map_err(|e| Failure { kind: "plot", error: output_error(e) })
}

impl LocateArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        self.locate().map_err(|f| f.report(self.json))
    }

    fn locate(&self) -> Result<ExitCode, Failure> {
        let inputs: Vec<(&str, &std::path::Path)> =
            std::iter::once(("photo", self.photo.as_path()))
                .chain(self.parts.iter().map(|p| ("part", p.as_path())))
                .collect();
        check_plot("--plot", &self.plot, &["png"], &inputs)
            .map_err(|e| Failure { kind: "bad_input", error: e })?;
        let size = [self.size_mm[0], self.size_mm[1]];
        let seen = see(&self.photo, &self.parts, size, self.corners.as_deref())?;
        if let Some(path) = &self.plot {
            write_plot(path, &seen, size[1])?;
        }
        let r = &seen.report;
        if self.json {
            println!("{}", serde_json::to_string(r).unwrap_or_default());
            return Ok(ExitCode::SUCCESS);
        }
        println!(
            "plate corners {} (px): {:?}; {:.3} mm per pixel; parts {} than the plate",
            if r.corners_found { "found" } else { "given" },
            r.corners.map(|c| [c[0].round(), c[1].round()]),
            r.pixel_mm,
            if r.parts_dark { "darker" } else { "lighter" }
        );
        for l in &r.parts {
            println!(
                "{:<16} x {:7.2} mm  y {:7.2} mm  θ {:7.2}°  {}  score {:.2}{}",
                l.part,
                l.x_mm,
                l.y_mm,
                l.theta_deg,
                match (l.flipped, l.face_certain) {
                    (_, false) => "face ?",
                    (true, _) => "flipped",
                    _ => "face up",
                },
                l.score,
                if l.touching { "  (touching another)" } else { "" }
            );
        }
        for u in &r.unknown {
            let what = match (&u.part, u.count) {
                (Some(p), Some(n)) => format!("{:?}: {n} × {p}", u.why),
                (Some(p), None) => format!("{:?}: likely {p}", u.why),
                _ => format!("{:?}", u.why),
            };
            println!(
                "unknown blob at x {:.1} y {:.1} mm, {:.0} mm²: {what}",
                u.x_mm, u.y_mm, u.area_mm2
            );
        }
        Ok(ExitCode::SUCCESS)
    }
}
