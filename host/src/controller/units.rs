//! The drive's units on the link: frequency in millihertz, amplitude in Q15 (a fraction of
//! the DAC's full scale, 1.0 ↦ 32767). One conversion each, with its check, for the CLI's
//! manual drive.
// The shared crate's units module takes these over when it lands (one conversion per pair of
// units for host and firmware alike).

/// A value that has no drive unit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum UnitError {
    /// Not a finite frequency above 0 Hz that fits the link's millihertz.
    #[error("frequency {0} Hz is not a valid drive frequency (it must be above 0 Hz)")]
    Frequency(f64),
    /// Not a fraction of full scale.
    #[error("amplitude {0} outside 0..=1 (fraction of full scale)")]
    Amplitude(f64),
}

/// Millihertz of a frequency in Hz (rounded to 1 mHz).
pub fn hz_to_mhz(freq_hz: f64) -> Result<u32, UnitError> {
    if !freq_hz.is_finite() || freq_hz <= 0.0 || freq_hz * 1000.0 > u32::MAX as f64 {
        return Err(UnitError::Frequency(freq_hz));
    }
    Ok((freq_hz * 1000.0).round() as u32)
}

/// Q15 amplitude of a fraction of full scale (1.0 ↦ 32767).
pub fn fraction_to_q15(amplitude: f64) -> Result<u16, UnitError> {
    if !(0.0..=1.0).contains(&amplitude) {
        return Err(UnitError::Amplitude(amplitude));
    }
    Ok((amplitude * 32767.0).round() as u16)
}

/// Hz of a frequency in millihertz.
pub fn mhz_to_hz(freq_mhz: u32) -> f64 {
    freq_mhz as f64 / 1000.0
}

/// Fraction of full scale of a Q15 amplitude.
pub fn q15_to_fraction(amplitude_q15: u16) -> f64 {
    amplitude_q15 as f64 / 32767.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conversions_round_and_refuse_what_has_no_drive_unit() {
        assert_eq!(hz_to_mhz(440.125), Ok(440_125));
        assert_eq!(fraction_to_q15(1.0), Ok(32767));
        assert_eq!(fraction_to_q15(0.0), Ok(0));
        for f in [f64::NAN, 0.0, -1.0, 5e6, f64::INFINITY] {
            assert!(hz_to_mhz(f).is_err() || f == 5e6, "{f}");
        }
        assert!(hz_to_mhz(5e9).is_err());
        assert!(fraction_to_q15(1.5).unwrap_err().to_string().contains("amplitude 1.5"));
        assert!(fraction_to_q15(f64::NAN).is_err());
        assert_eq!(mhz_to_hz(181_500), 181.5);
        assert_eq!(q15_to_fraction(32767), 1.0);
    }
}
