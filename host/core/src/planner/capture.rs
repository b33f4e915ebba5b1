//! The clamp capture zone of a plate model (docs/plan.md, "Whole-plate plans on grid modes").
//!
//! The physics: a clamped edge is a node of every mode (the plate does not move there:
//! φ = 0 and ∂φ/∂n = 0), so near it φ ≈ a·d² (d the distance from the edge) and the pull
//! f = −∇(φ²) points at the edge and falls off like d³. A part that reaches the clamp stays:
//! no mode pulls it off, and a "rest" there is a creep the model cannot place (the feed
//! search refuses it). A mode takes a drop to the clamp when, within the device's limit T
//! (one hour, [`DeviceLimits::DEFAULT`]), the part ends against the clamped rim, or is still
//! creeping less than its own radius r away from it (slower than the floor r / T).
//!
//! The capture zone is what a plan has to stay out of: the band along a clamped rim in each
//! column of which every mode takes some drop to the clamp, so whichever mode a plan starts
//! with, some part dropped there ends at the clamp. A feed region past it holds no such
//! column that the zone's sampling sees; a whole-plate failure counts its failed drops in it.
//!
//! How it is computed: a clamped rim is a plate edge along which every mode's sampled shape
//! stays below [`RIM_NODE`] of its largest (grid modes only; a straight-node mode moves parts
//! anywhere, so a plate with one has no zone). The part itself is run (the motion model, with
//! the rim) under each mode for T from columns of drops parallel to the rim, [`COLUMN_STEP_MM`]
//! apart, beginning where it touches the rim: [`ROWS`] positions along the rim × [`ANGLES`]
//! orientations (the orientation decides whether a long part reaches a mode's node). The zone
//! ends half a column past the first column that some mode keeps entirely off the clamp: the
//! drops are samples, and the boundary lies between them. On the cantilever's solver modes the
//! rectangle's first such column is at x = 90.6 mm, yet the feed search (216 starts) finds no
//! plan from `--feed 90.6 0 300 200` and plans from 90.8 mm; the zone ends at 95.6 mm. (The
//! earlier rule, a round probe every mode kept within its radius of where it started, ending
//! half-way to the first column it left, said 86 mm, and counted a part at rest on a node far
//! from the clamp as captured.) Zones are cached per plate and part (the CLI and the
//! whole-plate failure ask for the same one).
//!
//! Past the zone a feed region can still hold columns that every mode takes some drop of to
//! the clamp, farther out, so the first step of a plan from there has no mode that keeps
//! every part off it. The clear line ([`Band::clear_mm`]) is where that stops: half a column
//! past the farthest capturing column of the mode whose farthest one is nearest the clamp.
//! It is found from the far edge in, each mode leaving the scan at its first capture, and the
//! `plan` warning offers the plate past it as the `--feed` box.

use chladni_shared::icd::units::s_from_ms;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

use rayon::prelude::*;

use super::edges::PlateEdge;
use super::maps::map_thetas;
use crate::model::part::Part;
use crate::model::plate::{Mode, Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::integrate::SimParams;
use crate::motion::integrate::run;
use chladni_shared::icd::plan::DeviceLimits;

/// An edge is clamped (a node of the plate) when every mode's |φ| along it stays below this
/// fraction of the mode's largest |φ| (the solver writes exactly 0 there).
pub const RIM_NODE: f64 = 0.01;
/// Distance between two columns of probe start points (mm): the zone's resolution.
pub const COLUMN_STEP_MM: f64 = 10.0;
/// Drop positions per column, spread along the rim.
pub const ROWS: usize = 7;
/// Drop orientations per position (90° apart, 0.3 of a step off 0° as a simulated map's).
pub const ANGLES: usize = 4;
/// Outline samples of the part's body for the zone's runs (the whole-plate check's 160 give
/// the same columns at four times the cost).
const ZONE_SAMPLES: usize = 40;

/// The device's limit on a plan (s): the time a mode has at most to move a part.
pub(crate) fn device_limit_s() -> f64 {
    s_from_ms(DeviceLimits::DEFAULT.max_total_ms)
}

/// The band along one clamped rim where no mode moves a part off it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// The clamped edge.
    pub edge: PlateEdge,
    /// The band's width from that edge (mm).
    pub width_mm: f64,
    /// From this distance from the edge on (mm, at least `width_mm`), one mode takes no
    /// sampled drop to the clamp, so a feed region there can start with that mode: the
    /// zone's `clear_mm` box ([`CaptureZone::clear_box_mm`]).
    pub clear_mm: f64,
}

/// The capture zone of a plate for parts of one radius ([`zone`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureZone {
    /// One band per clamped rim that captures (at least its first column).
    pub bands: Vec<Band>,
    /// The part's radius (mm): the widest, for several parts.
    pub radius_mm: f64,
    /// The floor r / T (mm/s): slower than this, a part does not move its own radius within
    /// the device's limit.
    pub floor_mm_s: f64,
    /// The runs the computation took.
    pub runs: usize,
    /// Its wall time (s).
    pub compute_s: f64,
}

/// The distance of `p` from `edge` on a plate of size `[w, h]`.
pub(crate) fn from_edge(edge: PlateEdge, p: [f64; 2], [w, h]: [f64; 2]) -> f64 {
    match edge {
        PlateEdge::Left => p[0],
        PlateEdge::Right => w - p[0],
        PlateEdge::Bottom => p[1],
        PlateEdge::Top => h - p[1],
    }
}

/// How the message names the band of `edge` of width `d` ("x < 62 mm").
fn band_text(edge: PlateEdge, d: f64, [w, h]: [f64; 2]) -> String {
    match edge {
        PlateEdge::Left => format!("x < {d:.0} mm"),
        PlateEdge::Right => format!("x > {:.0} mm", w - d),
        PlateEdge::Bottom => format!("y < {d:.0} mm"),
        PlateEdge::Top => format!("y > {:.0} mm", h - d),
    }
}

/// The edge's name in text and JSON (`x = 0`, …).
pub fn edge_name(edge: PlateEdge) -> &'static str {
    match edge {
        PlateEdge::Left => "x = 0",
        PlateEdge::Right => "x = W",
        PlateEdge::Bottom => "y = 0",
        PlateEdge::Top => "y = H",
    }
}

impl CaptureZone {
    /// Whether the plate point `p` lies in the zone.
    pub fn contains(&self, plate: &PlateModel, p: [f64; 2]) -> bool {
        self.bands.iter().any(|b| from_edge(b.edge, p, plate.size_mm) < b.width_mm)
    }

    /// The plate minus the zone as a `--feed` box (mm: x0, y0, x1, y1), if any is left.
    pub fn outside_mm(&self, plate: &PlateModel) -> Option<[f64; 4]> {
        self.past(plate, |b| b.width_mm)
    }

    /// The plate past every band's `clear_mm` as a `--feed` box (mm: x0, y0, x1, y1), if any
    /// is left: where a feed region's first step has a mode that takes no sampled drop to the
    /// clamp.
    pub fn clear_box_mm(&self, plate: &PlateModel) -> Option<[f64; 4]> {
        self.past(plate, |b| b.clear_mm)
    }

    /// The plate past `depth` of every band, from its edge, as a box, if any is left.
    fn past(&self, plate: &PlateModel, depth: fn(&Band) -> f64) -> Option<[f64; 4]> {
        let [w, h] = plate.size_mm;
        let mut b = [0.0, 0.0, w, h];
        for band in &self.bands {
            let d = depth(band);
            match band.edge {
                PlateEdge::Left => b[0] = b[0].max(d),
                PlateEdge::Bottom => b[1] = b[1].max(d),
                PlateEdge::Right => b[2] = b[2].min(w - d),
                PlateEdge::Top => b[3] = b[3].min(h - d),
            }
        }
        (b[2] > b[0] && b[3] > b[1]).then_some(b)
    }

    /// `b` with the zone cut off (the side of each band), if anything is left.
    pub fn clip(&self, plate: &PlateModel, b: [f64; 4]) -> Option<[f64; 4]> {
        let o = self.outside_mm(plate)?;
        let c = [b[0].max(o[0]), b[1].max(o[1]), b[2].min(o[2]), b[3].min(o[3])];
        (c[2] > c[0] && c[3] > c[1]).then_some(c)
    }

    /// The bands as the messages name them: "x < 62 mm (clamped edge x = 0)".
    pub(crate) fn bands_text(&self, plate: &PlateModel) -> String {
        let bands: Vec<String> = (self.bands.iter())
            .map(|b| {
                let edge = edge_name(b.edge);
                format!("{} (clamped edge {edge})", band_text(b.edge, b.width_mm, plate.size_mm))
            })
            .collect();
        bands.join(" and ")
    }

    /// What the zone means: "the clamp's capture zone for this part (radius 20 mm): …".
    pub fn meaning(&self) -> String {
        format!(
            "the clamp's capture zone for this part (radius {:.0} mm): in every 10 mm of it \
             each mode takes some drop to the clamped edge, where the plate does not move (the \
             part ends there, or creeps less than its radius away within the device's {:.0} min \
             limit); whichever mode a plan starts with, some part dropped there ends at the clamp",
            self.radius_mm,
            device_limit_s() / 60.0
        )
    }

    /// "x < 62 mm (clamped edge x = 0) is the clamp's capture zone …".
    pub fn describe(&self, plate: &PlateModel) -> String {
        format!("{} is {}", self.bands_text(plate), self.meaning())
    }
}

/// A failure's drops and the capture zone: how many of them start in it
/// ([`super::whole::NotWhole::capture`]).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{failed_in} of the {failed} failed drops start in {bands}, {meaning}")]
pub struct InZone {
    /// The zone.
    pub zone: CaptureZone,
    /// The plate minus the zone (mm: x0, y0, x1, y1), if anything is left.
    pub outside_mm: Option<[f64; 4]>,
    /// The zone's [`CaptureZone::clear_box_mm`].
    pub clear_box_mm: Option<[f64; 4]>,
    /// Failed drops that start in the zone.
    pub failed_in: usize,
    /// Failed drops.
    pub failed: usize,
    bands: String,
    meaning: String,
}

impl InZone {
    /// The zone of `plate` and the count of failed drops in it.
    pub fn new(zone: CaptureZone, plate: &PlateModel, failed_in: usize, failed: usize) -> InZone {
        let (bands, meaning) = (zone.bands_text(plate), zone.meaning());
        let (outside_mm, clear_box_mm) = (zone.outside_mm(plate), zone.clear_box_mm(plate));
        InZone { zone, outside_mm, clear_box_mm, failed_in, failed, bands, meaning }
    }

    /// "x < 62 mm (clamped edge x = 0) is the clamp's capture zone …" ([`CaptureZone::describe`]).
    pub fn describe(&self) -> String {
        format!("{} is {}", self.bands, self.meaning)
    }
}

/// The plate's clamped rims: the edges along which every mode is a grid whose |φ| stays below
/// [`RIM_NODE`]. None when some mode is not a grid.
pub(crate) fn clamped_rims(plate: &PlateModel) -> Vec<PlateEdge> {
    let grids: Option<Vec<_>> = (plate.modes.iter())
        .map(|m| if let Node::Grid(g) = &m.node { Some(g) } else { None })
        .collect();
    let Some(grids) = grids.filter(|g| !g.is_empty()) else { return Vec::new() };
    let still = |edge: PlateEdge| {
        grids.iter().all(|g| {
            let max = g.values.iter().fold(0.0f64, |a, v| a.max(v.abs())).max(1e-300);
            let along: Vec<f64> = match edge {
                PlateEdge::Left => (0..g.ny).map(|j| g.at(0, j)).collect(),
                PlateEdge::Right => (0..g.ny).map(|j| g.at(g.nx - 1, j)).collect(),
                PlateEdge::Bottom => (0..g.nx).map(|i| g.at(i, 0)).collect(),
                PlateEdge::Top => (0..g.nx).map(|i| g.at(i, g.ny - 1)).collect(),
            };
            along.iter().all(|v| v.abs() < RIM_NODE * max)
        })
    };
    [PlateEdge::Left, PlateEdge::Right, PlateEdge::Bottom, PlateEdge::Top]
        .into_iter()
        .filter(|&e| still(e))
        .collect()
}

/// Does a part at `q` touch one of the `rims` (its centroid within the part's radius of it)?
pub fn touches(rims: &[PlateEdge], body: &Body, plate: &PlateModel, q: Pose) -> bool {
    rims.iter().any(|&e| from_edge(e, [q.x, q.y], plate.size_mm) < body.radius)
}

/// The capture zone of `plate` for `part` (None: no clamped rim, or no drop is captured even
/// where the part touches the rim). Cached per plate and part.
pub fn zone(plate: &PlateModel, part: &Part) -> Option<CaptureZone> {
    static CACHE: OnceLock<Mutex<HashMap<Vec<u64>, Option<CaptureZone>>>> = OnceLock::new();
    let key = plate_key(plate, part);
    let cache = CACHE.get_or_init(Default::default);
    if let Some(z) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
        return z;
    }
    let z = compute(plate, &Body::with_samples(part, ZONE_SAMPLES));
    if let Ok(mut c) = cache.lock() {
        c.insert(key, z.clone());
    }
    z
}

/// The zone of several parts (one plan's): along each clamped rim the widest of their bands.
pub fn zone_for_parts(plate: &PlateModel, parts: &[Part]) -> Option<CaptureZone> {
    let mut zones = parts.iter().filter_map(|p| zone(plate, p));
    let mut all = zones.next()?;
    for z in zones {
        for b in z.bands {
            match all.bands.iter_mut().find(|a| a.edge == b.edge) {
                Some(a) => {
                    a.width_mm = a.width_mm.max(b.width_mm);
                    a.clear_mm = a.clear_mm.max(b.clear_mm);
                }
                None => all.bands.push(b),
            }
        }
        all.radius_mm = all.radius_mm.max(z.radius_mm);
        all.floor_mm_s = all.floor_mm_s.max(z.floor_mm_s);
        all.runs += z.runs;
        all.compute_s += z.compute_s;
    }
    Some(all)
}

/// Everything the zone depends on, as the bits of its numbers (the whole key, so two parts or
/// plates never share a zone): the part's geometry, with each ring's length, and the plate.
fn plate_key(plate: &PlateModel, part: &Part) -> Vec<u64> {
    let mut key = Vec::new();
    for ring in std::iter::once(&part.outline).chain(&part.holes) {
        key.push(ring.len() as u64);
        key.extend(ring.iter().flatten().map(|v| v.to_bits()));
    }
    key.extend(plate.size_mm.iter().map(|v| v.to_bits()));
    key.extend(format!("{:?}", plate.edge).bytes().map(u64::from));
    key.push(plate.friction.to_bits());
    for m in &plate.modes {
        key.extend([m.speed_mm_s, m.gain_left, m.gain_right, m.amplitude].map(f64::to_bits));
        if let Node::Grid(g) = &m.node {
            key.extend([g.nx as u64, g.ny as u64]);
            key.extend(g.values.iter().map(|v| v.to_bits()));
        }
    }
    key
}

/// [`zone`], uncached.
fn compute(plate: &PlateModel, body: &Body) -> Option<CaptureZone> {
    let start = std::time::Instant::now();
    let rims = clamped_rims(plate);
    if rims.is_empty() {
        return None;
    }
    let r = body.radius;
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let runs = std::sync::atomic::AtomicUsize::new(0);
    let mut bands = Vec::new();
    for &edge in &rims {
        let cols = Columns { body, plate, fields: &fields, edge, runs: &runs };
        let width = cols.band_width();
        if width > 0.0 {
            bands.push(Band { edge, width_mm: width, clear_mm: cols.clear_width().max(width) });
        }
    }
    (!bands.is_empty()).then(|| CaptureZone {
        bands,
        radius_mm: r,
        floor_mm_s: r / device_limit_s(),
        runs: runs.into_inner(),
        compute_s: start.elapsed().as_secs_f64(),
    })
}

/// The columns of drops parallel to one clamped rim, and which modes take some drop of a
/// column to the clamp.
struct Columns<'a> {
    body: &'a Body,
    plate: &'a PlateModel,
    fields: &'a [FieldModel],
    edge: PlateEdge,
    runs: &'a std::sync::atomic::AtomicUsize,
}

impl Columns<'_> {
    /// The plate's extent across the rim and along it (mm).
    fn across_along(&self) -> (f64, f64) {
        let [w, h] = self.plate.size_mm;
        if matches!(self.edge, PlateEdge::Left | PlateEdge::Right) { (w, h) } else { (h, w) }
    }

    /// The drops of the column at distance `d` from the rim: [`ROWS`] × [`ANGLES`].
    fn drops(&self, d: f64) -> Vec<Pose> {
        let [w, h] = self.plate.size_mm;
        let r = self.body.radius;
        let (_, along) = self.across_along();
        let thetas = map_thetas(ANGLES);
        (0..ROWS)
            .flat_map(|k| {
                let s = r + (k as f64 + 0.5) / ROWS as f64 * (along - 2.0 * r).max(0.0);
                let [x, y] = match self.edge {
                    PlateEdge::Left => [d, s],
                    PlateEdge::Right => [w - d, s],
                    PlateEdge::Bottom => [s, d],
                    PlateEdge::Top => [s, h - d],
                };
                thetas
                    .iter()
                    .map(move |th| Pose { x, y, theta: th.to_radians() })
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    /// Whether mode `k` takes some drop of `column` to the clamp.
    fn captures(&self, k: usize, column: &[Pose]) -> bool {
        let (m, f) = (&self.plate.modes[k], &self.fields[k]);
        column.par_iter().any(|&q| {
            self.runs.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            captured_by(self.body, self.plate, m, f, self.edge, q)
        })
    }

    /// Half a column past the next column after the one at `d` (within the plate): where a
    /// line between sampled columns is put, the boundary lying between them.
    fn half_past(&self, d: f64) -> f64 {
        (d + 1.5 * COLUMN_STEP_MM).min(self.across_along().0)
    }

    /// The column distances from the rim: from where the part touches it, every
    /// [`COLUMN_STEP_MM`], to where it touches the far edge.
    fn distances(&self) -> Vec<f64> {
        let (r, (across, _)) = (self.body.radius, self.across_along());
        (0..).map(|i| r + i as f64 * COLUMN_STEP_MM).take_while(|&d| d <= across - r).collect()
    }

    /// The width of the band in each column of which every mode takes some drop to the clamp
    /// (0: not even in the column where the part touches the rim).
    fn band_width(&self) -> f64 {
        let nm = self.plate.modes.len();
        let mut last = None;
        for d in self.distances() {
            let column = self.drops(d);
            // In the zone when no mode keeps every drop of the column off the clamp:
            // whichever mode a plan starts with, some part dropped here ends there.
            if !(0..nm).all(|k| self.captures(k, &column)) {
                break;
            }
            last = Some(d);
        }
        // The band ends half a column past the first column some mode keeps off the clamp
        // (or at the plate's far edge): its drops are samples, and the boundary lies between
        // them.
        last.map_or(0.0, |d| self.half_past(d))
    }

    /// The distance from the rim past which one mode takes no drop of any column to the
    /// clamp, half a column past that mode's farthest capturing column (0: some mode captures
    /// none; the plate's extent: every mode captures in the farthest column). Columns go from
    /// the far edge in, and a mode leaves the scan at its first capture, so each column runs
    /// only the modes still clear.
    fn clear_width(&self) -> f64 {
        let mut clear: Vec<usize> = (0..self.plate.modes.len()).collect();
        for d in self.distances().into_iter().rev() {
            let column = self.drops(d);
            let left: Vec<usize> =
                clear.iter().copied().filter(|&k| !self.captures(k, &column)).collect();
            if left.is_empty() {
                return self.half_past(d);
            }
            clear = left;
        }
        0.0
    }
}

/// Whether `mode` leaves the part dropped at `q` captured by the clamped `edge`: within the
/// device's limit it ends against that edge, or it is still creeping and less than its radius
/// farther from the edge than it started. A part that came to rest elsewhere (on a node, or
/// where it was dropped) is not captured: a plan can orient it there.
fn captured_by(
    body: &Body,
    plate: &PlateModel,
    mode: &Mode,
    field: &FieldModel,
    edge: PlateEdge,
    q: Pose,
) -> bool {
    let params = SimParams::under(mode, plate, device_limit_s());
    let start = Rim::of(plate).project(body, q);
    let end = run(body, field, params, start);
    if end.lost {
        return false;
    }
    if touches(&[edge], body, plate, end.pose) {
        return true;
    }
    let (e, p) = ([end.pose.x, end.pose.y], [start.x, start.y]);
    !end.rested
        && from_edge(edge, e, plate.size_mm) - from_edge(edge, p, plate.size_mm) < body.radius
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(name: &str) -> PlateModel {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/plates")
            .join(name);
        PlateModel::load(&path).unwrap()
    }

    fn part(name: &str) -> Part {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../../examples/parts")
            .join(name);
        Part::load(&path).unwrap()
    }

    #[test]
    fn the_cantilever_has_a_band_at_its_clamp_and_the_free_plate_none() {
        let cant = example("cantilever-6-modes.toml");
        assert_eq!(clamped_rims(&cant), vec![PlateEdge::Left]);
        let rect = part("rectangle.json");
        let z = zone(&cant, &rect).expect("a capture zone at the clamp");
        assert_eq!(z.bands.len(), 1);
        let band = z.bands[0];
        eprintln!(
            "cantilever, rectangle: {} ({} runs, {:.2} s)",
            z.describe(&cant),
            z.runs,
            z.compute_s
        );
        assert_eq!(band.edge, PlateEdge::Left);
        // Measured: 95.6 mm (docs/plan.md; the feed search plans from x = 90.8 mm, not from
        // the round probe's 86): more than the part touching the clamp, far from the free end.
        assert!(band.width_mm > 40.0 && band.width_mm < 150.0, "{band:?}");
        assert!(z.contains(&cant, [30.0, 100.0]) && !z.contains(&cant, [250.0, 100.0]));
        let out = z.outside_mm(&cant).unwrap();
        assert_eq!(out, [band.width_mm, 0.0, 300.0, 200.0]);
        assert_eq!(z.clip(&cant, [0.0, 10.0, 100.0, 50.0]).unwrap()[0], band.width_mm);
        assert!(z.describe(&cant).starts_with(&format!("x < {:.0} mm", band.width_mm)));
        assert_eq!(zone(&cant, &rect), Some(z.clone()), "cached");
        // The clear line: never inside the zone; the rectangle's is its edge (95.6 mm).
        assert!(band.clear_mm >= band.width_mm && band.clear_mm < 300.0, "{band:?}");
        // Several parts: the widest band of each rim, and the farthest clear line.
        let key = part("l-shape.json");
        let wide = zone_for_parts(&cant, &[rect.clone(), key.clone()]).unwrap();
        let each = [&rect, &key].map(|p| zone(&cant, p).unwrap().bands[0]);
        assert_eq!(wide.bands.len(), 1);
        assert_eq!(wide.bands[0].width_mm, each[0].width_mm.max(each[1].width_mm));
        assert_eq!(wide.bands[0].clear_mm, each[0].clear_mm.max(each[1].clear_mm));
        // The L-shape: past its zone (91.6 mm) every mode still takes some sampled drop to the
        // clamp up to 141.6 mm; its clear line is half a column past that (151.6 mm).
        let l = each[1];
        assert!(l.clear_mm > l.width_mm + COLUMN_STEP_MM, "{l:?}");
        let clear = zone(&cant, &key).unwrap().clear_box_mm(&cant).unwrap();
        assert_eq!(clear, [l.clear_mm, 0.0, 300.0, 200.0]);
        // A whole-plate failure names how many of its failed drops start in the zone.
        let inz = InZone::new(z.clone(), &cant, 3, 4);
        let msg = inz.to_string();
        assert!(msg.starts_with("3 of the 4 failed drops start in x < "), "{msg}");
        assert!(msg.contains("whichever mode a plan starts with"), "{msg}");

        let free = example("free-6-modes.toml");
        assert!(clamped_rims(&free).is_empty());
        assert!(zone(&free, &rect).is_none());
        // Straight-node plates: no grid mode, no zone.
        assert!(zone(&example("four-lines.toml"), &rect).is_none());
    }
}
