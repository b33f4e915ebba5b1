//! Helpers shared by the end-to-end tests: start the emulated controller the same way
//! `chladni emulator` does, with a time limit and a log file per test.

use std::path::PathBuf;
use std::time::Duration;

use chladni::emulator::{Emulator, EmulatorConfig};

/// Longest any one emulator may live: QEMU is killed after this even if the test hangs.
pub const EMULATOR_TIME_LIMIT: Duration = Duration::from_secs(600);

/// The workspace root.
pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().unwrap().to_path_buf()
}

/// Where test `name` writes the firmware's decoded log.
pub fn log_path(name: &str) -> PathBuf {
    let dir = root().join("target/e2e-logs");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(format!("{name}.log"))
}

/// The flash file of test `name`'s controller.
pub fn flash_path(name: &str) -> PathBuf {
    log_path(name).with_extension("flash")
}

/// Builds the QEMU firmware if needed and starts it; panics with the log's tail on failure.
pub fn start_emulator(name: &str) -> Emulator {
    let log = log_path(name);
    let config = EmulatorConfig {
        log_file: Some(log.clone()),
        time_limit: Some(EMULATOR_TIME_LIMIT),
        flash_file: Some(flash_path(name)),
        ..Default::default()
    };
    match Emulator::start(&config) {
        Ok(emulator) => emulator,
        Err(e) => panic!("emulator for {name} did not start: {e}\nlog:\n{}", read_log(&log)),
    }
}

/// The log so far (empty if none).
pub fn read_log(path: &std::path::Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

/// xorshift64*: reproducible pseudo-random bytes without a dependency.
pub fn pseudo_random_bytes(seed: u64, len: usize) -> Vec<u8> {
    let mut state = seed.max(1);
    (0..len)
        .map(|_| {
            state ^= state >> 12;
            state ^= state << 25;
            state ^= state >> 27;
            (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 56) as u8
        })
        .collect()
}
