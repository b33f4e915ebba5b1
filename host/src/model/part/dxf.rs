//! DXF part import (docs/analyze.md, "DXF parts"): the closed loops of a CAD drawing become
//! the part's rings; the largest loop is the outline, the loops inside it are holes.
//!
//! What is read (read with the `dxf` crate, entities of the model space):
//! - closed LWPOLYLINE and POLYLINE (2-D; bulges are circular arcs) and CIRCLE: one loop each;
//! - LINE, ARC and open polylines: joined end to end into loops, an end meeting the next
//!   piece's start or end within [`JOIN_MM`] (after scaling to mm);
//! - arcs are flattened to chords whose sagitta is at most the chord tolerance
//!   ([`ImportOptions::chord_mm`], default [`DEFAULT_CHORD_MM`]), vertices on the arc;
//! - `$INSUNITS` scales to mm: mm, cm, m, inch, foot, micron; unitless is taken as mm (with a
//!   note); any other unit is refused ([`DxfError::UnknownUnits`]);
//! - `--layer NAME` keeps that layer's entities only (case-insensitive, as CAD treats names).
//!
//! Refused with a named error (entity handle, layer, position): a chain that does not close,
//! SPLINE and ELLIPSE (no exact flattening here: convert them to polylines in CAD), INSERT
//! (explode the block), a 3-D polyline or an entity off the XY plane, loops that lie outside
//! each other, a layer with nothing to read. Annotation (TEXT, DIMENSION, HATCH, POINT, …) is
//! skipped and counted in a note.

use std::f64::consts::TAU;
use std::path::Path;

use dxf::Drawing;
use dxf::entities::{Entity, EntityType};
use dxf::enums::Units;

use super::{Part, PartError, inside, signed_area};

/// Default chord tolerance (mm): the largest gap between an arc and its chords.
pub const DEFAULT_CHORD_MM: f64 = 0.05;
/// Chord tolerances accepted (mm).
pub const CHORD_RANGE_MM: std::ops::RangeInclusive<f64> = 1e-4..=5.0;
/// Ends of LINE/ARC pieces closer than this (mm) are one point.
pub const JOIN_MM: f64 = 1e-3;

/// How part files are read: the DXF layer and chord tolerance (other formats have neither
/// layers nor arcs).
#[derive(Debug, Clone, PartialEq)]
pub struct ImportOptions {
    /// Keep only this layer's entities (DXF only).
    pub layer: Option<String>,
    /// Largest sagitta of an arc's chords (mm), in [`CHORD_RANGE_MM`].
    pub chord_mm: f64,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions { layer: None, chord_mm: DEFAULT_CHORD_MM }
    }
}

/// Where an entity is: its handle (hex, as CAD shows it), type and layer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EntityRef {
    /// Handle, hexadecimal.
    pub handle: String,
    /// Entity type (`LINE`, `LWPOLYLINE`, …).
    pub kind: &'static str,
    /// Layer name.
    pub layer: String,
}

impl std::fmt::Display for EntityRef {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} #{} on layer \"{}\"", self.kind, self.handle, self.layer)
    }
}

/// Why a DXF drawing is not a part.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DxfError {
    /// The file is not DXF the reader understands.
    #[error("cannot read DXF: {0}")]
    Read(String),
    /// A chain of LINE/ARC pieces does not close.
    #[error(
        "open chain: {entity} ends at ({:.3}, {:.3}) mm and no other piece starts or ends \
         within {JOIN_MM} mm of it; close the outline in CAD (or join it into a closed \
         polyline)",
        at[0], at[1]
    )]
    OpenChain {
        /// The last piece of the chain.
        entity: EntityRef,
        /// Its loose end (mm).
        at: [f64; 2],
    },
    /// A SPLINE: no exact flattening here.
    #[error(
        "{entity} (first point ({:.3}, {:.3}) mm): splines are not supported; convert it to a \
         polyline in CAD (e.g. with a chord tolerance of 0.05 mm)",
        at[0], at[1]
    )]
    Spline {
        /// The spline.
        entity: EntityRef,
        /// Its first control or fit point (mm).
        at: [f64; 2],
    },
    /// Another entity that cannot be read as part geometry.
    #[error("{entity}: {why}")]
    Unsupported {
        /// The entity.
        entity: EntityRef,
        /// Why, and the fix.
        why: &'static str,
    },
    /// Closed loops that lie outside each other.
    #[error(
        "{count} separate outlines ({loops}): a part is one outline plus holes inside it; put \
         each part in its own file{hint}"
    )]
    SeparateOutlines {
        /// How many loops lie outside the largest one, plus it.
        count: usize,
        /// The entities they start at.
        loops: String,
        /// ", or pick one with --layer NAME (layers: …)" when the drawing has several layers.
        hint: String,
    },
    /// Nothing to read on the chosen layer (or in the drawing).
    #[error("{}", empty_message(layer.as_deref(), layers))]
    EmptyLayer {
        /// The layer asked for (`None`: the whole drawing).
        layer: Option<String>,
        /// Layers that have part geometry.
        layers: Vec<String>,
    },
    /// `$INSUNITS` names a unit this importer does not scale.
    #[error(
        "$INSUNITS = {code} ({name}): unsupported drawing units; save the drawing in mm, cm, m, \
         inches, feet or microns (or unitless, read as mm)"
    )]
    UnknownUnits {
        /// The header code.
        code: i32,
        /// Its name.
        name: String,
    },
}

fn empty_message(layer: Option<&str>, layers: &[String]) -> String {
    let have = if layers.is_empty() {
        "the drawing has no LINE, ARC, CIRCLE, LWPOLYLINE or POLYLINE".to_string()
    } else {
        format!("layers with part geometry: {}", layers.join(", "))
    };
    match layer {
        Some(l) => {
            format!("layer \"{l}\" has no part geometry (LINE, ARC, CIRCLE, polyline); {have}")
        }
        None => format!("no part geometry: {have}"),
    }
}

/// A DXF part and what the reader wants the user to know (unitless drawing, skipped entities).
#[derive(Debug, Clone)]
pub struct DxfPart {
    /// The validated part (mm).
    pub part: Part,
    /// Notes for the user.
    pub notes: Vec<String>,
}

/// Loads a DXF file as a part named `name`.
pub fn load(path: &Path, name: &str, opt: &ImportOptions) -> Result<DxfPart, PartError> {
    let drawing = Drawing::load_file(path).map_err(|e| DxfError::Read(e.to_string()))?;
    from_drawing(&drawing, name, opt)
}

/// Reads a drawing already in hand (see the module docs).
pub fn from_drawing(
    drawing: &Drawing,
    name: &str,
    opt: &ImportOptions,
) -> Result<DxfPart, PartError> {
    let mut notes = Vec::new();
    let scale = units_scale(drawing.header.default_drawing_units, &mut notes)?;
    let mut geometric_layers: Vec<String> = Vec::new();
    let mut reader = Reader { scale, chord: opt.chord_mm, loops: Vec::new(), pieces: Vec::new() };
    let mut skipped = 0;
    for e in drawing.entities() {
        let layer = &e.common.layer;
        let geometric = is_geometry(e);
        if geometric && !geometric_layers.iter().any(|l| l == layer) {
            geometric_layers.push(layer.clone());
        }
        if opt.layer.as_ref().is_some_and(|l| !l.eq_ignore_ascii_case(layer)) {
            continue;
        }
        if !reader.read(e)? {
            skipped += 1;
        }
    }
    if skipped > 0 {
        notes.push(format!("{skipped} annotation entities (text, dimensions, …) skipped"));
    }
    let mut loops = std::mem::take(&mut reader.loops);
    loops.extend(join(std::mem::take(&mut reader.pieces))?);
    if loops.is_empty() {
        return Err(
            DxfError::EmptyLayer { layer: opt.layer.clone(), layers: geometric_layers }.into()
        );
    }
    let (outline, holes) = outline_and_holes(loops, opt.layer.is_none(), &geometric_layers)?;
    let part = Part::new(name.to_string(), outline, holes)?;
    Ok(DxfPart { part, notes })
}

/// mm per drawing unit.
fn units_scale(units: Units, notes: &mut Vec<String>) -> Result<f64, DxfError> {
    Ok(match units {
        Units::Unitless => {
            notes.push("the drawing has no units ($INSUNITS 0): read as mm".into());
            1.0
        }
        Units::Millimeters => 1.0,
        Units::Centimeters => 10.0,
        Units::Meters => 1000.0,
        Units::Inches => 25.4,
        Units::Feet => 304.8,
        Units::Microns => 1e-3,
        other => {
            return Err(DxfError::UnknownUnits { code: other as i32, name: format!("{other:?}") });
        }
    })
}

/// A closed loop (mm) and the entity it starts at.
struct Loop {
    points: Vec<[f64; 2]>,
    from: EntityRef,
}

/// An open piece (mm, at least two points) to be joined.
struct Piece {
    points: Vec<[f64; 2]>,
    from: EntityRef,
}

struct Reader {
    scale: f64,
    chord: f64,
    loops: Vec<Loop>,
    pieces: Vec<Piece>,
}

fn entity_ref(e: &Entity, kind: &'static str) -> EntityRef {
    EntityRef { handle: e.common.handle.as_string(), kind, layer: e.common.layer.clone() }
}

/// Does this entity carry part geometry (for the layer list)?
fn is_geometry(e: &Entity) -> bool {
    matches!(
        e.specific,
        EntityType::Line(_)
            | EntityType::Arc(_)
            | EntityType::Circle(_)
            | EntityType::LwPolyline(_)
            | EntityType::Polyline(_)
            | EntityType::Spline(_)
    )
}

/// The object coordinate system of a planar entity: identity for +z, mirrored x for −z (the
/// DXF arbitrary-axis rule), `None` off the XY plane.
fn ocs_mirror(normal: &dxf::Vector) -> Option<bool> {
    let flat = normal.x.abs() < 1e-9 && normal.y.abs() < 1e-9;
    match (flat, normal.z > 0.0) {
        (true, up) => Some(!up),
        (false, _) => None,
    }
}

impl Reader {
    /// OCS point → mm.
    fn mm(&self, p: [f64; 2], mirror: bool) -> [f64; 2] {
        let x = if mirror { -p[0] } else { p[0] };
        [x * self.scale, p[1] * self.scale]
    }

    /// Reads one entity; `Ok(false)` when it is annotation (skipped).
    fn read(&mut self, e: &Entity) -> Result<bool, DxfError> {
        let off_plane = |kind| DxfError::Unsupported {
            entity: entity_ref(e, kind),
            why: "not in the XY plane (its normal is not ±z); draw the part flat in plan view",
        };
        match &e.specific {
            EntityType::Line(l) => {
                let pts = vec![self.mm([l.p1.x, l.p1.y], false), self.mm([l.p2.x, l.p2.y], false)];
                self.pieces.push(Piece { points: pts, from: entity_ref(e, "LINE") });
            }
            EntityType::Circle(c) => {
                let mirror = ocs_mirror(&c.normal).ok_or_else(|| off_plane("CIRCLE"))?;
                let pts = arc_points(
                    [c.center.x, c.center.y],
                    c.radius,
                    0.0,
                    TAU,
                    self.chord / self.scale,
                );
                let points = pts.iter().map(|&p| self.mm(p, mirror)).collect();
                self.loops.push(Loop { points, from: entity_ref(e, "CIRCLE") });
            }
            EntityType::Arc(a) => {
                let mirror = ocs_mirror(&a.normal).ok_or_else(|| off_plane("ARC"))?;
                let start = a.start_angle.to_radians();
                let mut sweep = (a.end_angle - a.start_angle).rem_euclid(360.0).to_radians();
                if sweep == 0.0 {
                    sweep = TAU;
                }
                let mut pts = arc_points(
                    [a.center.x, a.center.y],
                    a.radius,
                    start,
                    sweep,
                    self.chord / self.scale,
                );
                let (c, r) = ([a.center.x, a.center.y], a.radius);
                let end = start + sweep;
                pts.push([c[0] + r * end.cos(), c[1] + r * end.sin()]);
                let points: Vec<_> = pts.iter().map(|&p| self.mm(p, mirror)).collect();
                self.pieces.push(Piece { points, from: entity_ref(e, "ARC") });
            }
            EntityType::LwPolyline(p) => {
                let mirror =
                    ocs_mirror(&p.extrusion_direction).ok_or_else(|| off_plane("LWPOLYLINE"))?;
                let verts: Vec<([f64; 2], f64)> =
                    p.vertices.iter().map(|v| ([v.x, v.y], v.bulge)).collect();
                self.polyline(&verts, p.is_closed(), mirror, entity_ref(e, "LWPOLYLINE"));
            }
            EntityType::Polyline(p) => {
                if p.is_3d_polyline() || p.is_3d_polygon_mesh() || p.is_polyface_mesh() {
                    return Err(DxfError::Unsupported {
                        entity: entity_ref(e, "POLYLINE"),
                        why: "a 3-D polyline or mesh; draw the part as a 2-D polyline",
                    });
                }
                let mirror = ocs_mirror(&p.normal).ok_or_else(|| off_plane("POLYLINE"))?;
                let verts: Vec<([f64; 2], f64)> =
                    p.vertices().map(|v| ([v.location.x, v.location.y], v.bulge)).collect();
                self.polyline(&verts, p.is_closed(), mirror, entity_ref(e, "POLYLINE"));
            }
            EntityType::Spline(s) => {
                let first = s.control_points.first().or(s.fit_points.first());
                let at = first.map_or([0.0, 0.0], |p| self.mm([p.x, p.y], false));
                return Err(DxfError::Spline { entity: entity_ref(e, "SPLINE"), at });
            }
            EntityType::Ellipse(_) => {
                return Err(DxfError::Unsupported {
                    entity: entity_ref(e, "ELLIPSE"),
                    why: "ellipses are not supported; convert it to a polyline in CAD",
                });
            }
            EntityType::Insert(_) => {
                return Err(DxfError::Unsupported {
                    entity: entity_ref(e, "INSERT"),
                    why: "block references are not read; explode the block in CAD",
                });
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// A polyline's vertices with bulges (OCS units): a loop when closed, else a piece.
    fn polyline(&mut self, verts: &[([f64; 2], f64)], closed: bool, mirror: bool, from: EntityRef) {
        let n = verts.len();
        let mut pts = Vec::new();
        let segments = if closed { n } else { n.saturating_sub(1) };
        for i in 0..segments {
            let ((a, bulge), (b, _)) = (verts[i], verts[(i + 1) % n]);
            pts.push(a);
            pts.extend(bulge_points(a, b, bulge, self.chord / self.scale));
        }
        if !closed && let Some(&(last, _)) = verts.last() {
            pts.push(last);
        }
        let points: Vec<[f64; 2]> = pts.iter().map(|&p| self.mm(p, mirror)).collect();
        let ends_meet = points.len() > 2 && close(points[0], points[points.len() - 1]);
        if closed || ends_meet {
            self.loops.push(Loop { points, from });
        } else if points.len() >= 2 {
            self.pieces.push(Piece { points, from });
        }
    }
}

/// Points on a circle from angle `start` over `sweep` (rad, signed), without the end point,
/// spaced so the sagitta is at most `chord` (same units as `r`).
fn arc_points(c: [f64; 2], r: f64, start: f64, sweep: f64, chord: f64) -> Vec<[f64; 2]> {
    let step =
        if chord >= r { std::f64::consts::FRAC_PI_2 } else { 2.0 * (1.0 - chord / r).acos() };
    let full = (sweep.abs() - TAU).abs() < 1e-12;
    let min = if full { 8.0 } else { 1.0 };
    let n = (sweep.abs() / step).ceil().max(min) as usize;
    (0..n)
        .map(|k| {
            let t = start + sweep * k as f64 / n as f64;
            [c[0] + r * t.cos(), c[1] + r * t.sin()]
        })
        .collect()
}

/// The interior points of a bulged polyline segment from `a` to `b` (bulge = tan(θ/4), θ the
/// included angle, positive counter-clockwise).
fn bulge_points(a: [f64; 2], b: [f64; 2], bulge: f64, chord: f64) -> Vec<[f64; 2]> {
    let len = (b[0] - a[0]).hypot(b[1] - a[1]);
    if bulge.abs() < 1e-12 || !bulge.is_finite() || len == 0.0 {
        return Vec::new();
    }
    let theta = 4.0 * bulge.atan();
    let (u, mid) =
        ([(b[0] - a[0]) / len, (b[1] - a[1]) / len], [(a[0] + b[0]) / 2.0, (a[1] + b[1]) / 2.0]);
    // The centre lies left of the chord for a counter-clockwise arc shorter than a half circle.
    let d = (len / 2.0) / (theta / 2.0).tan();
    let c = [mid[0] - u[1] * d, mid[1] + u[0] * d];
    let r = (a[0] - c[0]).hypot(a[1] - c[1]);
    let start = (a[1] - c[1]).atan2(a[0] - c[0]);
    let mut pts = arc_points(c, r, start, theta, chord);
    pts.remove(0);
    pts
}

fn close(p: [f64; 2], q: [f64; 2]) -> bool {
    (p[0] - q[0]).hypot(p[1] - q[1]) <= JOIN_MM
}

/// Joins open pieces end to end into closed loops (greedy: each chain grows from its end
/// until it meets its start).
fn join(mut pieces: Vec<Piece>) -> Result<Vec<Loop>, DxfError> {
    let mut loops = Vec::new();
    while let Some(first) = pieces.pop() {
        let start = first.points[0];
        let mut points = first.points;
        let mut last = first.from.clone();
        let from = first.from;
        loop {
            let end = points[points.len() - 1];
            if points.len() > 2 && close(end, start) {
                points.pop();
                loops.push(Loop { points, from });
                break;
            }
            let next = pieces
                .iter()
                .position(|p| close(p.points[0], end) || close(p.points[p.points.len() - 1], end));
            let Some(k) = next else {
                return Err(DxfError::OpenChain { entity: last, at: end });
            };
            let mut p = pieces.swap_remove(k);
            if !close(p.points[0], end) {
                p.points.reverse();
            }
            points.extend_from_slice(&p.points[1..]);
            last = p.from;
        }
    }
    Ok(loops)
}

/// A ring of points (mm).
type Ring = Vec<[f64; 2]>;

/// The largest loop is the outline; every other loop must lie inside it (a hole).
fn outline_and_holes(
    mut loops: Vec<Loop>,
    all_layers: bool,
    layers: &[String],
) -> Result<(Ring, Vec<Ring>), DxfError> {
    let outer = (0..loops.len())
        .max_by(|&a, &b| {
            signed_area(&loops[a].points).abs().total_cmp(&signed_area(&loops[b].points).abs())
        })
        .unwrap_or(0);
    let outline = loops.remove(outer);
    let apart: Vec<&Loop> =
        loops.iter().filter(|l| !l.points.iter().any(|&p| inside(p, &outline.points))).collect();
    if !apart.is_empty() {
        let hint = if all_layers && layers.len() > 1 {
            format!(", or pick one with --layer NAME (layers: {})", layers.join(", "))
        } else {
            String::new()
        };
        let names = std::iter::once(&outline).chain(apart.iter().copied());
        return Err(DxfError::SeparateOutlines {
            count: apart.len() + 1,
            loops: names.map(|l| l.from.to_string()).collect::<Vec<_>>().join(", "),
            hint,
        });
    }
    Ok((outline.points, loops.into_iter().map(|l| l.points).collect()))
}
