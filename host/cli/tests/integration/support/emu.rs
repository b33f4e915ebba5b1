//! The one way the host's integration tests start the emulated controller (the QEMU board
//! behind the link proxy) and put plans on it: a scratch flash and log in the temp folder named
//! after the test and the process, QEMU killed after a time limit whatever the test does, and a
//! failed start reported with the log's tail. (The end-to-end crate, tests/, has its own
//! `start_emulator` in tests/lib.rs: the same, but its logs and flash files stay in
//! target/e2e-logs for CI to keep, and `CHLADNI_PORT` swaps in a real board.)
// Each includer uses only part of it.
#![allow(dead_code)]

use std::time::Duration;

use chladni_device::emulator::{Emulator, EmulatorConfig};
use chladni_shared::icd::plan::{Level, Plan, Step};
use chladni_shared::icd::store::PlanSummary;

/// Time limit of a test's emulator unless the test says otherwise.
pub const TIME_LIMIT: Duration = Duration::from_secs(300);

/// Starts a controller for test `name` (scratch flash and log, [`TIME_LIMIT`]).
pub fn emulator(name: &str) -> Emulator {
    emulator_for(name, TIME_LIMIT)
}

/// [`emulator`] killed after `limit`.
pub fn emulator_for(name: &str, limit: Duration) -> Emulator {
    start(&EmulatorConfig::scratch(name, limit))
}

/// Starts `config`; panics with the end of its log when the controller does not come up.
pub fn start(config: &EmulatorConfig) -> Emulator {
    Emulator::start(config).unwrap_or_else(|e| {
        let log = config.log_file.as_ref().and_then(|p| std::fs::read_to_string(p).ok());
        let log = log.unwrap_or_default();
        let tail = &log[log.len().saturating_sub(4_000)..];
        panic!("the emulator did not start: {e}\nlog tail:\n{tail}")
    })
}

/// An open-loop plan `name`, run once: one step at `drive` (Q15) per frequency in `freq_mhz`,
/// each `duration_ms` long with a 50 ms ramp.
pub fn open_loop_plan(name: &str, freq_mhz: &[u32], drive: u16, duration_ms: u32) -> Plan {
    let steps: Vec<Step> = freq_mhz
        .iter()
        .map(|&freq_mhz| Step { freq_mhz, level: Level::Drive(drive), duration_ms, ramp_ms: 50 })
        .collect();
    Plan {
        name: heapless::String::try_from(name).unwrap(),
        repeat: 1,
        steps: heapless::Vec::from_slice(&steps).unwrap(),
    }
}

/// Uploads `plan` into `slot` over a session of its own, released when this returns (so
/// another session, a cell's for one, may run it).
pub fn upload(emu: &Emulator, plan: &Plan, slot: u8) -> PlanSummary {
    let mut client = emu.connect("test upload").expect("connect to the emulator");
    client.upload(plan, Some(slot), |_, _| {}).expect("upload the plan")
}
