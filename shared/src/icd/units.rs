//! Units: the one conversion for each pair of units the host and the controller share.
//!
//! - [`MilliHz`]: drive frequency, Hz (`f64`) ↔ millihertz (`u32`, as on the wire). One
//!   validity check, one range (the drive's, [`DeviceLimits`]), one error ([`FrequencyError`]).
//! - [`Q15`]: drive amplitude, fraction of the DAC's full scale (`f64`, 0..=1) ↔ Q15 (`u16`,
//!   1.0 ↦ 32767), one error ([`AmplitudeError`]).
//! - [`MmPerS2`]: acceleration, m/s² (`f64`) ↔ mm/s² (`u32`, as on the wire: closed-loop
//!   targets, measurements, thresholds), one error ([`AccelError`]). Only representability is
//!   checked here; the device's limits are checked where they apply
//!   ([`DeviceLimits::check_setpoint`], the configuration's validation).
//! - [`MilliDb`]: a level ratio, dB ↔ millidecibels (`u32`, the control bands), one error
//!   ([`DbError`]); [`MilliDeg`]: a phase, millidegrees (`i32`) → degrees.
//! - Time on the drive's sample clock: samples → ms or s at a sample rate
//!   ([`ms_from_samples`], [`s_from_samples`], [`whole_ms_from_samples`]).
//! - [`Fx`] ↔ `f64` ([`Fx::from_f64`], [`Fx::to_f64`]) and binary angles ↔ degrees or radians
//!   ([`bam_from_deg`], [`deg_from_bam`], [`bam_from_rad`], [`rad_from_bam`]).
//! - [`Given`]: a number from a user's input echoed in a refusal (these errors' and the host's
//!   file and argument errors), huge and tiny ones in exponent form.
//!
//! The crate is `no_std`, so `f64::round` is not available: [`round_half_away`] is its exact
//! equivalent (tested against `std` bit for bit), and every conversion here gives the same
//! bits the host computed with `std` before this module existed.

use crate::analysis::fx::{Bam, Fx};
use crate::icd::plan::DeviceLimits;

/// 2³²: one unit of [`Fx`], and one turn of a [`Bam`].
const TWO_POW_32: f64 = 4_294_967_296.0;
/// Q15 value of full scale (amplitude 1.0).
const Q15_FULL: f64 = 32767.0;

/// `x` rounded to the nearest integer, halves away from zero, as `x.round() as i64` with `std`:
/// NaN gives 0 and values beyond `i64` saturate.
pub fn round_half_away(x: f64) -> i64 {
    let t = x as i64; // truncates toward zero (saturating; NaN → 0)
    // Exact for |x| < 2⁵³ (the fraction of a double is representable); beyond, x is an integer.
    let frac = x - t as f64;
    if frac >= 0.5 {
        t.saturating_add(1)
    } else if frac <= -0.5 {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// `x` modulo `m` in [0, m) for m > 0, as `x.rem_euclid(m)` with `std`.
fn rem_euclid(x: f64, m: f64) -> f64 {
    let r = x % m;
    if r < 0.0 { r + m.abs() } else { r }
}

// ---- Numbers echoed in refusals ----

/// `format!("{}", Given(v))`: `v` as Rust prints it (`300`, `0.5`, `NaN`, `inf`), or `1e308` /
/// `3e-9` when |v| ≥ 10⁹ or 0 < |v| < 10⁻⁶, so that a refusal of `1e300 Hz` names `1e300`, not
/// 301 digits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Given(pub f64);

impl core::fmt::Display for Given {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        let v = self.0;
        if v.is_finite() && (v.abs() >= 1e9 || (v != 0.0 && v.abs() < 1e-6)) {
            write!(f, "{v:e}")
        } else {
            write!(f, "{v}")
        }
    }
}

// ---- Frequency ----

/// A drive frequency in millihertz, as plans and the link carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MilliHz(pub u32);

/// A frequency the drive cannot produce.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FrequencyError {
    /// The frequency asked for, Hz (may be NaN or infinite).
    pub hz: f64,
    /// Lowest the drive produces, Hz.
    pub min_hz: f64,
    /// Highest the drive produces, Hz.
    pub max_hz: f64,
}

impl core::fmt::Display for FrequencyError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "frequency {} Hz is outside the drive's range {}..={} Hz",
            Given(self.hz),
            self.min_hz,
            self.max_hz
        )
    }
}

impl core::error::Error for FrequencyError {}

impl FrequencyError {
    /// `hz`, refused as outside the frequency range of `limits`.
    pub fn outside(hz: f64, limits: &DeviceLimits) -> FrequencyError {
        FrequencyError {
            hz,
            min_hz: MilliHz(limits.min_freq_mhz).to_hz(),
            max_hz: MilliHz(limits.max_freq_mhz).to_hz(),
        }
    }
}

impl MilliHz {
    /// `hz` rounded to the nearest millihertz, within the controller's range
    /// ([`DeviceLimits::DEFAULT`]).
    pub fn from_hz(hz: f64) -> Result<MilliHz, FrequencyError> {
        Self::from_hz_within(hz, &DeviceLimits::DEFAULT)
    }

    /// `hz` rounded to the nearest millihertz, within the range of `limits`.
    pub fn from_hz_within(hz: f64, limits: &DeviceLimits) -> Result<MilliHz, FrequencyError> {
        let (min, max) = (limits.min_freq_mhz, limits.max_freq_mhz);
        let mhz = round_mhz(hz);
        if !hz.is_finite() || mhz < min as i64 || mhz > max as i64 {
            return Err(FrequencyError::outside(hz, limits));
        }
        Ok(MilliHz(mhz as u32))
    }

    /// `hz` rounded to the nearest millihertz when that is representable (finite, at least
    /// 1 mHz once rounded, below `u32::MAX` mHz), no device range checked: a plan file's steps
    /// are converted with it and validated against the limits of the device that runs them.
    pub fn rounded(hz: f64) -> Option<MilliHz> {
        let mhz = hz * 1000.0;
        (mhz.is_finite() && mhz >= 0.5 && mhz < u32::MAX as f64)
            .then(|| MilliHz(round_mhz(hz) as u32))
    }

    /// The frequency in Hz.
    pub fn to_hz(self) -> f64 {
        self.0 as f64 / 1000.0
    }
}

/// The one Hz → mHz rounding: to nearest, half away from zero.
fn round_mhz(hz: f64) -> i64 {
    round_half_away(hz * 1000.0)
}

// ---- Amplitude ----

/// A drive amplitude in Q15 (32767 = the DAC's full scale), as plans and the link carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Q15(pub u16);

/// An amplitude that is not a fraction of full scale in 0..=1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AmplitudeError {
    /// The amplitude asked for (may be NaN).
    pub value: f64,
}

impl core::fmt::Display for AmplitudeError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "amplitude {} outside 0..=1 (fraction of full scale)", Given(self.value))
    }
}

impl core::error::Error for AmplitudeError {}

impl Q15 {
    /// Full scale (amplitude 1.0).
    pub const FULL: Q15 = Q15(32767);

    /// The Q15 value of a fraction of full scale, rounded to the nearest step.
    pub fn from_fraction(value: f64) -> Result<Q15, AmplitudeError> {
        if !(0.0..=1.0).contains(&value) {
            return Err(AmplitudeError { value });
        }
        Ok(Q15(round_half_away(value * Q15_FULL) as u16))
    }

    /// The amplitude as a fraction of full scale.
    pub fn to_fraction(self) -> f64 {
        self.0 as f64 / Q15_FULL
    }
}

// ---- Acceleration ----

/// `x` in thousandths, rounded to the nearest: `None` unless `x` is finite, not negative and
/// fits a u32 of thousandths (the one rule of the milli-units below).
fn milli(x: f64) -> Option<u32> {
    let m = round_half_away(x * 1000.0);
    (x.is_finite() && x >= 0.0 && (0..=u32::MAX as i64).contains(&m)).then_some(m as u32)
}

/// An acceleration amplitude in mm/s², as closed-loop levels, measurements and the control
/// thresholds carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MmPerS2(pub u32);

/// An acceleration that is not a finite, non-negative number of m/s² that fits in mm/s² (u32).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AccelError {
    /// The acceleration asked for, m/s² (may be NaN).
    pub mps2: f64,
}

impl core::fmt::Display for AccelError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "acceleration {} m/s² is not a number of m/s² in 0..={} (resolved to 1 mm/s²)",
            Given(self.mps2),
            u32::MAX / 1000
        )
    }
}

impl core::error::Error for AccelError {}

impl MmPerS2 {
    /// `mps2` m/s², rounded to the nearest mm/s².
    pub fn from_mps2(mps2: f64) -> Result<MmPerS2, AccelError> {
        milli(mps2).map(MmPerS2).ok_or(AccelError { mps2 })
    }

    /// The acceleration in m/s².
    pub fn to_mps2(self) -> f64 {
        self.0 as f64 / 1000.0
    }
}

// ---- Level ratios and phases ----

/// A level ratio in millidecibels (the half-widths of the control bands).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MilliDb(pub u32);

/// A level ratio that is not a finite, non-negative number of dB that fits in mdB (u32).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DbError {
    /// The ratio asked for, dB (may be NaN).
    pub db: f64,
}

impl core::fmt::Display for DbError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "{} dB is not a number of dB in 0..={} (resolved to 0.001 dB)",
            Given(self.db),
            u32::MAX / 1000
        )
    }
}

impl core::error::Error for DbError {}

impl MilliDb {
    /// `db` dB, rounded to the nearest millidecibel.
    pub fn from_db(db: f64) -> Result<MilliDb, DbError> {
        milli(db).map(MilliDb).ok_or(DbError { db })
    }

    /// The ratio in dB.
    pub fn to_db(self) -> f64 {
        self.0 as f64 / 1000.0
    }
}

/// A phase in millidegrees, as measurements carry it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MilliDeg(pub i32);

impl MilliDeg {
    /// The phase in degrees.
    pub fn to_deg(self) -> f64 {
        self.0 as f64 / 1000.0
    }
}

// ---- Time on the sample clock ----

/// Samples per second of the drive stream: the sample clock every plan duration and every
/// controller time is counted on (50 kS/s: TIM6 divides 80 MHz by exactly 1600).
pub const SAMPLE_RATE: u32 = 50_000;
/// Samples per millisecond (plans are written in ms; the runner counts samples).
pub const SAMPLES_PER_MS: u32 = SAMPLE_RATE / 1000;

/// `samples` of the drive's sample clock at `sample_rate` (Hz) in milliseconds (a rate of 0, a
/// status never filled in, counts as 1 Hz rather than dividing by zero).
pub fn ms_from_samples(samples: u64, sample_rate: u32) -> f64 {
    samples as f64 * 1000.0 / f64::from(sample_rate.max(1))
}

/// A duration in milliseconds (plans are written in ms) in seconds.
pub fn s_from_ms(ms: u64) -> f64 {
    ms as f64 / 1000.0
}

/// `samples` at `sample_rate` (Hz) in seconds (a rate of 0 counts as 1 Hz).
pub fn s_from_samples(samples: u64, sample_rate: u32) -> f64 {
    samples as f64 / f64::from(sample_rate.max(1))
}

/// `samples` at `sample_rate` (Hz) in whole milliseconds, rounded down, saturating at
/// `u64::MAX` (a rate of 0 counts as 1 Hz): exact integer arithmetic, for registers.
pub fn whole_ms_from_samples(samples: u64, sample_rate: u32) -> u64 {
    let ms = u128::from(samples) * 1000 / u128::from(sample_rate.max(1));
    u64::try_from(ms).unwrap_or(u64::MAX)
}

// ---- Fixed point and binary angles ----

impl Fx {
    /// The nearest [`Fx`] to `v` (halves away from zero; saturates beyond the range).
    pub fn from_f64(v: f64) -> Fx {
        Fx(round_half_away(v * TWO_POW_32))
    }

    /// The value as `f64` (exact for |raw| < 2⁵³).
    pub fn to_f64(self) -> f64 {
        self.0 as f64 / TWO_POW_32
    }
}

/// The nearest binary angle to `deg` degrees (any range; wraps, 360° ↦ 0).
pub fn bam_from_deg(deg: f64) -> Bam {
    round_half_away(rem_euclid(deg, 360.0) / 360.0 * TWO_POW_32) as u64 as u32
}

/// A binary angle in degrees, [0, 360).
pub fn deg_from_bam(a: Bam) -> f64 {
    a as f64 * 360.0 / TWO_POW_32
}

/// The nearest binary angle to `rad` radians (any range; wraps).
pub fn bam_from_rad(rad: f64) -> Bam {
    bam_from_deg(rad.to_degrees())
}

/// A binary angle in radians, [0, 2π).
pub fn rad_from_bam(a: Bam) -> f64 {
    deg_from_bam(a).to_radians()
}

#[cfg(test)]
mod tests {
    use super::*;

    extern crate std;

    /// Values around every rounding edge, the ranges' ends, and the non-finite ones.
    fn awkward() -> std::vec::Vec<f64> {
        let mut v = std::vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            2.5,
            -2.5,
            0.49999999999999994,
            -0.49999999999999994,
            4503599627370495.5,
            4503599627370497.0,
            9007199254740993.0,
            9.3e18,
            -9.3e18,
            1e300,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        // A deterministic spread over many magnitudes (xorshift of the bit pattern).
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        for _ in 0..20_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            let x = f64::from_bits(s);
            v.push(x);
            let small = (s >> 11) as f64 / (1u64 << 20) as f64 - 4096.0;
            v.push(small);
            v.push(small.trunc() + 0.5);
        }
        v
    }

    #[test]
    fn rounding_matches_std_bit_for_bit() {
        for x in awkward() {
            assert_eq!(round_half_away(x), x.round() as i64, "{x:e}");
            assert_eq!(rem_euclid(x, 360.0).to_bits(), x.rem_euclid(360.0).to_bits(), "{x:e}");
        }
    }

    #[test]
    fn conversions_match_the_host_formulas() {
        // The expressions the host wrote before this module, with std.
        for x in awkward() {
            assert_eq!(Fx::from_f64(x), Fx((x * 4_294_967_296.0).round() as i64), "{x:e}");
            let host_bam = (x.rem_euclid(360.0) / 360.0 * 4_294_967_296.0).round() as u64 as u32;
            assert_eq!(bam_from_deg(x), host_bam, "{x:e}");
            if (0.0..=1.0).contains(&x) {
                assert_eq!(Q15::from_fraction(x).unwrap().0, (x * 32767.0).round() as u16);
            }
            if let Ok(f) = MilliHz::from_hz(x) {
                assert_eq!(f.0, (x * 1000.0).round() as u32, "{x:e}");
            }
        }
        for raw in [0i64, 1, -1, i64::MAX, i64::MIN, 0x1_2345_6789] {
            assert_eq!(Fx(raw).to_f64(), raw as f64 / 4_294_967_296.0);
            assert_eq!(Fx::from_f64(Fx(raw).to_f64()), Fx(raw), "{raw}");
        }
        for a in [0u32, 1, 0x4000_0000, 0x8000_0000, u32::MAX] {
            assert_eq!(deg_from_bam(a), a as f64 * 360.0 / 4_294_967_296.0);
            assert_eq!(bam_from_deg(deg_from_bam(a)), a);
        }
        assert_eq!(bam_from_deg(360.0), 0);
        assert_eq!(bam_from_deg(-90.0), 3 << 30);
        assert_eq!(bam_from_rad(core::f64::consts::FRAC_PI_2), 1 << 30);
        assert!((rad_from_bam(1 << 31) - core::f64::consts::PI).abs() < 1e-15);
    }

    #[test]
    fn frequency_has_one_range_and_one_error() {
        assert_eq!(MilliHz::from_hz(440.125), Ok(MilliHz(440_125)));
        assert_eq!(MilliHz::from_hz(1.0), Ok(MilliHz(1_000)));
        assert_eq!(MilliHz::from_hz(2000.0), Ok(MilliHz(2_000_000)));
        assert_eq!(MilliHz(181_500).to_hz(), 181.5);
        for bad in [0.0, 0.9994, 2000.0006, -5.0, 5e6, f64::NAN, f64::INFINITY] {
            let e = MilliHz::from_hz(bad).unwrap_err();
            assert_eq!((e.min_hz, e.max_hz), (1.0, 2000.0));
            assert!(e.hz.to_bits() == bad.to_bits());
        }
        let e = MilliHz::from_hz(5e6).unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "frequency 5000000 Hz is outside the drive's range 1..=2000 Hz"
        );
        let narrow =
            DeviceLimits { min_freq_mhz: 50_000, max_freq_mhz: 60_000, ..Default::default() };
        assert_eq!(MilliHz::from_hz_within(55.0, &narrow), Ok(MilliHz(55_000)));
        assert_eq!(MilliHz::from_hz_within(61.0, &narrow).unwrap_err().max_hz, 60.0);
    }

    #[test]
    fn representable_frequencies_round_once_and_the_rest_are_none() {
        assert_eq!(MilliHz::rounded(60.0004), Some(MilliHz(60_000)));
        assert_eq!(MilliHz::rounded(0.0006), Some(MilliHz(1)));
        assert_eq!(MilliHz::rounded(5000.0), Some(MilliHz(5_000_000)), "no device range here");
        for bad in [0.0004, 0.0, -1.0, 4.3e6, f64::NAN, f64::INFINITY] {
            assert_eq!(MilliHz::rounded(bad), None, "{bad}");
        }
    }

    #[test]
    fn sample_clock_time_converts_once() {
        assert_eq!(ms_from_samples(48_000, 48_000), 1000.0);
        assert_eq!(ms_from_samples(24, 48_000), 0.5);
        assert_eq!(s_from_samples(120_000, 48_000), 2.5);
        assert_eq!(ms_from_samples(5, 0), 5000.0, "a rate of 0 counts as 1 Hz");
        assert_eq!(whole_ms_from_samples(47, 48_000), 0, "rounded down");
        assert_eq!(whole_ms_from_samples(96_047, 48_000), 2000);
        assert_eq!(whole_ms_from_samples(u64::MAX, 1), u64::MAX, "saturates");
    }

    #[test]
    fn amplitude_is_a_checked_fraction() {
        assert_eq!(Q15::from_fraction(1.0), Ok(Q15::FULL));
        assert_eq!(Q15::from_fraction(0.5), Ok(Q15(16384)));
        assert_eq!(Q15::from_fraction(0.0), Ok(Q15(0)));
        assert_eq!(Q15(32767).to_fraction(), 1.0);
        for bad in [-0.01, 1.0001, f64::NAN, f64::INFINITY] {
            assert!(Q15::from_fraction(bad).is_err(), "{bad}");
        }
        assert_eq!(
            std::format!("{}", Q15::from_fraction(1.5).unwrap_err()),
            "amplitude 1.5 outside 0..=1 (fraction of full scale)"
        );
    }

    #[test]
    fn acceleration_db_and_phase_convert_once() {
        assert_eq!(MmPerS2::from_mps2(12.3456), Ok(MmPerS2(12_346)));
        assert_eq!(MmPerS2::from_mps2(0.0), Ok(MmPerS2(0)));
        assert_eq!(MmPerS2(150_000).to_mps2(), 150.0);
        for bad in [-0.001, -1.0, 5e6, f64::NAN, f64::INFINITY] {
            assert!(MmPerS2::from_mps2(bad).is_err(), "{bad}");
        }
        assert_eq!(
            std::format!("{}", MmPerS2::from_mps2(-2.0).unwrap_err()),
            "acceleration -2 m/s² is not a number of m/s² in 0..=4294967 (resolved to 1 mm/s²)"
        );
        assert_eq!(MilliDb::from_db(1.5), Ok(MilliDb(1_500)));
        assert_eq!(MilliDb(3_000).to_db(), 3.0);
        assert!(MilliDb::from_db(-1.0).is_err() && MilliDb::from_db(f64::NAN).is_err());
        assert_eq!(MilliDeg(-90_500).to_deg(), -90.5);
    }

    #[test]
    fn given_numbers_are_echoed_as_given_and_extreme_ones_in_exponent_form() {
        use std::string::ToString;
        let shown = |v: f64| Given(v).to_string();
        assert_eq!(shown(300.0), "300");
        assert_eq!(shown(-2.5), "-2.5");
        assert_eq!(shown(0.0), "0");
        assert_eq!(shown(999_999_999.0), "999999999");
        assert_eq!(shown(1e308), "1e308");
        assert_eq!(shown(-1.5e300), "-1.5e300");
        assert_eq!(shown(3e-9), "3e-9");
        assert_eq!(shown(f64::NAN), "NaN");
        assert_eq!(shown(f64::NEG_INFINITY), "-inf");
        let e = MilliHz::from_hz(1e300).unwrap_err().to_string();
        assert_eq!(e, "frequency 1e300 Hz is outside the drive's range 1..=2000 Hz");
    }
}
