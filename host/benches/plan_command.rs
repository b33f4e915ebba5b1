//! The whole `chladni plan` command for the 64-gon on the 12-line plate (`benches/data/`, the
//! data of the `plan` bench), as a user runs it: the release binary spawned N times (process
//! start, file reads, maps, search, dynamic check, durations, JSON out). Also `--maps static`
//! and `chladni --version` (the process start alone). Prints min, median and max (ms).
//!
//! Then the planning time on a solver's plate (docs/plan.md, "Planning time"): `chladni plan
//! PART --plate examples/plates/cantilever-6-modes.toml --json` once per part of
//! `examples/parts/ordinary/` and the example parts, with `--max-time-s 60`: the wall time and
//! the outcome (steps, or the failure's name).
//!
//! `cargo bench -p chladni-host --bench plan_command` (N = 30; `CHLADNI_BENCH_RUNS=N`;
//! `CHLADNI_BENCH_GRID=0` leaves the solver plate out, `CHLADNI_BENCH_PARTS=key,gear` keeps
//! the parts whose file name contains one of these).

use std::process::Command;
use std::time::Instant;

/// One run of the release `chladni` with `args` (from the host crate's folder): the wall time
/// (s) and what it printed.
fn run(args: &[&str]) -> (f64, std::process::Output) {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let start = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_chladni"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("chladni runs");
    (start.elapsed().as_secs_f64(), out)
}

/// Runs `args` `n` times; the sorted wall times (ms). Panics when a run fails: a bench of a
/// failing command measures nothing.
fn times(args: &[&str], n: usize) -> Vec<f64> {
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let (s, out) = run(args);
            assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
            s * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t
}

/// One `chladni plan` run: wall time (s) and outcome (steps, or the failure's `error` name).
fn plan_once(args: &[&str]) -> (f64, String) {
    let (s, out) = run(args);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap_or_default();
    let outcome = match (v["steps"].as_array(), v["error"].as_str()) {
        (Some(st), _) => format!("{} steps", st.len()),
        (None, Some(e)) => e.to_string(),
        _ => format!("no JSON (exit {:?})", out.status.code()),
    };
    (s, outcome)
}

/// The parts planned on the solver plate (paths).
fn grid_parts() -> Vec<String> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/parts");
    let keep = std::env::var("CHLADNI_BENCH_PARTS").unwrap_or_default();
    let mut parts: Vec<String> = ["ordinary", "."]
        .iter()
        .flat_map(|sub| std::fs::read_dir(dir.join(sub)).into_iter().flatten().flatten())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "json"))
        .map(|p| p.display().to_string())
        .filter(|p| keep.is_empty() || keep.split(',').any(|k| p.contains(k)))
        .collect();
    parts.sort();
    parts
}

/// `chladni plan` on the cantilever's solver modes, one run per part.
fn solver_plate() {
    let plate = "../examples/plates/cantilever-6-modes.toml";
    for part in grid_parts() {
        let args = ["plan", &part, "--plate", plate, "--max-time-s", "60", "--json"];
        let (s, outcome) = plan_once(&args);
        let name = part.rsplit('/').next().unwrap_or(&part);
        println!("cantilever-6-modes, {name}: {s:.2} s, {outcome}");
    }
}

fn main() {
    let n = std::env::var("CHLADNI_BENCH_RUNS").ok().and_then(|v| v.parse().ok()).unwrap_or(30);
    let plan = ["plan", "benches/data/64-gon.json", "--plate", "benches/data/twelve-lines.toml"];
    let cases: [(&str, Vec<&str>); 3] = [
        ("chladni --version (process start)", vec!["--version"]),
        (
            "chladni plan 64-gon, 12 lines (default --maps auto) --json",
            [&plan[..], &["--json"]].concat(),
        ),
        (
            "chladni plan 64-gon, 12 lines --maps static --json",
            [&plan[..], &["--maps", "static", "--json"]].concat(),
        ),
    ];
    for (name, args) in &cases {
        // One run first: the page cache, not the command, would otherwise be timed.
        times(args, 1);
        let t = times(args, n);
        println!(
            "{name}: min {:.1} ms, median {:.1} ms, max {:.1} ms ({n} runs)",
            t[0],
            t[n / 2],
            t[n - 1]
        );
    }
    if std::env::var("CHLADNI_BENCH_GRID").as_deref() != Ok("0") {
        solver_plate();
    }
}
