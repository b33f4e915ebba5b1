//! Running the `chladni` binary from the CLI tests: one way to call it, to read its JSON and to
//! name scratch files, shared by every test file that includes `mod support;`.
// Each includer uses only part of it.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output};

/// Runs the `chladni` binary this test file was built with.
pub fn chladni(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_chladni")).args(args).output().unwrap()
}

/// `examples/PATH` as a string argument.
pub fn ex(path: &str) -> String {
    super::examples::root().join("examples").join(path).display().to_string()
}

/// stdout parsed as one JSON value; panics with the whole output when it is not one.
pub fn json(out: &Output) -> serde_json::Value {
    let text = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(&text).unwrap_or_else(|e| {
        panic!(
            "stdout is not one JSON value ({e}):\n{text}\nstderr:\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    })
}

/// A scratch path unique to this test process: `TMP/chladni-TAG-PID-NAME`.
pub fn tmp(tag: &str, name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("chladni-{tag}-{}-{name}", std::process::id()))
}
