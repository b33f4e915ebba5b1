//! `chladni physics ...`: the physics models behind the field model.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use plotters::prelude::*;
use serde_json::json;

use super::InputError;
use chladni::motion::string::{self, Params};
use chladni::plot::plate::ensure_font;

#[derive(Debug, Subcommand)]
pub enum PhysicsCommand {
    /// Particle bouncing on a vibrating string (paper Appendix, eqs. 8–10, Fig. 12).
    String(StringArgs),
}

impl PhysicsCommand {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        match self {
            PhysicsCommand::String(a) => a.run(),
        }
    }
}

#[derive(Debug, Args)]
pub struct StringArgs {
    /// Coefficient of restitution, in [0, 1].
    #[arg(long)]
    e: f64,
    /// Coulomb friction coefficient (impacts and sliding).
    #[arg(long, default_value_t = Params::default().mu)]
    mu: f64,
    /// Tangential impact law of the paper's eq. 8 with a constant dissipation factor β
    /// (w_t⁺ = β w_t) instead of Coulomb friction at impacts (μ still acts in contact).
    #[arg(long)]
    beta: Option<f64>,
    /// String amplitude A (m; the string spans x ∈ [0, π] m).
    #[arg(long, default_value_t = Params::default().amplitude)]
    amplitude: f64,
    /// Drive frequency (Hz).
    #[arg(long, default_value_t = Params::default().freq_hz)]
    freq_hz: f64,
    /// Start position x0.
    #[arg(long, default_value_t = 1.2)]
    x0: f64,
    /// Release height above the string's mean position (m; 0 = at rest on the string).
    /// Default: the period-1 bounce height g/(8 f²).
    #[arg(long)]
    drop: Option<f64>,
    /// Simulated time (s).
    #[arg(long, default_value_t = 300.0)]
    duration: f64,
    /// Averaging time per particle of the force profile (s; 8 particles per point).
    #[arg(long, default_value_t = 10.0)]
    average: f64,
    /// Write a PNG: x(t) and the averaged force with its −c·sin 2x fit.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

impl StringArgs {
    fn run(&self) -> anyhow::Result<ExitCode> {
        let unit = |name: &str, v: f64| -> Result<(), InputError> {
            if (0.0..=1.0).contains(&v) {
                Ok(())
            } else {
                Err(InputError(format!("--{name} must be in [0, 1], got {v}")))
            }
        };
        unit("e", self.e)?;
        if let Some(b) = self.beta {
            unit("beta", b)?;
        }
        for (name, v) in [("mu", self.mu), ("amplitude", self.amplitude), ("freq-hz", self.freq_hz)]
        {
            if !(v.is_finite() && v >= 0.0) || (name != "mu" && v == 0.0) {
                return Err(InputError(format!("--{name} must be positive, got {v}")).into());
            }
        }
        if !(self.x0 > 0.0 && self.x0 < std::f64::consts::PI) {
            return Err(InputError(format!("--x0 must be in (0, π), got {}", self.x0)).into());
        }
        if !(self.duration > 0.0
            && self.duration <= 1e5
            && self.average > 0.0
            && self.average <= 1e4)
        {
            return Err(InputError(format!(
                "--duration must be in (0, 1e5] and --average in (0, 1e4], got {} and {}",
                self.duration, self.average
            ))
            .into());
        }
        let p = Params {
            amplitude: self.amplitude,
            freq_hz: self.freq_hz,
            e: self.e,
            mu: self.mu,
            g: Params::default().g,
            beta: self.beta,
        };
        let points = 16;
        let bar = ProgressBar::new(points as u64 + 1).with_style(
            ProgressStyle::with_template("simulating {bar:30} {pos}/{len}")
                .unwrap_or(ProgressStyle::default_bar()),
        );
        let drop = self.drop.unwrap_or(p.g / (8.0 * p.freq_hz * p.freq_hz));
        if !(drop.is_finite() && drop >= 0.0) {
            return Err(InputError(format!("--drop must be ≥ 0, got {drop}")).into());
        }
        let traj = string::simulate(&p, self.x0, drop, self.duration, self.duration / 600.0);
        bar.inc(1);
        let profile = string::force_profile(&p, points, self.average, 8, || bar.inc(1));
        bar.finish_and_clear();
        let fit = string::fit_sin2x(&p, &profile);
        let x_end = traj.samples.last().map_or(self.x0, |s| s.1);
        let threshold = string::bounce_threshold(p.e);
        let stop = string::stop_position(&p);

        if let Some(path) = &self.plot {
            plot(path, &p, &traj, &profile, &fit, stop)
                .with_context(|| format!("plotting {}", path.display()))?;
        }
        if self.json {
            println!(
                "{}",
                json!({
                    "params": {"e": p.e, "mu": p.mu, "beta": p.beta, "amplitude_m": p.amplitude,
                               "freq_hz": p.freq_hz, "gamma": p.gamma()},
                    "trajectory": {"x0": self.x0, "drop_m": drop, "x_end": x_end, "duration_s": self.duration,
                                   "impacts": traj.stats.impacts, "impacts_above_mean": traj.stats.above_mean,
                                   "samples": traj.samples.iter().step_by(10).map(|s| [s.0, s.1]).collect::<Vec<_>>()},
                    "force": profile.iter().map(|(x, f)| [*x, *f]).collect::<Vec<_>>(),
                    "fit": {"model": "F = -c sin 2x", "c": fit.c, "r2": fit.r2, "c_per_e_a2_omega": fit.per_e_a2_omega},
                    "bouncing": {"threshold_gamma_sin_x": threshold, "stop_x": stop},
                })
            );
        } else {
            println!(
                "e = {}, μ = {}, A = {} m, f = {} Hz (Γ = Aω²/g = {:.2})",
                p.e,
                p.mu,
                p.amplitude,
                p.freq_hz,
                p.gamma()
            );
            println!(
                "x: {:.3} → {:.3} after {} s (dropped from {:.3} m; {} impacts, {:.0}% above the mean)",
                self.x0,
                x_end,
                self.duration,
                drop,
                traj.stats.impacts,
                100.0 * traj.stats.above_fraction()
            );
            println!(
                "averaged force ≈ −c·sin 2x: c = {:.4} m/s², R² = {:.3}, c/(e A² ω) = {:.3}",
                fit.c, fit.r2, fit.per_e_a2_omega
            );
            match stop {
                Some(x) => println!(
                    "bouncing needs Γ sin x ≥ π(1−e)/(1+e) = {threshold:.3}: the drift towards the nodes stops at x = {x:.3} and {:.3}",
                    std::f64::consts::PI - x
                ),
                None => {
                    // Γ ∝ f²: the frequency at which the start x0 can just keep bouncing.
                    let f_min = p.freq_hz * (threshold / (p.gamma() * self.x0.sin())).sqrt();
                    println!(
                        "bouncing needs Γ sin x ≥ π(1−e)/(1+e) = {threshold:.3} > Γ: the particle locks onto the string everywhere (from x0 = {} it needs --freq-hz > {f_min:.2})",
                        self.x0
                    );
                }
            }
        }
        Ok(ExitCode::SUCCESS)
    }
}

fn plot(
    path: &std::path::Path,
    p: &Params,
    traj: &string::Trajectory,
    profile: &[(f64, f64)],
    fit: &string::Fit,
    stop: Option<f64>,
) -> anyhow::Result<()> {
    ensure_font();
    let root = BitMapBackend::new(path, (900, 360)).into_drawing_area();
    root.fill(&WHITE)?;
    let (left, right) = root.split_horizontally(450);
    let t_end = traj.samples.last().map_or(1.0, |s| s.0);
    let mut c = ChartBuilder::on(&left)
        .caption(
            format!("particle on a string, e = {}, Γ = {:.2}", p.e, p.gamma()),
            ("sans-serif", 16),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(40)
        .build_cartesian_2d(0.0..t_end, 0.0..std::f64::consts::PI)?;
    c.configure_mesh().x_desc("time (s)").y_desc("x").label_style(("sans-serif", 11)).draw()?;
    c.draw_series(LineSeries::new(traj.samples.iter().copied(), BLUE.stroke_width(2)))?;
    // Where bouncing ends (Γ sin x = π(1−e)/(1+e)): the drift stops on these lines.
    for x in stop.into_iter().flat_map(|x| [x, std::f64::consts::PI - x]) {
        c.draw_series(DashedLineSeries::new(
            [(0.0, x), (t_end, x)],
            6,
            4,
            RGBColor(120, 120, 120).stroke_width(1),
        ))?;
    }
    let fmax = profile.iter().map(|(_, f)| f.abs()).fold(fit.c.abs(), f64::max).max(1e-9) * 1.1;
    let mut c = ChartBuilder::on(&right)
        .caption(
            format!("avg force, fit -c sin 2x: c = {:.3}, R² = {:.2}", fit.c, fit.r2),
            ("sans-serif", 14),
        )
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..std::f64::consts::PI, -fmax..fmax)?;
    c.configure_mesh().x_desc("x").y_desc("F (m/s²)").label_style(("sans-serif", 11)).draw()?;
    c.draw_series(profile.iter().map(|&(x, f)| Circle::new((x, f), 4, RED.filled())))?;
    c.draw_series(LineSeries::new(
        (0..=100).map(|k| {
            let x = std::f64::consts::PI * k as f64 / 100.0;
            (x, -fit.c * (2.0 * x).sin())
        }),
        BLACK.stroke_width(2),
    ))?;
    root.present()?;
    Ok(())
}
