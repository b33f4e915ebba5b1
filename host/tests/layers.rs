//! The host library's layers point one way (docs/architecture.md, "Layers"): a top-level module
//! of `host/src` may name (`crate::X` in a path or a `use crate::{X, …}` group) only modules of
//! a lower layer. The table is read from docs/architecture.md itself, so the rule written there
//! and the rule checked here are the same text; every top-level module must have a row.
//!
//! Comments are skipped (a doc link to a higher layer is no dependency); everything else counts,
//! `#[cfg(test)]` code too: a test that needs a higher layer lives in that layer.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// `module → layer` from the "Layers" section's table: lines `layer N  mod mod …`.
fn layers_from_doc(doc: &str) -> BTreeMap<String, u32> {
    let section = doc.split("\n## Layers").nth(1).expect("docs/architecture.md has a ## Layers");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut table = BTreeMap::new();
    for line in section.lines() {
        let mut words = line.split_whitespace();
        if words.next() != Some("layer") {
            continue;
        }
        let Some(Ok(n)) = words.next().map(str::parse::<u32>) else { continue };
        for m in words {
            assert!(table.insert(m.to_string(), n).is_none(), "{m} has two layers");
        }
    }
    assert!(!table.is_empty(), "no `layer N  modules` lines under ## Layers");
    table
}

/// The text without `//` comments (line and doc comments) and without string literals' bodies.
fn code_only(src: &str) -> String {
    let mut out = String::with_capacity(src.len());
    for line in src.lines() {
        let mut in_str = false;
        let mut prev = ' ';
        let mut kept = String::new();
        let chars: Vec<char> = line.chars().collect();
        let mut i = 0;
        while i < chars.len() {
            let c = chars[i];
            if in_str {
                if c == '"' && prev != '\\' {
                    in_str = false;
                }
                prev = if prev == '\\' && c == '\\' { ' ' } else { c };
                i += 1;
                continue;
            }
            if c == '"' && !(prev == '\'' && chars.get(i + 1) == Some(&'\'')) {
                in_str = true;
                prev = ' ';
                i += 1;
                continue;
            }
            if c == '/' && chars.get(i + 1) == Some(&'/') {
                break;
            }
            kept.push(c);
            prev = c;
            i += 1;
        }
        out.push_str(&kept);
        out.push('\n');
    }
    out
}

/// Every top-level module a source file names through `crate::`.
fn crate_paths(src: &str) -> Vec<String> {
    let code = code_only(src);
    let mut found = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        let before = code[..at].chars().next_back();
        if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == '$') {
            continue;
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            found.extend(group_heads(group));
        } else {
            found.push(ident(rest));
        }
    }
    found.retain(|m| !m.is_empty() && m != "self");
    found
}

/// The first identifier of each item of a `{a::b, c, d::{e, f}}` group (the text after `{`).
/// Whether the code (comments and strings skipped) names the external crate `krate`.
fn names_crate(src: &str, krate: &str) -> bool {
    let code = code_only(src);
    let pat = format!("{krate}::");
    code.match_indices(&pat).any(|(at, _)| {
        !code[..at].chars().next_back().is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':')
    })
}

fn group_heads(group: &str) -> Vec<String> {
    let mut heads = vec![ident(group.trim_start())];
    let mut depth = 0;
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => heads.push(ident(group[i + 1..].trim_start())),
            _ => {}
        }
    }
    heads
}

fn ident(s: &str) -> String {
    s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect()
}

/// The top-level module a file under `host/src` belongs to (`cli` for the binary's files).
fn top_module(rel: &Path) -> String {
    let first = rel.components().next().unwrap().as_os_str().to_string_lossy().into_owned();
    match first.strip_suffix(".rs") {
        Some("main") => "cli".to_string(),
        Some(m) => m.to_string(),
        None => first,
    }
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `file: module (layer a) uses crate::other (layer b)` for every import that does not point
/// down, and every module without a layer.
fn violations(table: &BTreeMap<String, u32>, files: &[(String, String)]) -> Vec<String> {
    let mut bad = Vec::new();
    for (name, src) in files {
        let top = top_module(Path::new(name));
        if top == "lib" {
            continue;
        }
        let Some(&own) = table.get(&top) else {
            bad.push(format!("{name}: module `{top}` has no layer in docs/architecture.md"));
            continue;
        };
        // The binary (`cli`) reaches the library as `chladni::`; `crate::` there is itself.
        if top == "cli" {
            continue;
        }
        // Argument parsing is the CLI's: no library type knows clap.
        if names_crate(src, "clap") {
            bad.push(format!("{name}: `{top}` uses clap; value parsers and enums live in cli/"));
        }
        for used in crate_paths(src) {
            if used == top {
                continue;
            }
            match table.get(&used) {
                Some(&l) if l < own => {}
                Some(&l) => bad.push(format!(
                    "{name}: `{top}` (layer {own}) uses crate::{used} (layer {l}); a module may \
                     only use lower layers"
                )),
                None => bad.push(format!("{name}: crate::{used} has no layer")),
            }
        }
    }
    bad
}

#[test]
fn every_host_module_imports_only_lower_layers() {
    let host = Path::new(env!("CARGO_MANIFEST_DIR"));
    let doc = std::fs::read_to_string(host.join("../docs/architecture.md")).unwrap();
    let table = layers_from_doc(&doc);
    let src = host.join("src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    paths.sort();
    let files: Vec<(String, String)> = paths
        .iter()
        .map(|p| {
            let rel = p.strip_prefix(&src).unwrap().to_string_lossy().into_owned();
            (rel, std::fs::read_to_string(p).unwrap())
        })
        .collect();
    assert!(files.len() > 50, "host/src read: {} files", files.len());
    let bad = violations(&table, &files);
    assert!(bad.is_empty(), "{} imports against the layers:\n{}", bad.len(), bad.join("\n"));
}

/// The checker itself: an upward import in a path, in a group, across lines, is reported; a
/// comment, a string or a lower layer is not.
#[test]
fn the_checker_finds_an_upward_import() {
    let doc =
        "x\n## Layers\n```\nlayer 0  rng\nlayer 1  model\nlayer 2  motion\nlayer 3  cli\n```\n";
    let table = layers_from_doc(doc);
    let file = |name: &str, src: &str| (name.to_string(), src.to_string());
    let clean = [
        file("motion/a.rs", "use crate::model::x;\nuse crate::{rng::Rng, self};\n"),
        file(
            "model/b.rs",
            "/// see [`crate::motion::y`]\nlet s = \"crate::motion\"; // crate::cli\n",
        ),
        file("main.rs", "use chladni::motion; mod cli; use crate::cli::x;"),
        file("cli/g.rs", "impl clap::ValueEnum for Law {}"),
    ];
    assert_eq!(violations(&table, &clean), Vec::<String>::new());
    let dirty = [
        file("model/plate.rs", "use crate::motion::Grid;\n"),
        file("model/c.rs", "use crate::{\n    rng::Rng,\n    motion::{a, b},\n};\n"),
        file("rng.rs", "fn f() { crate::model::g() }\n"),
        file("motion/d.rs", "use crate::motion::x; use crate::cli::y;"),
        file("vision/e.rs", "use crate::model::x;"),
        file("model/f.rs", "impl clap::ValueEnum for Law {}"),
    ];
    let bad = violations(&table, &dirty);
    assert_eq!(bad.len(), 6, "{bad:#?}");
    assert!(bad[0].contains("model/plate.rs") && bad[0].contains("crate::motion (layer 2)"));
    assert!(bad[1].contains("model/c.rs") && bad[1].contains("crate::motion"));
    assert!(bad[2].contains("crate::model"));
    assert!(bad[3].contains("crate::cli"));
    assert!(bad[4].contains("`vision` has no layer"));
    assert!(bad[5].contains("model/f.rs") && bad[5].contains("clap"));
}
