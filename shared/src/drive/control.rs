//! The amplitude controller: a PI loop that holds the plate's acceleration at a target by
//! setting the drive effort, with feed-forward from the measured plant gain and a ramped
//! setpoint.
//!
//! # The loop, normalised
//!
//! The plant's gain Ĝ (mm/s² of response per Q15 unit of effort) differs about tenfold between
//! resonance and off it (and from rig to rig), so the loop is written in effort units: every
//! acceleration error is divided by Ĝ, measured by the loop check just before the run (and again
//! after a frequency change, from the first window at the new frequency). With Ĝ right, the
//! open loop is then the same at every frequency, and so are the gains:
//!
//! effort = r/Ĝ (feed-forward) + Kp·e + I,  I ← I + Ki·e,  e = (r − y)/Ĝ,
//!
//! with r the ramped target at the measurement's instant and y the lock-in's amplitude (e is
//! taken against a reference model of r, see [`AmplitudeController::with_lag`]). The
//! feed-forward does nearly all the work (a step settles as fast as the plant's own envelope
//! allows); the PI removes what Ĝ got wrong (the check ends before a resonant plate has fully
//! risen, the gain drifts with temperature).
//!
//! # The gains
//!
//! Updates come once per lock-in window (≥ 5 ms). A resonant plate's envelope is a first-order
//! lag of τ = 1/(ζω₀) (17.7 ms for the simulated plate) and the measurement adds about one
//! window of delay. Integral gain Ki = 0.25 per update puts the loop's crossover near
//! Ki/T ≈ 50 rad/s, below 1/τ + delay, so the loop stays well damped also at resonance, and a
//! 3 % gain error is removed to < 2 % in a handful of windows; Kp = 0.25 adds damping without
//! amplifying the lock-in's noise (one window's noise is ≈ 1 LSB). The closed-loop tests sweep
//! below, at and above resonance and report the settling (docs/control.md).
//!
//! # Anti-windup
//!
//! Clamping (conditional integration): the integrator does not move further in a direction in
//! which the output is already at its limit (0 or the ceiling). The unclamped demand is kept
//! ([`AmplitudeController::demand_q15`]) for the saturation monitor.

/// Proportional gain, effort per unit normalised error.
pub const KP: f32 = 0.1;
/// Integral gain per update.
pub const KI: f32 = 0.1;

/// A linear setpoint ramp on the DAC sample clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ramp {
    from: u32,
    to: u32,
    start: u64,
    len: u64,
}

impl Ramp {
    /// A ramp from `from` to `to` (mm/s²) over `len` samples starting at sample `start`.
    pub const fn new(from: u32, to: u32, start: u64, len: u64) -> Self {
        Self { from, to, start, len }
    }

    /// The value at sample `at`.
    pub fn at(&self, at: u64) -> u32 {
        if at <= self.start {
            return self.from;
        }
        let done = at - self.start;
        if done >= self.len {
            return self.to;
        }
        let span = self.to as i64 - self.from as i64;
        (self.from as i64 + span * done as i64 / self.len as i64) as u32
    }

    /// The final value.
    pub fn target(&self) -> u32 {
        self.to
    }

    /// The sample at which the ramp ends.
    pub fn end(&self) -> u64 {
        self.start + self.len
    }
}

/// The PI amplitude controller. See the module docs.
#[derive(Debug, Clone, PartialEq)]
pub struct AmplitudeController {
    /// Ĝ, mm/s² per Q15 unit of effort.
    gain: f32,
    ramp: Ramp,
    integ: f32,
    effort: u16,
    demand: f32,
    /// The reference model: the response expected from the feed-forward alone.
    model: f32,
    /// The model's decay per update (0: no lag).
    alpha: f32,
}

impl AmplitudeController {
    /// A controller for a plant of gain `gain` (mm/s² per Q15 unit), starting at effort
    /// `effort` with the setpoint ramp `ramp`.
    pub fn new(gain: f32, effort: u16, ramp: Ramp) -> Self {
        let gain = gain.max(MIN_GAIN);
        // Start the integrator so that the first output equals the current effort: no bump.
        let from = ramp.at(ramp.start) as f32;
        let ff = from / gain;
        Self {
            gain,
            ramp,
            integ: effort as f32 - ff,
            effort,
            demand: effort as f32,
            model: from,
            alpha: 0.0,
        }
    }

    /// The same with a reference model: the plate's envelope follows the feed-forward as a
    /// first-order lag that decays by `alpha` (0..1) per update, and the PI acts only on the
    /// response's deviation from that model, so the plate's own rise is not mistaken for an
    /// error (which would wind the integrator up and overshoot at resonance).
    pub fn with_lag(mut self, alpha: f32) -> Self {
        self.alpha = alpha.clamp(0.0, 0.95);
        self
    }

    /// The plant gain in use, mm/s² per Q15 unit.
    pub fn gain(&self) -> f32 {
        self.gain
    }

    /// Re-measured plant gain (after a frequency change): keeps the effort, re-seeds the
    /// integrator and ramps from `from` (the response now) to the target.
    pub fn regain(&mut self, gain: f32, from: u32, now: u64, ramp_len: u64) {
        let target = self.ramp.target();
        let alpha = self.alpha;
        *self =
            Self::new(gain, self.effort, Ramp::new(from, target, now, ramp_len)).with_lag(alpha);
    }

    /// A new target, ramped from the current setpoint over `ramp_len` samples from `now`.
    pub fn set_target(&mut self, target: u32, now: u64, ramp_len: u64) {
        if target != self.ramp.target() {
            self.ramp = Ramp::new(self.ramp.at(now), target, now, ramp_len);
        }
    }

    /// The setpoint ramp.
    pub fn ramp(&self) -> &Ramp {
        &self.ramp
    }

    /// One step at sample `now` with the response `y` (mm/s²) measured around sample `at`;
    /// returns the effort (Q15, 0..=`ceiling`). The feed-forward follows the setpoint now; the
    /// reference model follows it as the measurement saw it, [`OUTPUT_DELAY`] earlier.
    pub fn update(&mut self, y: u32, at: u64, now: u64, ceiling: u16) -> u16 {
        let ff = self.ramp.at(now) as f32 / self.gain;
        let r = self.ramp.at(at.saturating_sub(OUTPUT_DELAY)) as f32;
        self.model = r + (self.model - r) * self.alpha;
        let e = (self.model - y as f32) / self.gain;
        let demand = ff + KP * e + self.integ + KI * e;
        let hi = ceiling as f32;
        // Integrate only if that does not push further into a limit (clamping anti-windup).
        let winding_up = demand > hi && e > 0.0;
        let winding_down = demand < 0.0 && e < 0.0;
        if !winding_up && !winding_down {
            self.integ += KI * e;
        }
        self.demand = demand;
        let out = demand.clamp(0.0, hi);
        self.effort = (out + 0.5) as u16;
        self.effort
    }

    /// The last effort, Q15.
    pub fn effort(&self) -> u16 {
        self.effort
    }

    /// The reference model's response at the last update, mm/s²: what the plate should answer
    /// by now (the fault monitors compare the response with it).
    pub fn model_mmps2(&self) -> u32 {
        (self.model.max(0.0) + 0.5) as u32
    }

    /// The last effort asked for before clamping, Q15 (may exceed the ceiling).
    pub fn demand_q15(&self) -> u32 {
        if self.demand <= 0.0 { 0 } else { (self.demand + 0.5) as u32 }
    }
}

/// From the effort's decision to its output, DAC samples: the next block is output after the
/// one playing now and ramps to the new effort across its length (1.5 blocks on average).
pub const OUTPUT_DELAY: u64 = 2 * crate::drive::runner::BLOCK_LEN as u64;

/// Least plant gain used (mm/s² per Q15): a gain of zero would ask for infinite effort.
pub const MIN_GAIN: f32 = 1e-3;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramp_is_linear_and_ends_on_target() {
        let r = Ramp::new(1000, 3000, 100, 200);
        assert_eq!(r.at(0), 1000);
        assert_eq!(r.at(200), 2000);
        assert_eq!(r.at(300), 3000);
        assert_eq!(r.at(10_000), 3000);
        let down = Ramp::new(3000, 1000, 0, 100);
        assert_eq!(down.at(50), 2000);
        assert_eq!(Ramp::new(5, 9, 0, 0).at(0), 5);
        assert_eq!(Ramp::new(5, 9, 0, 0).at(1), 9);
    }

    /// A static plant y = g·u: the loop converges to the target from a 30 % gain error.
    #[test]
    fn converges_on_a_static_plant_with_a_wrong_gain() {
        let g_true = 2.0f32;
        let mut c = AmplitudeController::new(1.4, 0, Ramp::new(0, 10_000, 0, 0));
        let mut u = 0u16;
        for k in 0..60 {
            let t = 1000 + k * 250;
            u = c.update((g_true * u as f32) as u32, t, t, 32767);
        }
        let y = g_true * u as f32;
        assert!((y - 10_000.0).abs() < 20.0, "y {y}");
    }

    #[test]
    fn clamps_and_does_not_wind_up() {
        // The plant is disconnected for 100 updates (no response), then answers with y = u.
        let mut c = AmplitudeController::new(1.0, 0, Ramp::new(0, 15_000, 0, 0));
        for k in 0..100 {
            let t = 1000 + k * 250;
            assert!(c.update(0, t, t, 20_000) <= 20_000);
        }
        assert_eq!(c.effort(), 20_000);
        assert!(c.demand_q15() > 20_000);
        // The integrator stopped at the limit: once the response arrives, the output leaves
        // the ceiling at once instead of unwinding for a hundred updates.
        let mut u = c.effort();
        let mut at_ceiling = 0;
        for k in 100..160 {
            let t = 1000 + k * 250;
            u = c.update(u as u32, t, t, 20_000);
            at_ceiling += (u == 20_000) as u32;
        }
        assert!(at_ceiling <= 2, "{at_ceiling} updates at the ceiling");
        assert!(u.abs_diff(15_000) < 50, "{u}");
    }
}
