//! The plate file: a TOML document with a `[plate]` table and an optional `[[mode]]` array.
//!
//! ```toml
//! [plate]
//! name = "cantilever 300x200"
//! size_mm = [300.0, 200.0]
//! thickness_mm = 2.0
//! youngs_modulus_gpa = 70.0
//! density_kg_m3 = 2700.0
//! poisson = 0.33
//! boundary = "cantilever"   # cantilever | free | hinged-rod
//! # hinged-rod only (defaults shown): hinge line x = hinge_x_mm, rod clamped at rod_mm
//! # hinge_x_mm = 150.0       # W/2
//! # rod_mm = [225.0, 100.0]  # [3W/4, H/2]
//! # drive_mm = [110.0, 70.0] # where the shaker drives the plate (forced response)
//! # clamps_mm = [[30.0, 40.0]] # point supports (w = 0 there)
//! # damping_ratio = 0.01     # modal damping ζ of the forced response (Q = 1/2ζ)
//! ```
//! Only `name` and `size_mm` are needed by every user of the file; the material and boundary
//! keys are needed by the mode solver and checked when it asks for them
//! ([`PlateTable::mechanics`]). `[[mode]]` entries are [`ModeEntry`]s: the one schema that
//! `chladni plate modes --write-modes` and `plate from-photo --out` write and the planner reads;
//! their values are checked when the planner types them ([`crate::model::plate`]).

use crate::model::part::MAX_COORD_MM;
use chladni_shared::icd::units::Given;
use std::path::Path;

use serde::{Deserialize, Serialize};

/// A whole plate file.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct PlateFile {
    /// The `[plate]` table.
    pub plate: PlateTable,
    /// The `[[mode]]` array, as written (values checked by [`crate::model::plate`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub mode: Vec<ModeEntry>,
    /// What `chladni plate learn` measured to correct the modes (informative: the corrections
    /// themselves are the entries' `speed_mm_s` and `shift_mm`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub learned: Option<Learned>,
}

/// The `[learned]` table: where the corrections of a learned plate come from, and how well
/// they predict bursts the fit did not see.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct Learned {
    /// The plate file the corrections start from.
    pub given: String,
    /// When the bursts were driven (UTC, RFC 3339).
    pub at: String,
    /// The camera the parts were seen with.
    pub camera: String,
    /// Bursts fitted.
    pub bursts: u32,
    /// Bursts kept out of the fit to judge it.
    pub held_out: u32,
    /// Per mode.
    #[serde(default)]
    pub mode: Vec<LearnedMode>,
}

/// One mode's correction and its held-out prediction error before (the given plate) and
/// after (the learned one).
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LearnedMode {
    /// The mode's drive frequency (Hz).
    pub freq_hz: f64,
    /// Bursts fitted.
    pub bursts: u32,
    /// Bursts held out.
    pub held_out: u32,
    /// Measured speed over the given one.
    pub speed_factor: f64,
    /// Measured node shift [dx, dy] (mm).
    pub shift_mm: [f64; 2],
    /// Held-out RMS position error of a burst's prediction on the given plate (mm).
    pub before_mm: f64,
    /// The same on the learned plate (mm).
    pub after_mm: f64,
    /// Held-out RMS orientation error on the given plate (degrees).
    pub before_deg: f64,
    /// The same on the learned plate (degrees).
    pub after_deg: f64,
}

/// One `[[mode]]` entry as written: every key optional here; which are needed, their ranges
/// and their combinations are checked by [`crate::model::plate::PlateModel::from_file`],
/// which names the mode, the key, the value and the fix. Keys not in this schema are kept in
/// [`ModeEntry::unknown`] (never written) so that the check can name them with the mode.
#[derive(Debug, Clone, Default, PartialEq, Deserialize, Serialize)]
#[serde(default)]
pub struct ModeEntry {
    /// Name (defaults to "mode N").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// Drive frequency (Hz).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub freq_hz: Option<f64>,
    /// Solver eigenvalue λ (informative, written by `plate modes`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub lambda: Option<f64>,
    /// Drive amplitude, fraction of full scale.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub amplitude: Option<f64>,
    /// Field law name (`sign`, `linear`, `sine`; see [`crate::model::field::Law`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// Sine law only: node-to-antinode distance (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub wavelength_mm: Option<f64>,
    /// Gain on both sides.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain: Option<f64>,
    /// Gain on the left of the node.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain_left: Option<f64>,
    /// Gain on the right of the node.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gain_right: Option<f64>,
    /// Settle speed μ.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub speed_mm_s: Option<f64>,
    /// Amplitude ramp (ms).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ramp_ms: Option<i64>,
    /// How far the mode's nodes lie from where `node` puts them, [dx, dy] (mm): a measured
    /// correction (`chladni plate learn` writes it), applied when the entry is typed.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "opt_pair")]
    pub shift_mm: Option<[f64; 2]>,
    /// The node.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "node_entry")]
    pub node: Option<NodeEntry>,
    /// Keys outside this schema (refused by the check, with the mode's index).
    #[serde(flatten, skip_serializing)]
    pub unknown: toml::Table,
}

/// The `node = { kind = ..., ... }` table as written.
#[derive(Debug, Clone, PartialEq, Deserialize, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum NodeEntry {
    /// A straight line (see [`crate::model::plate::Node::Line`]).
    Line {
        /// Direction (degrees CCW from plate x).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        angle_deg: Option<f64>,
        /// Signed distance from the plate centre (mm, default 0).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        offset_mm: Option<f64>,
    },
    /// Several straight lines of one mode (see [`crate::model::plate::Node::Lines`]).
    Lines {
        /// The lines: `[{ angle_deg, offset_mm }, ...]`.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        lines: Option<Vec<LineEntry>>,
    },
    /// One hyperbola branch (see [`crate::model::plate::Node::Hyperbola`]).
    Hyperbola {
        /// Centre [x, y] (mm).
        #[serde(default, skip_serializing_if = "Option::is_none", deserialize_with = "opt_pair")]
        center_mm: Option<[f64; 2]>,
        /// Axis direction (degrees, default 0).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        angle_deg: Option<f64>,
        /// Semi-axis a (mm).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        a_mm: Option<f64>,
        /// Semi-axis b (mm).
        #[serde(default, skip_serializing_if = "Option::is_none")]
        b_mm: Option<f64>,
    },
    /// A sampled mode shape φ, row-major from the bottom-left corner.
    Grid {
        /// Samples along x.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        nx: Option<i64>,
        /// Samples along y.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        ny: Option<i64>,
        /// nx·ny samples.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        values: Option<Vec<f64>>,
    },
}

/// One line of a `lines` node, as written.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LineEntry {
    /// Direction (degrees CCW from plate x).
    pub angle_deg: f64,
    /// Signed distance from the plate centre (mm, default 0).
    #[serde(default)]
    pub offset_mm: f64,
}

/// The node kinds as written.
pub(crate) const NODE_KINDS: [&str; 4] = ["line", "lines", "hyperbola", "grid"];

/// `node`: the kind is checked first so that a wrong one is named as written.
fn node_entry<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<NodeEntry>, D::Error> {
    use serde::de::Error;
    let value = toml::Value::deserialize(d)?;
    let Some(table) = value.as_table() else {
        return Err(D::Error::custom(format!(
            "node = {value}: must be a table: node = {{ kind = \"line\", ... }}"
        )));
    };
    match table.get("kind") {
        None => Err(D::Error::custom(
            "node.kind = missing: add kind = \"line\" | \"lines\" | \"hyperbola\" | \"grid\"",
        )),
        Some(k) if !k.as_str().is_some_and(|k| NODE_KINDS.contains(&k)) => Err(D::Error::custom(
            format!("node.kind = {k}: must be \"line\", \"lines\", \"hyperbola\" or \"grid\""),
        )),
        Some(_) => NodeEntry::deserialize(value).map(Some).map_err(D::Error::custom),
    }
}

/// `[x, y]`: exactly two numbers (a longer array is refused, not cut).
fn pair<'de, D: serde::Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
    use serde::de::Error;
    let v = Vec::<f64>::deserialize(d)?;
    match v[..] {
        [x, y] => Ok([x, y]),
        _ => Err(D::Error::custom(format!(
            "{v:?} has {} numbers: give exactly two, [x, y] (or [W, H]) in mm",
            v.len()
        ))),
    }
}

/// An optional [`pair`].
fn opt_pair<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<[f64; 2]>, D::Error> {
    pair(d).map(Some)
}

/// The `[plate]` table as written.
#[derive(Debug, Clone, Default, Deserialize, Serialize)]
#[serde(deny_unknown_fields, default)]
pub struct PlateTable {
    /// Free-form name.
    pub name: String,
    /// Plate size [W, H] (mm): x then y.
    #[serde(deserialize_with = "opt_pair")]
    pub size_mm: Option<[f64; 2]>,
    /// Thickness (mm).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub thickness_mm: Option<f64>,
    /// Young's modulus (GPa).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub youngs_modulus_gpa: Option<f64>,
    /// Density (kg/m³).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub density_kg_m3: Option<f64>,
    /// Poisson ratio, in (0, 0.5).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub poisson: Option<f64>,
    /// Boundary conditions.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary: Option<Boundary>,
    /// Hinge line position x (mm), hinged-rod only; default W/2.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub hinge_x_mm: Option<f64>,
    /// Rod attachment point [x, y] (mm), hinged-rod only; default [3W/4, H/2].
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "opt_pair")]
    pub rod_mm: Option<[f64; 2]>,
    /// The rim for the motion model: `"wall"` (default) or `"open"` (checked by
    /// [`crate::model::plate::PlateModel::from_file`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub edge: Option<String>,
    /// Coulomb friction coefficient between parts and the wall (default
    /// [`crate::model::plate::DEFAULT_FRICTION`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub friction: Option<f64>,
    /// Where the shaker drives the plate [x, y] (mm): the solver then writes the forced
    /// response at each resonance ([`crate::plate::drive`]).
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "opt_pair")]
    pub drive_mm: Option<[f64; 2]>,
    /// Point supports [[x, y], ...] (mm): w = 0 at each, imposed exactly by the solver.
    #[serde(skip_serializing_if = "Option::is_none", deserialize_with = "opt_pairs")]
    pub clamps_mm: Option<Vec<[f64; 2]>>,
    /// Modal damping ratio ζ of the forced response (default [`DEFAULT_DAMPING`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub damping_ratio: Option<f64>,
}

/// Default modal damping ratio ζ = 0.01 (Q = 50): a bolted aluminium plate is typically
/// 0.005–0.02. An assumption: a sweep's Q gives yours (ζ = 1/2Q, `chladni device sweep`).
pub const DEFAULT_DAMPING: f64 = 0.01;

/// Most point supports a plate takes (each is one constraint on the Ritz unknowns).
pub const MAX_CLAMPS: usize = 16;

/// An optional list of [`pair`]s.
fn opt_pairs<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<Vec<[f64; 2]>>, D::Error> {
    #[derive(Deserialize)]
    struct P(#[serde(deserialize_with = "pair")] [f64; 2]);
    Ok(Some(Vec::<P>::deserialize(d)?.into_iter().map(|p| p.0).collect()))
}

/// Boundary conditions of the plate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Boundary {
    /// Clamped along x = 0, the other three edges free (the paper's setup 1).
    Cantilever,
    /// All four edges free.
    Free,
    /// Hinged along x = hinge_x_mm, driven (clamped) by a rod at one point (the paper's setup 2).
    HingedRod,
}

impl Boundary {
    /// The plate file's key for it (`cantilever`, `free`, `hinged-rod`).
    pub fn key(self) -> &'static str {
        match self {
            Boundary::Cantilever => "cantilever",
            Boundary::Free => "free",
            Boundary::HingedRod => "hinged-rod",
        }
    }
}

/// A validated plate, ready for the mode solver.
#[derive(Debug, Clone, PartialEq)]
pub struct Plate {
    /// Name.
    pub name: String,
    /// Size [W, H] (mm).
    pub size_mm: [f64; 2],
    /// Thickness (mm).
    pub thickness_mm: f64,
    /// Young's modulus (GPa).
    pub youngs_modulus_gpa: f64,
    /// Density (kg/m³).
    pub density_kg_m3: f64,
    /// Poisson ratio.
    pub poisson: f64,
    /// Boundary conditions.
    pub boundary: Boundary,
    /// Hinge line x (mm) for hinged-rod.
    pub hinge_x_mm: f64,
    /// Rod point (mm) for hinged-rod.
    pub rod_mm: [f64; 2],
    /// Drive point (mm), if given: modes are written as the forced response there.
    pub drive_mm: Option<[f64; 2]>,
    /// Point supports (mm).
    pub clamps_mm: Vec<[f64; 2]>,
    /// Modal damping ratio ζ.
    pub damping_ratio: f64,
}

/// What is wrong with a plate file; each variant names the key and the offending value.
#[derive(Debug, thiserror::Error)]
pub enum PlateFileError {
    /// The file could not be read.
    #[error("cannot read plate file {path}: {source}")]
    Io {
        /// File.
        path: String,
        /// Cause.
        source: std::io::Error,
    },
    /// Not valid TOML, or not the expected structure (unknown key, wrong type).
    #[error("plate file {path}: {message}")]
    Syntax {
        /// File.
        path: String,
        /// Parser message (with line and column).
        message: String,
    },
    /// A key the mode solver needs is absent.
    #[error("[plate] needs `{0}` for the mode solver")]
    Missing(&'static str),
    /// A length, modulus or density that must be positive (and finite) is not.
    #[error("[plate] {key} must be positive and finite, got {}", Given(*.value))]
    NotPositive {
        /// Key.
        key: &'static str,
        /// Value.
        value: f64,
    },
    /// A plate side longer than any part may be ([`MAX_COORD_MM`]): no rig, and far past where
    /// the motion model's millimetre tolerances mean anything.
    #[error(
        "[plate] {key} = {} mm is absurdly large (limit {MAX_COORD_MM} mm): give the plate's \
         size in mm",
        Given(*.value)
    )]
    TooLarge {
        /// Key.
        key: &'static str,
        /// Value.
        value: f64,
    },
    /// Poisson ratio outside (0, 0.5).
    #[error("[plate] poisson must be in (0, 0.5), got {0}")]
    Poisson(f64),
    /// The hinge line or rod point lies outside the plate.
    #[error("[plate] {key} = {value:?} mm is outside the plate (0..{limit:?} mm)")]
    OutsidePlate {
        /// Key.
        key: &'static str,
        /// Value.
        value: Vec<f64>,
        /// Plate size.
        limit: [f64; 2],
    },
    /// A point support lies outside the plate.
    #[error(
        "[plate] clamps_mm[{index}] = {value:?} mm is outside the plate (0..{limit:?} mm): \
         move it onto the plate"
    )]
    ClampOutside {
        /// 0-based index in `clamps_mm`.
        index: usize,
        /// The point.
        value: [f64; 2],
        /// Plate size.
        limit: [f64; 2],
    },
    /// Two point supports at one place.
    #[error(
        "[plate] clamps_mm[{first}] and clamps_mm[{second}] are both at {value:?} mm: remove one"
    )]
    ClampDuplicate {
        /// First index.
        first: usize,
        /// Second index.
        second: usize,
        /// The point.
        value: [f64; 2],
    },
    /// More point supports than [`MAX_CLAMPS`].
    #[error("[plate] clamps_mm has {0} points: at most {MAX_CLAMPS}")]
    TooManyClamps(usize),
    /// The drive point is a support: it cannot move, so it excites nothing.
    #[error(
        "[plate] drive_mm = {drive:?} mm is at clamps_mm[{index}]: a supported point does not \
         move, so it drives nothing; move the drive point or the clamp"
    )]
    DriveAtClamp {
        /// Drive point.
        drive: [f64; 2],
        /// The clamp's index.
        index: usize,
    },
    /// Damping ratio outside (0, 0.2].
    #[error(
        "[plate] damping_ratio must be in (0, 0.2] (a lightly damped plate: 0.005–0.02), got \
         {0}"
    )]
    Damping(f64),
    /// The rod point lies on the hinge line (the plate could then rock freely).
    #[error("[plate] rod_mm {rod:?} lies on the hinge line x = {hinge} mm")]
    RodOnHinge {
        /// Rod point.
        rod: [f64; 2],
        /// Hinge x.
        hinge: f64,
    },
}

fn positive(key: &'static str, v: f64) -> Result<f64, PlateFileError> {
    if v.is_finite() && v > 0.0 {
        Ok(v)
    } else {
        Err(PlateFileError::NotPositive { key, value: v })
    }
}

/// Whether `v` (mm) is a plate side the tool takes: positive, finite and at most
/// [`MAX_COORD_MM`]. The one rule for plate files, `--size-mm` and photos.
pub fn is_plate_side(v: f64) -> bool {
    v.is_finite() && v > 0.0 && v <= MAX_COORD_MM
}

/// A side of the plate ([`is_plate_side`]), or the typed refusal.
fn side(key: &'static str, v: f64) -> Result<f64, PlateFileError> {
    let v = positive(key, v)?;
    if is_plate_side(v) { Ok(v) } else { Err(PlateFileError::TooLarge { key, value: v }) }
}

impl PlateFile {
    /// Parses a plate file from text (`path` only labels errors).
    pub fn parse(text: &str, path: &str) -> Result<Self, PlateFileError> {
        let file: PlateFile = toml::from_str(text)
            .map_err(|e| PlateFileError::Syntax { path: path.into(), message: e.to_string() })?;
        if let Some([w, h]) = file.plate.size_mm {
            side("size_mm[0]", w)?;
            side("size_mm[1]", h)?;
        }
        Ok(file)
    }

    /// Reads and parses a plate file.
    pub fn load(path: &Path) -> Result<Self, PlateFileError> {
        let label = path.display().to_string();
        let text = std::fs::read_to_string(path)
            .map_err(|source| PlateFileError::Io { path: label.clone(), source })?;
        Self::parse(&text, &label)
    }
}

impl PlateTable {
    /// Checks and returns everything the mode solver needs.
    pub fn mechanics(&self) -> Result<Plate, PlateFileError> {
        let [w, h] = self.size_mm.ok_or(PlateFileError::Missing("size_mm"))?;
        let w = side("size_mm[0]", w)?;
        let h = side("size_mm[1]", h)?;
        let t = positive(
            "thickness_mm",
            self.thickness_mm.ok_or(PlateFileError::Missing("thickness_mm"))?,
        )?;
        let e = positive(
            "youngs_modulus_gpa",
            self.youngs_modulus_gpa.ok_or(PlateFileError::Missing("youngs_modulus_gpa"))?,
        )?;
        let rho = positive(
            "density_kg_m3",
            self.density_kg_m3.ok_or(PlateFileError::Missing("density_kg_m3"))?,
        )?;
        let nu = self.poisson.ok_or(PlateFileError::Missing("poisson"))?;
        if !(nu > 0.0 && nu < 0.5) {
            return Err(PlateFileError::Poisson(nu));
        }
        let boundary = self.boundary.ok_or(PlateFileError::Missing("boundary"))?;
        let hinge = self.hinge_x_mm.unwrap_or(w / 2.0);
        let rod = self.rod_mm.unwrap_or([0.75 * w, 0.5 * h]);
        if boundary == Boundary::HingedRod {
            if !(hinge > 0.0 && hinge < w) {
                return Err(PlateFileError::OutsidePlate {
                    key: "hinge_x_mm",
                    value: vec![hinge],
                    limit: [w, h],
                });
            }
            if !(rod[0] >= 0.0 && rod[0] <= w && rod[1] >= 0.0 && rod[1] <= h) {
                return Err(PlateFileError::OutsidePlate {
                    key: "rod_mm",
                    value: rod.to_vec(),
                    limit: [w, h],
                });
            }
            if (rod[0] - hinge).abs() < 1e-3 * w {
                return Err(PlateFileError::RodOnHinge { rod, hinge });
            }
        }
        let (drive_mm, clamps_mm, damping_ratio) = self.drive_and_clamps([w, h])?;
        Ok(Plate {
            name: self.name.clone(),
            size_mm: [w, h],
            thickness_mm: t,
            youngs_modulus_gpa: e,
            density_kg_m3: rho,
            poisson: nu,
            boundary,
            hinge_x_mm: hinge,
            rod_mm: rod,
            drive_mm,
            clamps_mm,
            damping_ratio,
        })
    }

    /// `drive_mm`, `clamps_mm` and `damping_ratio`, checked against the plate [W, H].
    #[allow(clippy::type_complexity)]
    fn drive_and_clamps(
        &self,
        size: [f64; 2],
    ) -> Result<(Option<[f64; 2]>, Vec<[f64; 2]>, f64), PlateFileError> {
        let inside =
            |p: [f64; 2]| (0.0..=size[0]).contains(&p[0]) && (0.0..=size[1]).contains(&p[1]);
        // Two points closer than this are one point (a Ritz basis cannot tell them apart).
        let same = |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).hypot(a[1] - b[1]) < 1e-3 * size[0];
        if let Some(d) = self.drive_mm.filter(|&d| !inside(d)) {
            return Err(PlateFileError::OutsidePlate {
                key: "drive_mm",
                value: d.to_vec(),
                limit: size,
            });
        }
        let clamps = self.clamps_mm.clone().unwrap_or_default();
        if clamps.len() > MAX_CLAMPS {
            return Err(PlateFileError::TooManyClamps(clamps.len()));
        }
        for (index, &c) in clamps.iter().enumerate() {
            if !inside(c) {
                return Err(PlateFileError::ClampOutside { index, value: c, limit: size });
            }
            if let Some(first) = clamps[..index].iter().position(|&o| same(o, c)) {
                return Err(PlateFileError::ClampDuplicate { first, second: index, value: c });
            }
            if let Some(drive) = self.drive_mm.filter(|&d| same(d, c)) {
                return Err(PlateFileError::DriveAtClamp { drive, index });
            }
        }
        let zeta = self.damping_ratio.unwrap_or(DEFAULT_DAMPING);
        if !(zeta > 0.0 && zeta <= 0.2) {
            return Err(PlateFileError::Damping(zeta));
        }
        Ok((self.drive_mm, clamps, zeta))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
[plate]
name = "alu"
size_mm = [300.0, 200.0]
thickness_mm = 2.0
youngs_modulus_gpa = 70.0
density_kg_m3 = 2700.0
poisson = 0.33
boundary = "hinged-rod"

[[mode]]
freq_hz = 60.0
node = { kind = "line", angle_deg = 90.0, offset_mm = 0.0 }
"#;

    #[test]
    fn parses_plate_and_keeps_modes_raw() {
        let f = PlateFile::parse(GOOD, "t").unwrap();
        let p = f.plate.mechanics().unwrap();
        assert_eq!(p.boundary, Boundary::HingedRod);
        assert_eq!(p.hinge_x_mm, 150.0);
        assert_eq!(p.rod_mm, [225.0, 100.0]);
        assert_eq!(f.mode.len(), 1);
        assert_eq!(f.mode[0].freq_hz, Some(60.0));
    }

    #[test]
    fn size_with_three_numbers_is_refused_not_cut() {
        let e = PlateFile::parse("[plate]\nsize_mm = [300.0, 200.0, 5.0]\n", "t").unwrap_err();
        let e = e.to_string();
        assert!(
            e.contains("size_mm") && e.contains("3 numbers") && e.contains("exactly two"),
            "{e}"
        );
    }

    #[test]
    fn written_modes_are_the_schema_read_back() {
        let entry = ModeEntry {
            name: Some("m".into()),
            freq_hz: Some(60.0),
            field: Some("sine".into()),
            wavelength_mm: Some(80.0),
            shift_mm: Some([1.5, -2.0]),
            node: Some(NodeEntry::Hyperbola {
                center_mm: Some([150.0, 100.0]),
                angle_deg: Some(0.0),
                a_mm: Some(40.0),
                b_mm: Some(60.0),
            }),
            ..ModeEntry::default()
        };
        let file = PlateFile {
            plate: PlateTable { size_mm: Some([300.0, 200.0]), ..PlateTable::default() },
            mode: vec![entry.clone()],
            learned: None,
        };
        let back = PlateFile::parse(&toml::to_string(&file).unwrap(), "t").unwrap();
        assert_eq!(back.mode, vec![entry]);
        let e = PlateFile::parse("[plate]\n[[mode]]\nnode = { kind = \"circle\" }\n", "t");
        assert!(e.unwrap_err().to_string().contains("node.kind = \"circle\""));
    }

    #[test]
    fn planner_only_file_parses_without_material() {
        let f = PlateFile::parse("[plate]\nname = \"x\"\nsize_mm = [300.0, 200.0]\n", "t").unwrap();
        assert!(matches!(f.plate.mechanics(), Err(PlateFileError::Missing("thickness_mm"))));
    }

    #[test]
    fn named_errors() {
        let bad = |from: &str, to: &str| PlateFile::parse(&GOOD.replace(from, to), "t");
        let mech = |from: &str, to: &str| bad(from, to).unwrap().plate.mechanics();
        assert!(matches!(
            bad("[300.0, 200.0]", "[300.0, -2.0]"),
            Err(PlateFileError::NotPositive { key: "size_mm[1]", value }) if value == -2.0
        ));
        // A side past any rig is refused naming it readably, not as 309 digits.
        let huge = bad("[300.0, 200.0]", "[1e308, 200.0]").unwrap_err().to_string();
        assert_eq!(
            huge,
            "[plate] size_mm[0] = 1e308 mm is absurdly large (limit 100000 mm): give the plate's \
             size in mm"
        );
        assert!(
            matches!(mech("poisson = 0.33", "poisson = 0.5"), Err(PlateFileError::Poisson(v)) if v == 0.5)
        );
        assert!(matches!(
            mech("thickness_mm = 2.0", "thickness_mm = 0.0"),
            Err(PlateFileError::NotPositive { key: "thickness_mm", .. })
        ));
        let e = bad("poisson = 0.33", "poisson = 0.33\ncolour = 1").unwrap_err();
        assert!(e.to_string().contains("colour"), "{e}");
        let e = bad("\"hinged-rod\"", "\"clamped\"").unwrap_err();
        assert!(e.to_string().contains("clamped"), "{e}");
        assert!(matches!(
            mech("poisson = 0.33", "poisson = 0.33\nrod_mm = [150.0, 10.0]"),
            Err(PlateFileError::RodOnHinge { .. })
        ));
        assert!(matches!(
            mech("poisson = 0.33", "poisson = 0.33\nrod_mm = [400.0, 10.0]"),
            Err(PlateFileError::OutsidePlate { key: "rod_mm", .. })
        ));
    }

    #[test]
    fn drive_point_and_clamps_are_checked_and_named() {
        let with = |extra: &str| {
            PlateFile::parse(
                &GOOD.replace("poisson = 0.33", &format!("poisson = 0.33\n{extra}")),
                "t",
            )
            .map(|f| f.plate.mechanics())
        };
        let p = with("drive_mm = [100.0, 50.0]\nclamps_mm = [[10.0, 10.0], [290.0, 10.0]]")
            .unwrap()
            .unwrap();
        assert_eq!(p.drive_mm, Some([100.0, 50.0]));
        assert_eq!(p.clamps_mm, vec![[10.0, 10.0], [290.0, 10.0]]);
        assert_eq!(p.damping_ratio, DEFAULT_DAMPING);
        let e = with("drive_mm = [310.0, 50.0]").unwrap().unwrap_err();
        assert!(matches!(e, PlateFileError::OutsidePlate { key: "drive_mm", .. }), "{e}");
        let e = with("clamps_mm = [[10.0, 10.0], [10.0, -1.0]]").unwrap().unwrap_err();
        assert!(e.to_string().contains("clamps_mm[1] = [10.0, -1.0]"), "{e}");
        let e = with("clamps_mm = [[10.0, 10.0], [10.0, 10.0]]").unwrap().unwrap_err();
        assert!(matches!(e, PlateFileError::ClampDuplicate { first: 0, second: 1, .. }), "{e}");
        let e = with("drive_mm = [10.0, 10.0]\nclamps_mm = [[10.0, 10.0]]").unwrap().unwrap_err();
        assert!(e.to_string().contains("drives nothing"), "{e}");
        let e = with("damping_ratio = 0.0").unwrap().unwrap_err();
        assert!(matches!(e, PlateFileError::Damping(z) if z == 0.0), "{e}");
        let e = with("clamps_mm = [[10.0, 10.0, 1.0]]").unwrap_err().to_string();
        assert!(e.contains("exactly two"), "{e}");
    }
}
