//! The whole `chladni plan` command for the 64-gon on the 12-line plate (`benches/data/`, the
//! data of the `plan` bench), as a user runs it: the release binary spawned N times (process
//! start, file reads, maps, search, dynamic check, durations, JSON out). Also `--maps static`
//! and `chladni --version` (the process start alone). Prints min, median and max (ms).
//!
//! `cargo bench -p chladni-host --bench plan_command` (N = 30; `CHLADNI_BENCH_RUNS=N`).

use std::process::Command;
use std::time::Instant;

/// Runs `args` `n` times; the sorted wall times (ms). Panics when a run fails: a bench of a
/// failing command measures nothing.
fn times(args: &[&str], n: usize) -> Vec<f64> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut t: Vec<f64> = (0..n)
        .map(|_| {
            let start = Instant::now();
            let out = Command::new(env!("CARGO_BIN_EXE_chladni"))
                .current_dir(dir)
                .args(args)
                .output()
                .expect("chladni runs");
            let ms = start.elapsed().as_secs_f64() * 1e3;
            assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
            ms
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t
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
}
