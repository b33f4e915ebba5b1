//! Every figure kind the CLI draws as SVG (`--plot F.svg`, `plate modes --plot-format svg`):
//! the file parses as SVG (usvg, the tree the part import uses, and roxmltree for the text
//! usvg leaves out without its text feature) and holds the figure's elements: its axis
//! labels, legend entries, curves and parts. The analysis and string figures have theirs in
//! `cli_data_out.rs` and `cli_physics.rs`; the Bode plot in `plot::bode`'s unit tests.

use crate::support;

use std::path::Path;

use support::cli::{chladni, ex, tmp, triangle_on_four_lines};

/// An SVG figure read back: its size, its texts (with their x and anchor), and how many
/// elements of each drawing kind it has.
struct Svg {
    width: f64,
    texts: Vec<(String, f64, String)>,
    polylines: usize,
    polygons: usize,
}

impl Svg {
    fn read(path: &Path) -> Svg {
        let text = std::fs::read_to_string(path)
            .unwrap_or_else(|e| panic!("{} not written: {e}", path.display()));
        // usvg resolves the whole document (units, transforms, styles): what a viewer draws.
        let tree = usvg::Tree::from_str(&text, &usvg::Options::default())
            .unwrap_or_else(|e| panic!("{} is not SVG usvg reads: {e}", path.display()));
        assert!(tree.root().has_children(), "{}: nothing drawn", path.display());
        let doc = roxmltree::Document::parse(&text).unwrap();
        let root = doc.root_element();
        assert_eq!(root.tag_name().name(), "svg");
        let width = root.attribute("width").and_then(|w| w.parse().ok()).unwrap();
        let texts = doc
            .descendants()
            .filter(|n| n.has_tag_name("text"))
            .filter_map(|n| {
                let t = n.text()?.trim().to_string();
                let x = n.attribute("x").and_then(|x| x.parse().ok()).unwrap_or(f64::NAN);
                Some((t, x, n.attribute("text-anchor").unwrap_or("start").to_string()))
            })
            .collect();
        let count = |tag: &str| doc.descendants().filter(|n| n.has_tag_name(tag)).count();
        Svg { width, texts, polylines: count("polyline"), polygons: count("polygon") }
    }

    /// Panics unless some text reads exactly `want`.
    fn has(&self, want: &str) {
        assert!(self.texts.iter().any(|(t, ..)| t == want), "{want:?} not in {:?}", self.texts);
    }

    /// Panics unless some text starts with `want`.
    fn has_prefix(&self, want: &str) {
        assert!(
            self.texts.iter().any(|(t, ..)| t.starts_with(want)),
            "no text starting {want:?} in {:?}",
            self.texts
        );
    }
}

fn ok(out: &std::process::Output) {
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

#[test]
fn simulate_writes_the_traces_and_the_plan_figure_as_svg() {
    let traces = tmp("figsvg", "sim.svg");
    let plan_file = ex("plans/triangle-four-lines.json");
    let out = triangle_on_four_lines(
        "simulate",
        &["--plan", &plan_file, "--trials", "6", "--plot", traces.to_str().unwrap()],
    );
    ok(&out);
    let plan = traces
        .with_file_name(format!("{}-plan.svg", traces.file_stem().unwrap().to_str().unwrap()));
    assert!(String::from_utf8_lossy(&out.stdout).contains(plan.to_str().unwrap()));
    let t = Svg::read(&traces);
    for want in ["x (mm)", "y (mm)", "t (s)", "θ (deg)", "node, step 1", "node, step 2"] {
        t.has(want);
    }
    t.has("trials");
    t.has("predicted θ");
    // Six centroid paths and six θ(t) curves at least; each part a filled polygon.
    assert!(t.polylines >= 12, "{} polylines", t.polylines);
    assert!(t.polygons >= 12, "{} polygons: a start and an end part per trial", t.polygons);
    let p = Svg::read(&plan);
    p.has_prefix("step 1: ");
    p.has_prefix("step 2: ");
    p.has_prefix("triangle: plan step by step");
    // Three example starts × two steps, each panel the part before and after the step.
    assert!(p.polygons >= 12, "{} polygons", p.polygons);
    for f in [traces, plan] {
        std::fs::remove_file(f).unwrap();
    }
}

#[test]
fn plan_writes_its_figure_as_svg() {
    let fig = tmp("figsvg", "plan.svg");
    let out = triangle_on_four_lines("plan", &["--plot", fig.to_str().unwrap()]);
    ok(&out);
    let p = Svg::read(&fig);
    p.has_prefix("step 1: ");
    p.has_prefix("triangle: ");
    assert!(p.polygons >= 6, "{} polygons", p.polygons);
    std::fs::remove_file(fig).unwrap();
}

#[test]
fn plate_modes_write_svg_figures_with_the_last_x_tick_inside() {
    let dir = tmp("figsvg", "modes");
    let _ = std::fs::remove_dir_all(&dir);
    let args = [
        "plate",
        "modes",
        &ex("plate-cantilever.toml"),
        "--count",
        "2",
        "--terms",
        "8",
        "--plot",
        dir.to_str().unwrap(),
        "--plot-format",
        "svg",
    ];
    ok(&chladni(&args));
    for k in 1..=2 {
        let s = Svg::read(&dir.join(format!("mode-{k:02}.svg")));
        s.has("x (mm)");
        s.has("y (mm)");
        s.has_prefix(&format!("cantilever 300x200 — mode {k}: "));
        // The last x tick (the plate's 300 mm edge) is centred on the edge: half its width
        // (3 digits at 12 px, at most 7 px each) must fit inside the figure.
        let last = s.texts.iter().find(|(t, ..)| t == "300").expect("a 300 mm tick");
        let half = if last.2 == "middle" { 11.0 } else { 22.0 };
        assert!(last.1 + half <= s.width, "tick at x = {} clipped (width {})", last.1, s.width);
        assert!(s.polylines >= 1, "no node line");
    }
    assert!(!dir.join("mode-01.png").exists(), "svg asked for, png written");
    let bad = chladni(&[args[0], args[1], args[2], "--plot", "x", "--plot-format", "gif"]);
    assert_eq!(bad.status.code(), Some(2));
    std::fs::remove_dir_all(&dir).unwrap();
}
