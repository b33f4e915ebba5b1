//! The forced rocking of a hinged-rod plate as a `[[mode]]` entry (`chladni plate modes
//! --rocking-hz`, docs/plate.md): below the first elastic mode the rod turns the plate rigidly
//! about the hinge, w ∝ (x − hinge_x), so the node is the hinge line and the pull grows
//! linearly with the distance from it (the `linear` field law, docs/motion.md).

use crate::model::modes_file;
use crate::model::plate_file::{Boundary, ModeEntry, Plate};
use crate::plate::solver::ModalSolution;

/// The forced rocking's default drive frequency (Hz): the paper's setup 2 ran at 10 Hz.
pub const DEFAULT_ROCKING_HZ: f64 = 10.0;

/// Highest rocking frequency whatever the plate (Hz).
pub(crate) const MAX_ROCKING_HZ: f64 = 2000.0;

/// Why a plate cannot rock at the frequency asked for.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RockingError {
    /// A rocking frequency for a plate without a hinge.
    #[error(
        "--rocking-hz {hz}: only hinged-rod plates rock about a hinge; this plate is {plate} \
         (boundary = \"{boundary}\"): leave the option out"
    )]
    NotHinged {
        /// The frequency given (Hz).
        hz: f64,
        /// The plate's name.
        plate: String,
        /// Its boundary's key in the plate file.
        boundary: &'static str,
    },
    /// A frequency outside [1, limit] Hz.
    #[error(
        "--rocking-hz must be in [1, {limit:.1}] Hz (half the first elastic mode at {first:.1} Hz, so the plate rocks rigidly), got {hz}"
    )]
    Frequency {
        /// The frequency given (Hz).
        hz: f64,
        /// The highest allowed (Hz).
        limit: f64,
        /// The plate's first elastic mode (Hz).
        first: f64,
    },
}

/// The rocking entry of `plate` at `rocking_hz` (default [`DEFAULT_ROCKING_HZ`]) given its
/// elastic modes `sol`; `None` for a plate that is not hinged-rod and no frequency given.
pub fn rocking_mode(
    plate: &Plate,
    sol: &ModalSolution,
    rocking_hz: Option<f64>,
) -> Result<Option<ModeEntry>, RockingError> {
    if plate.boundary != Boundary::HingedRod {
        return match rocking_hz {
            Some(hz) => Err(RockingError::NotHinged {
                hz,
                plate: plate.name.clone(),
                boundary: plate.boundary.key(),
            }),
            None => Ok(None),
        };
    }
    let hz = rocking_hz.unwrap_or(DEFAULT_ROCKING_HZ);
    let first = sol.modes.first().map_or(f64::INFINITY, |m| m.freq_hz);
    // Half the first resonance keeps the elastic response small against the rigid
    // rocking (dynamic amplification of mode 1 ≤ 1/(1 − 0.5²) ≈ 1.33).
    let limit = (0.5 * first).min(MAX_ROCKING_HZ);
    if !(hz.is_finite() && (1.0..=limit).contains(&hz)) {
        return Err(RockingError::Frequency { hz, limit, first });
    }
    let mut m = modes_file::line_mode(
        "rocking (forced)",
        Some(hz),
        90.0,
        plate.hinge_x_mm - plate.size_mm[0] / 2.0,
    );
    m.field = Some("linear".into());
    Ok(Some(m))
}
