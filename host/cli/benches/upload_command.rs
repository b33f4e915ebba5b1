//! Whole commands against the QEMU controller, as a user runs them: `chladni device upload` of
//! a 256-step plan file (process start, connection, session, upload, commit, answer), and
//! `chladni device info` and `ping` for scale. The link's requests one by one are in the e2e
//! crate's bench (`cargo bench -p chladni-e2e --bench link`).
//!
//! `cargo bench -p chladni --bench upload_command` (builds the QEMU firmware if needed).
//! QEMU's clock follows the host's: these are wall-clock times on this machine, with QEMU's
//! semihosting file flash.

use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use chladni_device::emulator::{Emulator, EmulatorConfig};

/// A 256-step open-loop plan file whose steps all differ (as the e2e link bench's plans).
fn write_plan(path: &Path) {
    let steps: Vec<serde_json::Value> = (0..256u32)
        .map(|i| {
            serde_json::json!({
                "freq_hz": f64::from(50_000 + (i * 7_919 + 7 * 104_729) % 1_900_000) / 1000.0,
                "duration_ms": 5 + i % 40,
                "amplitude": f64::from((i * 131 + 7) % 30_000) / 32_767.0,
                "ramp_ms": i % 5,
            })
        })
        .collect();
    let plan = serde_json::json!({ "name": "bench-256", "repeat": 1, "steps": steps });
    std::fs::write(path, plan.to_string()).expect("write the plan file");
}

/// Runs `chladni ARGS` to success; returns its wall-clock time.
fn time_command(args: &[&str]) -> Duration {
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_chladni")).args(args).output().expect("run");
    let took = start.elapsed();
    assert!(out.status.success(), "chladni {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    took
}

/// min / median / 90th percentile / max, ms.
fn summary(label: &str, mut times: Vec<Duration>) {
    times.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    let at = |q: f64| ms(times[((times.len() - 1) as f64 * q).round() as usize]);
    println!(
        "{label:<44} n={:<3} min {:7.2} ms  median {:7.2} ms  p90 {:7.2} ms  max {:7.2} ms",
        times.len(),
        ms(times[0]),
        at(0.5),
        at(0.9),
        ms(*times.last().expect("timed at least once"))
    );
}

fn main() {
    let config = EmulatorConfig::scratch("bench-upload-command", Duration::from_secs(600));
    let emulator = Emulator::start(&config).expect("emulator");
    let port = emulator.address();
    let plan = std::env::temp_dir().join(format!("chladni-bench-{}.json", std::process::id()));
    write_plan(&plan);
    let plan_arg = plan.to_str().expect("UTF-8 temp path");

    let info: Vec<_> =
        (0..20).map(|_| time_command(&["device", "info", "--port", &port])).collect();
    summary("chladni device info (whole command)", info);
    let ping = (0..20).map(|_| time_command(&["device", "ping", "--port", &port])).collect();
    summary("chladni device ping (whole command)", ping);
    // Slots 0..8 in turn, each under its own name: each upload replaces a plan, as a user
    // re-uploading does.
    let upload = (0..40u32)
        .map(|i| {
            let (slot, name) = ((i % 8).to_string(), format!("bench-{}", i % 8));
            let args = ["device", "upload", "--port", &port, "--slot", &slot, "--name", &name];
            time_command(&[&args[..], &[plan_arg]].concat())
        })
        .collect();
    summary("chladni device upload, 256 steps (whole command)", upload);
    let _ = std::fs::remove_file(&plan);
}
