//! The clamp capture zone of a plate model (docs/plan.md, "Whole-plate plans on grid modes").
//!
//! The physics: a clamped edge is a node of every mode (the plate does not move there:
//! φ = 0 and ∂φ/∂n = 0), so near it φ ≈ a·d² (d the distance from the edge) and the pull
//! f = −∇(φ²) points at the edge and falls off like d³. Whatever mode the plate is driven in,
//! a part near the clamp creeps towards it, or jams against it, until some mode has a node
//! farther out to pull it to. The capture zone is the band along a clamped rim where no mode
//! does: from every point of it, every mode's field carries the part towards the clamped rim,
//! or moves it less than its own radius r away from it within the device's limit T (one hour,
//! [`DeviceLimits::DEFAULT`]), i.e. slower than the floor r / T. No plan can hold from there.
//!
//! How it is computed, cheaply: a clamped rim is a plate edge along which every mode's
//! sampled shape stays below [`RIM_NODE`] of its largest (grid modes only; a straight-node
//! mode moves parts anywhere, so a plate with one has no zone). A round probe of the part's
//! radius is run (the motion model, with the rim) under each mode for T from columns of start
//! points parallel to the rim, [`COLUMN_STEP_MM`] apart, beginning where it touches the rim;
//! the zone ends at the first column from which some mode takes the probe a radius farther
//! from the rim. Zones are cached per plate and radius (the CLI and the whole-plate failure
//! ask for the same one).

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::sync::{Mutex, OnceLock};

use rayon::prelude::*;

use super::whole::PlateEdge;
use crate::model::part::Part;
use crate::model::plate::{Mode, Node, PlateModel};
use crate::motion::sim::{Body, FieldModel, Pose, Rim, SimParams, run};
use chladni_shared::icd::plan::DeviceLimits;

/// An edge is clamped (a node of the plate) when every mode's |φ| along it stays below this
/// fraction of the mode's largest |φ| (the solver writes exactly 0 there).
pub const RIM_NODE: f64 = 0.01;
/// Distance between two columns of probe start points (mm): the zone's resolution.
pub const COLUMN_STEP_MM: f64 = 10.0;
/// Probe start points per column, spread along the rim.
pub const ROWS: usize = 6;
/// Sides of the round probe's polygon.
const PROBE_SIDES: usize = 24;

/// The device's limit on a plan (s): the time a mode has at most to move a part.
pub fn device_limit_s() -> f64 {
    DeviceLimits::DEFAULT.max_total_ms as f64 / 1000.0
}

/// The band along one clamped rim where no mode moves a part off it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// The clamped edge.
    pub edge: PlateEdge,
    /// The band's width from that edge (mm).
    pub width_mm: f64,
}

/// The capture zone of a plate for parts of one radius ([`zone`]).
#[derive(Debug, Clone, PartialEq)]
pub struct CaptureZone {
    /// One band per clamped rim that captures (at least its first column).
    pub bands: Vec<Band>,
    /// The probe's radius (mm): the part's.
    pub radius_mm: f64,
    /// The floor r / T (mm/s): slower than this, a part does not move its own radius within
    /// the device's limit.
    pub floor_mm_s: f64,
    /// The probe runs the computation took.
    pub runs: usize,
    /// Its wall time (s).
    pub compute_s: f64,
}

/// The distance of `p` from `edge` on a plate of size `[w, h]`.
pub fn from_edge(edge: PlateEdge, p: [f64; 2], [w, h]: [f64; 2]) -> f64 {
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
        let [w, h] = plate.size_mm;
        let mut b = [0.0, 0.0, w, h];
        for band in &self.bands {
            let d = band.width_mm;
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
    pub fn bands_text(&self, plate: &PlateModel) -> String {
        let bands: Vec<String> = (self.bands.iter())
            .map(|b| {
                let edge = edge_name(b.edge);
                format!("{} (clamped edge {edge})", band_text(b.edge, b.width_mm, plate.size_mm))
            })
            .collect();
        bands.join(" and ")
    }

    /// What the zone means: "the clamp's capture zone for a part of radius 20 mm: every mode …".
    pub fn meaning(&self) -> String {
        format!(
            "the clamp's capture zone for a part of radius {:.0} mm: every mode carries a part \
             there towards the clamped edge, where the plate does not move, or moves it less \
             than its radius away within the device's {:.0} min limit; no plan can hold from it",
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
        let outside_mm = zone.outside_mm(plate);
        InZone { zone, outside_mm, failed_in, failed, bands, meaning }
    }

    /// "x < 62 mm (clamped edge x = 0) is the clamp's capture zone …" ([`CaptureZone::describe`]).
    pub fn describe(&self) -> String {
        format!("{} is {}", self.bands, self.meaning)
    }
}

/// The plate's clamped rims: the edges along which every mode is a grid whose |φ| stays below
/// [`RIM_NODE`]. None when some mode is not a grid.
pub fn clamped_rims(plate: &PlateModel) -> Vec<PlateEdge> {
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

/// A round part of radius `r` (the probe).
fn probe(r: f64) -> Option<Body> {
    let outline = (0..PROBE_SIDES)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / PROBE_SIDES as f64;
            [r * a.cos(), r * a.sin()]
        })
        .collect();
    let part = Part::new("probe".into(), outline, Vec::new()).ok()?;
    Some(Body::with_samples(&part, 40))
}

/// The capture zone of `plate` for parts of radius `radius_mm` (None: no clamped rim, or no
/// band captures even where the part touches the rim). Cached per plate and radius.
pub fn zone(plate: &PlateModel, radius_mm: f64) -> Option<CaptureZone> {
    static CACHE: OnceLock<Mutex<HashMap<u64, Option<CaptureZone>>>> = OnceLock::new();
    let key = plate_key(plate, radius_mm);
    let cache = CACHE.get_or_init(Default::default);
    if let Some(z) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
        return z;
    }
    let z = compute(plate, radius_mm);
    if let Ok(mut c) = cache.lock() {
        c.insert(key, z.clone());
    }
    z
}

/// The zone of the widest band over several parts (one plan's parts).
pub fn zone_for_parts(plate: &PlateModel, parts: &[Part]) -> Option<CaptureZone> {
    let r = parts.iter().map(|p| Body::with_samples(p, 40).radius).fold(0.0, f64::max);
    (r > 0.0).then(|| zone(plate, r)).flatten()
}

/// A hash of everything the zone depends on.
fn plate_key(plate: &PlateModel, r: f64) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    let bits = |h: &mut std::collections::hash_map::DefaultHasher, v: f64| v.to_bits().hash(h);
    bits(&mut h, r);
    plate.size_mm.iter().for_each(|&v| bits(&mut h, v));
    format!("{:?}{}", plate.edge, plate.friction).hash(&mut h);
    for m in &plate.modes {
        [m.speed_mm_s, m.gain_left, m.gain_right, m.amplitude]
            .iter()
            .for_each(|&v| bits(&mut h, v));
        if let Node::Grid(g) = &m.node {
            (g.nx, g.ny).hash(&mut h);
            g.values.iter().for_each(|&v| bits(&mut h, v));
        }
    }
    h.finish()
}

/// [`zone`], uncached.
fn compute(plate: &PlateModel, r: f64) -> Option<CaptureZone> {
    let start = std::time::Instant::now();
    let rims = clamped_rims(plate);
    if rims.is_empty() {
        return None;
    }
    let body = probe(r)?;
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let runs = std::sync::atomic::AtomicUsize::new(0);
    let mut bands = Vec::new();
    for &edge in &rims {
        let width = band_width(&body, plate, &fields, edge, &runs);
        if width > 0.0 {
            bands.push(Band { edge, width_mm: width });
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

/// The width of the band along `edge` whose columns every mode captures (0: not even the
/// column where the probe touches the rim).
fn band_width(
    body: &Body,
    plate: &PlateModel,
    fields: &[FieldModel],
    edge: PlateEdge,
    runs: &std::sync::atomic::AtomicUsize,
) -> f64 {
    let [w, h] = plate.size_mm;
    let r = body.radius;
    let across = if matches!(edge, PlateEdge::Left | PlateEdge::Right) { w } else { h };
    let along = if matches!(edge, PlateEdge::Left | PlateEdge::Right) { h } else { w };
    let point = |d: f64, t: f64| {
        let s = r + t * (along - 2.0 * r).max(0.0);
        match edge {
            PlateEdge::Left => [d, s],
            PlateEdge::Right => [w - d, s],
            PlateEdge::Bottom => [s, d],
            PlateEdge::Top => [s, h - d],
        }
    };
    let mut last = None;
    let mut d = r;
    while d <= across - r {
        let column: Vec<[f64; 2]> =
            (0..ROWS).map(|k| point(d, (k as f64 + 0.5) / ROWS as f64)).collect();
        let held = column.par_iter().all(|&p| {
            plate.modes.iter().zip(fields).all(|(m, f)| {
                runs.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                captured_by(body, plate, m, f, edge, p)
            })
        });
        if !held {
            break;
        }
        last = Some(d);
        d += COLUMN_STEP_MM;
    }
    // The band ends half-way to the first column a mode frees (or at the last column).
    last.map_or(0.0, |d| (d + 0.5 * COLUMN_STEP_MM).min(across))
}

/// Whether `mode` leaves the probe dropped at `p` captured by the clamped `edge`: after the
/// device's limit it is less than its radius farther from the edge than it started.
fn captured_by(
    body: &Body,
    plate: &PlateModel,
    mode: &Mode,
    field: &FieldModel,
    edge: PlateEdge,
    p: [f64; 2],
) -> bool {
    let params = SimParams {
        speed: mode.speed_mm_s,
        t_limit: device_limit_s(),
        run_to_limit: false,
        rim: Some(Rim::of(plate)),
    };
    let end = run(body, field, params, Pose { x: p[0], y: p[1], theta: 0.0 });
    if end.lost {
        return false;
    }
    let e = [end.pose.x, end.pose.y];
    from_edge(edge, e, plate.size_mm) - from_edge(edge, p, plate.size_mm) < body.radius
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(name: &str) -> PlateModel {
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/plates").join(name);
        PlateModel::load(&path).unwrap()
    }

    #[test]
    fn the_cantilever_has_a_band_at_its_clamp_and_the_free_plate_none() {
        let cant = example("cantilever-6-modes.toml");
        assert_eq!(clamped_rims(&cant), vec![PlateEdge::Left]);
        let z = zone(&cant, 20.0).expect("a capture zone at the clamp");
        assert_eq!(z.bands.len(), 1);
        let band = z.bands[0];
        eprintln!(
            "cantilever, r = 20 mm: {} ({} runs, {:.2} s)",
            z.describe(&cant),
            z.runs,
            z.compute_s
        );
        assert_eq!(band.edge, PlateEdge::Left);
        // Measured: 85 mm (docs/plan.md); the band is more than the probe touching the clamp,
        // and far from the plate's free end.
        assert!(band.width_mm > 40.0 && band.width_mm < 150.0, "{band:?}");
        assert!(z.contains(&cant, [30.0, 100.0]) && !z.contains(&cant, [250.0, 100.0]));
        let out = z.outside_mm(&cant).unwrap();
        assert_eq!(out, [band.width_mm, 0.0, 300.0, 200.0]);
        assert_eq!(z.clip(&cant, [0.0, 10.0, 100.0, 50.0]).unwrap()[0], band.width_mm);
        assert!(z.describe(&cant).starts_with(&format!("x < {:.0} mm", band.width_mm)));
        assert_eq!(zone(&cant, 20.0), Some(z.clone()), "cached");
        // A whole-plate failure names how many of its failed drops start in the zone.
        let inz = InZone::new(z.clone(), &cant, 3, 4);
        let msg = inz.to_string();
        assert!(msg.starts_with("3 of the 4 failed drops start in x < "), "{msg}");
        assert!(msg.contains("no plan can hold from it"), "{msg}");

        let free = example("free-6-modes.toml");
        assert!(clamped_rims(&free).is_empty());
        assert!(zone(&free, 20.0).is_none());
        // Straight-node plates: no grid mode, no zone.
        assert!(zone(&example("four-lines.toml"), 20.0).is_none());
    }
}
