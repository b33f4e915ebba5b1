//! A particle bouncing on a vibrating string (the paper's Appendix, eqs. 8–10, Fig. 12).
//!
//! The string, `x ∈ [0, π]`, vibrates in its first mode, `y_s = A sin x sin ωt`, and is not
//! affected by the particle; its ends x = 0 and x = π are the nodes. The particle flies
//! ballistically under gravity between impacts.
//!
//! Impact law, in the string's local frame (tangent `t = (cos α, sin α)`, normal
//! `n = (−sin α, cos α)`, `tan α = A cos x sin ωt`); the string's material velocity is
//! `(0, ẏ_s)`, so the relative velocity is `w = (ẋ⁻, ẏ⁻ − ẏ_s)`:
//! ```text
//! w_n⁺ = −e w_n                                  (restitution, w_n < 0 approaching)
//! P_n  = (1 + e)|w_n|                            (normal impulse per unit mass)
//! w_t⁺ = w_t − sign(w_t) min(|w_t|, μ P_n)       (Coulomb: tangential impulse ≤ μ P_n)
//! ```
//! and back to (ẋ⁺, ẏ⁺) = (0, ẏ_s) + w_t⁺ t + w_n⁺ n. For small α this is the paper's
//! eqs. 8–9, `ẋ⁺ = e (ẏ⁻ − ẏ_s) sin α + β v_t`, `ẏ⁺ = ẏ_s (1 + e) − e ẏ⁻`, with the
//! dissipation factor `β = 1 − min(1, μ P_n / |v_t|)`. On a string with small slope the
//! tangential slip is much smaller than μ P_n, so β = 0 (the impact sticks tangentially) and
//! `ẋ⁺ = e w_n sin α`: the horizontal kick is the rebound along the tilted normal, pointing
//! downhill and proportional to e. Downhill is towards the nearer node while the string is
//! above its mean position (a hump) and towards the antinode while it is below (a dip).
//!
//! Option [`StringParams::beta`]: the paper's eq. 8 literally, `w_t⁺ = β w_t` with a constant β
//! (a tangential coefficient of restitution, no Coulomb bound), so that for small α
//! `ẋ⁺ ≈ β ẋ⁻ + (β + e) w_n sin α`.
//!
//! When the rebound is too slow to separate (relative normal velocity below
//! `Sim::stick_speed`, or too many impacts within one period: the chattering sequence of
//! small e) the particle rides on the string until the string's downward acceleration
//! exceeds g. In contact the apparent weight `g + ÿ_s` pushes it downhill with
//! `−(g + ÿ_s) tan α` and Coulomb friction `μ (g + ÿ_s)` opposes sliding. Both scale with
//! the same load, so a particle at rest slides only where `|tan α| > μ` (never for μ ≥ A);
//! when it does, the load-weighted slope averages to `+(A²ω²/4) sin 2x` per unit mass
//! (light load on the hump, heavy in the dip): contact sliding drifts towards the
//! *antinode*, not the node.
//!
//! The paper argues (eq. 10 and after) that the time-averaged horizontal force is
//! `F_avg ∝ −e A² ω sin 2x`, pointing from the antinode x = π/2 to the nodes, provided the
//! impacts happen mostly while the string is above its mean position. That is the case in
//! the periodic (period-1) bouncing regime, `Γ = Aω²/g` near 1; for larger Γ the bouncing is
//! chaotic and impacts below the mean (the string rising to meet a falling particle) win.
//! [`drift_profile`] measures the ensemble-averaged drift velocity of particles held at x (the
//! impacts stick tangentially, so the rebound's velocity over the following flight is what
//! moves a particle: an overdamped drift, velocity ∝ force, see [`average_drift`]), and
//! [`fit_sin2x`] fits it to `−c sin 2x`: c > 0 is the paper's sign (towards the nodes).
//!
//! The drift stops short of the node: period-1 bouncing needs the local drive
//! `Γ sin x ≥ π(1 − e)/(1 + e)` ([`bounce_threshold`]), and where the amplitude falls below it
//! the particle locks onto the string. [`stop_position`] predicts the stop; the simulation
//! agrees within 0.025 for e = 0.5…0.9 at Γ = 1.22, and for e = 0.1 at Γ = 2.99 (the lowest
//! e needs Γ sin x ≥ 2.57 to bounce at all). See docs/plate.md, "Particle on a string".

use crate::progress::Progress;
use std::f64::consts::PI;

use serde::Serialize;

/// Model parameters (SI units; x is the mode's phase coordinate on [0, π], in metres).
#[derive(Debug, Clone, Copy)]
pub struct StringParams {
    /// String amplitude A (m).
    pub amplitude: f64,
    /// Drive frequency (Hz); ω = 2π f.
    pub freq_hz: f64,
    /// Coefficient of restitution e.
    pub e: f64,
    /// Coulomb friction coefficient μ (impacts and sliding).
    pub mu: f64,
    /// Gravity (m/s²).
    pub g: f64,
    /// Tangential impact law: `None` = Coulomb (tangential impulse ≤ μ × normal impulse);
    /// `Some(β)` = the paper's eq. 8 with a constant dissipation factor, `w_t⁺ = β w_t`.
    pub beta: Option<f64>,
}

impl Default for StringParams {
    fn default() -> Self {
        StringParams { amplitude: 0.02, freq_hz: 3.9, e: 0.9, mu: 0.3, g: 9.81, beta: None }
    }
}

impl StringParams {
    fn omega(&self) -> f64 {
        2.0 * PI * self.freq_hz
    }
    fn ys(&self, x: f64, t: f64) -> f64 {
        self.amplitude * x.sin() * (self.omega() * t).sin()
    }
    fn ys_dot(&self, x: f64, t: f64) -> f64 {
        self.amplitude * self.omega() * x.sin() * (self.omega() * t).cos()
    }
    fn ys_ddot(&self, x: f64, t: f64) -> f64 {
        -self.amplitude * self.omega().powi(2) * x.sin() * (self.omega() * t).sin()
    }
    fn slope(&self, x: f64, t: f64) -> f64 {
        self.amplitude * x.cos() * (self.omega() * t).sin()
    }
    /// Peak string acceleration over g at the antinode (the particle can only leave the
    /// string where `Γ sin x > 1`).
    pub fn gamma(&self) -> f64 {
        self.amplitude * self.omega().powi(2) / self.g
    }
    fn period(&self) -> f64 {
        1.0 / self.freq_hz
    }
}

/// Local drive strength Γ sin x below which a particle of restitution `e` cannot keep
/// bouncing. In the period-1 orbit (one flight per drive period, the high-bounce bouncing
/// ball map) each impact must give back what the restitution took: the rebound speed
/// v* = gT/2 satisfies v* = e v* + (1 + e) A ω sin x cos φ, so cos φ = π(1 − e)/((1 + e) Γ sin x),
/// which needs Γ sin x ≥ π(1 − e)/(1 + e): 0.165 for e = 0.9, 2.57 for e = 0.1. Below it the
/// particle locks onto the string (takes off, chatters, rides) and its drift stops.
pub fn bounce_threshold(e: f64) -> f64 {
    PI * (1.0 - e) / (1.0 + e)
}

/// Where the drift towards the node x = 0 stops: Γ sin x = [`bounce_threshold`] (and
/// π − x for the node x = π). `None` when Γ is below the threshold: the particle cannot
/// bounce anywhere on the string.
pub fn stop_position(p: &StringParams) -> Option<f64> {
    let r = bounce_threshold(p.e) / p.gamma();
    (r <= 1.0).then(|| r.asin())
}

/// Particle state.
#[derive(Debug, Clone, Copy)]
struct State {
    t: f64,
    x: f64,
    y: f64,
    u: f64,
    v: f64,
    riding: bool,
}

/// Impact law (see the module docs): velocities just before → just after.
fn impact(p: &StringParams, x: f64, t: f64, u: f64, v: f64) -> (f64, f64) {
    let ysd = p.ys_dot(x, t);
    let tan_a = p.slope(x, t);
    let cos_a = 1.0 / (1.0 + tan_a * tan_a).sqrt();
    let sin_a = tan_a * cos_a;
    let (wx, wy) = (u, v - ysd);
    let wn = -wx * sin_a + wy * cos_a;
    let wt = wx * cos_a + wy * sin_a;
    let wn = wn.min(0.0);
    let pn = -(1.0 + p.e) * wn;
    let wn1 = -p.e * wn;
    let wt1 = match p.beta {
        Some(b) => b * wt,
        None => wt - wt.signum() * wt.abs().min(p.mu * pn),
    };
    (wt1 * cos_a - wn1 * sin_a, ysd + wt1 * sin_a + wn1 * cos_a)
}

/// Impact statistics.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ImpactStats {
    /// Number of impacts.
    pub impacts: u64,
    /// Impacts while the string was above its mean position (`sin ωt > 0`).
    pub above_mean: u64,
}

impl ImpactStats {
    /// Fraction of impacts above the string's mean position (0 if there were none).
    pub fn above_fraction(&self) -> f64 {
        if self.impacts == 0 { 0.0 } else { self.above_mean as f64 / self.impacts as f64 }
    }
}

/// Simulator. `hold_x` keeps the particle at its x (for the drift and force measurements):
/// it keeps its horizontal velocity ẋ, but x does not change; `shift` accumulates the
/// displacement ∫ẋ dt it would have made.
struct Sim {
    p: StringParams,
    s: State,
    dt: f64,
    hold_x: bool,
    shift: f64,
    stats: ImpactStats,
    /// Impacts since the particle last rode on the string or a period started.
    burst: u32,
    burst_start: f64,
}

/// Impacts within one drive period after which the particle is put in contact (chattering).
const MAX_BURST: u32 = 200;

impl Sim {
    fn new(p: StringParams, x0: f64, hold_x: bool) -> Self {
        let s =
            State { t: 0.0, x: x0, y: p.ys(x0, 0.0), u: 0.0, v: p.ys_dot(x0, 0.0), riding: true };
        Sim::with_state(p, s, hold_x)
    }

    fn with_state(p: StringParams, s: State, hold_x: bool) -> Self {
        Sim {
            p,
            s,
            dt: p.period() / 200.0,
            hold_x,
            shift: 0.0,
            stats: ImpactStats::default(),
            burst: 0,
            burst_start: s.t,
        }
    }

    /// Relative normal rebound speed below which the particle stays in contact (m/s).
    fn stick_speed(&self) -> f64 {
        1e-3 * self.p.amplitude * self.p.omega()
    }

    /// Advances to time `t_end`. Every step makes progress in time or ends in contact, and
    /// the chattering guard bounds the impacts per period, so this terminates.
    fn run_until(&mut self, t_end: f64) {
        while self.s.t < t_end {
            if self.s.riding {
                self.ride(t_end);
            } else {
                self.fly(t_end);
            }
            if !self.hold_x && (self.s.x <= 0.0 || self.s.x >= PI) {
                // Reached a node (an end of the string): it stays there.
                self.s.x = self.s.x.clamp(0.0, PI);
                self.s.u = 0.0;
                self.s.y = 0.0;
                self.s.v = 0.0;
                self.s.riding = true;
            }
        }
    }

    fn ride(&mut self, t_end: f64) {
        let p = self.p;
        let mut s = self.s;
        self.burst = 0;
        self.burst_start = s.t;
        while s.t < t_end {
            let t1 = s.t + self.dt;
            if p.ys_ddot(s.x, t1) < -p.g {
                // Leaves the string where its acceleration first drops below −g.
                let (mut lo, mut hi) = (s.t, t1);
                for _ in 0..40 {
                    let mid = 0.5 * (lo + hi);
                    if p.ys_ddot(s.x, mid) < -p.g { hi = mid } else { lo = mid }
                }
                s.t = hi;
                s.y = p.ys(s.x, s.t);
                s.v = p.ys_dot(s.x, s.t);
                s.riding = false;
                break;
            }
            // In contact: the slope's share of the apparent weight g + ÿ_s pushes downhill,
            // Coulomb friction μ(g + ÿ_s) opposes sliding (or holds the particle when the
            // slope is below μ).
            let load = (p.g + p.ys_ddot(s.x, s.t)).max(0.0);
            let push = -load * p.slope(s.x, s.t);
            let fric = p.mu * load;
            let u0 = s.u;
            if u0 == 0.0 {
                if push.abs() > fric {
                    s.u = (push - fric * push.signum()) * self.dt;
                }
            } else {
                s.u = u0 + (push - fric * u0.signum()) * self.dt;
                if s.u * u0 < 0.0 {
                    s.u = 0.0;
                }
            }
            if self.hold_x {
                self.shift += s.u * self.dt;
            } else {
                s.x += s.u * self.dt;
            }
            s.t = t1;
            s.y = p.ys(s.x, s.t);
            s.v = p.ys_dot(s.x, s.t);
        }
        self.s = s;
    }

    fn fly(&mut self, t_end: f64) {
        let p = self.p;
        let s0 = self.s;
        // Held: x stays, the velocity is kept (and its displacement counted in `shift`).
        let drift = if self.hold_x { 0.0 } else { s0.u };
        let gap = |t: f64| {
            let tau = t - s0.t;
            let x = s0.x + drift * tau;
            s0.y + s0.v * tau - 0.5 * p.g * tau * tau - p.ys(x, t)
        };
        let mut t = s0.t;
        loop {
            let t1 = (t + self.dt).min(t_end);
            if gap(t1) < 0.0 {
                // Bisection keeps `lo` on the free side; at lo = s0.t (just after the previous
                // impact) the gap is 0 but opening at ≥ stick_speed, so the root found is the
                // next impact, not the previous one.
                let (mut lo, mut hi) = (t, t1);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if gap(mid) < 0.0 { hi = mid } else { lo = mid }
                }
                let ti = lo;
                let tau = ti - s0.t;
                let x = s0.x + drift * tau;
                let (u, v) = impact(&p, x, ti, s0.u, s0.v - p.g * tau);
                self.stats.impacts += 1;
                if (p.omega() * ti).sin() > 0.0 {
                    self.stats.above_mean += 1;
                }
                if self.hold_x {
                    self.shift += s0.u * tau;
                }
                if ti - self.burst_start > p.period() {
                    self.burst = 0;
                    self.burst_start = ti;
                }
                self.burst += 1;
                let slow = v - p.ys_dot(x, ti) < self.stick_speed();
                let riding = slow || self.burst >= MAX_BURST;
                let (y, v) = if riding { (p.ys(x, ti), p.ys_dot(x, ti)) } else { (p.ys(x, ti), v) };
                self.s = State { t: ti, x, y, u, v, riding };
                return;
            }
            if t1 >= t_end {
                let tau = t1 - s0.t;
                if self.hold_x {
                    self.shift += s0.u * tau;
                }
                self.s = State {
                    t: t1,
                    x: s0.x + drift * tau,
                    y: s0.y + s0.v * tau - 0.5 * p.g * tau * tau,
                    u: s0.u,
                    v: s0.v - p.g * tau,
                    riding: false,
                };
                return;
            }
            t = t1;
        }
    }
}

/// A simulated trajectory.
#[derive(Debug, Clone)]
pub struct Trajectory {
    /// (time s, x) samples.
    pub samples: Vec<(f64, f64)>,
    /// Impact statistics.
    pub stats: ImpactStats,
}

impl Trajectory {
    /// The last sampled x.
    pub fn x_end(&self) -> f64 {
        self.samples.last().map_or(f64::NAN, |s| s.1)
    }

    /// First sampled time at which x is within `dist` of a node (0 or π).
    pub fn time_to_node(&self, dist: f64) -> Option<f64> {
        self.samples.iter().find(|&&(_, x)| x.min(PI - x) <= dist).map(|s| s.0)
    }
}

/// Simulates a particle released at rest at `x0`, `drop` metres above the string's mean
/// position (0: on the string), for `duration` seconds, sampling x every `sample_dt` seconds.
pub fn simulate(p: &StringParams, x0: f64, drop: f64, duration: f64, sample_dt: f64) -> Trajectory {
    let sim = if drop > 0.0 {
        let s = State { t: 0.0, x: x0, y: drop.max(p.amplitude), u: 0.0, v: 0.0, riding: false };
        Sim::with_state(*p, s, false)
    } else {
        Sim::new(*p, x0, false)
    };
    record(sim, x0, duration, sample_dt)
}

/// Runs `sim` for `duration` seconds, sampling x every `sample_dt` seconds from `x0` at t = 0.
fn record(mut sim: Sim, x0: f64, duration: f64, sample_dt: f64) -> Trajectory {
    let mut samples = vec![(0.0, x0)];
    let mut t = 0.0;
    while t < duration {
        t = (t + sample_dt).min(duration);
        sim.run_until(t);
        samples.push((t, sim.s.x));
    }
    Trajectory { samples, stats: sim.stats }
}

/// Release state of ensemble member `k` of `members` at `x`: dropped from rest at drive phase
/// 2π(k + ½)/members, from a height above the string's peak spread over
/// [0, 2 g T²/8) (twice the period-1 bounce height) by a golden-ratio sequence.
fn release(p: &StringParams, x: f64, k: usize, members: usize) -> State {
    let period = p.period();
    let h1 = p.g * period * period / 8.0;
    let t0 = period * (k as f64 + 0.5) / members.max(1) as f64;
    let h = 2.0 * h1 * ((k as f64 * 0.618_033_988_75 + 0.3) % 1.0);
    State { t: t0, x, y: p.amplitude + h, u: 0.0, v: 0.0, riding: false }
}

#[cfg(test)]
/// Trajectories of `members` particles dropped near `x0` (see `release`; member k is
/// released at time t0 < T and sampled from t = 0 with x = x0 until then).
pub(crate) fn simulate_ensemble(
    p: &StringParams,
    x0: f64,
    members: usize,
    duration: f64,
    sample_dt: f64,
) -> Vec<Trajectory> {
    (0..members.max(1))
        .map(|k| {
            let sim = Sim::with_state(*p, release(p, x0, k, members), false);
            record(sim, x0, duration, sample_dt)
        })
        .collect()
}

/// Ensemble-averaged drift velocity (m/s) of a particle held at `x`: the horizontal
/// displacement ∫ẋ dt it would make there, per unit time, averaged over `members` particles
/// dropped at different drive phases from different heights (see `release`), each followed
/// for `duration` seconds after a 10-period transient.
///
/// Why a velocity and not the impulse rate: each impact sticks tangentially (see the module
/// docs), so the particle keeps no horizontal momentum from one impact to the next; the
/// momentum the string gives (Σ Δẋ) sums to zero over any long run. What moves the particle
/// is the velocity e w_n sin α each rebound leaves it with, for the length of the flight
/// that follows: an overdamped drift, the quantity the plate's field model uses (velocity ∝
/// force, docs/motion.md). Counting the kicks per unit time instead weights the many short
/// chattering flights of a low-e particle like its long flights, and gives the wrong sign.
pub fn average_drift(
    p: &StringParams,
    x: f64,
    duration: f64,
    members: usize,
) -> (f64, ImpactStats) {
    let period = p.period();
    let mut total = 0.0;
    let mut stats = ImpactStats::default();
    let members = members.max(1);
    for k in 0..members {
        let s = release(p, x, k, members);
        let t0 = s.t;
        let mut sim = Sim::with_state(*p, s, true);
        sim.run_until(t0 + 10.0 * period);
        sim.shift = 0.0;
        sim.stats = ImpactStats::default();
        sim.run_until(t0 + 10.0 * period + duration);
        total += sim.shift / duration;
        stats.impacts += sim.stats.impacts;
        stats.above_mean += sim.stats.above_mean;
    }
    (total / members as f64, stats)
}

/// Ensemble-averaged drift velocity at `n` points spread over (0, π) (endpoints excluded).
pub fn drift_profile(
    p: &StringParams,
    n: usize,
    duration: f64,
    members: usize,
    progress: &dyn Progress,
) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            let x = PI * (k as f64 + 0.5) / n as f64;
            let (f, _) = average_drift(p, x, duration, members);
            progress.advance(1);
            (x, f)
        })
        .collect()
}

/// Least-squares fit of a drift profile `v(x) ≈ −c sin 2x` (the paper's `F_avg ∝ −e A² sin 2x`
/// in the overdamped reading, velocity ∝ force).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Coefficient c (m/s).
    pub c: f64,
    /// Coefficient of determination.
    pub r2: f64,
    /// c / (e A² ω), the proportionality constant of the paper's `F_avg ∝ −e A² ω sin 2x`
    /// (units 1/m).
    pub per_e_a2_omega: f64,
}

/// Fits `−c sin 2x` to a drift profile.
pub fn fit_sin2x(p: &StringParams, profile: &[(f64, f64)]) -> Fit {
    let s: Vec<f64> = profile.iter().map(|(x, _)| -(2.0 * x).sin()).collect();
    let sf: f64 = profile.iter().zip(&s).map(|((_, f), s)| f * s).sum();
    let ss: f64 = s.iter().map(|s| s * s).sum();
    let c = sf / ss;
    let mean = profile.iter().map(|(_, f)| f).sum::<f64>() / profile.len() as f64;
    let tot: f64 = profile.iter().map(|(_, f)| (f - mean).powi(2)).sum();
    let res: f64 = profile.iter().zip(&s).map(|((_, f), s)| (f - c * s).powi(2)).sum();
    Fit { c, r2: 1.0 - res / tot, per_e_a2_omega: c / (p.e * p.amplitude.powi(2) * p.omega()) }
}

/// Trajectory samples of an [`experiment`] at least (the plot's resolution).
pub const TRAJECTORY_INTERVALS: usize = 600;
/// Samples of the trajectory in the `--json` report unless `--samples` says otherwise.
pub const JSON_SAMPLES: usize = 61;
/// Points of the drift profile of an [`experiment`].
pub const PROFILE_POINTS: usize = 16;
/// Particles averaged per point of the force profile of an [`experiment`].
pub(crate) const PROFILE_MEMBERS: usize = 8;

/// The period-1 bounce height g/(8 f²) (m): the default release height.
pub fn period1_drop(p: &StringParams) -> f64 {
    p.g / (8.0 * p.freq_hz * p.freq_hz)
}

/// What `chladni physics string` computes: one trajectory from `x0`, the averaged drift
/// profile with its `−c sin 2x` fit, and where bouncing (and so the drift) stops.
#[derive(Debug, Clone)]
pub struct Experiment {
    /// The string and particle.
    pub params: StringParams,
    /// Start position.
    pub x0: f64,
    /// Release height (m).
    pub drop_m: f64,
    /// Simulated time (s).
    pub duration_s: f64,
    /// The trajectory, sampled at [`TRAJECTORY_INTERVALS`] (or more) equal intervals.
    pub trajectory: Trajectory,
    /// Averaged drift velocity at [`PROFILE_POINTS`] points: (x, v in m/s).
    pub profile: Vec<(f64, f64)>,
    /// The fit of the profile.
    pub fit: Fit,
    /// Γ sin x at which bouncing ends, π(1−e)/(1+e).
    pub threshold: f64,
    /// Where the drift towards the nodes stops, if the particle bounces at all.
    pub stop_x: Option<f64>,
}

/// Runs the experiment: `duration` s from `x0` released `drop` m above the string, and the
/// drift profile averaged `average` s per particle; the trajectory is sampled at
/// `intervals.max(TRAJECTORY_INTERVALS)` equal intervals; `progress` is called after the
/// trajectory and after each profile point ([`PROFILE_POINTS`] + 1 calls).
pub fn experiment(
    p: &StringParams,
    x0: f64,
    drop: f64,
    (duration, intervals): (f64, usize),
    average: f64,
    progress: &dyn Progress,
) -> Experiment {
    let intervals = intervals.max(TRAJECTORY_INTERVALS);
    let trajectory = simulate(p, x0, drop, duration, duration / intervals as f64);
    progress.advance(1);
    let profile = drift_profile(p, PROFILE_POINTS, average, PROFILE_MEMBERS, progress);
    Experiment {
        params: *p,
        x0,
        drop_m: drop,
        duration_s: duration,
        fit: fit_sin2x(p, &profile),
        trajectory,
        profile,
        threshold: bounce_threshold(p.e),
        stop_x: stop_position(p),
    }
}

impl Experiment {
    /// The last sampled x (`x0` if nothing was sampled).
    pub fn x_end(&self) -> f64 {
        self.trajectory.samples.last().map_or(self.x0, |s| s.1)
    }

    /// The lowest drive frequency at which the particle can just keep bouncing at `x0`
    /// (Γ ∝ f²).
    pub fn min_bouncing_freq_hz(&self) -> f64 {
        let p = &self.params;
        p.freq_hz * (self.threshold / (p.gamma() * self.x0.sin())).sqrt()
    }

    /// `n` (≥ 2) of the trajectory's samples `[t, x]`, evenly spread from the first to the
    /// last (the nearest stored sample to each of n equally spaced times).
    pub fn samples(&self, n: usize) -> Vec<[f64; 2]> {
        let s = &self.trajectory.samples;
        let n = n.max(2);
        (0..n)
            .filter_map(|k| s.get((k * (s.len().max(1) - 1) + (n - 1) / 2) / (n - 1)))
            .map(|&(t, x)| [t, x])
            .collect()
    }

    /// The `--json` report, with `samples` points of the trajectory.
    pub fn report(&self, samples: usize) -> ExperimentReport {
        let (p, t) = (&self.params, &self.trajectory);
        ExperimentReport {
            bouncing: Bouncing { stop_x: self.stop_x, threshold_gamma_sin_x: self.threshold },
            fit: FitReport {
                c: self.fit.c,
                c_per_e_a2_omega: self.fit.per_e_a2_omega,
                model: "v = -c sin 2x",
                r2: self.fit.r2,
            },
            drift: self.profile.iter().map(|&(x, f)| [x, f]).collect(),
            params: ParamsReport {
                amplitude_m: p.amplitude,
                beta: p.beta,
                e: p.e,
                freq_hz: p.freq_hz,
                gamma: p.gamma(),
                mu: p.mu,
            },
            trajectory: TrajectoryReport {
                drop_m: self.drop_m,
                duration_s: self.duration_s,
                impacts: t.stats.impacts,
                impacts_above_mean: t.stats.above_mean,
                samples: self.samples(samples),
                x0: self.x0,
                x_end: self.x_end(),
            },
        }
    }
}

/// The `chladni physics string --json` object (keys in alphabetical order, as printed).
#[derive(Debug, Clone, Serialize)]
pub struct ExperimentReport {
    /// Where bouncing ends.
    pub bouncing: Bouncing,
    /// The fit of the drift profile.
    pub fit: FitReport,
    /// The drift profile: `[x, v (m/s)]`, held particles' averaged velocity.
    pub drift: Vec<[f64; 2]>,
    /// The parameters.
    pub params: ParamsReport,
    /// The trajectory.
    pub trajectory: TrajectoryReport,
}

/// Where bouncing ends.
#[derive(Debug, Clone, Serialize)]
pub struct Bouncing {
    /// The drift stops at this x (and π − x); `None`: the particle never bounces.
    pub stop_x: Option<f64>,
    /// π(1−e)/(1+e).
    pub threshold_gamma_sin_x: f64,
}

/// The fit of the drift profile.
#[derive(Debug, Clone, Serialize)]
pub struct FitReport {
    /// Coefficient c (m/s; > 0: towards the nodes, the paper's sign).
    pub c: f64,
    /// c / (e A² ω).
    pub c_per_e_a2_omega: f64,
    /// The fitted law.
    pub model: &'static str,
    /// Coefficient of determination.
    pub r2: f64,
}

/// The parameters of the experiment.
#[derive(Debug, Clone, Serialize)]
pub struct ParamsReport {
    /// String amplitude (m).
    pub amplitude_m: f64,
    /// Tangential impact factor, if used.
    pub beta: Option<f64>,
    /// Restitution.
    pub e: f64,
    /// Drive frequency.
    pub freq_hz: f64,
    /// Γ = Aω²/g.
    pub gamma: f64,
    /// Friction.
    pub mu: f64,
}

/// The trajectory: start, end, impacts and `--samples` samples `[t (s), x]`.
#[derive(Debug, Clone, Serialize)]
pub struct TrajectoryReport {
    /// Release height (m).
    pub drop_m: f64,
    /// Simulated time (s).
    pub duration_s: f64,
    /// Impacts.
    pub impacts: u64,
    /// Impacts above the string's mean position.
    pub impacts_above_mean: u64,
    /// Evenly spread samples, first and last included.
    pub samples: Vec<[f64; 2]>,
    /// Start.
    pub x0: f64,
    /// End.
    pub x_end: f64,
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_e(e: f64) -> StringParams {
        StringParams { e, ..StringParams::default() }
    }

    #[test]
    fn impact_law_reverses_relative_normal_velocity_and_sticks_tangentially() {
        let p = with_e(0.5);
        // At ωt = 0 the string is flat (sin α = 0) and moving up at A ω sin x.
        let x = 1.0;
        let (u, v) = impact(&p, x, 0.0, 0.2, -1.0);
        let ysd = p.ys_dot(x, 0.0);
        assert!((v - ysd - 0.5 * (ysd + 1.0)).abs() < 1e-12);
        // |w_t| = 0.2 < μ P_n = 0.3 · 1.5 · (1 + ẏ_s): friction stops the slip.
        assert!(u.abs() < 1e-12, "{u}");
        // Frictionless: the tangential velocity is kept.
        let (u, _) = impact(&StringParams { mu: 0.0, ..p }, x, 0.0, 0.2, -1.0);
        assert!((u - 0.2).abs() < 1e-12, "{u}");
    }

    #[test]
    fn tilted_impact_kicks_downhill_by_e_times_normal_velocity() {
        // ωt = π/2: the string is a hump at rest (ẏ_s = 0), slope A cos x > 0 at x = 0.5.
        let p = with_e(0.9);
        let (x, t) = (0.5, 0.25 / p.freq_hz);
        let tan_a = p.slope(x, t);
        assert!(p.ys_dot(x, t).abs() < 1e-12 && tan_a > 0.0);
        let (u, v) = impact(&p, x, t, 0.0, -1.0);
        let sin_a = tan_a / (1.0 + tan_a * tan_a).sqrt();
        let wn = -(1.0 - sin_a * sin_a).sqrt();
        // ẋ⁺ = e w_n sin α (β = 0): towards the node x = 0.
        assert!((u - 0.9 * wn * sin_a).abs() < 1e-12, "{u}");
        assert!(u < 0.0 && v > 0.0);
    }

    #[test]
    fn fit_recovers_a_pure_sine_profile() {
        let p = with_e(0.5);
        let prof: Vec<(f64, f64)> = (0..10)
            .map(|k| {
                let x = PI * (k as f64 + 0.5) / 10.0;
                (x, -0.7 * (2.0 * x).sin())
            })
            .collect();
        let fit = fit_sin2x(&p, &prof);
        assert!((fit.c - 0.7).abs() < 1e-12 && (fit.r2 - 1.0).abs() < 1e-12, "{fit:?}");
        let flipped: Vec<(f64, f64)> = prof.iter().map(|&(x, f)| (x, -f)).collect();
        assert!(fit_sin2x(&p, &flipped).c < 0.0);
    }

    #[test]
    fn particle_stays_on_the_string_and_leaves_it_only_where_gamma_sin_x_exceeds_one() {
        let p = StringParams { freq_hz: 6.0, ..with_e(0.9) };
        // Near the node Γ sin x < 1: the string never throws the particle up.
        let near = simulate(&p, 0.2, 0.0, 5.0, 0.5);
        assert_eq!(near.stats.impacts, 0);
        assert!(near.samples.iter().all(|&(_, x)| (x - 0.2).abs() < 1e-12));
        let far = simulate(&p, 1.2, 0.0, 20.0, 0.5);
        assert!(far.stats.impacts > 20, "{:?}", far.stats);
        assert!(far.samples.iter().all(|&(_, x)| (0.0..=PI).contains(&x)));
    }

    #[test]
    fn chattering_low_restitution_particle_terminates_and_rides() {
        // e = 0.1 lands, chatters and rides every period; the run must stay bounded.
        let p = with_e(0.1);
        let tr = simulate(&p, 1.2, 0.0, 20.0, 1.0);
        let periods = 20.0 * p.freq_hz;
        assert!(tr.stats.impacts > 0 && (tr.stats.impacts as f64) < 20.0 * periods);
    }

    fn mean_end(p: &StringParams, x0: f64, secs: f64) -> (f64, Vec<Trajectory>) {
        let tr = simulate_ensemble(p, x0, 8, secs, 1.0);
        (tr.iter().map(Trajectory::x_end).sum::<f64>() / tr.len() as f64, tr)
    }

    // Fig. 12, high-e panel, in the periodic regime Γ = 1.22 (defaults): 8 particles
    // dropped at x = 1.2 (and at π − 1.2) drift to the nearer node; e = 0.1 does not beat it.
    #[test]
    fn particle_drifts_to_the_nearest_node_faster_for_high_restitution() {
        let (xh, hi) = mean_end(&with_e(0.9), 1.2, 90.0);
        let (xl, lo) = mean_end(&with_e(0.1), 1.2, 90.0);
        println!("mean x(90 s) from 1.2: e = 0.9 → {xh:.3}, e = 0.1 → {xl:.3}");
        assert!(xh < 0.5, "e = 0.9 should be close to the node: {xh}");
        assert!(hi.iter().all(|t| t.x_end() < 1.2 - 0.1), "every e = 0.9 particle moves to 0");
        assert!(xh < xl, "e = 0.9 should be nearer the node: {xh} vs {xl}");
        assert!(lo.iter().all(|t| t.x_end() <= 1.2 + 1e-3), "e = 0.1 never moves to π/2");
        // Mirror image: from the other half it goes to x = π.
        let (xr, right) = mean_end(&with_e(0.9), PI - 1.2, 90.0);
        assert!(xr > PI - 0.5, "{xr}");
        assert!(right.iter().all(|t| t.x_end() > PI - 1.2 + 0.1));
    }

    // Where the drift stops: period-1 bouncing needs Γ sin x ≥ π(1 − e)/(1 + e). At Γ = 1.22
    // particles released at x = 1.2 that leave the locked state drift towards x = 0 and stop
    // there, closer to the node the higher e (measured 1.03, 0.71, 0.49, 0.31, 0.16).
    #[test]
    fn drift_stops_where_period_one_bouncing_ends_closer_to_the_node_for_higher_e() {
        let mut last = f64::INFINITY;
        for e in [0.5, 0.6, 0.7, 0.8, 0.9] {
            let p = with_e(e);
            let stop = stop_position(&p).unwrap();
            let tr = simulate_ensemble(&p, 1.2, 8, 300.0, 10.0);
            let moved: Vec<f64> =
                tr.iter().map(Trajectory::x_end).filter(|x| (x - 1.2).abs() > 0.1).collect();
            println!("e = {e}: stop {stop:.3}, moved {} of 8 to {moved:.2?}", moved.len());
            assert!(moved.len() >= 4, "e = {e}: {moved:?}");
            assert!(moved.iter().all(|x| (x - stop).abs() < 0.05), "e = {e}: {stop} vs {moved:?}");
            assert!(stop < last);
            last = stop;
        }
        // e = 0.1 needs Γ sin x ≥ 2.57: at Γ = 1.22 it cannot bounce anywhere.
        assert_eq!(stop_position(&with_e(0.1)), None);
    }

    // Fig. 12, low-e panel: at a drive where e = 0.1 can bounce (Γ = 2.99 > 2.57), particles
    // released near the antinode drift to the nearer node, over ~1000 s as in the paper, and
    // stop where Γ sin x = 2.57 (x = 1.035; mirror image from the other half).
    #[test]
    fn low_restitution_particle_drifts_slowly_to_the_node_where_it_can_bounce() {
        let p = StringParams { freq_hz: 6.1, ..with_e(0.1) };
        let stop = stop_position(&p).unwrap();
        assert!((stop - 1.035).abs() < 0.01, "{stop}");
        for (x0, end) in [(1.45, stop), (PI - 1.45, PI - stop)] {
            let tr = simulate_ensemble(&p, x0, 8, 1500.0, 50.0);
            for t in &tr {
                assert!((t.x_end() - end).abs() < 0.03, "from {x0}: {} vs {end}", t.x_end());
                // Slow: after 300 s still less than half-way.
                let x300 = t.samples[6].1;
                assert!((x300 - x0).abs() < 0.5 * (end - x0).abs(), "{x300}");
            }
        }
    }

    // "Faster for e = 0.9 than for e = 0.1": each at a drive where it bounces periodically
    // (Γ = 1.22 resp. 2.99), the time to move 0.2 towards the node from rest near the antinode.
    #[test]
    fn high_restitution_drifts_many_times_faster_than_low() {
        let time_to_move = |p: &StringParams, x0: f64, secs: f64| -> f64 {
            let tr = simulate_ensemble(p, x0, 8, secs, 1.0);
            let mut t: Vec<f64> = tr
                .iter()
                .map(|t| t.samples.iter().find(|s| s.1 < x0 - 0.2).map_or(f64::INFINITY, |s| s.0))
                .collect();
            t.sort_by(f64::total_cmp);
            t[t.len() / 2]
        };
        let hi = time_to_move(&with_e(0.9), 1.2, 200.0);
        let lo = time_to_move(&StringParams { freq_hz: 6.1, ..with_e(0.1) }, 1.45, 1500.0);
        println!("median time to move 0.2 towards the node: e = 0.9 {hi} s, e = 0.1 {lo} s");
        assert!(hi.is_finite() && lo.is_finite() && lo > 5.0 * hi, "{hi} vs {lo}");
    }

    #[test]
    fn constant_beta_law_is_the_papers_eq_8_for_small_slope() {
        let p = StringParams { beta: Some(0.5), ..with_e(0.1) };
        let (x, t) = (0.7, 0.3 / p.freq_hz);
        let (u0, v0) = (0.05, -0.8);
        let (u, v) = impact(&p, x, t, u0, v0);
        let (ysd, sin_a) = (p.ys_dot(x, t), p.slope(x, t));
        let vt = (v0 - ysd) * sin_a + u0;
        // Eqs. 8–9 hold to first order in the slope (|tan α| ≤ A = 0.02).
        assert!((u - (p.e * (v0 - ysd) * sin_a + 0.5 * vt)).abs() < 1e-3, "{u}");
        assert!((v - (ysd * (1.0 + p.e) - p.e * v0)).abs() < 1e-3, "{v}");
    }

    // Mechanism (2) of the low-e question: sliding in contact. With μ = 0 the apparent weight's
    // downhill push −(g + ÿ_s) tan α averages to +(A²ω²/4) sin 2x: light load on the hump
    // (downhill = to the node), heavy load in the dip (downhill = to the antinode). So a
    // locked particle that can slide goes to the antinode, not the node.
    #[test]
    fn frictionless_contact_sliding_drifts_to_the_antinode() {
        let p = StringParams { mu: 0.0, beta: Some(0.5), ..with_e(0.1) };
        let tr = simulate(&p, 1.2, 0.0, 30.0, 1.0);
        assert!(tr.x_end() > 1.3, "{}", tr.x_end());
        // With friction μ = 0.3 > slope the same particle is held in place.
        let held = simulate(&StringParams { mu: 0.3, ..p }, 1.2, 0.0, 30.0, 1.0);
        assert!((held.x_end() - 1.2).abs() < 1e-3, "{}", held.x_end());
    }

    // Eq. 10's F_avg ∝ −e A² sin 2x with the paper's sign: the averaged drift of held
    // particles (8 dropped per point) points to the nodes, fitted c > 0, for e = 0.9 at the
    // defaults (measured c = 8.3·10⁻³ m/s, R² = 0.83 with 16 points × 10 s).
    #[test]
    fn averaged_drift_follows_minus_sin_2x_with_the_papers_sign() {
        let p = with_e(0.9);
        let prof = drift_profile(&p, 12, 10.0, 8, &crate::progress::Silent);
        let fit = fit_sin2x(&p, &prof);
        println!("e = 0.9: c = {:.2e} m/s, R² = {:.3}", fit.c, fit.r2);
        assert!(fit.c > 1e-3 && fit.r2 >= 0.7, "{fit:?}");
        // Mirror symmetry of the string: v(π − x) ≈ −v(x) (chaotic orbits: to 5 % of the peak).
        let peak = prof.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
        for (a, b) in prof.iter().zip(prof.iter().rev()) {
            assert!((a.1 + b.1).abs() < 0.05 * peak, "{a:?} {b:?}");
        }
    }

    // Fig. 12's low-e panel at a drive where e = 0.1 bounces (Γ = 2.99): between the antinode
    // and the stop line the drift points to the node (the paper's sign), below the stop line
    // (the locked orbit lands in the dip) it points back: x_stop attracts from both sides.
    #[test]
    fn low_restitution_drift_points_to_the_node_above_the_stop_line() {
        let p = StringParams { freq_hz: 6.1, ..with_e(0.1) };
        let stop = stop_position(&p).unwrap();
        for x in [1.2, 1.3, 1.45] {
            let (v, _) = average_drift(&p, x, 10.0, 8);
            assert!(v < 0.0 && x > stop, "x = {x}: v = {v}");
        }
        let (v, _) = average_drift(&p, 0.7, 10.0, 8);
        assert!(v > 0.0, "below the stop line: {v}");
    }

    // The momentum the string gives a free particle sums to (almost) nothing: each sticking
    // impact resets ẋ, so Σ Δẋ telescopes to the last ẋ. This is why the drift velocity, not
    // the impulse rate, is the measure of the paper's effective force.
    #[test]
    fn sticking_impacts_leave_no_horizontal_momentum_to_accumulate() {
        let p = with_e(0.9);
        let tr = simulate(&p, 1.2, period1_drop(&p), 60.0, 1.0);
        assert!(tr.stats.impacts > 100 && tr.x_end() < 1.1, "{:?} {}", tr.stats, tr.x_end());
        let (x, t) = (0.5, 0.25 / p.freq_hz);
        let (u1, v1) = impact(&p, x, t, 0.0, -1.0);
        // A second impact at the same point: the first kick is gone, not added to.
        let (u2, _) = impact(&p, x, t, u1, -v1);
        assert!((u2 - u1).abs() < 0.5 * u1.abs() + 1e-12, "{u1} {u2}");
    }
}

#[cfg(test)]
mod scan {
    use super::*;

    fn spec() -> Vec<(f64, Option<f64>, f64, f64, f64)> {
        // e, beta, mu, freq, secs from STRING_SCAN="e,beta|-,mu,freq,secs;..."
        std::env::var("STRING_SCAN")
            .unwrap_or_default()
            .split(';')
            .filter(|s| !s.is_empty())
            .map(|s| {
                let v: Vec<&str> = s.split(',').collect();
                let b = if v[1] == "-" { None } else { Some(v[1].parse().unwrap()) };
                (
                    v[0].parse().unwrap(),
                    b,
                    v[2].parse().unwrap(),
                    v[3].parse().unwrap(),
                    v[4].parse().unwrap(),
                )
            })
            .collect()
    }

    #[test]
    #[ignore]
    fn scan_models() {
        let x0: f64 = std::env::var("STRING_X0").ok().and_then(|s| s.parse().ok()).unwrap_or(1.2);
        for (e, beta, mu, f, secs) in spec() {
            let p = StringParams { e, beta, mu, freq_hz: f, ..StringParams::default() };
            let t0 = std::time::Instant::now();
            let tr = simulate_ensemble(&p, x0, 8, secs, secs / 6.0);
            let ends: Vec<String> = tr.iter().map(|t| format!("{:.2}", t.x_end())).collect();
            let mean = tr.iter().map(Trajectory::x_end).sum::<f64>() / 8.0;
            let mid: Vec<f64> =
                (0..=6).map(|k| tr.iter().map(|t| t.samples[k].1).sum::<f64>() / 8.0).collect();
            let imp: u64 = tr.iter().map(|t| t.stats.impacts).sum();
            let above: u64 = tr.iter().map(|t| t.stats.above_mean).sum();
            println!(
                "e={e} beta={beta:?} mu={mu} f={f} Γ={:.2} {secs}s: mean {mean:.3} path {:?} ends [{}] imp {imp} above {:.2} ({:.1}s)",
                p.gamma(),
                mid.iter().map(|m| (m * 1000.0).round() / 1000.0).collect::<Vec<_>>(),
                ends.join(" "),
                above as f64 / imp.max(1) as f64,
                t0.elapsed().as_secs_f64()
            );
        }
    }
}
