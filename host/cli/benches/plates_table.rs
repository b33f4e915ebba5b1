//! The plan table of docs/plan.md ("Ordinary parts on the solver's plates"): the ten parts of
//! `examples/parts/ordinary/` and the example parts on the three example plates' own solver
//! modes (`examples/plates/*-6-modes.toml`, written by `chladni plate modes … --count 6
//! --write-modes`), through the whole `chladni` commands a user runs:
//!
//! - cantilever: `plan` over the whole plate, then `simulate` (200 trials); then "outside the
//!   capture zone": `plan --feed` and `simulate --feed` in the plate minus the clamp's capture
//!   zone, the box that whole-plate `plan --json` names (`capture_zone.outside_mm`); and
//!   "clear of the clamp": the same past the zone's clear line (`capture_zone.clear_box_mm`);
//! - free and hinged-rod: `plan --feed` from a feed region on the left side ([`FEED`]) and
//!   `simulate --feed`; then `plate suggest` (its wall time is the suggest timing), the drive
//!   point and clamps of its best row written into a plate file, `plate modes --count 6
//!   --write-modes` on it, `plan` over the whole plate and `simulate`.
//!
//! A part that flips (`"flips": true`) is planned on both faces, with `--feed` too.
//!
//! Prints the markdown table and the counts (stdout) and a line per case (stderr).
//! `cargo bench -p chladni --bench plates_table` (release). Filters, comma-separated
//! substrings: `CHLADNI_TABLE_PLATES=free`, `CHLADNI_TABLE_PARTS=gear,key`;
//! `CHLADNI_TABLE_SUGGEST=0` skips the suggest rows, `only` runs them alone (each `plate suggest` stops at its
//! default `--budget-s 60`, past it by at most the first candidate that is planned); `CHLADNI_TABLE_JOBS=2` runs two cases at
//! once (default 1: the timings are per command on an otherwise idle machine);
//! `CHLADNI_TABLE_BIN=PATH` runs another `chladni` binary (an older build, to compare).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::Mutex;
use std::time::{Duration, Instant};

use serde_json::Value;

/// Feed region (mm, x0 y0 x1 y1): a hopper dropping parts along the plate's left side.
const FEED: [f64; 4] = [40.0, 50.0, 90.0, 150.0];
/// The cantilever's second case: `--feed` the plate minus the clamp's capture zone (the box
/// the whole-plate `plan --json` names in `capture_zone.outside_mm`).
const OUTSIDE: &str = "outside the capture zone";
/// The cantilever's third case: `--feed` the plate past the clear line (`capture_zone.
/// clear_box_mm`), from where one mode takes none of the zone's sampled drops to the clamp.
const CLEAR: &str = "clear of the clamp";
/// Monte Carlo trials per plan (`simulate --trials`).
const TRIALS: u32 = 200;
/// A plan counts when `simulate` confirms at least this success rate.
const CONFIRMED: f64 = 0.95;

/// One example plate: the short name, the plate file with the solver keys, the committed
/// solver-mode file, and whether it gets feed and suggest rows (no plan over the whole plate
/// is expected on a centrally symmetric plate driven at a symmetric point).
struct PlateCase {
    name: &'static str,
    source: &'static str,
    modes: &'static str,
    one_sided: bool,
}

const PLATES: [PlateCase; 3] = [
    PlateCase {
        name: "cantilever",
        source: "examples/plate-cantilever.toml",
        modes: "examples/plates/cantilever-6-modes.toml",
        one_sided: false,
    },
    PlateCase {
        name: "free",
        source: "examples/plate-free.toml",
        modes: "examples/plates/free-6-modes.toml",
        one_sided: true,
    },
    PlateCase {
        name: "hinged-rod",
        source: "examples/plate-hinged-rod.toml",
        modes: "examples/plates/hinged-rod-6-modes.toml",
        one_sided: true,
    },
];

/// A finished command.
struct Ran {
    ok: bool,
    stdout: String,
    stderr: String,
    wall: Duration,
}

fn chladni(root: &Path, args: &[&str]) -> Ran {
    let start = Instant::now();
    let bin = std::env::var_os("CHLADNI_TABLE_BIN")
        .map_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_chladni")), PathBuf::from);
    let out =
        Command::new(bin).current_dir(root).args(args).output().expect("the chladni binary runs");
    Ran {
        ok: out.status.success(),
        stdout: String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
        wall: start.elapsed(),
    }
}

/// `plan`'s answer: steps and total duration, or the failure's short reason.
#[derive(Clone)]
enum Planned {
    Plan { steps: usize, total_s: f64 },
    No(String),
}

/// One row of the table.
struct Row {
    plate: &'static str,
    case: &'static str,
    /// What the case column adds (the capture-zone case's `--feed` box).
    note: Option<String>,
    part: String,
    flips: bool,
    planned: Planned,
    plan_wall_s: f64,
    success: Option<f64>,
    suggest: Option<String>,
}

/// The first sentence of a failure (or of stderr), cut at 90 characters, table-safe.
fn short(msg: &str) -> String {
    let line = msg.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or("");
    let line = line.strip_prefix("error: ").unwrap_or(line);
    let first = line.split(". ").next().unwrap_or(line).split(": ").take(2).collect::<Vec<_>>();
    let mut s = first.join(": ");
    if s.chars().count() > 90 {
        s = s.chars().take(87).collect::<String>() + "…";
    }
    s.replace('|', "/")
}

/// What one `plan` gave: the answer, its wall time (s), and the two boxes of the clamp's
/// capture zone that its `--json` (plan or failure) names: `capture_zone.outside_mm` and
/// `capture_zone.clear_box_mm`.
type PlanRan = (Planned, f64, [Option<[f64; 4]>; 2]);

/// `chladni plan PART --plate P --json --out OUT [--feed …]`.
fn plan(root: &Path, part: &str, plate: &str, feed: Option<[f64; 4]>, out: &Path) -> PlanRan {
    let out_s = out.to_string_lossy().into_owned();
    let mut args = vec!["plan", part, "--plate", plate, "--json", "--out", &out_s];
    let f: Vec<String> = feed.iter().flatten().map(|v| v.to_string()).collect();
    if feed.is_some() {
        args.push("--feed");
        args.extend(f.iter().map(String::as_str));
    }
    let r = chladni(root, &args);
    let wall = r.wall.as_secs_f64();
    let v: Option<Value> = r.stdout.lines().rev().find_map(|l| serde_json::from_str(l).ok());
    let zone_box = |key: &str| {
        let b = v.as_ref()?["capture_zone"][key].as_array()?;
        let b: Vec<f64> = b.iter().filter_map(Value::as_f64).collect();
        <[f64; 4]>::try_from(b).ok()
    };
    let boxes = [zone_box("outside_mm"), zone_box("clear_box_mm")];
    let planned = match (r.ok, v) {
        (true, Some(v)) => {
            let steps = v["steps"].as_array().map_or(&[][..], Vec::as_slice);
            let ms: f64 = steps.iter().filter_map(|s| s["duration_ms"].as_f64()).sum();
            Planned::Plan { steps: steps.len(), total_s: ms / 1000.0 }
        }
        (_, Some(v)) if v["message"].is_string() => Planned::No(format!(
            "{}: {}",
            v["error"].as_str().unwrap_or("error"),
            short(v["message"].as_str().unwrap_or(""))
        )),
        _ => Planned::No(short(&r.stderr)),
    };
    (planned, wall, boxes)
}

/// `chladni simulate PART --plate P --plan PLAN --trials 200 --json [--feed …]`: the success
/// rate over all trials (both faces of a part that flips).
fn simulate(
    root: &Path,
    part: &str,
    plate: &str,
    plan: &Path,
    feed: Option<[f64; 4]>,
) -> Option<f64> {
    let plan_s = plan.to_string_lossy().into_owned();
    let trials = TRIALS.to_string();
    let mut args =
        vec!["simulate", part, "--plate", plate, "--plan", &plan_s, "--trials", &trials, "--json"];
    let f: Vec<String> = feed.iter().flatten().map(|v| v.to_string()).collect();
    if feed.is_some() {
        args.push("--feed");
        args.extend(f.iter().map(String::as_str));
    }
    let r = chladni(root, &args);
    let v: Value = r.stdout.lines().rev().find_map(|l| serde_json::from_str(l).ok())?;
    let reports: Vec<&Value> = match v["parts"].as_array() {
        Some(a) => a.iter().collect(),
        None => vec![&v],
    };
    let (mut ok, mut n) = (0.0, 0.0);
    for p in reports {
        let t = p["trials"].as_f64()?;
        ok += p["success_rate"].as_f64()? * t;
        n += t;
    }
    (n > 0.0).then(|| ok / n)
}

/// What `plate suggest` gave: the chosen row (fewest steps, then shortest) and the counts.
struct Suggested {
    wall_s: f64,
    chosen: Option<([f64; 2], Vec<[f64; 2]>)>,
    text: String,
}

fn suggest(root: &Path, source: &str, part: &str) -> Suggested {
    let r = chladni(root, &["plate", "suggest", source, part, "--json"]);
    let wall_s = r.wall.as_secs_f64();
    let v: Option<Value> = r.stdout.lines().rev().find_map(|l| serde_json::from_str(l).ok());
    let Some(rows) = v.as_ref().and_then(|v| v["rows"].as_array()) else {
        return Suggested { wall_s, chosen: None, text: format!("failed: {}", short(&r.stderr)) };
    };
    let plans: Vec<&Value> = rows.iter().filter(|r| r["outcome"] == "plan").collect();
    let tried = rows.iter().filter(|r| r["outcome"] != "not_tried").count();
    let best = plans.iter().min_by(|a, b| {
        let key = |r: &Value| (r["steps"].as_u64().unwrap_or(u64::MAX), r["total_s"].as_f64());
        let (ka, kb) = (key(a), key(b));
        ka.0.cmp(&kb.0).then(ka.1.partial_cmp(&kb.1).unwrap_or(std::cmp::Ordering::Equal))
    });
    let pt = |p: &Value| [p[0].as_f64().unwrap_or(0.0), p[1].as_f64().unwrap_or(0.0)];
    let chosen = best.map(|b| {
        let clamps = b["clamps_mm"].as_array().map_or(Vec::new(), |c| c.iter().map(pt).collect());
        (pt(&b["drive_mm"]), clamps)
    });
    let mut why: Vec<(String, usize)> = Vec::new();
    for w in rows.iter().filter(|r| r["same_as"].is_null()).filter_map(|r| r["why"].as_str()) {
        match why.iter_mut().find(|(n, _)| n == w) {
            Some((_, c)) => *c += 1,
            None => why.push((w.to_string(), 1)),
        }
    }
    let why: Vec<String> = why.iter().map(|(n, c)| format!("{n} {c}")).collect();
    let planned = rows.iter().filter(|r| r["outcome"] != "not_tried" && r["same_as"].is_null());
    let head = format!(
        "{}/{tried} tried plan ({} planned, the rest same modes as a row), of {}{}",
        plans.len(),
        planned.count(),
        rows.len(),
        if why.is_empty() { String::new() } else { format!("; no plan: {}", why.join(", ")) }
    );
    let text = match &chosen {
        None => head,
        Some((d, c)) => {
            let c: Vec<String> = c.iter().map(|c| format!("({:.0}, {:.0})", c[0], c[1])).collect();
            let c = if c.is_empty() { "none".to_string() } else { c.join(" ") };
            format!("{head}; drive ({:.0}, {:.0}), clamps {c}", d[0], d[1])
        }
    };
    Suggested { wall_s, chosen, text }
}

/// The plate file with `drive_mm` and `clamps_mm` and its `plate modes --count 6
/// --write-modes` file (the `[plate]` table is the source file's only table).
fn solver_file(
    root: &Path,
    source: &str,
    chosen: &([f64; 2], Vec<[f64; 2]>),
    dir: &Path,
) -> Result<PathBuf, String> {
    let mut text = std::fs::read_to_string(root.join(source)).map_err(|e| e.to_string())?;
    let (d, c) = chosen;
    text += &format!("drive_mm = [{}, {}]\n", d[0], d[1]);
    if !c.is_empty() {
        let c: Vec<String> = c.iter().map(|c| format!("[{}, {}]", c[0], c[1])).collect();
        text += &format!("clamps_mm = [{}]\n", c.join(", "));
    }
    let plate = dir.join("suggested.toml");
    let modes = dir.join("suggested-6-modes.toml");
    std::fs::write(&plate, text).map_err(|e| e.to_string())?;
    let (p, m) = (plate.to_string_lossy(), modes.to_string_lossy());
    let r = chladni(root, &["plate", "modes", &p, "--count", "6", "--write-modes", &m]);
    if r.ok { Ok(modes) } else { Err(short(&r.stderr)) }
}

fn flips(root: &Path, part: &str) -> bool {
    part.ends_with(".json")
        && std::fs::read_to_string(root.join(part))
            .ok()
            .and_then(|t| serde_json::from_str::<Value>(&t).ok())
            .is_some_and(|v| v["flips"] == Value::Bool(true))
}

/// Which rows of the free and hinged-rod plates run (`CHLADNI_TABLE_SUGGEST`: `0`, unset,
/// `only`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Suggest {
    /// The feed rows only.
    Off,
    /// The feed and the suggest rows.
    On,
    /// The suggest rows only.
    Only,
}

/// Every row of one plate and one part.
fn rows_of(root: &Path, pc: &PlateCase, part: &str, dir: &Path, suggest_rows: Suggest) -> Vec<Row> {
    std::fs::create_dir_all(dir).expect("temp dir");
    let name = Path::new(part).file_stem().unwrap_or_default().to_string_lossy().into_owned();
    let fl = flips(root, part);
    let row = |case, planned, plan_wall_s, success, suggest| Row {
        plate: pc.name,
        case,
        note: None,
        part: name.clone(),
        flips: fl,
        planned,
        plan_wall_s,
        success,
        suggest,
    };
    let out = dir.join("plan.json");
    let run = |plate: &str, part: &str, feed: Option<[f64; 4]>| {
        let _ = std::fs::remove_file(&out);
        let (planned, wall, boxes) = plan(root, part, plate, feed, &out);
        let success = match planned {
            Planned::Plan { .. } => simulate(root, part, plate, &out, feed),
            Planned::No(_) => None,
        };
        (planned, wall, success, boxes)
    };
    let mut rows = Vec::new();
    if !pc.one_sided {
        let (p, w, s, boxes) = run(pc.modes, part, None);
        rows.push(row("whole plate", p, w, s, None));
        // The plate minus the clamp's capture zone, and past its clear line, as the
        // whole-plate `plan --json` named them.
        for (case, b) in [OUTSIDE, CLEAR].into_iter().zip(boxes) {
            match b {
                Some(b) => {
                    let (p, w, s, _) = run(pc.modes, part, Some(b));
                    let note = format!("feed {:.0} {:.0} {:.0} {:.0}", b[0], b[1], b[2], b[3]);
                    rows.push(Row { note: Some(note), ..row(case, p, w, s, None) });
                }
                None => {
                    let why = Planned::No(format!("plan --json named no {case} box"));
                    rows.push(row(case, why, 0.0, None, None));
                }
            }
        }
        return rows;
    }
    if suggest_rows != Suggest::Only {
        let (p, w, s, _) = run(pc.modes, part, Some(FEED));
        rows.push(row("feed (left)", p, w, s, None));
    }
    if suggest_rows == Suggest::Off {
        return rows;
    }
    let sug = suggest(root, pc.source, part);
    let text = format!("{} ({:.1} s)", sug.text, sug.wall_s);
    let (p, w, s) = match &sug.chosen {
        None => (Planned::No("no candidate plans (suggest)".into()), 0.0, None),
        Some(c) => match solver_file(root, pc.source, c, dir) {
            Ok(m) => {
                let (p, w, s, _) = run(&m.to_string_lossy(), part, None);
                (p, w, s)
            }
            Err(e) => (Planned::No(format!("plate modes: {e}")), 0.0, None),
        },
    };
    rows.push(row("whole, suggest", p, w, s, Some(text)));
    rows
}

fn parts(root: &Path) -> Vec<String> {
    let mut ordinary: Vec<String> = std::fs::read_dir(root.join("examples/parts/ordinary"))
        .expect("examples/parts/ordinary")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".json"))
        .map(|n| format!("examples/parts/ordinary/{n}"))
        .collect();
    ordinary.sort();
    let mut examples: Vec<String> = std::fs::read_dir(root.join("examples/parts"))
        .expect("examples/parts")
        .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".json") || n.ends_with(".svg"))
        .map(|n| format!("examples/parts/{n}"))
        .collect();
    examples.sort();
    ordinary.extend(examples);
    ordinary
}

fn wanted(var: &str, name: &str) -> bool {
    match std::env::var(var) {
        Ok(f) if !f.is_empty() => f.split(',').any(|s| name.contains(s.trim())),
        _ => true,
    }
}

fn cell(r: &Row) -> String {
    let part = r.part.clone();
    let flips = if r.flips { "yes" } else { "no" };
    let (plan, steps, dur) = match &r.planned {
        Planned::Plan { steps, total_s } => {
            ("plan".to_string(), steps.to_string(), format!("{:.1} min", total_s / 60.0))
        }
        Planned::No(why) => (why.clone(), "–".into(), "–".into()),
    };
    let sim = r.success.map_or("–".to_string(), |s| format!("{:.1} %", s * 100.0));
    let sug = r.suggest.clone().unwrap_or_default();
    let case = r.note.as_ref().map_or(r.case.to_string(), |n| format!("{} ({n})", r.case));
    format!(
        "| {} | {case} | {part} | {flips} | {plan} | {steps} | {dur} | {sim} | {:.2} s | {sug} |",
        r.plate, r.plan_wall_s
    )
}

fn summary(rows: &[Row]) {
    println!("\n| plate | case | ordinary parts confirmed ≥ 95 % | example parts confirmed |");
    println!("| --- | --- | --- | --- |");
    // Each (plate, case) once, in first-seen order: a plate's cases alternate part by part.
    let mut keys: Vec<(&str, &str)> = Vec::new();
    for k in rows.iter().map(|r| (r.plate, r.case)) {
        if !keys.contains(&k) {
            keys.push(k);
        }
    }
    for (plate, case) in keys {
        let of = |ordinary: bool| {
            let sel: Vec<&Row> = rows
                .iter()
                .filter(|r| r.plate == plate && r.case == case)
                .filter(|r| ordinary == ORDINARY.contains(&r.part.as_str()))
                .collect();
            let ok = sel.iter().filter(|r| r.success.is_some_and(|s| s >= CONFIRMED)).count();
            format!("{ok} of {}", sel.len())
        };
        println!("| {plate} | {case} | {} | {} |", of(true), of(false));
    }
    let walls: Vec<f64> = rows
        .iter()
        .filter(|r| matches!(r.planned, Planned::Plan { .. }))
        .map(|r| r.plan_wall_s)
        .collect();
    let max = walls.iter().copied().fold(0.0, f64::max);
    let over = walls.iter().filter(|&&w| w > 2.0).count();
    println!(
        "\nplan wall time of the {} plans found: max {max:.2} s, {over} over 2 s",
        walls.len()
    );
}

/// The stems of `examples/parts/ordinary/` (for the summary's split).
const ORDINARY: [&str; 10] = [
    "corner-bracket",
    "crank-lever",
    "gusset",
    "hex-key",
    "house-key",
    "keyed-gear",
    "slotted-strap",
    "spring-clip",
    "tee-plate",
    "u-channel",
];

fn main() {
    // `cargo bench` passes `--bench`; nothing else is taken.
    // host/cli → the workspace root.
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).ancestors().nth(2).expect("workspace root");
    let root = root.to_owned();
    let with_suggest = match std::env::var("CHLADNI_TABLE_SUGGEST").as_deref() {
        Ok("0") => Suggest::Off,
        Ok("only") => Suggest::Only,
        _ => Suggest::On,
    };
    let jobs: usize =
        std::env::var("CHLADNI_TABLE_JOBS").ok().and_then(|v| v.parse().ok()).unwrap_or(1).max(1);
    let tmp = std::env::temp_dir().join(format!("chladni-plates-table-{}", std::process::id()));
    let mut cases = Vec::new();
    for pc in PLATES.iter().filter(|p| wanted("CHLADNI_TABLE_PLATES", p.name)) {
        for part in parts(&root).into_iter().filter(|p| wanted("CHLADNI_TABLE_PARTS", p)) {
            cases.push((pc, part));
        }
    }
    let start = Instant::now();
    let next = Mutex::new(0usize);
    let done: Mutex<Vec<(usize, Vec<Row>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..jobs {
            s.spawn(|| {
                loop {
                    let i = {
                        let mut n = next.lock().expect("lock");
                        *n += 1;
                        *n - 1
                    };
                    let Some((pc, part)) = cases.get(i) else { break };
                    let t = Instant::now();
                    let rows = rows_of(&root, pc, part, &tmp.join(i.to_string()), with_suggest);
                    for r in &rows {
                        eprintln!("{}  ({:.1} s)", cell(r), t.elapsed().as_secs_f64());
                    }
                    done.lock().expect("lock").push((i, rows));
                }
            });
        }
    });
    let mut done = done.into_inner().expect("lock");
    done.sort_by_key(|(i, _)| *i);
    let rows: Vec<Row> = done.into_iter().flat_map(|(_, r)| r).collect();
    println!(
        "| plate | case | part | flips | plan (or the planner's reason) | steps | plan duration | \
         simulate {TRIALS} | plan wall | suggest (best row, wall) |"
    );
    println!("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |");
    for r in &rows {
        println!("{}", cell(r));
    }
    summary(&rows);
    println!("\ntotal run time {:.0} s ({jobs} job(s))", start.elapsed().as_secs_f64());
    let _ = std::fs::remove_dir_all(&tmp);
}
