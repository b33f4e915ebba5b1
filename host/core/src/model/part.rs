//! Planar parts: import from JSON (format in docs/physics.md), SVG or DXF ([`dxf`]),
//! validation, conversion to the fixed-point rings of `chladni_shared::analysis::rest`.
//!
//! JSON: `{"name": "...", "outline": [[x,y],...], "holes": [[[x,y],...],...], "flips": false}`,
//! mm, any winding, y up; `flips: true` says the part can land on either face (plan and
//! simulate it and its mirror image, [`mirror`]). SVG ([`svg`], through usvg): every shape,
//! curves flattened to the chord tolerance, physical units honoured, the fill rule deciding
//! holes within an element; the largest filled region is the outline, other elements inside it
//! holes; SVG's y-down axis is flipped, so the part looks
//! as drawn. DXF: closed polylines, circles and LINE/ARC chains of the model space (or of one
//! layer), arcs flattened to a chord tolerance, scaled from `$INSUNITS` to mm (see [`dxf`]).
//!
//! After import every ring is checked and the winding normalised (outline counter-clockwise,
//! holes clockwise). Errors name the problem, the ring and the vertex index (0-based, as in
//! the file).

use chladni_shared::icd::units::Given;
use std::fmt;
use std::path::Path;

use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;

pub use crate::model::geometry::inside;
pub(crate) use crate::model::geometry::signed_area;
use crate::model::geometry::{self, orient, segments_meet};
pub use dxf::{DxfError, ImportOptions};

pub mod dxf;
pub mod mirror;
pub mod svg;

/// Coordinates beyond this (mm) are rejected as absurd.
pub const MAX_COORD_MM: f64 = 1.0e5;
/// Parts smaller than this across (mm) are rejected as absurd.
pub const MIN_SIZE_MM: f64 = 1.0e-3;
/// Parts whose area (outline minus holes) is below this fraction of the square of their
/// larger bounding-box side are refused as slivers: a 10 mm part needs at least 10⁻⁴ mm². Below
/// it the part is a line for the physics (no area for the field to act on), and the analysis's
/// fixed-point area (the part scaled into a unit box, 2⁻³² steps) keeps fewer than three
/// significant digits.
pub const MIN_AREA_FRACTION: f64 = 1.0e-6;
/// Rings with more vertices than this are rejected.
pub(crate) const MAX_VERTICES: usize = 1_000_000;

/// Which ring of a part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Ring {
    /// The outer boundary.
    Outline,
    /// Hole number i (0-based).
    Hole(usize),
}

impl Ring {
    fn of(i: usize) -> Ring {
        if i == 0 { Ring::Outline } else { Ring::Hole(i - 1) }
    }
}

impl fmt::Display for Ring {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ring::Outline => write!(f, "outline"),
            Ring::Hole(i) => write!(f, "hole {i}"),
        }
    }
}

/// Why a part file was rejected.
#[derive(Debug, thiserror::Error)]
pub enum PartError {
    /// The file could not be read.
    #[error("cannot read part file: {0}")]
    Io(#[from] std::io::Error),
    /// Not valid JSON for a part.
    #[error("invalid part JSON: {0}")]
    Json(#[from] serde_json::Error),
    /// The file's top level is not a JSON object ([`crate::model::json_top`]).
    #[error(
        "invalid part JSON: the file is {0}; a part file is one JSON object: {{\"name\": …, \
         \"outline\": [[x, y], …], \"holes\": [[[x, y], …], …]}} in mm (docs/analyze.md)"
    )]
    NotAnObject(&'static str),
    /// JSON with NaN or Infinity, which JSON does not have.
    #[error(
        "invalid part JSON: `{token}` at line {line} column {column} (in \"{key}\"): JSON has no \
         NaN or Infinity; give finite numbers in mm"
    )]
    JsonNotFinite {
        /// The token as written.
        token: String,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// The key whose value holds it (the nearest key before it).
        key: String,
    },
    /// A non-finite number in an SVG coordinate list.
    #[error(
        "invalid SVG: <{element}> attribute {attribute}: coordinate `{token}` is not a finite \
         number; give finite numbers"
    )]
    SvgNotFinite {
        /// Element name.
        element: String,
        /// Attribute name.
        attribute: &'static str,
        /// The token as written.
        token: String,
    },
    /// More than one outline in an SVG drawing.
    #[error(
        "SVG has {count} separate outlines ({names}): a part is one outline plus holes inside \
         it; put each part in its own file"
    )]
    SvgSeparateOutlines {
        /// How many rings lie outside each other.
        count: usize,
        /// The elements they come from, e.g. `shape 0`, `shape 1 (id \"b\")`.
        names: String,
    },
    /// Not well-formed XML.
    #[error("invalid SVG: {0}")]
    Xml(#[from] roxmltree::Error),
    /// A malformed attribute in the SVG.
    #[error("invalid SVG: <{element}> attribute {attribute}: {message}")]
    SvgAttribute {
        /// Element name.
        element: String,
        /// Attribute name.
        attribute: &'static str,
        /// What is wrong.
        message: String,
    },
    /// No polygon or path found.
    #[error("SVG has no filled shape (<path>, <rect>, <circle>, <ellipse>, <polygon>, …)")]
    NoShape,
    /// Unknown file type.
    #[error("unknown part format (expected .json, .svg or .dxf)")]
    UnknownFormat,
    /// A DXF drawing that is not a part (entity, layer and position named).
    #[error("DXF: {0}")]
    Dxf(#[from] DxfError),
    /// `--layer` given for a file without layers.
    #[error("--layer {0}: only DXF part files have layers")]
    LayerNotDxf(String),
    /// Fewer than three vertices.
    #[error("{ring}: {count} vertices, a polygon needs at least 3")]
    TooFewVertices {
        /// Which ring.
        ring: Ring,
        /// How many it has.
        count: usize,
    },
    /// Too many vertices.
    #[error("{ring}: {count} vertices, more than the limit of {MAX_VERTICES}")]
    TooManyVertices {
        /// Which ring.
        ring: Ring,
        /// How many it has.
        count: usize,
    },
    /// NaN or infinity.
    #[error("{ring}, vertex {index}: coordinate is not a finite number ({value})")]
    NotFinite {
        /// Which ring.
        ring: Ring,
        /// Vertex index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// A coordinate beyond [`MAX_COORD_MM`].
    #[error(
        "{ring}, vertex {index}: coordinate {} mm is absurdly large (limit ±{MAX_COORD_MM} mm)",
        Given(*.value)
    )]
    TooLarge {
        /// Which ring.
        ring: Ring,
        /// Vertex index.
        index: usize,
        /// The value.
        value: f64,
    },
    /// The part is smaller than [`MIN_SIZE_MM`].
    #[error("part is absurdly small: {size:e} mm across (minimum {MIN_SIZE_MM} mm)")]
    TooSmall {
        /// Its size.
        size: f64,
    },
    /// Outline minus holes below [`MIN_AREA_FRACTION`] of the size squared.
    #[error(
        "part is a sliver: area {area:e} mm² for {size} mm across (at least {min:e} mm², \
         {MIN_AREA_FRACTION:e} of the size squared); draw the part with its real width"
    )]
    Sliver {
        /// Its area, mm².
        area: f64,
        /// Its larger bounding-box side, mm.
        size: f64,
        /// The least area accepted for that size, mm².
        min: f64,
    },
    /// Two consecutive vertices coincide.
    #[error("{ring}, vertex {index}: repeats the previous vertex (zero-length edge)")]
    DuplicateVertex {
        /// Which ring.
        ring: Ring,
        /// Vertex index.
        index: usize,
    },
    /// Zero area after normalising the winding.
    #[error("{ring}: zero area (all vertices on a line?), starting at vertex 0")]
    ZeroArea {
        /// Which ring.
        ring: Ring,
    },
    /// Two edges of one ring cross or touch.
    #[error("{ring}: self-intersection, edge from vertex {a} crosses edge from vertex {b}")]
    SelfIntersection {
        /// Which ring.
        ring: Ring,
        /// Start vertex of the first edge.
        a: usize,
        /// Start vertex of the second edge.
        b: usize,
    },
    /// A hole is not inside the outline.
    #[error("hole {hole}, vertex {index}: lies outside the outline or on it")]
    HoleOutside {
        /// Which hole.
        hole: usize,
        /// Vertex index (or start of the crossing edge).
        index: usize,
    },
    /// Two holes overlap or one contains the other.
    #[error("hole {a}, vertex {index}: overlaps hole {b}")]
    HolesOverlap {
        /// First hole.
        a: usize,
        /// Its vertex (or start of the crossing edge).
        index: usize,
        /// Second hole.
        b: usize,
    },
}

/// A validated part: outline counter-clockwise, holes clockwise, coordinates in mm.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// Name (from the file, or its stem).
    pub name: String,
    /// Outline, counter-clockwise.
    pub outline: Vec<[f64; 2]>,
    /// Holes, clockwise.
    pub holes: Vec<Vec<[f64; 2]>>,
    /// The part can land on either face (JSON `"flips": true`): plans and simulations take
    /// its mirror image too ([`mirror`]). False for parts from SVG and DXF drawings and from
    /// [`Part::new`].
    pub flips: bool,
}

#[derive(serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct PartJson {
    name: Option<String>,
    outline: Vec<[f64; 2]>,
    #[serde(default)]
    holes: Vec<Vec<[f64; 2]>>,
    #[serde(default)]
    flips: bool,
}

impl Part {
    /// Loads a `.json`, `.svg` or `.dxf` part file with the default [`ImportOptions`].
    pub fn load(path: &Path) -> Result<Part, PartError> {
        Part::load_with(path, &ImportOptions::default()).map(|(part, _)| part)
    }

    /// Loads a part file (format by extension) and the notes the reader has for the user
    /// (e.g. a DXF drawing without units, read as mm). `opt.layer` is refused for files
    /// without layers; `opt.chord_mm` only matters for DXF arcs.
    pub fn load_with(path: &Path, opt: &ImportOptions) -> Result<(Part, Vec<String>), PartError> {
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        if ext.as_deref() == Some("dxf") {
            // The reader opens the file itself (DXF may be binary).
            std::fs::metadata(path)?;
            let d = dxf::load(path, &stem, opt)?;
            return Ok((d.part, d.notes));
        }
        if let Some(layer) = &opt.layer {
            return Err(PartError::LayerNotDxf(layer.clone()));
        }
        let text = std::fs::read_to_string(path)?;
        let part = match ext.as_deref() {
            Some("json") => Part::from_json(&text, &stem),
            Some("svg") => return svg::read(&text, &stem, opt.chord_mm),
            _ => Err(PartError::UnknownFormat),
        }?;
        Ok((part, Vec::new()))
    }

    /// Parses the JSON part format; `default_name` is used when the file has none.
    pub(crate) fn from_json(text: &str, default_name: &str) -> Result<Part, PartError> {
        if let Some(kind) = crate::model::json_top::not_an_object(text) {
            return Err(PartError::NotAnObject(kind));
        }
        let j: PartJson = serde_json::from_str(text).map_err(|e| json_error(text, e))?;
        let part =
            Part::new(j.name.unwrap_or_else(|| default_name.to_string()), j.outline, j.holes)?;
        Ok(Part { flips: j.flips, ..part })
    }

    #[cfg(test)]
    /// Parses an SVG drawing with the default chord tolerance ([`svg`]).
    pub(crate) fn from_svg(text: &str, name: &str) -> Result<Part, PartError> {
        svg::read(text, name, dxf::DEFAULT_CHORD_MM).map(|(part, _)| part)
    }

    /// Validates and normalises a part.
    pub fn new(
        name: String,
        outline: Vec<[f64; 2]>,
        holes: Vec<Vec<[f64; 2]>>,
    ) -> Result<Part, PartError> {
        let mut rings: Vec<Vec<[f64; 2]>> = Some(outline).into_iter().chain(holes).collect();
        for (i, ring) in rings.iter_mut().enumerate() {
            check_ring(Ring::of(i), ring)?;
        }
        let (lo, hi) = geometry::bounds(rings.iter().flatten());
        let size = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        if size < MIN_SIZE_MM {
            return Err(PartError::TooSmall { size });
        }
        check_not_flat(&rings, size)?;
        check_intersections(&rings)?;
        wind(&mut rings, size)?;
        check_containment(&rings)?;
        let area: f64 = rings.iter().map(|r| signed_area(r)).sum();
        let min = MIN_AREA_FRACTION * size * size;
        if area < min {
            return Err(PartError::Sliver { area, size, min });
        }
        let outline = rings.remove(0);
        Ok(Part { name, outline, holes: rings, flips: false })
    }

    /// All rings (outline first).
    pub fn rings(&self) -> impl Iterator<Item = &Vec<[f64; 2]>> {
        std::iter::once(&self.outline).chain(self.holes.iter())
    }

    /// Area (mm²).
    pub fn area(&self) -> f64 {
        self.rings().map(|r| signed_area(r)).sum()
    }

    /// Centroid of the contact surface (outline minus holes), mm.
    pub fn centroid(&self) -> [f64; 2] {
        geometry::centroid(self.rings().map(Vec::as_slice))
    }

    /// Number of vertices over all rings.
    pub fn vertex_count(&self) -> usize {
        self.rings().map(Vec::len).sum()
    }

    /// The rings in Q31.32 (mm), for `chladni_shared::analysis::rest::Analyzer`.
    pub fn to_fixed(&self) -> Vec<Vec<Pt>> {
        self.rings()
            .map(|r| r.iter().map(|p| Pt::new(Fx::from_f64(p[0]), Fx::from_f64(p[1]))).collect())
            .collect()
    }
}

/// One ring's vertices: finite, within [`MAX_COORD_MM`], a closing duplicate of the first
/// dropped, 3 to [`MAX_VERTICES`] of them, no two neighbours equal.
fn check_ring(which: Ring, ring: &mut Vec<[f64; 2]>) -> Result<(), PartError> {
    for (index, p) in ring.iter().enumerate() {
        for value in *p {
            if !value.is_finite() {
                return Err(PartError::NotFinite { ring: which, index, value });
            }
            if value.abs() > MAX_COORD_MM {
                return Err(PartError::TooLarge { ring: which, index, value });
            }
        }
    }
    // A closing vertex equal to the first is common (SVG, GeoJSON habits): drop it.
    if ring.len() > 1 && ring.first() == ring.last() {
        ring.pop();
    }
    if ring.len() < 3 {
        return Err(PartError::TooFewVertices { ring: which, count: ring.len() });
    }
    if ring.len() > MAX_VERTICES {
        return Err(PartError::TooManyVertices { ring: which, count: ring.len() });
    }
    for index in 1..ring.len() {
        if ring[index] == ring[index - 1] {
            return Err(PartError::DuplicateVertex { ring: which, index });
        }
    }
    Ok(())
}

/// All vertices of a ring on one line: a zero-area ring (checked before the crossing test,
/// which would call it a fold-back). `size` is the part's larger extent (mm).
fn check_not_flat(rings: &[Vec<[f64; 2]>], size: f64) -> Result<(), PartError> {
    for (i, ring) in rings.iter().enumerate() {
        let far = ring.iter().copied().max_by(|p, q| {
            let d = |v: &[f64; 2]| (v[0] - ring[0][0]).hypot(v[1] - ring[0][1]);
            d(p).total_cmp(&d(q))
        });
        let far = far.unwrap_or(ring[0]);
        if ring.iter().all(|&v| orient(ring[0], far, v).abs() <= 1e-12 * size * size) {
            return Err(PartError::ZeroArea { ring: Ring::of(i) });
        }
    }
    Ok(())
}

/// Winding: outline counter-clockwise, holes clockwise; zero area is an error.
fn wind(rings: &mut [Vec<[f64; 2]>], size: f64) -> Result<(), PartError> {
    for (i, ring) in rings.iter_mut().enumerate() {
        let a = signed_area(ring);
        // Relative to the part's size: a "polygon" thinner than 1e-9 of it is a line.
        if a.abs() <= 1e-9 * size * size {
            return Err(PartError::ZeroArea { ring: Ring::of(i) });
        }
        if (i == 0) != (a > 0.0) {
            ring.reverse();
        }
    }
    Ok(())
}

/// Containment: every hole inside the outline (`rings[0]`), no hole inside another.
fn check_containment(rings: &[Vec<[f64; 2]>]) -> Result<(), PartError> {
    for (h, hole) in rings.iter().enumerate().skip(1) {
        if !inside(hole[0], &rings[0]) {
            return Err(PartError::HoleOutside { hole: h - 1, index: 0 });
        }
        for (g, other) in rings.iter().enumerate().skip(1) {
            if g != h && inside(hole[0], other) {
                return Err(PartError::HolesOverlap { a: h - 1, index: 0, b: g - 1 });
            }
        }
    }
    Ok(())
}

/// A JSON syntax error, or the named NaN/Infinity error when the offending token is one.
fn json_error(text: &str, e: serde_json::Error) -> PartError {
    let (line, column) = (e.line(), e.column());
    let Some(row) = text.lines().nth(line.saturating_sub(1)) else {
        return PartError::Json(e);
    };
    // serde_json points at or just after the start of the bad value.
    let start =
        row.char_indices().map(|(i, _)| i).nth(column.saturating_sub(1)).unwrap_or(row.len());
    let before = &row[..start];
    let from = before.rfind(|c: char| "[,:".contains(c)).map_or(0, |i| i + 1);
    let rest = row[from..].trim_start();
    let token: String =
        rest.chars().take_while(|c| c.is_ascii_alphanumeric() || "+-.".contains(*c)).collect();
    if !non_finite_token(&token) {
        return PartError::Json(e);
    }
    let upto: String = text.lines().take(line - 1).chain([before]).collect::<Vec<_>>().join("\n");
    PartError::JsonNotFinite { token, line, column, key: last_key(&upto) }
}

/// `NaN`, `Infinity`, `inf`, … (any case, any sign).
fn non_finite_token(token: &str) -> bool {
    let t = token.trim_start_matches(['+', '-']).to_ascii_lowercase();
    t.starts_with("nan") || t.starts_with("inf")
}

/// The last `"key":` in `text` ("?" when there is none).
fn last_key(text: &str) -> String {
    let mut key = String::from("?");
    let mut rest = text;
    while let Some(colon) = rest.find(':') {
        let head = rest[..colon].trim_end();
        if let Some(h) = head.strip_suffix('"')
            && let Some(open) = h.rfind('"')
        {
            key = h[open + 1..].to_string();
        }
        rest = &rest[colon + 1..];
    }
    key
}

/// The first NaN/Infinity token of an SVG coordinate list (`points` or `d`).
pub(crate) fn svg_non_finite(list: &str) -> Option<String> {
    list.split(|c: char| c.is_whitespace() || c == ',')
        .flat_map(|t| t.split(|c: char| "MLHVZmlhvz".contains(c)))
        .find(|t| non_finite_token(t))
        .map(str::to_string)
}

/// Adjacent edges of one ring meet only at their shared vertex (no fold-back).
fn adjacent_overlap(prev: [f64; 2], shared: [f64; 2], next: [f64; 2]) -> bool {
    // Collinear and pointing back along the previous edge.
    orient(prev, shared, next) == 0.0
        && (next[0] - shared[0]) * (prev[0] - shared[0])
            + (next[1] - shared[1]) * (prev[1] - shared[1])
            > 0.0
}

/// Sweep over all edges sorted by their left end; reports the first crossing found.
fn check_intersections(rings: &[Vec<[f64; 2]>]) -> Result<(), PartError> {
    struct Edge {
        ring: usize,
        index: usize,
        a: [f64; 2],
        b: [f64; 2],
        xmin: f64,
        xmax: f64,
    }
    let mut edges: Vec<Edge> = Vec::new();
    for (r, ring) in rings.iter().enumerate() {
        let n = ring.len();
        for i in 0..n {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            edges.push(Edge {
                ring: r,
                index: i,
                a,
                b,
                xmin: a[0].min(b[0]),
                xmax: a[0].max(b[0]),
            });
        }
    }
    edges.sort_by(|p, q| p.xmin.total_cmp(&q.xmin));
    // Report crossings in vertex order for stable messages: keep the smallest pair.
    let mut found: Option<(usize, usize, usize, usize)> = None;
    for i in 0..edges.len() {
        let e = &edges[i];
        for f in edges[i + 1..].iter().take_while(|f| f.xmin <= e.xmax) {
            let (ymin_e, ymax_e) = (e.a[1].min(e.b[1]), e.a[1].max(e.b[1]));
            if f.a[1].max(f.b[1]) < ymin_e || f.a[1].min(f.b[1]) > ymax_e {
                continue;
            }
            let crossing = if e.ring == f.ring {
                let n = rings[e.ring].len();
                let (lo, hi) = (e.index.min(f.index), e.index.max(f.index));
                if hi == lo + 1 || (lo == 0 && hi == n - 1) {
                    // Adjacent: the shared vertex is fine, folding back onto the edge is not.
                    let ring = &rings[e.ring];
                    let (p, s, q) = if hi == lo + 1 {
                        (ring[lo], ring[hi], ring[(hi + 1) % n])
                    } else {
                        (ring[n - 1], ring[0], ring[1])
                    };
                    adjacent_overlap(p, s, q)
                } else {
                    segments_meet(e.a, e.b, f.a, f.b)
                }
            } else {
                segments_meet(e.a, e.b, f.a, f.b)
            };
            if crossing {
                let key = if (e.ring, e.index) < (f.ring, f.index) {
                    (e.ring, e.index, f.ring, f.index)
                } else {
                    (f.ring, f.index, e.ring, e.index)
                };
                if found.is_none_or(|k| key < k) {
                    found = Some(key);
                }
            }
        }
    }
    match found {
        None => Ok(()),
        Some((r1, i1, r2, i2)) if r1 == r2 => {
            Err(PartError::SelfIntersection { ring: Ring::of(r1), a: i1, b: i2 })
        }
        Some((0, _, r2, i2)) => Err(PartError::HoleOutside { hole: r2 - 1, index: i2 }),
        Some((r1, i1, r2, _)) => Err(PartError::HolesOverlap { a: r1 - 1, index: i1, b: r2 - 1 }),
    }
}

#[cfg(test)]
mod tests;
