//! Figures: rest analysis (part, turn and alignment functions), plans and motion traces,
//! Chladni figures of plate modes, the particle on a string, and the Bode plot of a sweep.
//!
//! One font for every figure: Ubuntu Light, shipped inside the binary by the
//! `epaint_default_fonts` crate and rendered by plotters' `ab_glyph` backend, registered once
//! as "sans-serif" by [`ensure_font`] (so plotting needs no system fonts or fontconfig). One
//! error type, [`PlotError`]. Every figure is written atomically through
//! [`crate::output::write_with`].

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use plotters::style::FontStyle;

pub mod analysis;
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
    crate::output::write_with(path, draw).map_err(|e| PlotError::Draw {
        path: path.to_path_buf(),
        message: match e {
            crate::output::OutputError::Write { message, .. } => message,
            other => other.to_string(),
        },
    })
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
}
