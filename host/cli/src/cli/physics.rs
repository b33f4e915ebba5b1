//! `chladni physics ...`: the physics models behind the field model.

use crate::cli::progress::Bar;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use super::parse::{f64_where, non_negative, positive, unit_interval, usize_in};
use super::{InputError, check_plot, plot_error};
use chladni_core::motion::string::{self, Experiment, StringParams};
use chladni_media::plot::string::string_figure;

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
    #[arg(long, value_parser = unit_interval("e"))]
    e: f64,
    /// Coulomb friction coefficient (impacts and sliding).
    #[arg(long, default_value_t = StringParams::default().mu, value_parser = non_negative("mu"))]
    mu: f64,
    /// Tangential impact law of the paper's eq. 8 with a constant dissipation factor β
    /// (w_t⁺ = β w_t) instead of Coulomb friction at impacts (μ still acts in contact).
    #[arg(long, value_parser = unit_interval("beta"))]
    beta: Option<f64>,
    /// String amplitude A (m; the string spans x ∈ [0, π] m).
    #[arg(long, default_value_t = StringParams::default().amplitude, value_parser = positive("amplitude"))]
    amplitude: f64,
    /// Drive frequency (Hz).
    #[arg(long, default_value_t = StringParams::default().freq_hz, value_parser = positive("freq-hz"))]
    freq_hz: f64,
    /// Start position x0.
    #[arg(long, default_value_t = 1.2,
          value_parser = f64_where("x0", "in (0, π)", |v| v > 0.0 && v < std::f64::consts::PI))]
    x0: f64,
    /// Release height above the string's mean position (m; 0 = at rest on the string).
    /// Default: the period-1 bounce height g/(8 f²).
    #[arg(long, value_parser = f64_where("drop", "≥ 0", |v| v.is_finite() && v >= 0.0))]
    drop: Option<f64>,
    /// Simulated time (s).
    #[arg(long, default_value_t = 300.0,
          value_parser = f64_where("duration", "in (0, 1e5]", |v| v > 0.0 && v <= 1e5))]
    duration: f64,
    /// Averaging time per particle of the force profile (s; 8 particles per point).
    #[arg(long, default_value_t = 10.0,
          value_parser = f64_where("average", "in (0, 1e4]", |v| v > 0.0 && v <= 1e4))]
    average: f64,
    /// Write a figure (PNG or SVG, by the extension): x(t) and the averaged drift with its
    /// −c·sin 2x fit.
    #[arg(long, value_name = "FILE")]
    plot: Option<PathBuf>,
    /// Trajectory samples `[t, x]` in the `--json` report (first and last included).
    #[arg(long, default_value_t = string::JSON_SAMPLES,
          value_parser = usize_in("samples", 2, 100_000))]
    samples: usize,
    /// Print JSON.
    #[arg(long)]
    json: bool,
}

impl StringArgs {
    fn run(&self) -> anyhow::Result<ExitCode> {
        check_plot("--plot", &self.plot, &["png", "svg"], &[])?;
        let p = StringParams {
            amplitude: self.amplitude,
            freq_hz: self.freq_hz,
            e: self.e,
            mu: self.mu,
            g: StringParams::default().g,
            beta: self.beta,
        };
        let drop = self.drop.unwrap_or(string::period1_drop(&p));
        if !(drop.is_finite() && drop >= 0.0) {
            return Err(InputError(format!("--drop must be ≥ 0, got {drop}")).into());
        }
        let bar = ProgressBar::new(string::PROFILE_POINTS as u64 + 1).with_style(
            ProgressStyle::with_template("simulating {bar:30} {pos}/{len}")
                .unwrap_or(ProgressStyle::default_bar()),
        );
        let run = (self.duration, self.samples - 1);
        let ex = string::experiment(&p, self.x0, drop, run, self.average, &Bar(bar.clone()));
        bar.finish_and_clear();
        if let Some(path) = &self.plot {
            string_figure(path, &ex).map_err(plot_error)?;
        }
        if self.json {
            println!("{}", serde_json::to_string(&ex.report(self.samples))?);
        } else {
            print_experiment(&ex);
        }
        Ok(ExitCode::SUCCESS)
    }
}

fn print_experiment(ex: &Experiment) {
    let p = &ex.params;
    println!(
        "e = {}, μ = {}, A = {} m, f = {} Hz (Γ = Aω²/g = {:.2})",
        p.e,
        p.mu,
        p.amplitude,
        p.freq_hz,
        p.gamma()
    );
    let stats = &ex.trajectory.stats;
    println!(
        "x: {:.3} → {:.3} after {} s (dropped from {:.3} m; {} impacts, {:.0}% above the mean)",
        ex.x0,
        ex.x_end(),
        ex.duration_s,
        ex.drop_m,
        stats.impacts,
        100.0 * stats.above_fraction()
    );
    println!(
        "averaged drift ≈ −c·sin 2x: c = {:.2e} m/s (> 0: towards the nodes), R² = {:.3}, c/(e A² ω) = {:.3}",
        ex.fit.c, ex.fit.r2, ex.fit.per_e_a2_omega
    );
    let threshold = ex.threshold;
    match ex.stop_x {
        Some(x) => println!(
            "bouncing needs Γ sin x ≥ π(1−e)/(1+e) = {threshold:.3}: the drift towards the nodes stops at x = {x:.3} and {:.3}",
            std::f64::consts::PI - x
        ),
        None => println!(
            "bouncing needs Γ sin x ≥ π(1−e)/(1+e) = {threshold:.3} > Γ: the particle locks onto the string everywhere (from x0 = {} it needs --freq-hz > {:.2})",
            ex.x0,
            ex.min_bouncing_freq_hz()
        ),
    }
}
