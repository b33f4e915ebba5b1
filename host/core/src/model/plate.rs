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
//! shift_mm = [0.0, 0.0]              # the nodes moved by [dx, dy] (a learned correction)
//! node = { kind = "line", angle_deg = 90.0, offset_mm = 0.0 }
//! # or several lines of one mode:
//! # node = { kind = "lines", lines = [{ angle_deg = 90.0, offset_mm = -50.0 }, { angle_deg = 0.0 }] }
//! ```
//!
//! One drive frequency is one mode: the plate vibrates in one shape, so entries at the same
//! frequency (within [`SAME_FREQ_HZ`]) are one mode. Straight-node entries that agree on
//! everything but their lines are merged into one [`Node::Lines`] mode (the node is all their
//! lines; names joined by " + "); any other pair is refused ([`ModelError::SameFrequency`]),
//! since the planner would otherwise plan "60 Hz → 60 Hz" steps the plate cannot tell apart.

use crate::model::field::Law;
use std::path::Path;

use crate::model::field::LawError;
use crate::model::grid::Grid;
use crate::model::plan_file::check_drive_freq;
use crate::model::plate_file::{LineEntry, ModeEntry, NodeEntry, PlateFile, PlateFileError};
use chladni_shared::icd::units::Given;

/// Entries whose frequencies differ by less than this (Hz) are one mode (the drive's
/// resolution is 1 mHz).
pub const SAME_FREQ_HZ: f64 = 1e-3;

/// One straight line of a [`Node::Lines`] node (the conventions of [`Node::Line`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NodeLine {
    /// Direction α (degrees).
    pub angle_deg: f64,
    /// n̂·(p − c) on the line (mm).
    pub offset_mm: f64,
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
    /// Several straight lines of one mode (e.g. a Chladni figure with two or more lines): the
    /// field at a point is that of the nearest line, with the mode's law and gains (left and
    /// right of that line).
    Lines(Vec<NodeLine>),
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
    /// The same node moved by `shift` (mm): a line's offset changes by the shift's component
    /// along its normal n̂, a hyperbola's centre moves. A grid is resampled at the moved points; where they fall off the grid,
    /// φ is extended linearly from its edge ([`Grid::shifted`]).
    pub fn shifted(self, shift: [f64; 2]) -> Node {
        if shift == [0.0, 0.0] {
            return self;
        }
        let moved = |l: NodeLine| {
            let (s, c) = l.angle_deg.to_radians().sin_cos();
            NodeLine {
                angle_deg: l.angle_deg,
                offset_mm: l.offset_mm - s * shift[0] + c * shift[1],
            }
        };
        match self {
            Node::Line { angle_deg, offset_mm } => {
                let l = moved(NodeLine { angle_deg, offset_mm });
                Node::Line { angle_deg: l.angle_deg, offset_mm: l.offset_mm }
            }
            Node::Lines(lines) => Node::Lines(lines.into_iter().map(moved).collect()),
            Node::Hyperbola { center_mm, angle_deg, a_mm, b_mm } => Node::Hyperbola {
                center_mm: [center_mm[0] + shift[0], center_mm[1] + shift[1]],
                angle_deg,
                a_mm,
                b_mm,
            },
            Node::Grid(g) => Node::Grid(g.shifted(shift)),
        }
    }

    /// Kind name.
    pub fn kind(&self) -> &'static str {
        match self {
            Node::Line { .. } => "line",
            Node::Lines(_) => "lines",
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
    /// How far the nodes were moved from where the entry's `node` puts them (mm): `node` is
    /// already the moved one; kept to say so and to write it back.
    pub shift_mm: [f64; 2],
    /// The node.
    pub node: Node,
}

impl Mode {
    /// Equal gains on a straight node: orientations only matter modulo 180°.
    pub(crate) fn is_symmetric_line(&self) -> bool {
        matches!(self.node, Node::Line { .. }) && self.gain_left == self.gain_right
    }
}

/// What the plate's edge does to a part (`[plate] edge`, docs/plate.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Edge {
    /// A rim the part cannot pass; it slides along it with Coulomb friction (feeder
    /// platforms have one).
    #[default]
    Wall,
    /// No rim: a part whose centroid crosses the edge falls off and is lost.
    Open,
}

/// Default wall friction coefficient: mild steel sliding on aluminium, dry, kinetic (0.47 in
/// the friction tables of Marks' Standard Handbook for Mechanical Engineers). An assumption,
/// not a measurement of any rig: set `[plate] friction` for yours (docs/plate.md).
pub const DEFAULT_FRICTION: f64 = 0.47;

/// A plate ready for planning: size, rim and typed modes.
#[derive(Debug, Clone, PartialEq)]
pub struct PlateModel {
    /// Name.
    pub name: String,
    /// Size [W, H] (mm); the plate is [0, W]×[0, H].
    pub size_mm: [f64; 2],
    /// Modes, in file order.
    pub modes: Vec<Mode>,
    /// The rim.
    pub edge: Edge,
    /// Coulomb friction coefficient between parts and the wall.
    pub friction: f64,
}

/// What is wrong with a `[[mode]]` entry (or the plate as a whole, for planning).
#[derive(Debug, thiserror::Error)]
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
    /// A `[plate]` key of the motion model is wrong.
    #[error("[plate] {key} = {value}: {fix}")]
    PlateKey {
        /// Key.
        key: &'static str,
        /// Offending value.
        value: String,
        /// How to fix it.
        fix: &'static str,
    },
    /// No modes.
    #[error(
        "the plate file has no [[mode]] entries: write them with `chladni plate modes PLATE.toml \
         --write-modes OUT.toml` (or by hand, docs/plan.md)"
    )]
    NoModes,
    /// Two entries at one drive frequency that cannot be one mode.
    #[error(
        "[[mode]] {first} ({first_name}) and [[mode]] {second} ({second_name}) are both at \
         {freq_hz} Hz: one drive frequency makes one vibration, so one mode; {why}. Fix the \
         file: put all node lines of that frequency in one entry (node = {{ kind = \"lines\", \
         lines = [...] }}), or remove one entry"
    )]
    SameFrequency {
        /// The frequency (Hz).
        freq_hz: f64,
        /// 1-based index of the first entry.
        first: usize,
        /// Its name.
        first_name: String,
        /// 1-based index of the second entry.
        second: usize,
        /// Its name.
        second_name: String,
        /// Why they cannot be merged.
        why: String,
    },
    /// A `[[mode]]` table in hand that is not a mode entry (unknown key, wrong type).
    #[error("[[mode]] {index}: {source}")]
    Entry {
        /// 1-based index of the entry.
        index: usize,
        /// The deserialiser's message (key, type, position).
        source: toml::de::Error,
    },
    /// The file is not a plate file (syntax, types, unknown `[plate]` keys).
    #[error(transparent)]
    File(#[from] PlateFileError),
}

/// Why [`PlateModel::load`] failed: the file (unreadable, not a plate file) or its modes.
#[derive(Debug, thiserror::Error)]
pub enum PlateLoadError {
    /// Not readable, or not a plate file.
    #[error(transparent)]
    File(#[from] PlateFileError),
    /// A plate file whose modes cannot be planned with.
    #[error("{}: {source}", path.display())]
    Model {
        /// The file.
        path: std::path::PathBuf,
        /// What is wrong (boxed: a ModelError is large).
        source: Box<ModelError>,
    },
}

/// Names the mode in every error.
struct Ctx {
    index: usize,
    name: String,
}

/// Bounds of the keys that must be positive (gains, speed, semi-axes, wavelength).
const MAX_POSITIVE: f64 = 1e7;

impl Ctx {
    fn bad(&self, key: &str, value: impl std::fmt::Display, fix: &str) -> ModelError {
        ModelError::Bad {
            index: self.index,
            name: self.name.clone(),
            key: key.into(),
            value: value.to_string(),
            fix: fix.into(),
        }
    }
    fn finite(&self, key: &str, v: Option<f64>) -> Result<Option<f64>, ModelError> {
        match v {
            Some(f) if !f.is_finite() => Err(self.bad(key, Given(f), "must be a finite number")),
            other => Ok(other),
        }
    }
    fn positive(&self, key: &str, v: Option<f64>) -> Result<Option<f64>, ModelError> {
        match self.finite(key, v)? {
            Some(v) if v <= 0.0 || v > MAX_POSITIVE => {
                Err(self.bad(key, Given(v), "must be positive (and at most 1e7)"))
            }
            other => Ok(other),
        }
    }
}

/// The keys of a `[[mode]]` entry, for the unknown-key message.
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
    "shift_mm",
    "node",
    "lambda",
];

/// Checks one `[[mode]]` entry and types it (`index` is 1-based, for messages).
pub(crate) fn check_mode(
    index: usize,
    e: &ModeEntry,
    size_mm: [f64; 2],
) -> Result<Mode, ModelError> {
    let name = e.name.clone().unwrap_or_else(|| format!("mode {index}"));
    let c = Ctx { index, name: name.clone() };
    if let Some((k, v)) = e.unknown.iter().next() {
        return Err(c.bad(k, v, &format!("unknown key; known keys: {}", MODE_KEYS.join(", "))));
    }
    // Drive.
    let freq_hz = c
        .finite("freq_hz", e.freq_hz)?
        .ok_or_else(|| c.bad("freq_hz", "missing", "add freq_hz = <drive frequency in Hz>"))?;
    check_drive_freq(freq_hz).map_err(|r| c.bad("freq_hz", Given(freq_hz), &r.to_string()))?;
    let amplitude = c.finite("amplitude", e.amplitude)?.unwrap_or(1.0);
    if !(amplitude > 0.0 && amplitude <= 1.0) {
        return Err(c.bad(
            "amplitude",
            Given(amplitude),
            "must be in (0, 1] (fraction of full scale)",
        ));
    }
    let speed_mm_s = c.positive("speed_mm_s", e.speed_mm_s)?.unwrap_or(10.0);
    let ramp_ms = match e.ramp_ms {
        None => 20,
        Some(i) if (0..=60_000).contains(&i) => i as u32,
        Some(v) => return Err(c.bad("ramp_ms", v, "must be an integer in 0..=60000")),
    };
    let (gain_left, gain_right) = gains(&c, e)?;
    let node = match &e.node {
        Some(n) => node_of(&c, n, size_mm)?,
        None => {
            // A mode measured by `chladni device sweep` has a frequency and no node yet.
            return Err(c.bad(
                "node",
                "missing",
                "add node = { kind = \"line\", angle_deg = 90.0, offset_mm = 0.0 }, or take \
                 it from `chladni plate modes` or `chladni plate from-photo` (a mode measured \
                 by `chladni device sweep` has none until it is filled in)",
            ));
        }
    };
    let law = law_of(&c, e, &node)?;
    let shift_mm = shift_of(&c, e.shift_mm, size_mm)?;
    let node = node.shifted(shift_mm);
    let (gl, gr) = (gain_left, gain_right);
    Ok(Mode {
        name,
        freq_hz,
        amplitude,
        law,
        gain_left: gl,
        gain_right: gr,
        speed_mm_s,
        ramp_ms,
        shift_mm,
        node,
    })
}

/// A mode's `shift_mm`: finite, and less than the plate's size along each axis.
fn shift_of(c: &Ctx, shift: Option<[f64; 2]>, size_mm: [f64; 2]) -> Result<[f64; 2], ModelError> {
    let Some(s) = shift else { return Ok([0.0, 0.0]) };
    if s.iter().zip(size_mm).all(|(v, side)| v.is_finite() && v.abs() < side) {
        return Ok(s);
    }
    Err(c.bad(
        "shift_mm",
        format!("{s:?}"),
        &format!(
            "must be [dx, dy] in mm, each less than the plate's side ({} x {} mm)",
            size_mm[0], size_mm[1]
        ),
    ))
}

#[cfg(test)]
/// Checks one `[[mode]]` table in hand (as [`check_mode`] after deserialising it).
pub(crate) fn parse_mode(
    index: usize,
    t: &toml::Table,
    size_mm: [f64; 2],
) -> Result<Mode, ModelError> {
    use serde::Deserialize;
    let e = ModeEntry::deserialize(toml::Value::Table(t.clone()))
        .map_err(|source| ModelError::Entry { index, source })?;
    check_mode(index, &e, size_mm)
}

/// `gain` or `gain_left`/`gain_right` (default 1 each).
fn gains(c: &Ctx, e: &ModeEntry) -> Result<(f64, f64), ModelError> {
    let gain = c.positive("gain", e.gain)?;
    let gl = c.positive("gain_left", e.gain_left)?;
    let gr = c.positive("gain_right", e.gain_right)?;
    match (gain, gl, gr) {
        (Some(g), None, None) => Ok((g, g)),
        (None, l, r) => Ok((l.unwrap_or(1.0), r.unwrap_or(1.0))),
        (Some(g), _, _) => {
            Err(c.bad("gain", Given(g), "give either gain or gain_left/gain_right, not both"))
        }
    }
}

/// The field law from `field` and `wavelength_mm` (grid nodes have none: always φ²).
fn law_of(c: &Ctx, e: &ModeEntry, node: &Node) -> Result<Law, ModelError> {
    let wavelength = c.positive("wavelength_mm", e.wavelength_mm)?;
    let name = match (e.field.as_deref(), node) {
        (Some(f), Node::Grid(_)) => {
            return Err(c.bad(
                "field",
                format!("\"{f}\""),
                "a grid node's field is always f = −∇(K·φ²): remove `field`",
            ));
        }
        (None, _) => "linear",
        (Some(f), _) => f,
    };
    Law::from_name(name, wavelength).map_err(|err| match err {
        LawError::Unknown(f) => {
            c.bad("field", format!("\"{f}\""), "must be \"sign\", \"linear\" or \"sine\"")
        }
        LawError::NeedsWavelength => c.bad(
            "wavelength_mm",
            "missing",
            "field = \"sine\" needs wavelength_mm = <node-to-antinode distance, mm>",
        ),
        LawError::Wavelength(w) => c.bad("wavelength_mm", w, "must be positive (and at most 1e7)"),
        LawError::WavelengthNotSine(w) => {
            c.bad("wavelength_mm", w, "only applies to field = \"sine\": remove it")
        }
    })
}

/// Checks and types a node.
fn node_of(c: &Ctx, n: &NodeEntry, size_mm: [f64; 2]) -> Result<Node, ModelError> {
    let [w, h] = size_mm;
    let diag = w.hypot(h);
    match *n {
        NodeEntry::Line { angle_deg, offset_mm } => {
            let l = line_of(c, "node", angle_deg, offset_mm, diag)?;
            Ok(Node::Line { angle_deg: l.angle_deg, offset_mm: l.offset_mm })
        }
        NodeEntry::Lines { ref lines } => {
            let lines = lines.as_deref().unwrap_or_default();
            if lines.is_empty() {
                return Err(c.bad(
                    "node.lines",
                    "missing",
                    "add lines = [{ angle_deg = .., offset_mm = .. }, ...] (at least one)",
                ));
            }
            let lines = (lines.iter().enumerate())
                .map(|(i, &LineEntry { angle_deg, offset_mm })| {
                    line_of(c, &format!("node.lines[{i}]"), Some(angle_deg), Some(offset_mm), diag)
                })
                .collect::<Result<Vec<_>, _>>()?;
            Ok(match lines[..] {
                [one] => Node::Line { angle_deg: one.angle_deg, offset_mm: one.offset_mm },
                _ => Node::Lines(lines),
            })
        }
        NodeEntry::Hyperbola { center_mm, angle_deg, a_mm, b_mm } => {
            let center_mm = match center_mm {
                Some([x, y]) if x.is_finite() && y.is_finite() => [x, y],
                Some(v) => {
                    return Err(c.bad("node.center_mm", format!("{v:?}"), "must be [x, y] in mm"));
                }
                None => {
                    return Err(c.bad(
                        "node.center_mm",
                        "missing",
                        "add center_mm = [x, y] (plate frame, mm)",
                    ));
                }
            };
            let angle_deg = c.finite("node.angle_deg", angle_deg)?.unwrap_or(0.0);
            let a_mm = c.positive("node.a_mm", a_mm)?.ok_or_else(|| {
                c.bad("node.a_mm", "missing", "add a_mm = <centre-to-vertex distance, mm>")
            })?;
            let b_mm = c
                .positive("node.b_mm", b_mm)?
                .ok_or_else(|| c.bad("node.b_mm", "missing", "add b_mm = <semi-axis b, mm>"))?;
            Ok(Node::Hyperbola { center_mm, angle_deg, a_mm, b_mm })
        }
        NodeEntry::Grid { nx, ny, ref values } => grid_of(c, nx, ny, values.as_deref(), size_mm),
    }
}

/// One straight line (`key`: where it is written, for messages).
fn line_of(
    c: &Ctx,
    key: &str,
    angle_deg: Option<f64>,
    offset_mm: Option<f64>,
    diag: f64,
) -> Result<NodeLine, ModelError> {
    let angle_key = format!("{key}.angle_deg");
    let angle_deg = c.finite(&angle_key, angle_deg)?.ok_or_else(|| {
        c.bad(
            &angle_key,
            "missing",
            "add angle_deg = <direction of the node line, degrees CCW from plate x>",
        )
    })?;
    let offset_key = format!("{key}.offset_mm");
    let offset_mm = c.finite(&offset_key, offset_mm)?.unwrap_or(0.0);
    if offset_mm.abs() > diag / 2.0 {
        return Err(c.bad(
            &offset_key,
            Given(offset_mm),
            &format!("the line misses the plate: |offset| must be at most {:.1} mm", diag / 2.0),
        ));
    }
    Ok(NodeLine { angle_deg, offset_mm })
}

/// The straight lines of a line or lines node (`None` for other kinds).
pub fn node_lines(node: &Node) -> Option<Vec<NodeLine>> {
    match node {
        Node::Line { angle_deg, offset_mm } => {
            Some(vec![NodeLine { angle_deg: *angle_deg, offset_mm: *offset_mm }])
        }
        Node::Lines(lines) => Some(lines.clone()),
        _ => None,
    }
}

/// Why two modes at one frequency cannot be one mode (`None`: they can).
fn unmergeable(a: &Mode, b: &Mode) -> Option<String> {
    if node_lines(&a.node).is_none() || node_lines(&b.node).is_none() {
        return Some(format!(
            "a {} node and a {} node cannot be merged (only straight lines can)",
            a.node.kind(),
            b.node.kind()
        ));
    }
    let differ = [
        ("field", a.law != b.law),
        ("gain_left", a.gain_left != b.gain_left),
        ("gain_right", a.gain_right != b.gain_right),
        ("amplitude", a.amplitude != b.amplitude),
        ("speed_mm_s", a.speed_mm_s != b.speed_mm_s),
        ("ramp_ms", a.ramp_ms != b.ramp_ms),
    ];
    let keys: Vec<&str> = differ.iter().filter(|d| d.1).map(|d| d.0).collect();
    (!keys.is_empty()).then(|| format!("their lines would merge, but {} differ", keys.join(", ")))
}

/// Merges modes at one frequency (see the module docs); `Err` names the pair that cannot be.
fn merge_same_frequency(modes: Vec<Mode>) -> Result<Vec<Mode>, ModelError> {
    // (1-based file index of the kept mode, mode)
    let mut kept: Vec<(usize, Mode)> = Vec::new();
    for (i, m) in modes.into_iter().enumerate() {
        let Some((first, k)) =
            kept.iter_mut().find(|(_, k)| (k.freq_hz - m.freq_hz).abs() < SAME_FREQ_HZ)
        else {
            kept.push((i + 1, m));
            continue;
        };
        if let Some(why) = unmergeable(k, &m) {
            return Err(ModelError::SameFrequency {
                freq_hz: k.freq_hz,
                first: *first,
                first_name: k.name.clone(),
                second: i + 1,
                second_name: m.name,
                why,
            });
        }
        let mut lines = node_lines(&k.node).unwrap_or_default();
        lines.extend(node_lines(&m.node).unwrap_or_default());
        k.node = Node::Lines(lines);
        k.name = format!("{} + {}", k.name, m.name);
    }
    Ok(kept.into_iter().map(|(_, m)| m).collect())
}

/// A grid node: sample counts, nx·ny finite samples, normalised to max |φ| = 1.
fn grid_of(
    c: &Ctx,
    nx: Option<i64>,
    ny: Option<i64>,
    values: Option<&[f64]>,
    size_mm: [f64; 2],
) -> Result<Node, ModelError> {
    let dim = |k: &str, v: Option<i64>| match v {
        Some(i) if (2..=1000).contains(&i) => Ok(i as usize),
        Some(v) => Err(c.bad(&format!("node.{k}"), v, "must be an integer in 2..=1000")),
        None => Err(c.bad(&format!("node.{k}"), "missing", "add the sample count")),
    };
    let (nx, ny) = (dim("nx", nx)?, dim("ny", ny)?);
    let values = values
        .ok_or_else(|| c.bad("node.values", "missing", "add values = [nx·ny samples of φ]"))?;
    if let Some((i, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        return Err(c.bad(&format!("node.values[{i}]"), v, "must be a finite number"));
    }
    if values.len() != nx * ny {
        return Err(c.bad(
            "node.values",
            format!("{} samples", values.len()),
            &format!("need nx·ny = {}", nx * ny),
        ));
    }
    let max = values.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if max == 0.0 {
        return Err(c.bad("node.values", "all zero", "a mode shape must not vanish everywhere"));
    }
    Ok(Node::Grid(Grid { nx, ny, size_mm, values: values.iter().map(|v| v / max).collect() }))
}

/// The `[plate]` table's `edge` and `friction`, checked.
fn rim_of(t: &crate::model::plate_file::PlateTable) -> Result<(Edge, f64), ModelError> {
    let edge = match t.edge.as_deref() {
        None | Some("wall") => Edge::Wall,
        Some("open") => Edge::Open,
        Some(other) => {
            return Err(ModelError::PlateKey {
                key: "edge",
                value: format!("{other:?}"),
                fix: "use \"wall\" (a rim parts slide along) or \"open\" (parts fall off)",
            });
        }
    };
    let friction = t.friction.unwrap_or(DEFAULT_FRICTION);
    if !(friction.is_finite() && friction >= 0.0) {
        return Err(ModelError::PlateKey {
            key: "friction",
            value: friction.to_string(),
            fix: "use a Coulomb coefficient ≥ 0 (e.g. 0.47, steel on aluminium; 0 frictionless)",
        });
    }
    Ok((edge, friction))
}

/// Is the point `p` (mm) on a plate of `size_mm`, its edges included? A coordinate that is not
/// a number is not: a run that ends there ended nowhere on the plate. The one test of the
/// plate's extent that the motion model (a part lost off an open edge) and the planners (a
/// run that ended off the plate) share.
pub fn on_plate(size_mm: [f64; 2], p: [f64; 2]) -> bool {
    (0.0..=size_mm[0]).contains(&p[0]) && (0.0..=size_mm[1]).contains(&p[1])
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
            .map(|(i, e)| check_mode(i + 1, e, size_mm))
            .collect::<Result<Vec<_>, _>>()?;
        let modes = merge_same_frequency(modes)?;
        let name =
            if file.plate.name.is_empty() { "plate".to_string() } else { file.plate.name.clone() };
        let (edge, friction) = rim_of(&file.plate)?;
        Ok(PlateModel { name, size_mm, modes, edge, friction })
    }

    /// Parses and types a plate file's text (`label` names it in messages).
    pub fn parse(text: &str, label: &str) -> Result<PlateModel, ModelError> {
        let file = PlateFile::parse(text, label)?;
        PlateModel::from_file(&file)
    }

    /// Reads, parses and types a plate file (every error is bad input: exit code 2).
    pub fn load(path: &Path) -> Result<PlateModel, PlateLoadError> {
        let file = PlateFile::load(path)?;
        PlateModel::from_file(&file)
            .map_err(|e| PlateLoadError::Model { path: path.to_path_buf(), source: Box::new(e) })
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
        PlateModel::parse(&text, "t")
    }

    #[test]
    fn a_point_is_on_the_plate_up_to_its_edges_and_never_when_not_a_number() {
        let size = [300.0, 200.0];
        for p in [[0.0, 0.0], [300.0, 200.0], [150.0, 0.0], [0.0, 200.0]] {
            assert!(on_plate(size, p), "{p:?}");
        }
        for p in [[-1e-9, 10.0], [300.0 + 1e-9, 10.0], [10.0, 200.1], [f64::NAN, 10.0]] {
            assert!(!on_plate(size, p), "{p:?}");
        }
        assert!(!on_plate(size, [10.0, f64::INFINITY]));
    }

    #[test]
    fn the_rim_defaults_to_a_wall_and_bad_rims_are_named() {
        let line = "[[mode]]\nfreq_hz = 50.0\nnode = { kind = \"line\", angle_deg = 0.0 }\n";
        let m = model(line).unwrap();
        assert_eq!((m.edge, m.friction), (Edge::Wall, DEFAULT_FRICTION));
        let rim = |keys: &str| {
            let text = format!("[plate]\nsize_mm = [300.0, 200.0]\n{keys}\n{line}");
            PlateModel::parse(&text, "t")
        };
        let m = rim("edge = \"open\"\nfriction = 0.2").unwrap();
        assert_eq!((m.edge, m.friction), (Edge::Open, 0.2));
        let e = rim("edge = \"rim\"").unwrap_err().to_string();
        assert!(e.contains("edge = \"rim\"") && e.contains("\"wall\""), "{e}");
        let e = rim("friction = -0.1").unwrap_err().to_string();
        assert!(e.contains("friction = -0.1") && e.contains("≥ 0"), "{e}");
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
    fn a_shift_moves_each_kind_of_node_and_is_kept() {
        let m = model(
            r#"
[[mode]]
freq_hz = 60.0
shift_mm = [3.0, -4.0]
node = { kind = "line", angle_deg = 90.0, offset_mm = 10.0 }
[[mode]]
freq_hz = 80
shift_mm = [3.0, -4.0]
node = { kind = "hyperbola", center_mm = [150.0, 100.0], a_mm = 40.0, b_mm = 60.0 }
"#,
        )
        .unwrap();
        // A vertical line's normal n̂ = (−1, 0): moving right by 3 mm is an offset of −3.
        assert_eq!(m.modes[0].node, Node::Line { angle_deg: 90.0, offset_mm: 7.0 });
        assert_eq!(m.modes[0].shift_mm, [3.0, -4.0]);
        let Node::Hyperbola { center_mm, .. } = m.modes[1].node else { panic!("hyperbola") };
        assert_eq!(center_mm, [153.0, 96.0]);
        let far = r#"
[[mode]]
freq_hz = 60
shift_mm = [400.0, 0.0]
node = { kind = "line", angle_deg = 0.0 }
"#;
        let e = model(far);
        let e = e.unwrap_err().to_string();
        assert!(e.contains("shift_mm") && e.contains("400") && e.contains("300 x 200"), "{e}");
    }

    #[test]
    fn a_shifted_grid_is_the_shape_moved() {
        use std::f64::consts::PI;
        // φ = sin(πx/W)·cos(πy/H) sampled every 5 mm; shifted by 5 mm along x it must read, at
        // interior points, what the original reads 5 mm left of them, up to the sign the
        // renormalisation may pick (the field is −∇φ², blind to it; the peak stays a sample,
        // so the scale is unchanged).
        let (nx, ny, size) = (61, 41, [300.0, 200.0]);
        let phi = |x: f64, y: f64| (PI * x / size[0]).sin() * (PI * y / size[1]).cos();
        let values = (0..ny)
            .flat_map(|j| (0..nx).map(move |i| (i, j)))
            .map(|(i, j)| phi(i as f64 * 5.0, j as f64 * 5.0))
            .collect();
        let g = Grid { nx, ny, size_mm: size, values };
        let shifted = g.shifted([5.0, 0.0]);
        let field = crate::motion::field::grid_eval;
        for p in [[100.0, 50.0], [200.0, 150.0], [37.0, 121.0]] {
            let (moved, _) = field(&shifted, p);
            let (there, _) = field(&g, [p[0] - 5.0, p[1]]);
            assert!((moved.abs() - there.abs()).abs() < 1e-3, "{p:?}: {moved} vs {there}");
        }
        // Off the plate's edge the shape goes on along its edge slope, not flat: the sample at
        // x = 0 comes from x = −5, φ(0) and 5 mm of the slope back.
        let edge = shifted.at(0, 32);
        let slope = PI / size[0] * (PI * 160.0 / size[1]).cos();
        assert!((edge.abs() - (5.0 * slope).abs()).abs() < 1e-3, "{edge} vs {}", -5.0 * slope);
        // Along y: the nodal line y = 100 moves to y = 107.
        let up = g.shifted([0.0, 7.0]);
        for x in [40.0, 150.0, 260.0] {
            let (v, _) = field(&up, [x, 107.0]);
            assert!(v.abs() < 1e-3, "φ({x}, 107) = {v}");
        }
    }

    #[test]
    fn one_frequency_is_one_mode() {
        let line = |f: f64, a: f64, o: f64, extra: &str| {
            format!(
                "[[mode]]\nname = \"{a}\"\nfreq_hz = {f}\n{extra}\nnode = {{ kind = \"line\", angle_deg = {a}, offset_mm = {o} }}\n"
            )
        };
        // Two lines at 60 Hz (0.5 mHz apart) and one at 80 Hz: two modes.
        let m = model(
            &(line(60.0, 90.0, -50.0, "")
                + &line(80.0, 0.0, 0.0, "")
                + &line(60.0005, 0.0, 20.0, "")),
        )
        .unwrap();
        assert_eq!(m.modes.len(), 2);
        assert_eq!(m.modes[0].name, "90 + 0");
        let want = vec![
            NodeLine { angle_deg: 90.0, offset_mm: -50.0 },
            NodeLine { angle_deg: 0.0, offset_mm: 20.0 },
        ];
        assert_eq!(m.modes[0].node, Node::Lines(want));
        assert_eq!(m.modes[1].node, Node::Line { angle_deg: 0.0, offset_mm: 0.0 });
        // 2 mHz apart: two modes.
        assert_eq!(
            model(&(line(60.0, 90.0, 0.0, "") + &line(60.002, 0.0, 0.0, ""))).unwrap().modes.len(),
            2
        );
        // Different amplitudes: refused, naming both entries, the frequency and the key.
        let e = model(&(line(60.0, 90.0, 0.0, "") + &line(60.0, 0.0, 0.0, "amplitude = 0.5")))
            .unwrap_err();
        assert!(
            matches!(&e, ModelError::SameFrequency { first: 1, second: 2, freq_hz, .. } if *freq_hz == 60.0),
            "{e}"
        );
        let text = e.to_string();
        assert!(text.contains("amplitude") && text.contains("kind = \"lines\""), "{text}");
        // A grid and a line at one frequency cannot merge.
        let grid = "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"grid\", nx = 2, ny = 2, values = [1.0, -1.0, 0.5, -0.5] }\n";
        let e = model(&(line(60.0, 90.0, 0.0, "") + grid)).unwrap_err().to_string();
        assert!(e.contains("a line node and a grid node"), "{e}");
        // Written as one `lines` entry; a one-line `lines` node is a line; each line checked.
        let lines = "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"lines\", lines = [{ angle_deg = 90.0, offset_mm = 10.0 }, { angle_deg = 0.0 }] }\n";
        assert_eq!(model(lines).unwrap().modes[0].node.kind(), "lines");
        let one = "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"lines\", lines = [{ angle_deg = 90.0 }] }\n";
        assert_eq!(model(one).unwrap().modes[0].node.kind(), "line");
        let far = lines.replace("offset_mm = 10.0", "offset_mm = 900.0");
        let e = model(&far).unwrap_err().to_string();
        assert!(e.contains("node.lines[0].offset_mm = 900"), "{e}");
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
        assert!(matches!(model("").unwrap_err(), ModelError::NoModes));
    }
}
