//! The field law of a straight or hyperbolic node: one type for plate files, the planner, the
//! simulator, the f64 reference analysis and the CLI's `--field` (docs/plan.md, "Plate model
//! file"; docs/analyze.md).

use chladni_shared::analysis::field::FieldKind;
use chladni_shared::analysis::fx::Fx;

/// The linear field's length scale: its pull equals the gain this far from the node.
pub const LINEAR_SCALE_MM: f64 = 10.0;

/// Longest sine wavelength accepted (mm).
pub const MAX_WAVELENGTH_MM: f64 = 1e7;

/// Field law of a line or hyperbola node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Law {
    /// f = −k·sign(d) (paper eq. 5).
    Sign,
    /// f = −k·d / [`LINEAR_SCALE_MM`] (paper §5.2).
    Linear,
    /// f = −k·sin(π d / w).
    Sine {
        /// Node-to-antinode distance (mm).
        wavelength_mm: f64,
    },
}

#[cfg(test)]
/// The law names as written in files and on the command line.
pub(crate) const LAW_NAMES: [&str; 3] = ["sign", "linear", "sine"];

impl Law {
    /// Name as written in files and on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Law::Sign => "sign",
            Law::Linear => "linear",
            Law::Sine { .. } => "sine",
        }
    }

    /// The law named `name`; `wavelength_mm` is the sine law's wavelength (`None` for the
    /// others). `Err` names what is wrong, as [`LawError`].
    pub fn from_name(name: &str, wavelength_mm: Option<f64>) -> Result<Law, LawError> {
        match (name, wavelength_mm) {
            ("sine", None) => Err(LawError::NeedsWavelength),
            ("sine", Some(w)) if w.is_finite() && w > 0.0 && w <= MAX_WAVELENGTH_MM => {
                Ok(Law::Sine { wavelength_mm: w })
            }
            ("sine", Some(w)) => Err(LawError::Wavelength(w)),
            ("sign" | "linear", Some(w)) => Err(LawError::WavelengthNotSine(w)),
            ("sign", None) => Ok(Law::Sign),
            ("linear", None) => Ok(Law::Linear),
            (other, _) => Err(LawError::Unknown(other.to_string())),
        }
    }

    /// The same law with the wavelength `wavelength_mm` (checked; see [`Law::from_name`]).
    pub fn with_wavelength(self, wavelength_mm: Option<f64>) -> Result<Law, LawError> {
        Law::from_name(self.name(), wavelength_mm)
    }

    /// g(d), the field's shape (force per unit gain, towards the node for d > 0 along −∇d).
    pub fn g(&self, d: f64) -> f64 {
        match *self {
            Law::Sign => d.signum(),
            Law::Linear => d / LINEAR_SCALE_MM,
            Law::Sine { wavelength_mm } => (std::f64::consts::PI * d / wavelength_mm).sin(),
        }
    }

    /// G(d) = ∫₀ᵈ g (the potential per unit gain).
    pub(crate) fn big_g(&self, d: f64) -> f64 {
        match *self {
            Law::Sign => d.abs(),
            Law::Linear => 0.5 * d * d / LINEAR_SCALE_MM,
            Law::Sine { wavelength_mm: w } => {
                let k = std::f64::consts::PI / w;
                (1.0 - (k * d).cos()) / k
            }
        }
    }

    /// The fixed-point law of `chladni_shared::analysis::field` (same shape; the shared linear law has
    /// no length scale, which changes no rest orientation).
    pub fn to_fixed(&self) -> FieldKind {
        match *self {
            Law::Sign => FieldKind::Sign,
            Law::Linear => FieldKind::Linear,
            Law::Sine { wavelength_mm } => {
                FieldKind::Sine { wavelength: Fx::from_f64(wavelength_mm) }
            }
        }
    }
}

/// Why a field law cannot be built.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LawError {
    /// Not one of `LAW_NAMES`.
    #[error("\"{0}\": must be \"sign\", \"linear\" or \"sine\"")]
    Unknown(String),
    /// Sine without a wavelength.
    #[error("the sine law needs a wavelength (node-to-antinode distance, mm)")]
    NeedsWavelength,
    /// A wavelength outside (0, [`MAX_WAVELENGTH_MM`]].
    #[error("wavelength {0} mm: must be in (0, 1e7] mm")]
    Wavelength(f64),
    /// A wavelength given to a law that has none.
    #[error("wavelength {0} mm only applies to the sine law")]
    WavelengthNotSine(f64),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_wavelength_is_checked() {
        for name in LAW_NAMES {
            let w = (name == "sine").then_some(80.0);
            assert_eq!(Law::from_name(name, w).unwrap().name(), name);
        }
        assert_eq!(Law::from_name("sine", None), Err(LawError::NeedsWavelength));
        assert_eq!(Law::from_name("sine", Some(-1.0)), Err(LawError::Wavelength(-1.0)));
        assert_eq!(Law::from_name("sign", Some(3.0)), Err(LawError::WavelengthNotSine(3.0)));
        assert_eq!(Law::from_name("cosine", None), Err(LawError::Unknown("cosine".into())));
        assert_eq!(Law::Linear.to_fixed(), FieldKind::Linear);
    }
}
