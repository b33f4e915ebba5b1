//! Typed plate model for the planner and the simulator: the `[plate]` table's size plus the
//! `[[mode]]` entries parsed into [`Mode`]s, each checked with a named error (offending value
//! and how to fix it). Schema in docs/plan.md.
//!
//! ```toml
//! [[mode]]
//! name = "60 Hz"                     # optional
//! freq_hz = 60.0                     # drive frequency (needed to plan)
//! amplitude = 0.8                    # drive amplitude, fraction of full scale (default 1)
//! field = "sign"                     # sign | linear | sine (line and hyperbola nodes)
//! wavelength_mm = 80.0               # sine only: node-to-antinode distance
//! gain = 1.0                         # or gain_left / gain_right
//! speed_mm_s = 10.0                  # settle speed μ (default 10)
//! ramp_ms = 20                       # amplitude ramp at the start of the step (default 20)
//! node = { kind = "line", angle_deg = 90.0, offset_mm = 0.0 }
//! ```

use std::path::Path;

use toml::{Table, Value};

use crate::model::plate_file::{PlateFile, PlateFileError};
use crate::plate::solver::Grid;

/// The linear field's length scale: its pull equals the gain this far from the node.
pub const LINEAR_SCALE_MM: f64 = 10.0;

/// Field law of a line or hyperbola node.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Law {
    /// f = −k·sign(d).
    Sign,
    /// f = −k·d / [`LINEAR_SCALE_MM`].
    Linear,
    /// f = −k·sin(π d / w).
    Sine {
        /// Node-to-antinode distance (mm).
        wavelength_mm: f64,
    },
}

impl Law {
    /// Name as written in files.
    pub fn name(&self) -> &'static str {
        match self {
            Law::Sign => "sign",
            Law::Linear => "linear",
            Law::Sine { .. } => "sine",
        }
    }
    /// g(d), the field's shape (force per unit gain, towards the node for d > 0 along −∇d).
    pub fn g(&self, d: f64) -> f64 {
        match *self {
            Law::Sign => d.signum(),
            Law::Linear => d / LINEAR_SCALE_MM,
            Law::Sine { wavelength_mm } => (std::f64::consts::PI * d / wavelength_mm).sin(),
        }
    }
    /// G(d) = ∫₀ᵈ g (the potential per unit gain).
    pub fn big_g(&self, d: f64) -> f64 {
        match *self {
            Law::Sign => d.abs(),
            Law::Linear => 0.5 * d * d / LINEAR_SCALE_MM,
            Law::Sine { wavelength_mm: w } => {
                let k = std::f64::consts::PI / w;
                (1.0 - (k * d).cos()) / k
            }
        }
    }
}

/// The node a mode creates.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// A straight line: direction `angle_deg` (CCW from plate +x), signed distance
    /// `offset_mm` from the plate centre c along n̂ = (−sin α, cos α).
    Line {
        /// Direction α (degrees).
        angle_deg: f64,
        /// n̂·(p − c) on the line (mm).
        offset_mm: f64,
    },
    /// One branch of a hyperbola: c + R(α)·(a cosh t, b sinh t), t ∈ ℝ.
    Hyperbola {
        /// Centre (plate frame, mm; origin at the plate corner).
        center_mm: [f64; 2],
        /// Direction of the axis through the branch's vertex (degrees).
        angle_deg: f64,
        /// Semi-axis a (centre to vertex, mm).
        a_mm: f64,
        /// Semi-axis b (mm): the asymptotes have slope ±b/a.
        b_mm: f64,
    },
    /// A sampled mode shape φ; the field is f = −∇(K·φ²).
    Grid(Grid),
}

impl Node {
    /// Kind name.
    pub fn kind(&self) -> &'static str {
        match self {
            Node::Line { .. } => "line",
            Node::Hyperbola { .. } => "hyperbola",
            Node::Grid(_) => "grid",
        }
    }
}

/// One mode of the plate.
#[derive(Debug, Clone, PartialEq)]
pub struct Mode {
    /// Name (defaults to "mode N").
    pub name: String,
    /// Drive frequency (Hz).
    pub freq_hz: f64,
    /// Drive amplitude, fraction of full scale.
    pub amplitude: f64,
    /// Field law (line and hyperbola nodes; grid nodes always use φ²).
    pub law: Law,
    /// Gain on the left of the node (walking along its direction; +n̂ side).
    pub gain_left: f64,
    /// Gain on the right (−n̂ side).
    pub gain_right: f64,
    /// Settle speed μ (mm/s per unit force per area).
    pub speed_mm_s: f64,
    /// Amplitude ramp (ms).
    pub ramp_ms: u32,
    /// The node.
    pub node: Node,
}

impl Mode {
    /// Equal gains on a straight node: orientations only matter modulo 180°.
    pub fn is_symmetric_line(&self) -> bool {
        matches!(self.node, Node::Line { .. }) && self.gain_left == self.gain_right
    }
}

/// A plate ready for planning: size and typed modes.
#[derive(Debug, Clone, PartialEq)]
pub struct PlateModel {
    /// Name.
    pub name: String,
    /// Size [W, H] (mm); the plate is [0, W]×[0, H].
    pub size_mm: [f64; 2],
    /// Modes, in file order.
    pub modes: Vec<Mode>,
}

/// What is wrong with a `[[mode]]` entry (or the plate as a whole, for planning).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ModelError {
    /// A key is wrong; names the mode, key, value and a fix.
    #[error("[[mode]] {index} ({name}): {key} = {value}: {fix}")]
    Bad {
        /// 1-based mode index.
        index: usize,
        /// Mode name.
        name: String,
        /// Key.
        key: String,
        /// Offending value (as written, or "missing").
        value: String,
        /// How to fix it.
        fix: String,
    },
    /// The plate has no size.
    #[error("[plate] needs size_mm = [W, H] for planning")]
    NoSize,
    /// No modes.
    #[error("the plate file has no [[mode]] entries: add at least one (docs/plan.md)")]
    NoModes,
}

struct Ctx<'a> {
    index: usize,
    name: String,
    t: &'a Table,
}

impl Ctx<'_> {
    fn bad(&self, key: &str, value: impl std::fmt::Display, fix: &str) -> ModelError {
        ModelError::Bad {
            index: self.index,
            name: self.name.clone(),
            key: key.into(),
            value: value.to_string(),
            fix: fix.into(),
        }
    }
    fn num(&self, t: &Table, key: &str, prefix: &str) -> Result<Option<f64>, ModelError> {
        match t.get(key) {
            None => Ok(None),
            Some(Value::Float(f)) if f.is_finite() => Ok(Some(*f)),
            Some(Value::Integer(i)) => Ok(Some(*i as f64)),
            Some(v) => Err(self.bad(&format!("{prefix}{key}"), v, "must be a finite number")),
        }
    }
    fn positive(&self, t: &Table, key: &str, prefix: &str) -> Result<Option<f64>, ModelError> {
        match self.num(t, key, prefix)? {
            Some(v) if v <= 0.0 || v > 1e7 => {
                Err(self.bad(&format!("{prefix}{key}"), v, "must be positive (and at most 1e7)"))
            }
            other => Ok(other),
        }
    }
}

const MODE_KEYS: &[&str] = &[
    "name",
    "freq_hz",
    "amplitude",
    "field",
    "wavelength_mm",
    "gain",
    "gain_left",
    "gain_right",
    "speed_mm_s",
    "ramp_ms",
    "node",
    "lambda",
];

/// Parses one `[[mode]]` table (`index` is 1-based, for messages).
pub fn parse_mode(index: usize, t: &Table, size_mm: [f64; 2]) -> Result<Mode, ModelError> {
    let name = match t.get("name") {
        Some(Value::String(s)) => s.clone(),
        _ => format!("mode {index}"),
    };
    let c = Ctx { index, name: name.clone(), t };
    for k in c.t.keys() {
        if !MODE_KEYS.contains(&k.as_str()) {
            return Err(c.bad(
                k,
                &c.t[k],
                &format!("unknown key; known keys: {}", MODE_KEYS.join(", ")),
            ));
        }
    }
    if let Some(v) = t.get("name")
        && !v.is_str()
    {
        return Err(c.bad("name", v, "must be a string"));
    }
    let freq_hz = c
        .positive(t, "freq_hz", "")?
        .ok_or_else(|| c.bad("freq_hz", "missing", "add freq_hz = <drive frequency in Hz>"))?;
    if !(1.0..=2000.0).contains(&freq_hz) {
        return Err(c.bad("freq_hz", freq_hz, "the drive takes 1..=2000 Hz"));
    }
    let amplitude = c.num(t, "amplitude", "")?.unwrap_or(1.0);
    if !(amplitude > 0.0 && amplitude <= 1.0) {
        return Err(c.bad("amplitude", amplitude, "must be in (0, 1] (fraction of full scale)"));
    }
    let speed_mm_s = c.positive(t, "speed_mm_s", "")?.unwrap_or(10.0);
    let ramp_ms = match t.get("ramp_ms") {
        None => 20,
        Some(Value::Integer(i)) if (0..=60_000).contains(i) => *i as u32,
        Some(v) => return Err(c.bad("ramp_ms", v, "must be an integer in 0..=60000")),
    };
    // Gains.
    let gain = c.positive(t, "gain", "")?;
    let gl = c.positive(t, "gain_left", "")?;
    let gr = c.positive(t, "gain_right", "")?;
    let (gain_left, gain_right) = match (gain, gl, gr) {
        (Some(g), None, None) => (g, g),
        (None, l, r) => (l.unwrap_or(1.0), r.unwrap_or(1.0)),
        (Some(g), _, _) => {
            return Err(c.bad("gain", g, "give either gain or gain_left/gain_right, not both"));
        }
    };
    // Node.
    let node_t = match t.get("node") {
        Some(Value::Table(n)) => n,
        Some(v) => {
            return Err(c.bad("node", v, "must be a table: node = { kind = \"line\", ... }"));
        }
        None => {
            return Err(c.bad(
                "node",
                "missing",
                "add node = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }",
            ));
        }
    };
    let kind = match node_t.get("kind") {
        Some(Value::String(s)) => s.as_str(),
        Some(v) => {
            return Err(c.bad("node.kind", v, "must be \"line\", \"hyperbola\" or \"grid\""));
        }
        None => {
            return Err(c.bad(
                "node.kind",
                "missing",
                "add kind = \"line\" | \"hyperbola\" | \"grid\"",
            ));
        }
    };
    let allowed: &[&str] = match kind {
        "line" => &["kind", "angle_deg", "offset_mm"],
        "hyperbola" => &["kind", "center_mm", "angle_deg", "a_mm", "b_mm"],
        "grid" => &["kind", "nx", "ny", "values"],
        other => {
            return Err(c.bad(
                "node.kind",
                format!("\"{other}\""),
                "must be \"line\", \"hyperbola\" or \"grid\"",
            ));
        }
    };
    for k in node_t.keys() {
        if !allowed.contains(&k.as_str()) {
            return Err(c.bad(
                &format!("node.{k}"),
                &node_t[k],
                &format!("unknown key for a {kind} node; known: {}", allowed.join(", ")),
            ));
        }
    }
    let [w, h] = size_mm;
    let diag = w.hypot(h);
    let node = match kind {
        "line" => {
            let angle_deg = c.num(node_t, "angle_deg", "node.")?.ok_or_else(|| {
                c.bad(
                    "node.angle_deg",
                    "missing",
                    "add angle_deg = <direction of the node line, degrees CCW from plate x>",
                )
            })?;
            let offset_mm = c.num(node_t, "offset_mm", "node.")?.unwrap_or(0.0);
            if offset_mm.abs() > diag / 2.0 {
                return Err(c.bad(
                    "node.offset_mm",
                    offset_mm,
                    &format!(
                        "the line misses the plate: |offset| must be at most {:.1} mm",
                        diag / 2.0
                    ),
                ));
            }
            Node::Line { angle_deg, offset_mm }
        }
        "hyperbola" => {
            let center_mm = match node_t.get("center_mm") {
                Some(Value::Array(a)) if a.len() == 2 => {
                    let f = |v: &Value| v.as_float().or(v.as_integer().map(|i| i as f64));
                    match (f(&a[0]), f(&a[1])) {
                        (Some(x), Some(y)) if x.is_finite() && y.is_finite() => [x, y],
                        _ => {
                            return Err(c.bad(
                                "node.center_mm",
                                &node_t["center_mm"],
                                "must be [x, y] in mm",
                            ));
                        }
                    }
                }
                Some(v) => return Err(c.bad("node.center_mm", v, "must be [x, y] in mm")),
                None => {
                    return Err(c.bad(
                        "node.center_mm",
                        "missing",
                        "add center_mm = [x, y] (plate frame, mm)",
                    ));
                }
            };
            let angle_deg = c.num(node_t, "angle_deg", "node.")?.unwrap_or(0.0);
            let a_mm = c.positive(node_t, "a_mm", "node.")?.ok_or_else(|| {
                c.bad("node.a_mm", "missing", "add a_mm = <centre-to-vertex distance, mm>")
            })?;
            let b_mm = c
                .positive(node_t, "b_mm", "node.")?
                .ok_or_else(|| c.bad("node.b_mm", "missing", "add b_mm = <semi-axis b, mm>"))?;
            Node::Hyperbola { center_mm, angle_deg, a_mm, b_mm }
        }
        _ => {
            let dim = |k: &str| match node_t.get(k) {
                Some(Value::Integer(i)) if (2..=1000).contains(i) => Ok(*i as usize),
                Some(v) => Err(c.bad(&format!("node.{k}"), v, "must be an integer in 2..=1000")),
                None => Err(c.bad(&format!("node.{k}"), "missing", "add the sample count")),
            };
            let (nx, ny) = (dim("nx")?, dim("ny")?);
            let values: Vec<f64> = match node_t.get("values") {
                Some(Value::Array(a)) => {
                    let mut out = Vec::with_capacity(a.len());
                    for (i, v) in a.iter().enumerate() {
                        match v.as_float().or(v.as_integer().map(|i| i as f64)) {
                            Some(f) if f.is_finite() => out.push(f),
                            _ => {
                                return Err(c.bad(
                                    &format!("node.values[{i}]"),
                                    v,
                                    "must be a finite number",
                                ));
                            }
                        }
                    }
                    out
                }
                _ => {
                    return Err(c.bad(
                        "node.values",
                        "missing",
                        "add values = [nx·ny samples of φ]",
                    ));
                }
            };
            if values.len() != nx * ny {
                return Err(c.bad(
                    "node.values",
                    format!("{} samples", values.len()),
                    &format!("need nx·ny = {}", nx * ny),
                ));
            }
            let max = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            if max == 0.0 {
                return Err(c.bad(
                    "node.values",
                    "all zero",
                    "a mode shape must not vanish everywhere",
                ));
            }
            Node::Grid(Grid { nx, ny, size_mm, values: values.iter().map(|v| v / max).collect() })
        }
    };
    // Field law.
    let field = match t.get("field") {
        None => None,
        Some(Value::String(s)) => Some(s.as_str()),
        Some(v) => return Err(c.bad("field", v, "must be \"sign\", \"linear\" or \"sine\"")),
    };
    let wavelength = c.positive(t, "wavelength_mm", "")?;
    let law = match (field, &node) {
        (Some(f), Node::Grid(_)) => {
            return Err(c.bad(
                "field",
                format!("\"{f}\""),
                "a grid node's field is always f = −∇(K·φ²): remove `field`",
            ));
        }
        (None, Node::Grid(_)) => Law::Linear,
        (None | Some("linear"), _) => Law::Linear,
        (Some("sign"), _) => Law::Sign,
        (Some("sine"), _) => Law::Sine {
            wavelength_mm: wavelength.ok_or_else(|| {
                c.bad(
                    "wavelength_mm",
                    "missing",
                    "field = \"sine\" needs wavelength_mm = <node-to-antinode distance, mm>",
                )
            })?,
        },
        (Some(other), _) => {
            return Err(c.bad(
                "field",
                format!("\"{other}\""),
                "must be \"sign\", \"linear\" or \"sine\"",
            ));
        }
    };
    if let (Some(wl), false) = (wavelength, matches!(law, Law::Sine { .. })) {
        return Err(c.bad("wavelength_mm", wl, "only applies to field = \"sine\": remove it"));
    }
    Ok(Mode { name, freq_hz, amplitude, law, gain_left, gain_right, speed_mm_s, ramp_ms, node })
}

impl PlateModel {
    /// Types a parsed plate file.
    pub fn from_file(file: &PlateFile) -> Result<PlateModel, ModelError> {
        let size_mm = file.plate.size_mm.ok_or(ModelError::NoSize)?;
        if file.mode.is_empty() {
            return Err(ModelError::NoModes);
        }
        let modes = file
            .mode
            .iter()
            .enumerate()
            .map(|(i, t)| parse_mode(i + 1, t, size_mm))
            .collect::<Result<Vec<_>, _>>()?;
        let name =
            if file.plate.name.is_empty() { "plate".to_string() } else { file.plate.name.clone() };
        Ok(PlateModel { name, size_mm, modes })
    }

    /// Reads, parses and types a plate file (every error is a message for exit code 2).
    pub fn load(path: &Path) -> Result<PlateModel, String> {
        let file = PlateFile::load(path).map_err(|e: PlateFileError| e.to_string())?;
        PlateModel::from_file(&file).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The plate centre.
    pub fn center(&self) -> [f64; 2] {
        [self.size_mm[0] / 2.0, self.size_mm[1] / 2.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(modes: &str) -> Result<PlateModel, ModelError> {
        let text = format!("[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n{modes}");
        PlateModel::from_file(&PlateFile::parse(&text, "t").unwrap())
    }

    #[test]
    fn parses_each_node_kind() {
        let m = model(
            r#"
[[mode]]
freq_hz = 60.0
field = "sign"
node = { kind = "line", angle_deg = 90.0, offset_mm = 0.0 }
gain_right = 2.0
[[mode]]
freq_hz = 80
field = "sine"
wavelength_mm = 90.0
node = { kind = "hyperbola", center_mm = [150.0, 100.0], angle_deg = 0.0, a_mm = 40.0, b_mm = 60.0 }
[[mode]]
freq_hz = 100.0
lambda = 3.2
node = { kind = "grid", nx = 2, ny = 2, values = [1.0, -1.0, 0.5, -0.5] }
"#,
        )
        .unwrap();
        assert_eq!(m.modes.len(), 3);
        assert_eq!((m.modes[0].gain_left, m.modes[0].gain_right), (1.0, 2.0));
        assert!(!m.modes[0].is_symmetric_line());
        assert_eq!(m.modes[1].law, Law::Sine { wavelength_mm: 90.0 });
        assert_eq!(m.modes[1].node.kind(), "hyperbola");
        assert_eq!(m.modes[2].node.kind(), "grid");
        assert_eq!(m.modes[2].name, "mode 3");
    }

    #[test]
    fn named_errors_with_value_and_fix() {
        let line = "node = { kind = \"line\", angle_deg = 0.0 }";
        let err = |s: &str| model(s).unwrap_err().to_string();
        let e = err(&format!("[[mode]]\n{line}"));
        assert!(e.contains("freq_hz = missing") && e.contains("add freq_hz"), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 5000.0\n{line}"));
        assert!(e.contains("freq_hz = 5000") && e.contains("1..=2000"), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 50.0\nfield = \"cosine\"\n{line}"));
        assert!(e.contains("\"cosine\""), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 50.0\nfield = \"sine\"\n{line}"));
        assert!(e.contains("wavelength_mm = missing"), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 50.0\ngain = -1.0\n{line}"));
        assert!(e.contains("gain = -1"), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 50.0\ngain = 1.0\ngain_left = 2.0\n{line}"));
        assert!(e.contains("not both"), "{e}");
        let e = err(&format!("[[mode]]\nfreq_hz = 50.0\ncolour = 1\n{line}"));
        assert!(e.contains("colour") && e.contains("unknown key"), "{e}");
        let e = err("[[mode]]\nfreq_hz = 50.0\nnode = { kind = \"circle\" }");
        assert!(e.contains("\"circle\""), "{e}");
        let e = err(
            "[[mode]]\nfreq_hz = 50.0\nnode = { kind = \"hyperbola\", center_mm = [0.0, 0.0], a_mm = 0.0, b_mm = 1.0 }",
        );
        assert!(e.contains("node.a_mm = 0"), "{e}");
        let e = err(
            "[[mode]]\nfreq_hz = 50.0\nnode = { kind = \"grid\", nx = 2, ny = 2, values = [1.0] }",
        );
        assert!(e.contains("need nx·ny = 4"), "{e}");
        let e = err(
            "[[mode]]\nfreq_hz = 50.0\nfield = \"sign\"\nnode = { kind = \"grid\", nx = 2, ny = 2, values = [1.0, 0.0, 0.0, 1.0] }",
        );
        assert!(e.contains("remove `field`"), "{e}");
        let e = err(
            "[[mode]]\nfreq_hz = 50.0\nnode = { kind = \"line\", angle_deg = 0.0, offset_mm = 900.0 }",
        );
        assert!(e.contains("misses the plate"), "{e}");
        assert_eq!(model("").unwrap_err(), ModelError::NoModes);
    }
}
