//! Running the `chladni` binary from the CLI tests: one way to call it, to read its JSON and to
//! name and write scratch files, shared by every test file that includes `mod support;`.
// Each includer uses only part of it.
#![allow(dead_code)]

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

/// The `chladni` binary this test file was built with, its stdin closed (no test types).
pub fn command() -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_chladni"));
    command.stdin(Stdio::null());
    command
}

/// Runs `chladni ARGS` to its end.
pub fn chladni(args: &[&str]) -> Output {
    command().args(args).output().unwrap()
}

/// `chladni COMMAND` (`plan`, `simulate`) of the example triangle on the four-lines plate, then
/// `more` (`--plan F`, `--trials N`, …): the case most CLI tests run.
pub fn triangle_on_four_lines(command: &str, more: &[&str]) -> Output {
    let (part, plate) = (ex("parts/triangle.json"), ex("plates/four-lines.toml"));
    let mut args = vec![command, &part, "--plate", &plate];
    args.extend_from_slice(more);
    chladni(&args)
}

/// `examples/PATH` as a string argument.
pub fn ex(path: &str) -> String {
    repo(&format!("examples/{path}"))
}

/// `PATH` (relative to the workspace root) as a string argument.
pub fn repo(path: &str) -> String {
    super::examples::root().join(path).display().to_string()
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

/// [`json`] of a run that must have succeeded (exit 0); panics with its stderr otherwise.
pub fn ok_json(out: &Output) -> serde_json::Value {
    assert_eq!(
        out.status.code(),
        Some(0),
        "stdout:\n{}\nstderr:\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    json(out)
}

/// The keys of a JSON object, in the order the object holds them.
pub fn keys(v: &serde_json::Value) -> Vec<&str> {
    v.as_object()
        .unwrap_or_else(|| panic!("not an object: {v}"))
        .keys()
        .map(String::as_str)
        .collect()
}

/// A JSON array of numbers as `f64`s.
pub fn floats(v: &serde_json::Value) -> Vec<f64> {
    let all = v.as_array().unwrap_or_else(|| panic!("not an array: {v}"));
    all.iter().map(|x| x.as_f64().unwrap_or_else(|| panic!("not a number: {x}"))).collect()
}

/// A scratch path unique to this test process: `TMP/chladni-TAG-PID-NAME`.
pub fn tmp(tag: &str, name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("chladni-{tag}-{}-{name}", std::process::id()))
}

/// A scratch folder unique to this test process, created: `TMP/chladni-TAG-PID/`, for files
/// that name each other by relative path.
pub fn tmp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("chladni-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Writes `bytes` to [`tmp`]`(tag, name)`; its path as a string argument.
pub fn write_tmp(tag: &str, name: &str, bytes: impl AsRef<[u8]>) -> String {
    let path = tmp(tag, name);
    std::fs::write(&path, bytes).unwrap();
    path.display().to_string()
}
