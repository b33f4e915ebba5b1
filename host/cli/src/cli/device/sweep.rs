//! `chladni device sweep`: the plate's frequency response and its resonances.
//!
//! Every input is checked before connecting (the sweep's shape as the controller checks it,
//! the output files and the plate file to append to), so bad input exits 2 at once. The sweep
//! is a run: the progress bar follows it (points × dwell), Ctrl-C stops the drive (exit 130),
//! a fault ends it with the cause. Then the points are fetched, the resonances found
//! ([`chladni_device::sweep`]), and the results written: CSV, Bode plot, `[[mode]]`
//! entries, a table or JSON.

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Instant;

use anyhow::Context;
use chladni_core::model::modes_file::{self, measured_mode};
use chladni_core::model::plate_file::{PlateFile, PlateTable};
use chladni_device::client::{DeviceClient, RunOutcome};
use chladni_device::sweep::{
    Resonance, SweepSample, find_resonances, sweep_ms, sweep_request, to_csv,
};
use chladni_shared::icd::link::{RunNumber, Sweep};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use super::PortArg;
use super::render::{fault_text, print_json};
use super::watch::{EXIT_INTERRUPTED, interrupt_flag};
use crate::cli::{InputError, check_output, check_plot, output_error, plot_error};
use chladni_device::json::SweepJson;

/// `device sweep`.
#[derive(Debug, Args)]
pub struct SweepArgs {
    #[command(flatten)]
    port: PortArg,
    /// First frequency, Hz.
    #[arg(long, value_name = "HZ")]
    from: f64,
    /// Last frequency, Hz (above --from; points are spaced geometrically).
    #[arg(long, value_name = "HZ")]
    to: f64,
    /// Number of points (2..=200).
    #[arg(long, value_name = "N", default_value_t = 100)]
    points: u16,
    /// Drive amplitude, fraction of full scale (open loop).
    #[arg(long, value_name = "A", default_value_t = 0.1)]
    amplitude: f64,
    /// Time at each point before it is measured, ms (10..=10000).
    #[arg(long = "dwell-ms", value_name = "MS", default_value_t = 150)]
    dwell_ms: u32,
    /// Write the points as CSV: freq_hz,accel_mps2,phase_deg.
    #[arg(long, value_name = "sweep.csv")]
    out: Option<PathBuf>,
    /// Draw the Bode plot (PNG, or SVG for a .svg name).
    #[arg(long, value_name = "sweep.png|sweep.svg")]
    plot: Option<PathBuf>,
    /// Print JSON: {"points":[{"freq_hz","accel_mps2","phase_deg"}],"resonances":[{"freq_hz","q"}]}.
    #[arg(long)]
    json: bool,
    /// Append each resonance to this plate file as a `[[mode]]` with its frequency and no node
    /// (fill the node from `chladni plate modes` or a photo before planning with it).
    #[arg(long = "write-modes", value_name = "PLATE.toml")]
    write_modes: Option<PathBuf>,
}

impl SweepArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let sweep = sweep_request(self.from, self.to, self.points, self.amplitude, self.dwell_ms)
            .map_err(|e| InputError(format!("sweep refused: {e}")))?;
        let plate = self.check_outputs()?;
        let mut client = self.port.open("sweep")?;
        let interrupted = interrupt_flag()?;
        let run = client.sweep(sweep)?;
        if !self.json {
            eprintln!(
                "sweeping {:.3}–{:.3} Hz, {} points at amplitude {}, {} ms each (run {}; Ctrl-C \
                 stops it)",
                self.from, self.to, sweep.points, self.amplitude, sweep.dwell_ms, run.0
            );
        }
        let outcome = follow(&mut client, &sweep, run, || interrupted.load(Ordering::SeqCst))?;
        match outcome {
            RunOutcome::Done(_) => {}
            RunOutcome::Interrupted(_) => {
                let stop = client.stop()?;
                eprintln!(
                    "interrupted: stopped the sweep (run {}; the stop is run {})",
                    run.0, stop.0
                );
                return Ok(ExitCode::from(EXIT_INTERRUPTED));
            }
            RunOutcome::Faulted(s) => {
                anyhow::bail!(
                    "the drive faulted during the sweep (run {}): {}",
                    run.0,
                    fault_text(&s)
                )
            }
            RunOutcome::Superseded(s) => anyhow::bail!(
                "the sweep (run {}) was superseded by run {} (a stop, drive, plan or sweep from \
                 this or another client)",
                run.0,
                s.run.0
            ),
            RunOutcome::NeverStarted(s) => anyhow::bail!(
                "the sweep (run {}) never started: the controller still shows run {}",
                run.0,
                s.run.0
            ),
        }
        let samples: Vec<SweepSample> =
            client.sweep_points(run)?.iter().map(SweepSample::from).collect();
        drop(client);
        let resonances = find_resonances(&samples);
        self.write_outputs(&samples, &resonances, plate)?;
        if self.json {
            print_json(&SweepJson { points: &samples, resonances: &resonances })?;
        } else {
            print!("{}", table(&samples, &resonances));
        }
        Ok(ExitCode::SUCCESS)
    }

    /// Checks the outputs before connecting; returns the plate file to append to (loaded now,
    /// so a broken one is bad input before the sweep runs), if any.
    fn check_outputs(&self) -> anyhow::Result<Option<PlateFile>> {
        let modes = self.write_modes.as_deref();
        let inputs: Vec<(&str, &std::path::Path)> =
            modes.map(|p| ("plate", p)).into_iter().collect();
        check_plot("--plot", &self.plot, &chladni_media::plot::FIGURE_EXTENSIONS, &inputs)?;
        if let Some(out) = &self.out {
            check_output("--out", out, &inputs)?;
        }
        let Some(path) = modes else { return Ok(None) };
        if !path.exists() {
            return Ok(None);
        }
        let file = PlateFile::load(path).map_err(|e| InputError(format!("--write-modes: {e}")))?;
        Ok(Some(file))
    }

    fn write_outputs(
        &self,
        samples: &[SweepSample],
        resonances: &[Resonance],
        plate: Option<PlateFile>,
    ) -> anyhow::Result<()> {
        if let Some(out) = &self.out {
            chladni_core::output::write_atomic(out, to_csv(samples).as_bytes())
                .map_err(output_error)?;
        }
        if let Some(plot) = &self.plot {
            let title =
                format!("sweep {:.3}–{:.3} Hz, amplitude {}", self.from, self.to, self.amplitude);
            chladni_media::plot::bode::bode_figure(plot, &title, samples, resonances)
                .map_err(plot_error)?;
        }
        if let Some(path) = &self.write_modes {
            let mut file = plate.unwrap_or_else(|| PlateFile {
                plate: PlateTable { name: "from sweep".into(), ..PlateTable::default() },
                mode: Vec::new(),
                learned: None,
            });
            file.mode.extend(resonances.iter().map(|r| measured_mode(r.freq_hz, r.q)));
            let text = modes_file::render(&file.plate, file.mode)
                .with_context(|| format!("rendering {}", path.display()))?;
            chladni_core::output::write_atomic(path, text.as_bytes()).map_err(output_error)?;
        }
        Ok(())
    }
}

/// Follows sweep `run` with a progress bar (its length is points × dwell) until it is over or
/// `interrupted()`.
fn follow(
    client: &mut DeviceClient,
    sweep: &Sweep,
    run: RunNumber,
    interrupted: impl Fn() -> bool,
) -> anyhow::Result<RunOutcome> {
    let total = sweep_ms(sweep);
    let bar = ProgressBar::new(total.max(1));
    bar.set_style(
        ProgressStyle::with_template("{bar:40.cyan/blue} {percent:>3}%  {msg}  (~{eta} left)")
            .expect("static template"),
    );
    let start = Instant::now();
    let outcome = client.wait_for_run(run, |s| {
        if interrupted() {
            return ControlFlow::Break(());
        }
        bar.set_position((start.elapsed().as_millis() as u64).min(total));
        let measured = s.measured.map_or("-".into(), |m| {
            format!("{:.3} m/s²", chladni_shared::icd::units::MmPerS2(m.accel_mmps2).to_mps2())
        });
        bar.set_message(format!(
            "{:.3} Hz  {measured}",
            chladni_shared::icd::units::MilliHz(s.freq_mhz).to_hz()
        ));
        ControlFlow::Continue(())
    });
    bar.finish_and_clear();
    Ok(outcome?)
}

/// The table for people: the resonances, then a count of the points.
fn table(samples: &[SweepSample], resonances: &[Resonance]) -> String {
    let measured = samples.iter().filter(|s| s.accel_mps2.is_some()).count();
    let mut out = format!("{} point(s), {measured} measured\n", samples.len());
    if resonances.is_empty() {
        out.push_str("no resonance found (widen the range, add points, or raise --amplitude)\n");
        return out;
    }
    out.push_str("resonance  freq (Hz)  peak (m/s²)      Q\n");
    for (i, r) in resonances.iter().enumerate() {
        let q = r.q.map_or("-".to_string(), |q| format!("{q:.1}"));
        out.push_str(&format!(
            "{:>9}  {:>9.3}  {:>11.3}  {q:>5}\n",
            i + 1,
            r.freq_hz,
            r.accel_mps2
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_json_and_table_have_the_documented_shape() {
        let samples = [
            SweepSample { freq_hz: 100.0, accel_mps2: Some(1.5), phase_deg: Some(-10.0) },
            SweepSample { freq_hz: 110.0, accel_mps2: None, phase_deg: None },
        ];
        let res = [
            Resonance { freq_hz: 181.5, q: Some(47.62), accel_mps2: 24.3 },
            Resonance { freq_hz: 412.0, q: None, accel_mps2: 3.0 },
        ];
        let v = serde_json::to_value(SweepJson { points: &samples, resonances: &res }).unwrap();
        assert_eq!(
            v,
            serde_json::json!({
                "points": [
                    {"freq_hz": 100.0, "accel_mps2": 1.5, "phase_deg": -10.0},
                    {"freq_hz": 110.0, "accel_mps2": null, "phase_deg": null}
                ],
                "resonances": [{"freq_hz": 181.5, "q": 47.62}, {"freq_hz": 412.0, "q": null}]
            })
        );
        let t = table(&samples, &res);
        assert_eq!(
            t,
            "2 point(s), 1 measured\nresonance  freq (Hz)  peak (m/s²)      Q\n        1    181.500       \
             24.300   47.6\n        2    412.000        3.000      -\n"
        );
        assert!(table(&samples, &[]).contains("no resonance found"));
    }
}
