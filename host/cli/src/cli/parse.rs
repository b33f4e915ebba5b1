//! Value parsers for the options: each refuses a value outside its range with a message that
//! names the option and the value; clap then exits with code 2 (bad input).

use chladni_core::model::field::Law;
use chladni_shared::icd::units::{MilliHz, MmPerS2, Q15};
use clap::builder::PossibleValue;

/// A value parser for an `f64` option `--NAME` accepted when `ok`; refused with
/// "--NAME must be WHAT, got VALUE".
pub fn f64_where(
    name: &'static str,
    what: &'static str,
    ok: fn(f64) -> bool,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    move |s: &str| {
        let v: f64 = s.trim().parse().map_err(|_| format!("--{name} must be a number, got {s}"))?;
        if ok(v) { Ok(v) } else { Err(format!("--{name} must be {what}, got {v}")) }
    }
}

/// `--NAME` in [0, 1].
pub fn unit_interval(
    name: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    f64_where(name, "in [0, 1]", |v| (0.0..=1.0).contains(&v))
}

/// `--NAME` finite and above 0.
pub fn positive(
    name: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    f64_where(name, "positive", |v| v.is_finite() && v > 0.0)
}

/// `--NAME` any finite number.
pub fn finite(
    name: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    f64_where(name, "a finite number", f64::is_finite)
}

/// `--NAME` finite and at least 0.
pub fn non_negative(
    name: &'static str,
) -> impl Fn(&str) -> Result<f64, String> + Clone + Send + Sync + 'static {
    f64_where(name, "finite and at least 0", |v| v.is_finite() && v >= 0.0)
}

/// `--NAME`: a whole number in LO..=HI.
pub fn usize_in(
    name: &'static str,
    lo: usize,
    hi: usize,
) -> impl Fn(&str) -> Result<usize, String> + Clone + Send + Sync + 'static {
    move |s: &str| match s.trim().parse::<usize>() {
        Ok(v) if (lo..=hi).contains(&v) => Ok(v),
        _ => Err(format!("--{name} must be in {lo}..={hi}, got {s}")),
    }
}

/// `--freq` of the manual drive, Hz → mHz (the one conversion, with its check).
pub fn drive_freq(s: &str) -> Result<u32, String> {
    let v: f64 = s.trim().parse().map_err(|_| format!("--freq must be a number in Hz, got {s}"))?;
    MilliHz::from_hz(v).map(|f| f.0).map_err(|e| e.to_string())
}

/// `--amplitude` of the manual drive, fraction of full scale → Q15.
pub fn drive_amplitude(s: &str) -> Result<u16, String> {
    let v: f64 =
        s.trim().parse().map_err(|_| format!("--amplitude must be a number in 0..=1, got {s}"))?;
    Q15::from_fraction(v).map(|a| a.0).map_err(|e| e.to_string())
}

/// `--accel` of the manual drive, m/s² → mm/s² (the device's limit is checked with the
/// setpoint).
pub fn drive_accel(s: &str) -> Result<u32, String> {
    let v: f64 =
        s.trim().parse().map_err(|_| format!("--accel must be a number in m/s², got {s}"))?;
    MmPerS2::from_mps2(v).map(|a| a.0).map_err(|e| format!("--accel: {e}"))
}

/// `--field sign|linear|sine`: the model's field law as a clap value (the model knows no clap).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldArg(pub Law);

impl std::ops::Deref for FieldArg {
    type Target = Law;
    fn deref(&self) -> &Law {
        &self.0
    }
}

/// The sine variant carries a placeholder wavelength (NaN) until [`Law::with_wavelength`] gives
/// it the real one.
impl clap::ValueEnum for FieldArg {
    fn value_variants<'a>() -> &'a [Self] {
        &[
            FieldArg(Law::Sign),
            FieldArg(Law::Linear),
            FieldArg(Law::Sine { wavelength_mm: f64::NAN }),
        ]
    }

    fn to_possible_value(&self) -> Option<PossibleValue> {
        let help = match self.0 {
            Law::Sign => "Constant force towards the node (paper eq. 5)",
            Law::Linear => "Force proportional to the distance from the node (paper §5.2)",
            Law::Sine { .. } => "sin(π d / w): needs --wavelength",
        };
        Some(PossibleValue::new(self.0.name()).help(help))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_name_the_option_and_the_value() {
        assert_eq!(unit_interval("e")("1.5").unwrap_err(), "--e must be in [0, 1], got 1.5");
        assert_eq!(unit_interval("e")("0.25"), Ok(0.25));
        assert_eq!(positive("tol-deg")("0").unwrap_err(), "--tol-deg must be positive, got 0");
        assert_eq!(positive("tol-deg")("x").unwrap_err(), "--tol-deg must be a number, got x");
        assert_eq!(non_negative("mu")("0"), Ok(0.0));
        assert!(non_negative("mu")("NaN").is_err());
        assert_eq!(usize_in("grid", 3, 401)("2").unwrap_err(), "--grid must be in 3..=401, got 2");
        assert_eq!(usize_in("grid", 3, 401)("41"), Ok(41));
        assert_eq!(drive_freq("440.125"), Ok(440_125));
        assert!(drive_freq("0").unwrap_err().contains("frequency 0 Hz"));
        assert_eq!(drive_amplitude("1"), Ok(32767));
        assert!(drive_amplitude("1.5").unwrap_err().contains("amplitude 1.5"));
        assert_eq!(drive_accel("12.5"), Ok(12_500));
        assert!(drive_accel("-1").unwrap_err().starts_with("--accel: acceleration -1 m/s²"));
        assert!(drive_accel("fast").unwrap_err().contains("number in m/s²"));
    }
}
