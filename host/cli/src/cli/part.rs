//! Part files on the command line of `analyze`, `plan` and `simulate`, with the options of
//! the DXF and SVG readers (`--layer`, `--chord-mm`): one place, so every command reads parts alike.

use std::path::{Path, PathBuf};

use chladni_core::model::part::dxf::{CHORD_RANGE_MM, DEFAULT_CHORD_MM};
use chladni_core::model::part::{ImportOptions, Part};
use clap::Args;

use super::InputError;
use super::parse::f64_where;

/// How part files are read (DXF layer and chord tolerance).
#[derive(Debug, Args)]
pub struct PartRead {
    /// DXF parts: read only this layer (case-insensitive).
    #[arg(long, value_name = "NAME")]
    pub layer: Option<String>,
    /// DXF and SVG parts: arcs and curves become chords at most this far (sagitta, mm) from
    /// the curve.
    #[arg(long, value_name = "MM", default_value_t = DEFAULT_CHORD_MM,
          value_parser = f64_where("chord-mm", "in [0.0001, 5] mm", |v| CHORD_RANGE_MM.contains(&v)))]
    pub chord_mm: f64,
}

impl PartRead {
    /// Reads a part (every error is bad input); the reader's notes go to stderr.
    pub fn load(&self, path: &Path) -> anyhow::Result<Part> {
        let opt = ImportOptions { layer: self.layer.clone(), chord_mm: self.chord_mm };
        let (part, notes) = Part::load_with(path, &opt)
            .map_err(|e| InputError(format!("{}: {e}", path.display())))?;
        for n in notes {
            eprintln!("note: {}: {n}", path.display());
        }
        Ok(part)
    }
}

/// One part file and how to read it.
#[derive(Debug, Args)]
pub struct PartArgs {
    /// Part file: .json (docs/analyze.md), .svg (every shape, curves flattened, units honoured)
    /// or .dxf (closed polylines, circles, LINE/ARC chains, blocks; docs/analyze.md).
    pub part: PathBuf,
    #[command(flatten)]
    pub read: PartRead,
}

impl PartArgs {
    /// The part file's path.
    pub fn path(&self) -> &Path {
        &self.part
    }

    /// Reads the part (see [`PartRead::load`]).
    pub fn load(&self) -> anyhow::Result<Part> {
        self.read.load(&self.part)
    }
}
