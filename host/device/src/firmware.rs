//! Locating and building firmware images.
//!
//! Builds go through `scripts/firmware.sh` (the single place that knows the cargo flags and the
//! separate `target/firmware` directory), so the CLI, the tests and CI build the same image.

use std::path::{Path, PathBuf};
use std::process::Command;

use chladni_shared::icd::link::Board;

/// Why an image could not be had.
#[derive(Debug, thiserror::Error)]
pub enum FirmwareError {
    /// Not running from a source checkout, and no image was named.
    #[error(
        "no Chladni source tree at {0}: pass --firmware ELF, or run from a checkout of the project"
    )]
    NoSourceTree(PathBuf),
    /// The build failed.
    #[error(
        "building the {board} firmware failed (exit {status}); run `scripts/firmware.sh build {board}` to see why"
    )]
    BuildFailed {
        /// Board name.
        board: &'static str,
        /// Exit status.
        status: String,
    },
    /// Could not run the build at all.
    #[error("cannot run scripts/firmware.sh: {0}")]
    Spawn(#[from] std::io::Error),
}

/// The source checkout this binary was built from, if it is still there.
pub fn source_root() -> Option<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent()?.parent()?.to_path_buf();
    root.join("scripts/firmware.sh").is_file().then_some(root)
}

/// Builds the image for `board` if it is missing or stale (cargo decides) and returns its path.
pub fn build(board: Board) -> Result<PathBuf, FirmwareError> {
    let root = source_root()
        .ok_or_else(|| FirmwareError::NoSourceTree(PathBuf::from(env!("CARGO_MANIFEST_DIR"))))?;
    let out = Command::new(root.join("scripts/firmware.sh"))
        .args(["build", board.name()])
        .current_dir(&root)
        .stderr(std::process::Stdio::inherit())
        .output()?;
    if !out.status.success() {
        return Err(FirmwareError::BuildFailed {
            board: board.name(),
            status: out.status.to_string(),
        });
    }
    let rel = String::from_utf8_lossy(&out.stdout).trim().to_string();
    Ok(root.join(rel))
}
