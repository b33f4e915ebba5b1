//! A particle bouncing on a vibrating string (the paper's Appendix, eqs. 8–10, Fig. 12).
//!
//! The string, `x ∈ [0, π]`, vibrates in its first mode, `y_s = A sin x sin ωt`, and is not
//! affected by the particle; its ends x = 0 and x = π are the nodes. The particle flies
//! ballistically under gravity between impacts. At an impact, with string slope
//! `tan α = A cos x sin ωt` (small: sin α ≈ tan α, cos α ≈ 1) and velocities just before
//! (`ẋ⁻`, `ẏ⁻`), the paper's impact law is
//! ```text
//! ẋ⁺ = e (ẏ⁻ − ẏ_s) sin α + β v_t,   v_t = (ẏ⁻ − ẏ_s) sin α + ẋ⁻        (eq. 8)
//! ẏ⁺ = ẏ_s (1 + e) − e ẏ⁻                                              (eq. 9)
//! ```
//! with restitution `e` and tangential dissipation factor `β ∈ [0, 1]` (set by friction).
//! When the rebound is too slow to separate (`ẏ⁺ − ẏ_s` below a small threshold) the particle
//! rides on the string until the string's downward acceleration exceeds g, sliding with
//! Coulomb friction `μ` meanwhile. This resolves the chattering sequence that a small `e`
//! produces, which would otherwise take infinitely many impacts.
//!
//! The paper argues (eq. 10 and after) that the time-averaged horizontal force is
//! `F_avg ∝ −e A² ω sin 2x`, pointing from the antinode x = π/2 to the nodes.
//! [`force_profile`] measures the average force on a particle held at x, and [`fit_sin2x`]
//! fits it to `−c sin 2x`.

use std::f64::consts::PI;

/// Model parameters (SI units; x is the mode's phase coordinate on [0, π], in metres).
#[derive(Debug, Clone, Copy)]
pub struct Params {
    /// String amplitude A (m).
    pub amplitude: f64,
    /// Drive frequency (Hz); ω = 2π f.
    pub freq_hz: f64,
    /// Coefficient of restitution e.
    pub e: f64,
    /// Tangential dissipation factor β of eq. 8.
    pub beta: f64,
    /// Coulomb friction while riding on the string.
    pub mu: f64,
    /// Gravity (m/s²).
    pub g: f64,
}

impl Default for Params {
    fn default() -> Self {
        Params { amplitude: 0.02, freq_hz: 6.0, e: 0.9, beta: 0.5, mu: 0.3, g: 9.81 }
    }
}

impl Params {
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

/// Impact law (eqs. 8–9): returns (ẋ⁺, ẏ⁺).
fn impact(p: &Params, x: f64, t: f64, u: f64, v: f64) -> (f64, f64) {
    let ysd = p.ys_dot(x, t);
    let tan_a = p.slope(x, t);
    let sin_a = tan_a / (1.0 + tan_a * tan_a).sqrt();
    let vt = (v - ysd) * sin_a + u;
    (p.e * (v - ysd) * sin_a + p.beta * vt, ysd * (1.0 + p.e) - p.e * v)
}

/// Simulator. `hold_x` keeps the particle at its x (for force measurement): its ẋ is
/// recorded at each impact and reset to zero.
struct Sim {
    p: Params,
    s: State,
    dt: f64,
    hold_x: bool,
    impulse: f64,
    impacts: u64,
}

impl Sim {
    fn new(p: Params, x0: f64, hold_x: bool) -> Self {
        let s =
            State { t: 0.0, x: x0, y: p.ys(x0, 0.0), u: 0.0, v: p.ys_dot(x0, 0.0), riding: true };
        Sim { p, s, dt: 1.0 / (p.freq_hz * 200.0), hold_x, impulse: 0.0, impacts: 0 }
    }

    /// Separation below which a rebound counts as staying in contact (m/s).
    fn stick_speed(&self) -> f64 {
        1e-4 * self.p.amplitude * self.p.omega()
    }

    /// Advances to time `t_end`.
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
            }
        }
    }

    fn ride(&mut self, t_end: f64) {
        let p = self.p;
        let mut s = self.s;
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
            // Sliding with Coulomb friction under the normal load g + ÿ_s ≥ 0.
            if !self.hold_x {
                let normal = (p.g + p.ys_ddot(s.x, s.t)).max(0.0);
                let du = p.mu * normal * self.dt;
                s.u = if s.u.abs() <= du { 0.0 } else { s.u - du * s.u.signum() };
                s.x += s.u * self.dt;
            }
            s.t = t1;
        }
        self.s = s;
    }

    fn fly(&mut self, t_end: f64) {
        let p = self.p;
        let s0 = self.s;
        let gap = |t: f64| {
            let tau = t - s0.t;
            let x = s0.x + s0.u * tau;
            s0.y + s0.v * tau - 0.5 * p.g * tau * tau - p.ys(x, t)
        };
        let mut t = s0.t;
        loop {
            let t1 = t + self.dt;
            if gap(t1) < 0.0 {
                let (mut lo, mut hi) = (t, t1);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if gap(mid) < 0.0 { hi = mid } else { lo = mid }
                }
                let ti = lo;
                let tau = ti - s0.t;
                let x = s0.x + s0.u * tau;
                let (u, v) = impact(&p, x, ti, s0.u, s0.v - p.g * tau);
                self.impacts += 1;
                let u = if self.hold_x {
                    self.impulse += u;
                    0.0
                } else {
                    u
                };
                let riding = v - p.ys_dot(x, ti) < self.stick_speed();
                self.s = State { t: ti, x, y: p.ys(x, ti), u, v, riding };
                return;
            }
            if t1 >= t_end {
                let tau = t1 - s0.t;
                self.s = State {
                    t: t1,
                    x: s0.x + s0.u * tau,
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
    /// Number of impacts.
    pub impacts: u64,
}

/// Simulates a particle released at rest on the string at `x0` for `duration` seconds,
/// sampling x every `sample_dt` seconds.
pub fn simulate(p: &Params, x0: f64, duration: f64, sample_dt: f64) -> Trajectory {
    let mut sim = Sim::new(*p, x0, false);
    let mut samples = vec![(0.0, x0)];
    let mut t = 0.0;
    while t < duration {
        t = (t + sample_dt).min(duration);
        sim.run_until(t);
        samples.push((t, sim.s.x));
    }
    Trajectory { samples, impacts: sim.impacts }
}

/// Average horizontal force per unit mass (m/s²) on a particle held at `x`, over `duration`
/// seconds: the total ẋ the impacts give it, divided by the time.
pub fn average_force(p: &Params, x: f64, duration: f64) -> f64 {
    let mut sim = Sim::new(*p, x, true);
    sim.run_until(duration);
    sim.impulse / duration
}

/// Average force at `n` points spread over (0, π) (endpoints excluded).
pub fn force_profile(
    p: &Params,
    n: usize,
    duration: f64,
    mut progress: impl FnMut(),
) -> Vec<(f64, f64)> {
    (0..n)
        .map(|k| {
            let x = PI * (k as f64 + 0.5) / n as f64;
            let f = average_force(p, x, duration);
            progress();
            (x, f)
        })
        .collect()
}

/// Least-squares fit of `F(x) ≈ −c sin 2x`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fit {
    /// Coefficient c (m/s²).
    pub c: f64,
    /// Coefficient of determination.
    pub r2: f64,
    /// c / (e A² ω), the proportionality constant of the paper's `F_avg ∝ −e A² ω sin 2x`
    /// (units 1/(m·s)).
    pub per_e_a2_omega: f64,
}

/// Fits `−c sin 2x` to a force profile.
pub fn fit_sin2x(p: &Params, profile: &[(f64, f64)]) -> Fit {
    let s: Vec<f64> = profile.iter().map(|(x, _)| -(2.0 * x).sin()).collect();
    let sf: f64 = profile.iter().zip(&s).map(|((_, f), s)| f * s).sum();
    let ss: f64 = s.iter().map(|s| s * s).sum();
    let c = sf / ss;
    let mean = profile.iter().map(|(_, f)| f).sum::<f64>() / profile.len() as f64;
    let tot: f64 = profile.iter().map(|(_, f)| (f - mean).powi(2)).sum();
    let res: f64 = profile.iter().zip(&s).map(|((_, f), s)| (f - c * s).powi(2)).sum();
    Fit { c, r2: 1.0 - res / tot, per_e_a2_omega: c / (p.e * p.amplitude.powi(2) * p.omega()) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_e(e: f64) -> Params {
        Params { e, ..Params::default() }
    }

    #[test]
    fn impact_law_reverses_relative_normal_velocity() {
        let p = with_e(0.5);
        // At ωt = 0 the string is flat (sin α = 0) and moving up at A ω sin x.
        let x = 1.0;
        let (u, v) = impact(&p, x, 0.0, 0.2, -1.0);
        let ysd = p.ys_dot(x, 0.0);
        assert!((v - ysd - 0.5 * (ysd + 1.0)).abs() < 1e-12);
        assert!((u - 0.5 * 0.2).abs() < 1e-12, "only β·ẋ⁻ remains on a flat string: {u}");
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
        let p = with_e(0.9);
        // Near the node Γ sin x < 1: the string never throws the particle up.
        let near = simulate(&p, 0.2, 5.0, 0.5);
        assert_eq!(near.impacts, 0);
        assert!(near.samples.iter().all(|&(_, x)| (x - 0.2).abs() < 1e-12));
        let far = simulate(&p, 1.2, 20.0, 0.5);
        assert!(far.impacts > 20, "{}", far.impacts);
        assert!(far.samples.iter().all(|&(_, x)| (0.0..=PI).contains(&x)));
    }

    // The two tests below state the paper's Fig. 12 / eq. 10 claims. With eqs. 8–9 simulated
    // literally they do not hold (see docs/plate.md, "Particle on a string"): kept, ignored,
    // so that a corrected model can be checked against them.
    #[test]
    #[ignore = "eqs. 8-9 simulated literally do not reproduce Fig. 12's drift; see docs/plate.md"]
    fn particle_drifts_to_the_nearest_node_faster_for_high_restitution() {
        let left_hi = simulate(&with_e(0.9), 1.2, 60.0, 1.0);
        let left_lo = simulate(&with_e(0.1), 1.2, 60.0, 1.0);
        let (xh, xl) = (left_hi.samples.last().unwrap().1, left_lo.samples.last().unwrap().1);
        println!("x(60 s) from 1.2: e = 0.9 → {xh:.3}, e = 0.1 → {xl:.3}");
        assert!(xh < xl, "e = 0.9 should be nearer the node: {xh} vs {xl}");
        assert!(xl < 1.2 - 0.05, "e = 0.1 should still drift toward x = 0: {xl}");
        assert!(xh < 0.5, "e = 0.9 should be close to the node: {xh}");
        // Mirror image: from the other half it goes to x = π.
        let right = simulate(&with_e(0.9), PI - 1.2, 60.0, 1.0);
        assert!(right.samples.last().unwrap().1 > PI - 0.5);
    }

    #[test]
    #[ignore = "eqs. 8-9 simulated literally give an erratic averaged force; see docs/plate.md"]
    fn averaged_force_follows_minus_sin_2x_and_grows_with_e() {
        let fits: Vec<Fit> = [0.9, 0.1]
            .iter()
            .map(|&e| {
                let p = with_e(e);
                let prof = force_profile(&p, 12, 20.0, || {});
                let fit = fit_sin2x(&p, &prof);
                println!(
                    "e = {e}: c = {:.4} m/s², R² = {:.3}, c/(eA²ω) = {:.0}",
                    fit.c, fit.r2, fit.per_e_a2_omega
                );
                fit
            })
            .collect();
        assert!(fits[0].c > 0.0 && fits[1].c > 0.0);
        assert!(fits[0].c > 2.0 * fits[1].c, "{fits:?}");
        assert!(fits[0].r2 > 0.8, "{fits:?}");
    }
}
