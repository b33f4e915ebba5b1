//! The PWM drive option's arithmetic: DDS sample codes to timer compare values, the carrier
//! plan, and the reconstruction filter the PWM pin needs before the shaker amplifier.
//!
//! The board can play the drive stream ([`super::dds`], 12-bit codes at [`SAMPLE_RATE`])
//! through a timer PWM instead of the DAC: one DMA write of the compare register per sample,
//! the duty = code / 4096 of the period. Everything here is plain integer or `f64` arithmetic,
//! so it is tested on the host and the firmware only moves the results into registers.
//!
//! - **Carrier** ([`carrier_plan`], [`PLAN`]): carrier = [`SAMPLE_RATE`] × periods per sample,
//!   and the timer period (ARR + 1) = timer clock / carrier, exactly (the DDS assumes exactly
//!   50 kS/s). The carrier must be at least [`MIN_CARRIER_RATIO`] × the highest drive frequency
//!   of the device limits (2 kHz → 40 kHz), so that one first- to third-order filter can keep
//!   the drive band and remove the carrier. [`PLAN`] is checked when the crate compiles.
//! - **Resolution**: at 80 MHz and one PWM period per sample, ARR = 1599: 1601 duty values
//!   (0..=1600), log2(1600) ≈ 10.6 bits against the DAC's 12. One duty step is 2.56 DAC codes;
//!   the quantisation noise of a full-scale sine is ≈ 65.8 dB below it instead of ≈ 74 dB.
//!   A higher carrier (2, 3 … periods per sample, duty repeated) buys filter margin with
//!   resolution (ARR = 799 at 100 kHz: 9.6 bits), so the plan keeps one period per sample:
//!   the 25× ratio already meets the 20× rule.
//! - **Duty** ([`duty_of_code`]): symmetric about mid-scale, code 2048 → exactly half the
//!   period, each half rounded half away from zero, so a sine stays odd-symmetric (no added
//!   offset or even harmonics from the mapping).
//! - **Filter** ([`RcFilter`], [`FilterReport`]): `n` equal RC sections (buffered, so they do
//!   not load each other). One RC section cannot do the job: keeping the 2 kHz drive within
//!   1 dB leaves the 50 kHz carrier only ≈ 20 dB down. [`RECOMMENDED_FILTER`], three sections
//!   of 2.2 kΩ / 10 nF (corner 7.23 kHz), keeps the top drive frequency within 0.96 dB and
//!   46° of lag and puts the worst-case carrier ripple 48 dB below full scale.

use crate::drive::dds::{DAC_MAX, DAC_MID};
use crate::icd::plan::DeviceLimits;
use crate::icd::units::SAMPLE_RATE;

/// Timer kernel clock of the board's PWM timer (TIM3 on APB1, SYSCLK 80 MHz, APB1 ÷ 1).
pub const TIMER_CLOCK_HZ: u32 = 80_000_000;
/// Smallest carrier / top drive frequency ratio the plan accepts.
pub const MIN_CARRIER_RATIO: u32 = 20;
/// Number of 12-bit codes: the duty of a code is `code / CODE_SPAN` of the period.
pub const CODE_SPAN: u32 = DAC_MAX as u32 + 1;

/// How the timer makes the carrier: clock, ARR and how many periods play each sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CarrierPlan {
    /// Timer kernel clock, Hz.
    pub timer_clock_hz: u32,
    /// Auto-reload value: the period is `arr + 1` timer clocks.
    pub arr: u16,
    /// PWM periods per drive sample (the duty is repeated that many times).
    pub periods_per_sample: u16,
}

impl CarrierPlan {
    /// The PWM period in timer clocks (ARR + 1); also the compare value of 100 % duty.
    pub const fn period(&self) -> u16 {
        self.arr + 1
    }

    /// The carrier frequency, Hz.
    pub const fn carrier_hz(&self) -> u32 {
        self.timer_clock_hz / self.period() as u32
    }

    /// The compare value of mid-scale (half duty, zero signal after the filter).
    pub const fn mid(&self) -> u16 {
        self.period() / 2
    }

    /// Effective resolution in bits: log2 of the number of duty steps.
    pub fn resolution_bits(&self) -> f64 {
        libm::log2(f64::from(self.period()))
    }

    /// Signal-to-quantisation-noise ratio of a full-scale sine, dB (6.02·bits + 1.76).
    pub fn full_scale_sqnr_db(&self) -> f64 {
        6.02 * self.resolution_bits() + 1.76
    }
}

/// Why a carrier plan is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CarrierError {
    /// A zero sample rate, timer clock or periods per sample.
    Zero,
    /// The timer clock is not a whole multiple of the carrier, so the sample rate would drift.
    NotDivisible {
        /// The carrier asked for, Hz.
        carrier_hz: u32,
    },
    /// The period (ARR + 1) must be even (an exact mid-scale duty) and within 2..=65534 (a
    /// 16-bit compare register that can also hold 100 %).
    BadPeriod {
        /// Timer clocks per carrier period.
        period: u32,
    },
    /// The carrier is below [`MIN_CARRIER_RATIO`] × the highest drive frequency.
    CarrierTooLow {
        /// The carrier, Hz.
        carrier_hz: u32,
        /// The lowest carrier allowed, Hz.
        min_hz: u32,
    },
}

/// Plans the carrier: `periods_per_sample` PWM periods per sample at `sample_rate`, for drive
/// frequencies up to `max_drive_mhz`. Every constraint is checked; see [`CarrierError`].
pub const fn carrier_plan(
    timer_clock_hz: u32,
    sample_rate: u32,
    periods_per_sample: u16,
    max_drive_mhz: u32,
) -> Result<CarrierPlan, CarrierError> {
    if timer_clock_hz == 0 || sample_rate == 0 || periods_per_sample == 0 {
        return Err(CarrierError::Zero);
    }
    let carrier = sample_rate as u64 * periods_per_sample as u64;
    if carrier > timer_clock_hz as u64 {
        return Err(CarrierError::BadPeriod { period: 0 });
    }
    let carrier_hz = carrier as u32;
    if !(timer_clock_hz as u64).is_multiple_of(carrier) {
        return Err(CarrierError::NotDivisible { carrier_hz });
    }
    let period = timer_clock_hz / carrier_hz;
    if period < 2 || period > 65_534 || !period.is_multiple_of(2) {
        return Err(CarrierError::BadPeriod { period });
    }
    // Compared in mHz: carrier·1000 ≥ ratio·max_drive_mhz.
    let min_mhz = MIN_CARRIER_RATIO as u64 * max_drive_mhz as u64;
    if (carrier_hz as u64) * 1000 < min_mhz {
        return Err(CarrierError::CarrierTooLow {
            carrier_hz,
            min_hz: min_mhz.div_ceil(1000) as u32,
        });
    }
    Ok(CarrierPlan { timer_clock_hz, arr: (period - 1) as u16, periods_per_sample })
}

/// The board's carrier: one PWM period per sample, 50 kHz at 80 MHz (ARR = 1599), for the
/// default device limits (2 kHz). A change that breaks a constraint fails to compile.
pub const PLAN: CarrierPlan =
    match carrier_plan(TIMER_CLOCK_HZ, SAMPLE_RATE, 1, DeviceLimits::DEFAULT.max_freq_mhz) {
        Ok(plan) => plan,
        Err(_) => panic!("the PWM carrier plan breaks its constraints (see CarrierError)"),
    };

/// The compare value (duty in timer clocks) of a 12-bit sample code: `code / 4096` of the
/// period, symmetric about [`DAC_MID`] → `plan.mid()`. Codes above [`DAC_MAX`] count as
/// [`DAC_MAX`].
#[inline(always)]
pub const fn duty_of_code(code: u16, plan: &CarrierPlan) -> u16 {
    let code = if code > DAC_MAX { DAC_MAX } else { code };
    let period = plan.period() as u32;
    let mid = plan.mid();
    // Magnitude from mid-scale, rounded half up: the same on both sides, so odd symmetry holds.
    if code >= DAC_MID {
        let k = (code - DAC_MID) as u32;
        let step = ((k * period + CODE_SPAN / 2) / CODE_SPAN) as u16;
        mid + step
    } else {
        let k = (DAC_MID - code) as u32;
        let step = ((k * period + CODE_SPAN / 2) / CODE_SPAN) as u16;
        mid - step
    }
}

/// `codes` and `duties` of different lengths in [`duties_of_block`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LengthMismatch;

/// Converts a block of sample codes into compare values, one for one.
pub fn duties_of_block(
    codes: &[u16],
    duties: &mut [u16],
    plan: &CarrierPlan,
) -> Result<(), LengthMismatch> {
    if codes.len() != duties.len() {
        return Err(LengthMismatch);
    }
    for (d, &c) in duties.iter_mut().zip(codes) {
        *d = duty_of_code(c, plan);
    }
    Ok(())
}

/// A reconstruction filter of `sections` equal RC sections, each buffered (or impedance-scaled
/// by ≥ 10× per section), so the response is that of one section raised to the `sections`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RcFilter {
    /// Series resistor of each section, ohms.
    pub r_ohm: f64,
    /// Shunt capacitor of each section, farads.
    pub c_farad: f64,
    /// Number of sections (filter order).
    pub sections: u8,
}

/// The recommended filter: three sections of 2.2 kΩ / 10 nF (corner 7.23 kHz), see
/// docs/pwm.md for the schematic and the numbers.
pub const RECOMMENDED_FILTER: RcFilter = RcFilter { r_ohm: 2_200.0, c_farad: 10e-9, sections: 3 };

impl RcFilter {
    /// The −3 dB corner of one section, 1 / (2π·R·C), Hz.
    pub fn corner_hz(&self) -> f64 {
        1.0 / (2.0 * core::f64::consts::PI * self.r_ohm * self.c_farad)
    }

    /// Gain magnitude at `f_hz`: (1 + (f/fc)²)^(−n/2).
    pub fn gain_at(&self, f_hz: f64) -> f64 {
        let x = f_hz / self.corner_hz();
        libm::pow(1.0 + x * x, -f64::from(self.sections) / 2.0)
    }

    /// Attenuation at `f_hz`, dB (positive: the signal is that much smaller).
    pub fn attenuation_db_at(&self, f_hz: f64) -> f64 {
        -20.0 * libm::log10(self.gain_at(f_hz))
    }

    /// Phase at `f_hz`, degrees (negative: lag), −n·atan(f/fc).
    pub fn phase_deg_at(&self, f_hz: f64) -> f64 {
        -f64::from(self.sections) * libm::atan(f_hz / self.corner_hz()).to_degrees()
    }
}

/// What a filter does to a PWM drive: the numbers docs/pwm.md quotes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FilterReport {
    /// Corner of one section, Hz.
    pub corner_hz: f64,
    /// Attenuation of the carrier's fundamental, dB.
    pub carrier_attenuation_db: f64,
    /// Worst-case (50 % duty) carrier ripple after the filter, peak, as a fraction of the
    /// full-scale sine amplitude (half the supply).
    pub ripple_of_full_scale: f64,
    /// Gain error at the top drive frequency, dB (negative: smaller).
    pub top_gain_db: f64,
    /// Phase at the top drive frequency, degrees (negative: lag).
    pub top_phase_deg: f64,
}

/// Evaluates `filter` for a PWM carrier `plan` and drive frequencies up to `max_drive_mhz`.
///
/// Ripple: a 0/V square wave of duty d has a fundamental of peak (2V/π)·sin(πd) at the
/// carrier, largest at d = ½: 2V/π, i.e. 4/π of the full-scale sine amplitude V/2. The higher
/// harmonics are attenuated more and are not counted.
pub fn filter_report(filter: &RcFilter, plan: &CarrierPlan, max_drive_mhz: u32) -> FilterReport {
    let carrier = f64::from(plan.carrier_hz());
    let top = f64::from(max_drive_mhz) / 1000.0;
    FilterReport {
        corner_hz: filter.corner_hz(),
        carrier_attenuation_db: filter.attenuation_db_at(carrier),
        ripple_of_full_scale: 4.0 / core::f64::consts::PI * filter.gain_at(carrier),
        top_gain_db: -filter.attenuation_db_at(top),
        top_phase_deg: filter.phase_deg_at(top),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::drive::dds::{Dds, gain_of_q15, tuning_word};
    use crate::drive::runner::BLOCK_LEN;

    const TOP_MHZ: u32 = DeviceLimits::DEFAULT.max_freq_mhz;

    #[test]
    fn the_board_plan_is_50_khz_with_1600_steps() {
        assert_eq!(PLAN.arr, 1599);
        assert_eq!(PLAN.carrier_hz(), SAMPLE_RATE);
        assert_eq!(u32::from(PLAN.period()) * SAMPLE_RATE, TIMER_CLOCK_HZ);
        assert!((PLAN.resolution_bits() - 10.644).abs() < 1e-3);
        assert!(PLAN.full_scale_sqnr_db() < 6.02 * 12.0 + 1.76 - 8.0);
    }

    #[test]
    fn the_duty_has_exact_endpoints_and_midpoint() {
        for plan in [PLAN, carrier_plan(TIMER_CLOCK_HZ, SAMPLE_RATE, 2, TOP_MHZ).unwrap()] {
            assert_eq!(duty_of_code(0, &plan), 0);
            assert_eq!(duty_of_code(DAC_MID, &plan), plan.period() / 2);
            assert_eq!(duty_of_code(DAC_MAX, &plan), plan.period());
            // Out-of-range codes saturate instead of overflowing the period.
            assert_eq!(duty_of_code(u16::MAX, &plan), plan.period());
            // The DDS's full-scale swing (1..=4095) reaches both rails.
            assert_eq!(duty_of_code(1, &plan), 0);
        }
    }

    #[test]
    fn the_duty_is_monotonic_odd_symmetric_and_within_half_a_step() {
        let period = f64::from(PLAN.period());
        let mut last = 0;
        for code in 0..=DAC_MAX {
            let duty = duty_of_code(code, &PLAN);
            assert!(duty >= last, "code {code}: {duty} < {last}");
            last = duty;
            let ideal = f64::from(code) * period / f64::from(CODE_SPAN);
            assert!((f64::from(duty) - ideal).abs() <= 0.5 + 1e-9, "code {code}");
            if code >= 1 {
                let mirror = i32::from(duty_of_code(2 * DAC_MID - code, &PLAN));
                let mid = i32::from(PLAN.mid());
                assert_eq!(i32::from(duty) - mid, mid - mirror, "code {code}");
            }
        }
    }

    #[test]
    fn the_carrier_constraints_are_enforced() {
        // The 20× rule: 2 kHz needs 40 kHz; 1 period per sample at 25 kS/s is 25 kHz.
        assert_eq!(
            carrier_plan(TIMER_CLOCK_HZ, 25_000, 1, TOP_MHZ),
            Err(CarrierError::CarrierTooLow { carrier_hz: 25_000, min_hz: 40_000 })
        );
        // Two periods per sample at 25 kS/s is 50 kHz again: accepted.
        assert_eq!(carrier_plan(TIMER_CLOCK_HZ, 25_000, 2, TOP_MHZ).map(|p| p.arr), Ok(1599));
        // Exactly 20×: accepted; a hair above the limit frequency: refused.
        assert!(carrier_plan(TIMER_CLOCK_HZ, 40_000, 1, TOP_MHZ).is_ok());
        assert!(carrier_plan(TIMER_CLOCK_HZ, 40_000, 1, TOP_MHZ + 1).is_err());
        // 80 MHz / 48 kHz is not whole: the sample rate would drift.
        assert_eq!(
            carrier_plan(TIMER_CLOCK_HZ, 48_000, 1, TOP_MHZ),
            Err(CarrierError::NotDivisible { carrier_hz: 48_000 })
        );
        // A period past the 16-bit register, and an odd period (no exact mid-scale).
        assert_eq!(
            carrier_plan(TIMER_CLOCK_HZ, 1_000, 1, 1_000),
            Err(CarrierError::BadPeriod { period: 80_000 })
        );
        assert_eq!(
            carrier_plan(3 * 50_000, 50_000, 1, 1_000),
            Err(CarrierError::BadPeriod { period: 3 })
        );
        assert_eq!(carrier_plan(TIMER_CLOCK_HZ, 0, 1, TOP_MHZ), Err(CarrierError::Zero));
        // More periods per sample: a higher carrier, fewer duty steps.
        let p4 = carrier_plan(TIMER_CLOCK_HZ, SAMPLE_RATE, 4, TOP_MHZ).unwrap();
        assert_eq!((p4.carrier_hz(), p4.period()), (200_000, 400));
    }

    #[test]
    fn one_rc_section_is_3_db_at_its_corner_and_20_db_per_decade() {
        let one = RcFilter { r_ohm: 1_000.0, c_farad: 100e-9, sections: 1 };
        let fc = one.corner_hz();
        assert!((fc - 1591.549).abs() < 1e-3);
        assert!((one.attenuation_db_at(fc) - 10.0 * libm::log10(2.0)).abs() < 1e-9);
        assert!((one.phase_deg_at(fc) + 45.0).abs() < 1e-9);
        // Far above the corner: +20 dB per decade.
        let slope = one.attenuation_db_at(1000.0 * fc) - one.attenuation_db_at(100.0 * fc);
        assert!((slope - 20.0).abs() < 1e-3);
        // n sections: n times the dB and the phase of one.
        let three = RcFilter { sections: 3, ..one };
        for f in [100.0, 2_000.0, 50_000.0] {
            assert!((three.attenuation_db_at(f) - 3.0 * one.attenuation_db_at(f)).abs() < 1e-9);
            assert!((three.phase_deg_at(f) - 3.0 * one.phase_deg_at(f)).abs() < 1e-9);
        }
    }

    #[test]
    fn the_recommended_filter_meets_its_targets_and_one_section_cannot() {
        let r = filter_report(&RECOMMENDED_FILTER, &PLAN, TOP_MHZ);
        assert!((r.corner_hz - 7_234.3).abs() < 0.1, "{r:?}");
        assert!(r.top_gain_db > -1.0 && r.top_gain_db < -0.5, "{r:?}");
        assert!(r.top_phase_deg < -45.0 && r.top_phase_deg > -47.0, "{r:?}");
        assert!(r.carrier_attenuation_db > 50.0, "{r:?}");
        // Worst-case ripple below 1 % of full scale (−40 dB).
        assert!(r.ripple_of_full_scale < 0.01, "{r:?}");
        // One section with the same 1 dB budget at 2 kHz: corner ≥ 3.93 kHz, ripple ≫ 1 %.
        let fc = 2_000.0 / libm::sqrt(libm::pow(10.0, 0.1) - 1.0);
        let r_ohm = 1.0 / (2.0 * core::f64::consts::PI * fc * 10e-9);
        let one = RcFilter { r_ohm, c_farad: 10e-9, sections: 1 };
        let r1 = filter_report(&one, &PLAN, TOP_MHZ);
        assert!((r1.top_gain_db + 1.0).abs() < 1e-6, "{r1:?}");
        assert!(r1.ripple_of_full_scale > 0.09, "{r1:?}");
    }

    #[test]
    fn a_dds_block_converts_bit_exactly() {
        let mut dds = Dds::new(tuning_word(1_234_567));
        let mut codes = [0u16; BLOCK_LEN];
        let mut duties = [0u16; BLOCK_LEN];
        for _ in 0..8 {
            dds.fill_steady(&mut codes, gain_of_q15(32_767));
            duties_of_block(&codes, &mut duties, &PLAN).unwrap();
            for (&c, &d) in codes.iter().zip(&duties) {
                // Reference: round half away from zero of (c − 2048)·1600/4096, in f64.
                let x = (f64::from(c) - f64::from(DAC_MID)) * 1600.0 / 4096.0;
                let reference = 800.0 + x.signum() * libm::floor(x.abs() + 0.5);
                assert_eq!(f64::from(d), reference, "code {c}");
            }
        }
        assert_eq!(duties_of_block(&codes, &mut duties[1..], &PLAN), Err(LengthMismatch));
    }
}
