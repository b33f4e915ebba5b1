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
//! - INSERT (block references, MINSERT arrays too) is exploded: the block's entities placed
//!   by its location, scale, rotation and base point; entities on the block's layer "0" take
//!   the INSERT's layer, as in CAD.
//!
//! Layers: the part is the closed geometry of one layer. A drawing as CAD writes it also has
//! dimensions, centre lines, a title block: when exactly one layer closes any loop, the
//! entities of the other layers that close nothing are ignored (one note names the layers and
//! counts); closed loops on several layers are refused naming each layer with its loop count
//! and `--layer` ([`DxfError::SeveralLayers`]).
//!
//! Refused with a named error (entity handle, layer, position): a chain that does not close on
//! the part's layer, SPLINE and ELLIPSE (no exact flattening here: convert them to polylines in
//! CAD), a block that is missing or nested more than 8 deep, a 3-D polyline or an entity off
//! the XY plane, loops that lie outside each other, a layer with nothing to read. Annotation
//! (DIMENSION, TEXT, MTEXT, HATCH, LEADER, POINT, …) is skipped and named with its count in a
//! note.

use crate::model::angle::wrap_deg;
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
         each part in its own file"
    )]
    SeparateOutlines {
        /// How many loops lie outside the largest one, plus it.
        count: usize,
        /// The entities they start at.
        loops: String,
    },
    /// Closed loops on more than one layer (and no `--layer`).
    #[error("closed loops on {count} layers: {layers}; pick the part's layer with --layer NAME")]
    SeveralLayers {
        /// How many layers have closed loops.
        count: usize,
        /// Each such layer with its loop count, e.g. `PART (3 closed loops)`.
        layers: String,
    },
    /// An INSERT that cannot be exploded (missing block, nesting too deep).
    #[error("{entity}: block {block:?} {why}")]
    Block {
        /// The INSERT.
        entity: EntityRef,
        /// The block's name.
        block: String,
        /// What is wrong.
        why: &'static str,
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
    // Entities of the right kinds that give no piece: nothing with a length to join.
    let no_length = "have no length (empty or one-point polylines, zero-length lines), so \
                     there is no outline to read";
    let have = if layers.is_empty() {
        "the drawing has no LINE, ARC, CIRCLE, LWPOLYLINE or POLYLINE".to_string()
    } else {
        format!("layers with part geometry: {}", layers.join(", "))
    };
    match layer {
        Some(l) if layers.iter().any(|x| x.eq_ignore_ascii_case(l)) => {
            format!("layer \"{l}\": its LINE, ARC, CIRCLE and polyline entities {no_length}")
        }
        Some(l) => {
            format!("layer \"{l}\" has no part geometry (LINE, ARC, CIRCLE, polyline); {have}")
        }
        None if !layers.is_empty() => format!(
            "no part geometry: the LINE, ARC, CIRCLE and polyline entities on layer(s) {} \
             {no_length}",
            layers.join(", ")
        ),
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
    let mut part = from_drawing(&drawing, name, opt)?;
    // HATCH and a few others are not modelled by the `dxf` crate (it drops them): count them
    // from the text so the note names them too.
    if let Ok(text) = std::fs::read_to_string(path) {
        let mut unread = unmodelled_entities(&text);
        if !unread.is_empty() {
            // One note for everything skipped.
            if let Some(i) = part.notes.iter().position(|n| n.starts_with(SKIPPED)) {
                let old = part.notes.remove(i);
                let list = old.trim_start_matches(SKIPPED).trim_end_matches(SKIPPED_WHY);
                unread.insert(0, list.to_string());
            }
            part.notes.push(format!("{SKIPPED}{}{SKIPPED_WHY}", unread.join(", ")));
        }
    }
    Ok(part)
}

/// The note on skipped annotation: `skipped 3 DIMENSION, 1 HATCH (annotation, …)`.
const SKIPPED: &str = "skipped ";
const SKIPPED_WHY: &str = " (annotation, not part geometry)";

/// Entity types in the ENTITIES section that the `dxf` crate does not model, with counts
/// (`3 HATCH`).
fn unmodelled_entities(text: &str) -> Vec<String> {
    const NAMES: [&str; 5] = ["HATCH", "MLEADER", "MULTILEADER", "ACAD_TABLE", "ARC_DIMENSION"];
    let lines: Vec<&str> = text.lines().map(str::trim).collect();
    let mut counts = [0usize; NAMES.len()];
    let mut in_entities = false;
    for pair in lines.chunks(2) {
        let [code, value] = pair else { break };
        if *code != "0" && *code != "2" {
            continue;
        }
        match (*code, *value) {
            ("2", "ENTITIES") => in_entities = true,
            ("0", "ENDSEC") => in_entities = false,
            ("0", v) if in_entities => {
                if let Some(i) = NAMES.iter().position(|n| *n == v) {
                    counts[i] += 1;
                }
            }
            _ => {}
        }
    }
    NAMES.iter().zip(counts).filter(|(_, c)| *c > 0).map(|(n, c)| format!("{c} {n}")).collect()
}

/// Reads a drawing already in hand (see the module docs).
pub(crate) fn from_drawing(
    drawing: &Drawing,
    name: &str,
    opt: &ImportOptions,
) -> Result<DxfPart, PartError> {
    let mut notes = Vec::new();
    let scale = units_scale(drawing.header.default_drawing_units, &mut notes)?;
    let mut reader = Reader {
        scale,
        chord: opt.chord_mm,
        ts: IDENTITY,
        drawing,
        only: opt.layer.clone(),
        layers: Vec::new(),
        skipped: Vec::new(),
        geometric_layers: Vec::new(),
    };
    for e in drawing.entities() {
        reader.entity(e, None, 0)?;
    }
    if !reader.skipped.is_empty() {
        let list: Vec<String> = reader.skipped.iter().map(|(k, n)| format!("{n} {k}")).collect();
        notes.push(format!("{SKIPPED}{}{SKIPPED_WHY}", list.join(", ")));
    }
    let geometric_layers = std::mem::take(&mut reader.geometric_layers);
    let loops = part_loops(reader.layers, opt.layer.clone(), &geometric_layers, &mut notes)?;
    let (outline, holes) = outline_and_holes(loops)?;
    let part = Part::new(name.to_string(), outline, holes)?;
    Ok(DxfPart { part, notes })
}

/// One layer's geometry: closed loops, and open pieces still to be joined.
struct LayerGeometry {
    name: String,
    loops: Vec<Loop>,
    pieces: Vec<Piece>,
}

/// The loops of the part: those of the one layer that closes any. Other layers whose entities
/// close nothing (dimensions, centre lines drawn as lines) are ignored with one note; closed
/// loops on several layers are refused, naming them and `--layer`.
fn part_loops(
    layers: Vec<LayerGeometry>,
    only: Option<String>,
    geometric: &[String],
    notes: &mut Vec<String>,
) -> Result<Vec<Loop>, DxfError> {
    let mut closed = Vec::new();
    let mut open = Vec::new();
    for l in layers {
        let entities = l.pieces.len();
        let (mut loops, chains) = join(l.pieces);
        loops.extend(l.loops);
        if loops.is_empty() {
            open.push((l.name, entities, chains));
        } else {
            closed.push((l.name, loops, chains));
        }
    }
    match closed.len() {
        0 => match open.into_iter().find_map(|(_, _, c)| c.into_iter().next()) {
            Some((entity, at)) => Err(DxfError::OpenChain { entity, at }),
            None => Err(DxfError::EmptyLayer { layer: only, layers: geometric.to_vec() }),
        },
        1 => {
            let (_, loops, chains) = closed.pop().expect("one layer");
            if let Some((entity, at)) = chains.into_iter().next() {
                return Err(DxfError::OpenChain { entity, at });
            }
            if !open.is_empty() {
                let list: Vec<String> =
                    open.iter().map(|(n, c, _)| format!("\"{n}\" ({c} entities)")).collect();
                notes.push(format!(
                    "ignored entities that close no loop on layer(s) {} (dimensions, centre \
                     lines, …; the part is the closed outline on its own layer)",
                    list.join(", ")
                ));
            }
            Ok(loops)
        }
        count => {
            let list: Vec<String> = closed
                .iter()
                .map(|(n, l, _)| format!("\"{n}\" ({} closed loop(s))", l.len()))
                .collect();
            Err(DxfError::SeveralLayers { count, layers: list.join(", ") })
        }
    }
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

/// An affine map of drawing units, `(x, y) ↦ (a x + c y + e, b x + d y + f)`.
type Affine = [f64; 6];
const IDENTITY: Affine = [1.0, 0.0, 0.0, 1.0, 0.0, 0.0];
/// Deepest nesting of block references exploded.
const MAX_BLOCK_DEPTH: usize = 8;

/// `outer ∘ inner`.
fn compose(o: Affine, i: Affine) -> Affine {
    [
        o[0] * i[0] + o[2] * i[1],
        o[1] * i[0] + o[3] * i[1],
        o[0] * i[2] + o[2] * i[3],
        o[1] * i[2] + o[3] * i[3],
        o[0] * i[4] + o[2] * i[5] + o[4],
        o[1] * i[4] + o[3] * i[5] + o[5],
    ]
}

struct Reader<'d> {
    scale: f64,
    chord: f64,
    /// Block placement of the entities being read (identity in the model space).
    ts: Affine,
    drawing: &'d Drawing,
    /// `--layer`: only this layer is read.
    only: Option<String>,
    layers: Vec<LayerGeometry>,
    /// Annotation skipped, by DXF type name.
    skipped: Vec<(&'static str, usize)>,
    /// Layers with part geometry (for the empty-layer message).
    geometric_layers: Vec<String>,
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

/// The DXF type name of an entity the reader skips.
fn skipped_name(e: &EntityType) -> &'static str {
    match e {
        EntityType::RotatedDimension(_)
        | EntityType::RadialDimension(_)
        | EntityType::DiameterDimension(_)
        | EntityType::AngularThreePointDimension(_)
        | EntityType::OrdinateDimension(_) => "DIMENSION",
        EntityType::Text(_) => "TEXT",
        EntityType::MText(_) => "MTEXT",
        EntityType::Leader(_) => "LEADER",
        EntityType::ModelPoint(_) => "POINT",
        EntityType::Solid(_) => "SOLID",
        EntityType::Attribute(_) | EntityType::AttributeDefinition(_) => "ATTRIB",
        EntityType::Tolerance(_) => "TOLERANCE",
        EntityType::XLine(_) | EntityType::Ray(_) => "XLINE",
        _ => "other",
    }
}

impl Reader<'_> {
    /// OCS point → mm (through the block placement).
    fn mm(&self, p: [f64; 2], mirror: bool) -> [f64; 2] {
        let x = if mirror { -p[0] } else { p[0] };
        let t = self.ts;
        let (x, y) = (t[0] * x + t[2] * p[1] + t[4], t[1] * x + t[3] * p[1] + t[5]);
        [x * self.scale, y * self.scale]
    }

    /// The chord tolerance in the entity's own units (the placement may scale it).
    fn local_chord(&self) -> f64 {
        let t = self.ts;
        let stretch = (t[0] * t[0] + t[1] * t[1] + t[2] * t[2] + t[3] * t[3]).sqrt().max(1e-300);
        self.chord / self.scale / stretch
    }

    /// The geometry of `layer`, created on first use.
    fn layer(&mut self, layer: &str) -> &mut LayerGeometry {
        let i = match self.layers.iter().position(|l| l.name == layer) {
            Some(i) => i,
            None => {
                let g = LayerGeometry { name: layer.to_string(), loops: vec![], pieces: vec![] };
                self.layers.push(g);
                self.layers.len() - 1
            }
        };
        &mut self.layers[i]
    }

    /// Reads one entity of the model space or of a block (`inherited`: the INSERT's layer,
    /// which entities on layer "0" of a block take, as in CAD).
    fn entity(
        &mut self,
        e: &Entity,
        inherited: Option<&str>,
        depth: usize,
    ) -> Result<(), DxfError> {
        let own = e.common.layer.as_str();
        let layer = match inherited {
            Some(l) if own == "0" => l.to_string(),
            _ => own.to_string(),
        };
        if is_geometry(e) && !self.geometric_layers.contains(&layer) {
            self.geometric_layers.push(layer.clone());
        }
        if self.only.as_ref().is_some_and(|l| !l.eq_ignore_ascii_case(&layer)) {
            return Ok(());
        }
        if let EntityType::Insert(ins) = &e.specific {
            return self.insert(e, ins, &layer, depth);
        }
        if !self.read(e, &layer)? {
            let name = skipped_name(&e.specific);
            match self.skipped.iter_mut().find(|(k, _)| *k == name) {
                Some((_, n)) => *n += 1,
                None => self.skipped.push((name, 1)),
            }
        }
        Ok(())
    }

    /// Explodes a block reference: the block's entities placed by the INSERT (location,
    /// scale, rotation, base point; MINSERT rows and columns).
    fn insert(
        &mut self,
        e: &Entity,
        ins: &dxf::entities::Insert,
        layer: &str,
        depth: usize,
    ) -> Result<(), DxfError> {
        let block_err =
            |why| DxfError::Block { entity: entity_ref(e, "INSERT"), block: ins.name.clone(), why };
        if depth >= MAX_BLOCK_DEPTH {
            return Err(block_err("is nested more than 8 deep; explode it in CAD"));
        }
        let drawing = self.drawing;
        let block = drawing
            .blocks()
            .find(|b| b.name.eq_ignore_ascii_case(&ins.name))
            .ok_or_else(|| block_err("is not defined in the drawing"))?;
        let mirror = ocs_mirror(&ins.extrusion_direction).ok_or_else(|| {
            block_err("is inserted off the XY plane; draw the part flat in plan view")
        })?;
        let (sn, cs) = ins.rotation.to_radians().sin_cos();
        let (sx, sy) = (ins.x_scale_factor, ins.y_scale_factor);
        let base = [block.base_point.x, block.base_point.y];
        let saved = self.ts;
        for col in 0..ins.column_count.max(1) {
            for row in 0..ins.row_count.max(1) {
                let (ox, oy) =
                    (f64::from(col) * ins.column_spacing, f64::from(row) * ins.row_spacing);
                let at = [ins.location.x + cs * ox - sn * oy, ins.location.y + sn * ox + cs * oy];
                let place = compose(
                    [cs, sn, -sn, cs, at[0], at[1]],
                    [sx, 0.0, 0.0, sy, -sx * base[0], -sy * base[1]],
                );
                let place =
                    if mirror { compose([-1.0, 0.0, 0.0, 1.0, 0.0, 0.0], place) } else { place };
                self.ts = compose(saved, place);
                for be in &block.entities {
                    let r = self.entity(be, Some(layer), depth + 1);
                    if r.is_err() {
                        self.ts = saved;
                        return r;
                    }
                }
            }
        }
        self.ts = saved;
        Ok(())
    }

    /// Reads one entity onto `layer`; `Ok(false)` when it is annotation (skipped).
    fn read(&mut self, e: &Entity, layer: &str) -> Result<bool, DxfError> {
        let off_plane = |kind| DxfError::Unsupported {
            entity: entity_ref(e, kind),
            why: "not in the XY plane (its normal is not ±z); draw the part flat in plan view",
        };
        match &e.specific {
            EntityType::Line(l) => {
                let pts = vec![self.mm([l.p1.x, l.p1.y], false), self.mm([l.p2.x, l.p2.y], false)];
                self.layer(layer).pieces.push(Piece { points: pts, from: entity_ref(e, "LINE") });
            }
            EntityType::Circle(c) => {
                let mirror = ocs_mirror(&c.normal).ok_or_else(|| off_plane("CIRCLE"))?;
                let pts =
                    arc_points([c.center.x, c.center.y], c.radius, 0.0, TAU, self.local_chord());
                let points = pts.iter().map(|&p| self.mm(p, mirror)).collect();
                self.layer(layer).loops.push(Loop { points, from: entity_ref(e, "CIRCLE") });
            }
            EntityType::Arc(a) => {
                let mirror = ocs_mirror(&a.normal).ok_or_else(|| off_plane("ARC"))?;
                let start = a.start_angle.to_radians();
                let mut sweep = wrap_deg(a.end_angle - a.start_angle).to_radians();
                if sweep == 0.0 {
                    sweep = TAU;
                }
                let mut pts = arc_points(
                    [a.center.x, a.center.y],
                    a.radius,
                    start,
                    sweep,
                    self.local_chord(),
                );
                let (c, r) = ([a.center.x, a.center.y], a.radius);
                let end = start + sweep;
                pts.push([c[0] + r * end.cos(), c[1] + r * end.sin()]);
                let points: Vec<_> = pts.iter().map(|&p| self.mm(p, mirror)).collect();
                self.layer(layer).pieces.push(Piece { points, from: entity_ref(e, "ARC") });
            }
            EntityType::LwPolyline(p) => {
                let mirror =
                    ocs_mirror(&p.extrusion_direction).ok_or_else(|| off_plane("LWPOLYLINE"))?;
                let verts: Vec<([f64; 2], f64)> =
                    p.vertices.iter().map(|v| ([v.x, v.y], v.bulge)).collect();
                self.polyline(&verts, p.is_closed(), mirror, entity_ref(e, "LWPOLYLINE"), layer);
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
                self.polyline(&verts, p.is_closed(), mirror, entity_ref(e, "POLYLINE"), layer);
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
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// A polyline's vertices with bulges (OCS units): a loop when closed, else a piece.
    fn polyline(
        &mut self,
        verts: &[([f64; 2], f64)],
        closed: bool,
        mirror: bool,
        from: EntityRef,
        layer: &str,
    ) {
        let chord = self.local_chord();
        let n = verts.len();
        let mut pts = Vec::new();
        let segments = if closed { n } else { n.saturating_sub(1) };
        for i in 0..segments {
            let ((a, bulge), (b, _)) = (verts[i], verts[(i + 1) % n]);
            pts.push(a);
            pts.extend(bulge_points(a, b, bulge, chord));
        }
        if !closed && let Some(&(last, _)) = verts.last() {
            pts.push(last);
        }
        let points: Vec<[f64; 2]> = pts.iter().map(|&p| self.mm(p, mirror)).collect();
        let ends_meet = points.len() > 2 && close(points[0], points[points.len() - 1]);
        if closed || ends_meet {
            self.layer(layer).loops.push(Loop { points, from });
        } else if points.len() >= 2 {
            self.layer(layer).pieces.push(Piece { points, from });
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

/// A chain that does not close: its last piece and its loose end (mm).
type OpenEnd = (EntityRef, [f64; 2]);

/// Joins open pieces end to end into closed loops (greedy: each chain grows from its end
/// until it meets its start); returns the loops and the chains that stay open.
fn join(mut pieces: Vec<Piece>) -> (Vec<Loop>, Vec<OpenEnd>) {
    let (mut loops, mut open) = (Vec::new(), Vec::new());
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
                open.push((last, end));
                break;
            };
            let mut p = pieces.swap_remove(k);
            if !close(p.points[0], end) {
                p.points.reverse();
            }
            points.extend_from_slice(&p.points[1..]);
            last = p.from;
        }
    }
    (loops, open)
}

/// A ring of points (mm).
type Ring = Vec<[f64; 2]>;

/// The largest loop is the outline; every other loop must lie inside it (a hole).
fn outline_and_holes(mut loops: Vec<Loop>) -> Result<(Ring, Vec<Ring>), DxfError> {
    let outer = (0..loops.len())
        .max_by(|&a, &b| {
            signed_area(&loops[a].points).abs().total_cmp(&signed_area(&loops[b].points).abs())
        })
        .unwrap_or(0);
    let outline = loops.remove(outer);
    let apart: Vec<&Loop> =
        loops.iter().filter(|l| !l.points.iter().any(|&p| inside(p, &outline.points))).collect();
    if !apart.is_empty() {
        let names = std::iter::once(&outline).chain(apart.iter().copied());
        return Err(DxfError::SeparateOutlines {
            count: apart.len() + 1,
            loops: names.map(|l| l.from.to_string()).collect::<Vec<_>>().join(", "),
        });
    }
    Ok((outline.points, loops.into_iter().map(|l| l.points).collect()))
}
