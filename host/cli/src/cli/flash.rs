//! `chladni flash`: writes the board firmware through a debug probe (see docs/flash.md).

use std::path::PathBuf;
use std::process::ExitCode;

use chladni_device::flash::{self, FlashError, ProbeSelector};
use chladni_device::json::FlashJson;
use chladni_shared::icd::link::Board;
use clap::Args;
use indicatif::{MultiProgress, ProgressBar, ProgressStyle};
use probe_rs::flashing::{ProgressEvent, ProgressOperation};

use super::InputError;

#[derive(Debug, Args)]
pub struct FlashArgs {
    /// Target chip, as probe-rs names it.
    #[arg(long, default_value = flash::DEFAULT_CHIP)]
    chip: String,
    /// Debug probe to use when several are attached: VID:PID[:SERIAL], VID and PID in hex.
    #[arg(long, value_name = "VID:PID[:SERIAL]", value_parser = parse_selector)]
    probe: Option<ProbeSelector>,
    /// Firmware ELF to flash (default: build the board image with scripts/firmware.sh).
    #[arg(long)]
    elf: Option<PathBuf>,
    /// Do not read the flash back to compare after programming.
    #[arg(long)]
    no_verify: bool,
    /// Print one JSON object instead of progress bars and a summary.
    #[arg(long)]
    json: bool,
}

fn parse_selector(text: &str) -> Result<ProbeSelector, String> {
    text.parse()
}

/// Bad input exits 2, everything else 1.
fn classify(err: FlashError) -> anyhow::Error {
    if err.is_bad_input() { InputError(err.to_string()).into() } else { err.into() }
}

impl FlashArgs {
    pub fn run(&self) -> anyhow::Result<ExitCode> {
        let target = flash::find_target(&self.chip).map_err(classify)?;
        let elf = match &self.elf {
            Some(path) => path.clone(),
            None => chladni_device::firmware::build(Board::Stm32l475)?,
        };
        let image = flash::check_image(&elf, &flash::flash_region()?).map_err(classify)?;
        let probes = flash::list_probes();
        let index = flash::choose_probe(&probes.descs, self.probe.as_ref()).map_err(classify)?;
        let probe = probes.descs[index].to_string();
        if !self.json {
            eprintln!(
                "flashing {} ({} bytes) to {} via {probe}",
                elf.display(),
                image.bytes(),
                target.name
            );
        }
        let chip = target.name.clone();
        let mut bars = Bars::new(self.json);
        let report = flash::flash(&image, target, &probes, index, !self.no_verify, |event| {
            bars.update(event)
        })?;
        if self.json {
            println!("{}", serde_json::to_string(&FlashJson::of(&image, &chip, &probe, &report))?);
        } else {
            let secs = report.duration.as_secs_f64();
            let verified = if report.verified { ", verified" } else { "" };
            println!(
                "flashed {} bytes to {chip} in {secs:.1} s{verified}; the core is running",
                report.bytes
            );
        }
        Ok(ExitCode::SUCCESS)
    }
}

/// One progress bar per operation (erase, program, verify), created as probe-rs announces them.
struct Bars {
    multi: MultiProgress,
    hidden: bool,
    bars: Vec<(&'static str, ProgressBar)>,
}

impl Bars {
    fn new(hidden: bool) -> Self {
        Bars { multi: MultiProgress::new(), hidden, bars: Vec::new() }
    }

    fn name(op: ProgressOperation) -> &'static str {
        match op {
            ProgressOperation::Fill => "reading",
            ProgressOperation::Erase => "erasing",
            ProgressOperation::Program => "programming",
            ProgressOperation::Verify => "verifying",
        }
    }

    fn bar(&mut self, op: ProgressOperation) -> Option<&ProgressBar> {
        let name = Self::name(op);
        self.bars.iter().find(|(n, _)| *n == name).map(|(_, bar)| bar)
    }

    fn update(&mut self, event: ProgressEvent) {
        if self.hidden {
            return;
        }
        match event {
            ProgressEvent::AddProgressBar { operation, total } => {
                let bar = self.multi.add(ProgressBar::new(total.unwrap_or(0)));
                let template = "{msg:>12} {wide_bar} {bytes}/{total_bytes} [{elapsed}]";
                if let Ok(style) = ProgressStyle::with_template(template) {
                    bar.set_style(style);
                }
                bar.set_message(Self::name(operation));
                self.bars.push((Self::name(operation), bar));
            }
            ProgressEvent::Progress { operation, size, .. } => {
                self.bar(operation).inspect(|bar| bar.inc(size));
            }
            ProgressEvent::Finished(operation) => {
                self.bar(operation).inspect(|bar| bar.finish());
            }
            ProgressEvent::Failed(operation) => {
                self.bar(operation).inspect(|bar| bar.abandon_with_message("failed"));
            }
            ProgressEvent::DiagnosticMessage { message } => {
                let _ = self.multi.println(message);
            }
            ProgressEvent::FlashLayoutReady { .. } | ProgressEvent::Started(_) => {}
        }
    }
}
