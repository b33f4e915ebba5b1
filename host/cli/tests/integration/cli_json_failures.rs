//! Every `--json` failure prints one JSON object on stdout (`{"error": kind, "message": …}`,
//! or a command's own failure object with its data), whatever the command and whatever the
//! failure: a usage error clap refuses, bad input (exit 2), a failed operation (exit 1).
//! Also: research before the device (device limits warn in `plan`/`simulate`, refuse at
//! `device upload` with the fix), and the messages of issue 25.

use crate::support;
use support::cli::{chladni, ex, tmp};

/// Exit `code`, and stdout is exactly one JSON object with string `error` and `message`.
fn one_json_failure(args: &[&str], code: i32) -> serde_json::Value {
    let out = chladni(args);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(code), "{args:?}\nstdout: {stdout}\nstderr: {stderr}");
    let mut values = serde_json::Deserializer::from_str(&stdout).into_iter::<serde_json::Value>();
    let v = match values.next() {
        Some(Ok(v)) => v,
        other => panic!("{args:?}: no JSON object on stdout ({other:?}): {stdout:?}\n{stderr}"),
    };
    assert!(values.next().is_none(), "{args:?}: more than one JSON value: {stdout}");
    assert!(v["error"].is_string() && v["message"].is_string(), "{args:?}: {v}");
    v
}

fn write(name: &str, text: &str) -> String {
    let p = tmp("json-failures", name);
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

/// The triangle's plan repeated 100 times: 7090 s, past the device's hour.
fn long_plan() -> String {
    let text = std::fs::read_to_string(ex("plans/triangle-four-lines.json")).unwrap();
    write("long.json", &text.replace("\"repeat\": 1", "\"repeat\": 100"))
}

/// The cantilever example's `[plate]` table as a free plate, without `[[mode]]` entries.
fn free_plate() -> String {
    let text = std::fs::read_to_string(ex("plates/cantilever-solver.toml")).unwrap();
    let table = text.split("[[mode]]").next().unwrap();
    write("free.toml", &table.replace("boundary = \"cantilever\"", "boundary = \"free\""))
}

#[test]
fn every_command_answers_its_failures_in_json() {
    let tri = ex("parts/triangle.json");
    let four = ex("plates/four-lines.toml");
    let plan = ex("plans/triangle-four-lines.json");
    let missing = tmp("json-failures", "missing.json").display().to_string();
    let port = "tcp://127.0.0.1:1";
    let two = write(
        "two.svg",
        r#"<svg xmlns="http://www.w3.org/2000/svg"><rect width="10" height="10"/><rect x="20" width="10" height="10"/></svg>"#,
    );
    let cases: Vec<(Vec<&str>, i32, &str)> = vec![
        // usage errors (clap)
        (vec!["nonsense", "--json"], 2, "usage"),
        (vec!["analyze", &tri, "--field", "sign", "--gain-right", "0", "--json"], 2, "usage"),
        (vec!["physics", "string", "--e", "2", "--json"], 2, "usage"),
        (vec!["plan", &tri, "--plate", &four, "--margin-deg", "50", "--json"], 2, "usage"),
        // bad input
        (vec!["analyze", &missing, "--field", "sign", "--json"], 2, "bad_input"),
        (vec!["analyze", &two, "--field", "sign", "--json"], 2, "bad_input"),
        (vec!["analyze", &tri, "--field", "sine", "--json"], 2, "bad_input"),
        (vec!["analyze", &tri, "--field", "sine", "--wavelength", "1", "--json"], 2, "bad_input"),
        (vec!["plan", &tri, "--plate", &missing, "--json"], 2, "bad_input"),
        (
            vec!["plan", &tri, "--plate", &four, "--feed", "0", "0", "1e4", "1e4", "--json"],
            2,
            "bad_input",
        ),
        (vec!["simulate", &tri, "--plate", &four, "--plan", &missing, "--json"], 2, "bad_input"),
        (vec!["simulate", &tri, &tri, "--plate", &four, "--plan", &plan, "--json"], 2, "bad_input"),
        (vec!["plate", "modes", &missing, "--json"], 2, "bad_input"),
        (vec!["device", "upload", &missing, "--port", port, "--json"], 2, "bad_input"),
        (vec!["device", "run", "65", "--port", port, "--json"], 2, "usage"),
        // failed operations
        (vec!["device", "info", "--port", port, "--json"], 1, "failed"),
        (vec!["device", "status", "--port", "/dev/no-such-port", "--json"], 1, "failed"),
    ];
    for (args, code, kind) in &cases {
        let v = one_json_failure(args, *code);
        assert_eq!(v["error"], *kind, "{args:?}: {v}");
    }
    // A command's own failure object keeps its name and data: the unreachable goal.
    let v = one_json_failure(&["plan", &tri, "--plate", &four, "--goal-deg", "7", "--json"], 1);
    assert_eq!(v["error"], "goal_unreachable", "{v}");
    assert!(v["reachable_deg"].is_array(), "{v}");
}

#[test]
fn device_limits_warn_before_the_device_and_refuse_at_upload_with_the_fix() {
    let tri = ex("parts/triangle.json");
    let four = ex("plates/four-lines.toml");
    let long = long_plan();
    let out =
        chladni(&["simulate", &tri, "--plate", &four, "--plan", &long, "--trials", "2", "--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("warning:") && err.contains("device upload") && err.contains("split"),
        "{err}"
    );
    serde_json::from_slice::<serde_json::Value>(&out.stdout).unwrap();
    let v =
        one_json_failure(&["device", "upload", &long, "--port", "tcp://127.0.0.1:1", "--json"], 2);
    let m = v["message"].as_str().unwrap();
    assert!(m.contains("controller's limits") && m.contains("at most an hour"), "{m}");
}

#[test]
fn messages_name_the_fix() {
    // --rocking-hz on a plate that does not rock: refused, not ignored.
    let free = free_plate();
    let out = chladni(&["plate", "modes", &free, "--count", "1", "--rocking-hz", "5"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--rocking-hz 5: only hinged-rod plates") && err.contains("\"free\""),
        "{err}"
    );
    // The header names the boundary as the file does.
    let out = chladni(&["plate", "modes", &ex("plates/hinged-rod-solver.toml"), "--count", "1"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.contains("(hinged-rod, "), "{text}");
    // A plate without modes points to --write-modes.
    let out = chladni(&["plan", &ex("parts/triangle.json"), "--plate", &free]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("plate modes") && err.contains("--write-modes"), "{err}");
    // A sliver is refused.
    let sliver = write("sliver.json", r#"{"outline": [[0, 0], [10, 0], [10, 0.000005]]}"#);
    let out = chladni(&["analyze", &sliver, "--field", "sign"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("sliver"), "{err}");
    // The old division by zero: gains 1 and 2 analyse.
    for part in ["rectangle.json", "triangle.json", "l-shape.json", "plate-with-hole.json"] {
        let out = chladni(&[
            "analyze",
            &ex(&format!("parts/{part}")),
            "--field",
            "sign",
            "--gain-right",
            "2",
        ]);
        assert!(out.status.success(), "{part}: {}", String::from_utf8_lossy(&out.stderr));
    }
    // --safety below 1: a warning, not a refusal (refused only if not positive).
    let out = chladni(&[
        "plan",
        &ex("parts/triangle.json"),
        "--plate",
        &ex("plates/four-lines.toml"),
        "--safety",
        "0.5",
        "--json",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success() && err.contains("--safety 0.5 < 1"), "{err}");
}
