//! Figures: rest analysis (part, turn and alignment functions), plans and motion traces,
//! Chladni figures of plate modes, the particle on a string, the Bode plot of a sweep, and the
//! animation of a simulated plan (GIF, [`animate`]).
//!
//! One font for every figure: Ubuntu Light, shipped inside the binary by the
//! `epaint_default_fonts` crate and rendered by plotters' `ab_glyph` backend, registered once
//! as "sans-serif" by [`ensure_font`] (so plotting needs no system fonts or fontconfig). One
//! error type, [`PlotError`]. Every figure is written atomically through
//! [`chladni_core::output::write_with`]. One choice of backend, `write_chart`: the file's extension
//! picks plotters' SVG backend (`.svg`) or its bitmap backend (`.png`), so every figure that
//! implements `Figure` is drawn by the same code in both formats.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::coord::Shift;
use plotters::prelude::{BitMapBackend, DrawingArea, DrawingBackend, IntoDrawingArea, SVGBackend};
use plotters::style::FontStyle;

pub mod analysis;
pub mod animate;
pub mod bode;
pub mod plan;
pub mod plate;
pub mod string;

/// Registers the embedded font as "sans-serif", normal and bold (idempotent; every figure
/// calls it before drawing).
pub fn ensure_font() {
    static DONE: OnceLock<()> = OnceLock::new();
    DONE.get_or_init(|| {
        for style in [FontStyle::Normal, FontStyle::Bold] {
            // The bytes are a valid TrueType font shipped by the crate; failure would be a bug.
            plotters::style::register_font("sans-serif", style, epaint_default_fonts::UBUNTU_LIGHT)
                .unwrap_or_else(|_| panic!("embedded font rejected"));
        }
    });
}

/// Why a figure was not written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    /// The file name's extension is not one this figure can be written as (bad input).
    #[error("{flag} file must end in {expected}: {path}")]
    Format {
        /// The option that named the file.
        flag: String,
        /// The file.
        path: PathBuf,
        /// The extensions allowed, e.g. ".png or .svg".
        expected: String,
    },
    /// Drawing or writing failed (plotters' errors are generic: their text is kept).
    #[error("plotting {path}: {message}")]
    Draw {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

impl PlotError {
    /// True when the error is the user's (a file name the figure cannot be written as).
    pub fn is_bad_input(&self) -> bool {
        matches!(self, PlotError::Format { .. })
    }
}

/// Checks, before any work, that `path` (given by option `flag`) ends in one of `extensions`
/// (lower case, without the dot; compared case-insensitively).
pub fn check_extension(flag: &str, path: &Path, extensions: &[&str]) -> Result<(), PlotError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref().is_some_and(|e| extensions.contains(&e)) {
        return Ok(());
    }
    let dotted: Vec<String> = extensions.iter().map(|e| format!(".{e}")).collect();
    Err(PlotError::Format {
        flag: flag.to_string(),
        path: path.to_path_buf(),
        expected: dotted.join(" or "),
    })
}

/// Draws a figure into `path` atomically: `draw` renders into the temporary file it is given
/// (same directory and extension), which then replaces `path`.
pub(crate) fn write_figure<E: std::fmt::Display>(
    path: &Path,
    draw: impl FnOnce(&Path) -> Result<(), E>,
) -> Result<(), PlotError> {
    ensure_font();
    chladni_core::output::write_with(path, draw).map_err(|e| PlotError::Draw {
        path: path.to_path_buf(),
        message: match e {
            chladni_core::output::OutputError::Write { message, .. } => message,
            other => other.to_string(),
        },
    })
}

/// The file types every `Figure` can be written as.
pub const FIGURE_EXTENSIONS: [&str; 2] = ["png", "svg"];

/// A figure drawn by the same code on any plotters backend (see [`write_chart`]).
pub(crate) trait Figure {
    /// Width and height (pixels; SVG user units).
    fn size(&self) -> (u32, u32);
    /// Draws the whole figure on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), String>
    where
        DB::ErrorType: 'static;
}

/// Writes `figure` to `path` atomically: SVG when the extension is `.svg`, PNG otherwise
/// (callers check the extension with [`check_extension`] against [`FIGURE_EXTENSIONS`]).
pub(crate) fn write_chart(path: &Path, figure: &impl Figure) -> Result<(), PlotError> {
    let svg = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("svg"));
    let size = figure.size();
    write_figure(path, |tmp| {
        if svg {
            let root = SVGBackend::new(tmp, size).into_drawing_area();
            figure.draw(&root)?;
            root.present().map_err(text)
        } else {
            let root = BitMapBackend::new(tmp, size).into_drawing_area();
            figure.draw(&root)?;
            root.present().map_err(text)
        }
    })
}

/// A tick label with as many decimals as the axis span `scale` needs, never "-0.0".
pub(crate) fn tick(v: f64, scale: f64) -> String {
    let decimals =
        if scale >= 10.0 { 0 } else { (1.0 - scale.abs().max(1e-12).log10().floor()) as usize };
    let s = format!("{:.*}", decimals.min(9), v);
    if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// The figures' one legend style: a light box with a black border, `font_px` sans-serif,
/// placed at `at`.
pub(crate) fn draw_legend<'a, DB, CT>(
    chart: &mut plotters::chart::ChartContext<'a, DB, CT>,
    font_px: u32,
    at: plotters::chart::SeriesLabelPosition,
) -> Result<(), String>
where
    DB: DrawingBackend + 'a,
    CT: plotters::coord::CoordTranslate,
{
    use plotters::style::{BLACK, Color, WHITE};
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font(("sans-serif", font_px))
        .position(at)
        .draw()
        .map_err(text)
}

/// A drawing error as text (plotters' error types are generic over the backend).
pub(crate) fn text<E: std::fmt::Display>(e: E) -> String {
    e.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn extensions_are_checked_case_insensitively_and_named() {
        assert!(check_extension("--plot", Path::new("a/B.PNG"), &["png"]).is_ok());
        let e = check_extension("--plot", Path::new("x.gif"), &["png", "svg"]).unwrap_err();
        assert!(e.is_bad_input());
        assert_eq!(e.to_string(), "--plot file must end in .png or .svg: x.gif");
        assert!(check_extension("--plot", Path::new("noext"), &["png"]).is_err());
    }

    #[test]
    fn ticks_never_read_minus_zero() {
        assert_eq!(tick(-0.0001, 1.0), "0.0");
        assert_eq!(tick(-0.5, 1.0), "-0.5");
        assert_eq!(tick(12.0, 100.0), "12");
    }
}
