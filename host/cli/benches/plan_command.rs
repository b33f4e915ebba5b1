//! The whole `chladni plan` command for the 64-gon on the 12-line plate (`benches/data/`, the
//! data of the `plan` bench), as a user runs it: the release binary spawned N times (process
//! start, file reads, maps, search, dynamic check, durations, JSON out). Also `--maps static`
//! and `chladni --version` (the process start alone). Prints min, median and max (ms).
//!
//! Then the planning time on a solver's plate (docs/plan.md, "Planning time"): `chladni plan
//! PART --plate examples/plates/cantilever-6-modes.toml --json` once per part of
//! `examples/parts/ordinary/` and the example parts, with `--max-time-s 60`: the wall time and
//! the outcome (steps, or the failure's name); and three parts from the free plate's feed
//! region. `CHLADNI_BENCH_PROFILE=PART.json` instead prints where one plan's CPU time goes
//! ([`profile`]).
//!
//! `cargo bench -p chladni --bench plan_command` (N = 30; `CHLADNI_BENCH_RUNS=N`;
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
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/parts");
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
    let plate = "../../examples/plates/cantilever-6-modes.toml";
    for part in grid_parts() {
        let args = ["plan", &part, "--plate", plate, "--max-time-s", "60", "--json"];
        let (s, outcome) = plan_once(&args);
        let name = part.rsplit('/').next().unwrap_or(&part);
        println!("cantilever-6-modes, {name}: {s:.2} s, {outcome}");
    }
}

/// `chladni plan` from the free plate's left feed region (docs/plan.md, "Ordinary parts on
/// the solver's plates") for three parts, one run each.
fn free_feed() {
    let plate = "../../examples/plates/free-6-modes.toml";
    for part in ["rectangle", "triangle", "ordinary/crank-lever"] {
        let path = format!("../../examples/parts/{part}.json");
        let feed = ["--feed", "40", "50", "90", "150"];
        let args = [&["plan", &path, "--plate", plate, "--max-time-s", "60", "--json"][..], &feed]
            .concat();
        let (s, outcome) = plan_once(&args);
        println!("free-6-modes --feed 40 50 90 150, {part}: {s:.2} s, {outcome}");
    }
}

fn main() {
    if let Ok(spec) = std::env::var("CHLADNI_BENCH_PROFILE") {
        profile(&spec);
        return;
    }
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
        free_feed();
    }
}

/// CPU time of the calling thread (s), from `/proc/thread-self/schedstat` (ns; Linux): the
/// profile's times, which the machine's load does not inflate as it does wall times.
fn thread_cpu_s() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next().and_then(|v| v.parse::<f64>().ok()))
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

/// `CHLADNI_BENCH_PROFILE=PART.json[,PLATE.toml]` (paths from the host crate's folder; the
/// plate defaults to the cantilever's solver modes): where a plan's time goes, in-process on
/// one thread, as CPU time ([`thread_cpu_s`]): the phases (the maps alone, the maps with their
/// evidence margins, the whole plan without and with the whole-plate check), each grid mode's
/// map and evidence margin, then every grid mode's step-map runs one by one
/// ([`chladni_core::planner::map_starts`] × the distinct start orientations, the planner's run
/// settings, no run called off; only with `CHLADNI_BENCH_PROFILE_RUNS=1`): per start point the runs, how many came to rest, the steps
/// (sum, largest, runs stopped by the 20 000-step cap) and the time; per mode the cost of one
/// field wrench (the per-step work: about two per Heun step).
fn profile(spec: &str) {
    use chladni_core::model::{part::Part, plate::PlateModel};
    use chladni_core::motion::body::Body;
    use chladni_core::planner::{self, PlanOptions, Problem, plan_period, sampled_map};
    let (part_path, plate_path) =
        spec.split_once(',').unwrap_or((spec, "../../examples/plates/cantilever-6-modes.toml"));
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let part = Part::load(&dir.join(part_path)).expect("the part loads");
    let plate = PlateModel::load(&dir.join(plate_path)).expect("the plate loads");
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a pool");
    let name = &part.name;
    let timed = |what: &str, f: &dyn Fn() -> String| {
        let t = thread_cpu_s();
        let out = f();
        println!("profile {name}: {what}: {:.2} s CPU ({out})", thread_cpu_s() - t);
    };
    let outcome = |r: Result<planner::Synthesis, planner::PlanFailure>| match r {
        Ok(s) => format!("{} steps", s.steps.len()),
        Err(e) => e.to_string().chars().take(60).collect(),
    };
    let opt = PlanOptions::default();
    pool.install(|| {
        let maps_only = PlanOptions { margin_auto: false, ..opt };
        let ok = |r: Result<Problem, planner::PlanFailure>| {
            r.map_or_else(|e| e.to_string(), |_| "ok".into())
        };
        timed("maps", &|| ok(Problem::new(&part, &plate, &maps_only)));
        timed("maps + evidence", &|| ok(Problem::new(&part, &plate, &opt)));
        timed("plan, no whole-plate check", &|| outcome(planner::plan(&part, &plate, &opt)));
        let whole = PlanOptions { refine_rounds: planner::whole::REFINE_ROUNDS, ..opt };
        timed("plan (as `chladni plan`)", &|| outcome(planner::plan(&part, &plate, &whole)));
    });
    let body = Body::with_samples(&part, chladni_core::motion::body::PLANNER_BODY_SAMPLES);
    let n = opt.sim_starts;
    let m = planner::symmetry_order(&part) as usize;
    let distinct = if m > 1 && n.is_multiple_of(m) { n / m } else { n };
    let period = plan_period(&part, &plate);
    pool.install(|| {
        for (k, mode) in plate.modes.iter().enumerate() {
            let t = thread_cpu_s();
            let map = sampled_map(&body, mode, &plate, n, period);
            let t_map = thread_cpu_s() - t;
            let margin = planner::margin::grid_margin(&body, mode, &plate, n, period, &map);
            println!(
                "profile {name} mode {}: map {t_map:.2} s CPU ({} rests, {} boundaries, dead starts {}), evidence margin {:.2} s CPU ({:?})",
                k + 1,
                map.stable.len(),
                map.boundaries.len(),
                map.dead_starts,
                thread_cpu_s() - t - t_map,
                margin.map(|m| m.deg),
            );
        }
    });
    if std::env::var("CHLADNI_BENCH_PROFILE_RUNS").as_deref() != Ok("1") {
        return;
    }
    pool.install(|| {
        for (k, mode) in plate.modes.iter().enumerate() {
            run_profile(name, k, &body, mode, &plate, n, distinct);
        }
    });
}

/// The per-run part of [`profile`] for mode `k`.
fn run_profile(
    name: &str,
    k: usize,
    body: &chladni_core::motion::body::Body,
    mode: &chladni_core::model::plate::Mode,
    plate: &chladni_core::model::plate::PlateModel,
    n: usize,
    distinct: usize,
) {
    use chladni_core::model::pose::Pose;
    use chladni_core::motion::contact::Rim;
    use chladni_core::motion::field::FieldModel;
    use chladni_core::motion::integrate::SimParams;
    let field = FieldModel::new(mode, plate);
    let rim = Rim::of(plate);
    let p = SimParams::to_rest(body, mode, &field, plate);
    let (mut mode_steps, mut mode_s, mut poses) = (0usize, 0.0, Vec::new());
    for (j, s) in chladni_core::planner::map_starts(body, mode, plate).iter().enumerate() {
        let (mut steps, mut big, mut capped, mut rested) = (0usize, 0usize, 0usize, 0usize);
        let t = thread_cpu_s();
        for i in 0..distinct {
            let th = (i as f64 + 0.3) * 360.0 / n as f64;
            let q = rim.project(body, Pose { x: s[0], y: s[1], theta: th.to_radians() });
            let r = chladni_core::motion::integrate::run(body, &field, p, q);
            steps += r.steps;
            big = big.max(r.steps);
            capped += usize::from(r.steps >= 20_000);
            rested += usize::from(r.rested);
            poses.extend(r.trace.iter().step_by(97).map(|x| x.1));
        }
        let secs = thread_cpu_s() - t;
        (mode_steps, mode_s) = (mode_steps + steps, mode_s + secs);
        println!(
            "profile {name} mode {}: start {j} ({:.0}, {:.0}): {distinct} runs, {rested} rested, steps {steps} (max {big}, {capped} at the cap), {secs:.3} s CPU",
            k + 1,
            s[0],
            s[1]
        );
    }
    let t = thread_cpu_s();
    let sink: f64 = poses.iter().map(|q| field.wrench(body, *q).fx).sum();
    let per = (thread_cpu_s() - t) / poses.len().max(1) as f64;
    println!(
        "profile {name} mode {}: {mode_steps} steps, {mode_s:.2} s CPU, {:.2} µs/step, one wrench {:.2} µs ({sink:.1e})",
        k + 1,
        mode_s / mode_steps.max(1) as f64 * 1e6,
        per * 1e6
    );
}
