//! What the controller drove between two status polls, on its own sample clock: the rig's time
//! base, so the parts follow drive time exactly however fast QEMU runs.
//!
//! The status says what is output at the poll (`freq_mhz`, `amplitude_q15`; frequency 0 when
//! silent), the sample clock (`clock`) and the samples output since the current plan or manual
//! drive started (`elapsed_samples`: it stops while idle and restarts at 0 when a plan starts or
//! a manual drive starts from anything but a manual drive). So between two polls:
//!
//! - with the same drive going on (or stopped since: a stop keeps the count), the drive was on
//!   for exactly the growth of `elapsed_samples`: at the one frequency both polls show (the
//!   amplitude as the root mean square of the two polls': speed goes with its square), or, if
//!   the frequency changed (a plan's next step, a new manual frequency), half at each;
//! - when a new drive started (the run number changed and the count restarted), it ran for its
//!   `elapsed_samples`, and the drive before it (if any) for the rest of the interval.

use chladni_shared::icd::link::{DriveState, StatusReport};
use chladni_shared::icd::units::Q15;

/// A stretch of drive between two polls.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// Frequency output (mHz).
    pub freq_mhz: u32,
    /// Amplitude output, fraction of full scale.
    pub amplitude: f64,
    /// How long (s of the controller's sample clock).
    pub seconds: f64,
}

/// Is the status's drive running a manual setpoint (not a plan, not stopping)?
fn manual(s: &StatusReport) -> bool {
    s.step.is_none()
        && matches!(s.state, DriveState::RampUp | DriveState::Running | DriveState::RampDown)
}

/// Does the status show output (a frequency and an amplitude)?
fn sounding(s: &StatusReport) -> bool {
    s.freq_mhz != 0 && s.amplitude_q15 > 0
}

/// The amplitude a status shows (fraction of full scale).
fn amplitude(s: &StatusReport) -> f64 {
    Q15(s.amplitude_q15).to_fraction()
}

/// Did the drive's count restart between the polls (a new plan, or a manual drive started from
/// idle, a stop or a plan)?
fn restarted(before: &StatusReport, after: &StatusReport) -> bool {
    let started =
        matches!(after.state, DriveState::RampUp | DriveState::Running | DriveState::RampDown);
    after.elapsed_samples < before.elapsed_samples
        || (after.run != before.run && started && !(manual(before) && manual(after)))
}

/// What was driven between `before` and `after` (in that order); empty when nothing was, or
/// when the clock went back (the controller restarted: nothing is known of the gap).
pub fn stretches(before: &StatusReport, after: &StatusReport) -> Vec<Stretch> {
    let rate = f64::from(after.sample_rate);
    if after.clock <= before.clock
        || after.sample_rate == 0
        || before.sample_rate != after.sample_rate
    {
        return Vec::new();
    }
    let span = after.clock - before.clock;
    let at = |s: &StatusReport, a: f64, samples: u64| Stretch {
        freq_mhz: s.freq_mhz,
        amplitude: a,
        seconds: samples as f64 / rate,
    };
    let mut out = Vec::with_capacity(2);
    if restarted(before, after) {
        let new = after.elapsed_samples.min(span);
        if sounding(before) && new < span {
            out.push(at(before, amplitude(before), span - new));
        }
        if sounding(after) && new > 0 {
            out.push(at(after, amplitude(after), new));
        }
        return out;
    }
    let on = after.elapsed_samples.saturating_sub(before.elapsed_samples).min(span);
    if on == 0 {
        return out;
    }
    match (sounding(before), sounding(after)) {
        (true, true) if before.freq_mhz == after.freq_mhz => {
            let rms = (0.5 * (amplitude(before).powi(2) + amplitude(after).powi(2))).sqrt();
            out.push(at(after, rms, on));
        }
        (true, true) => {
            out.push(at(before, amplitude(before), on / 2));
            out.push(at(after, amplitude(after), on - on / 2));
        }
        (true, false) => out.push(at(before, amplitude(before), on)),
        (false, true) => out.push(at(after, amplitude(after), on)),
        (false, false) => {}
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_shared::icd::link::RunNumber;

    /// A status at `clock` (samples at 50 kHz).
    fn at(
        clock: u64,
        state: DriveState,
        run: u32,
        elapsed: u64,
        freq_mhz: u32,
        amp: u16,
    ) -> StatusReport {
        StatusReport {
            state,
            run: RunNumber(run),
            clock,
            elapsed_samples: elapsed,
            sample_rate: 50_000,
            freq_mhz,
            amplitude_q15: amp,
            ..StatusReport::IDLE
        }
    }

    const FULL: u16 = 32767;

    #[test]
    fn a_manual_drive_counts_from_its_start_to_its_stop_at_its_frequency() {
        use DriveState::*;
        let idle = at(100_000, Idle, 0, 0, 0, 0);
        // Started 400 samples before the poll.
        let a = at(101_000, Running, 1, 400, 60_000, FULL);
        assert_eq!(
            stretches(&idle, &a),
            [Stretch { freq_mhz: 60_000, amplitude: 1.0, seconds: 0.008 }]
        );
        let b = at(102_000, Running, 1, 1400, 60_000, FULL);
        assert_eq!(
            stretches(&a, &b),
            [Stretch { freq_mhz: 60_000, amplitude: 1.0, seconds: 0.02 }]
        );
        // Stopped (run 2) and idle: the count stopped at 1900 samples.
        let c = at(103_000, Idle, 2, 1900, 0, 0);
        assert_eq!(
            stretches(&b, &c),
            [Stretch { freq_mhz: 60_000, amplitude: 1.0, seconds: 0.01 }]
        );
        // Idle since: nothing.
        let d = at(104_000, Idle, 2, 1900, 0, 0);
        assert!(stretches(&c, &d).is_empty());
        // Stopping, ramping down: the root mean square of the two amplitudes.
        let e = at(102_500, Stopping, 2, 1900, 60_000, FULL / 2);
        let s = stretches(&b, &e);
        assert_eq!(s.len(), 1);
        assert!((s[0].amplitude - (0.5 * (1.0 + 0.25f64)).sqrt()).abs() < 1e-4, "{s:?}");
    }

    #[test]
    fn a_new_drive_takes_its_count_and_the_old_one_the_rest_of_the_interval() {
        use DriveState::*;
        // A plan (step 0) replaced by a manual drive 300 samples before the poll.
        let plan = at(0, Running, 1, 5000, 100_000, FULL / 2);
        let plan = StatusReport { step: Some(0), ..plan };
        let manual = at(1000, Running, 2, 300, 60_000, FULL);
        let s = stretches(&plan, &manual);
        assert_eq!(s.len(), 2);
        assert_eq!((s[0].freq_mhz, s[0].seconds), (100_000, 700.0 / 50_000.0));
        assert_eq!((s[1].freq_mhz, s[1].seconds), (60_000, 300.0 / 50_000.0));
        // A manual drive at a new frequency keeps the count: half at each.
        let m1 = at(0, Running, 1, 5000, 60_000, FULL);
        let m2 = at(1000, Running, 2, 6000, 70_000, FULL);
        let s = stretches(&m1, &m2);
        assert_eq!(
            s.iter().map(|s| (s.freq_mhz, s.seconds)).collect::<Vec<_>>(),
            [(60_000, 0.01), (70_000, 0.01)]
        );
    }

    #[test]
    fn a_clock_that_goes_back_or_stands_still_drives_nothing() {
        use DriveState::*;
        let a = at(5000, Running, 1, 5000, 60_000, FULL);
        let restarted = at(100, Idle, 0, 0, 0, 0);
        assert!(stretches(&a, &restarted).is_empty());
        assert!(stretches(&a, &a).is_empty());
    }
}
