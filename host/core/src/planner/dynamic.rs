//! Dynamic step maps for straight-node modes (docs/plan.md, "Step maps").
//!
//! The static map ([`super::line_map`]) is the paper's alignment function: translate the part
//! until it balances on the node, then rotate. A part that arrives from afar also turns while
//! it crosses the node (under the linear and sine laws it turns even far from it, towards its
//! principal axes), which can carry it into another basin. Where that happens the static plan
//! fails its dynamic confirmation and the search used to end with "no plan" even when another
//! sequence holds.
//!
//! Here the map is measured instead: the part is simulated quasi-statically
//! ([`crate::motion::integrate`]) to rest from start points on both sides of the node (the farthest
//! point along the normal that keeps the part on the plate, just beyond the part's radius, and
//! half-way across), for a grid of start orientations. Final orientations are clustered (2°,
//! modulo the period) and snapped to the exact rests of the static analysis (the rests are the
//! same equilibria; only their basins differ). Where two neighbouring start orientations end in
//! different rests from one start point, the change is located by bisection, so the basin
//! boundaries are known to a fraction of a degree rather than half the grid spacing. A start
//! orientation whose start points end in different rests is *ambiguous*: its image is all of
//! them ([`StepMap::apply_all`]), and the search carries the whole set on. The map's basin
//! boundaries are the located changes plus the static unstable rests (equilibria whatever the
//! approach, where a part lingers).
//!
//! Maps are cached in memory per (part geometry, mode parameters, plate size, settings):
//! [`MapCache::global`] serves [`super::Problem::new`]; the settle speed, frequency, amplitude
//! and ramp do not change where a part comes to rest and are not part of the key.

use crate::model::angle::wrap_deg;
use crate::motion::body::PLANNER_BODY_SAMPLES;
use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock};

use rayon::prelude::*;

use super::cluster::{CLUSTER_DEG, Clusters};
use super::{Backend, MapError, StepMap, line_map};
use crate::model::angle::cdist;
use crate::model::field::Law;
use crate::model::part::Part;
use crate::model::plate::{Mode, Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;
use crate::motion::integrate::SimParams;

/// Which model gives straight-node step maps ([`super::PlanOptions::maps`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MapKind {
    /// The static maps first (checked by simulation), the dynamic ones when those give no
    /// plan (`planner::fallback`): the static maps are 10–30× cheaper and a scan of 750
    /// problems found no plan the dynamic maps find and they miss (docs/plan.md).
    #[default]
    Auto,
    /// The paper's alignment function (balance, then rotate), checked afterwards by simulation.
    Static,
    /// Measured by simulating the approach from both sides of the node (this module); the
    /// static maps when those give no plan.
    Dynamic,
}

/// Settings of dynamic maps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DynSettings {
    /// Start orientations (evenly spaced, 0.3 of a step off 0°).
    pub orientations: usize,
    /// Bisection steps locating each change of outcome between neighbouring orientations.
    pub refine: u32,
}

impl Default for DynSettings {
    fn default() -> Self {
        DynSettings { orientations: 72, refine: 4 }
    }
}

/// A cluster within this of a static rest (deg) takes the exact static value.
const SNAP_DEG: f64 = 1.0;

/// What the simulation measured for one mode: per start point, the rest each start
/// orientation reached, and where between neighbouring orientations the outcome changes.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Outcomes {
    /// First start orientation (deg); the others follow every `step` degrees.
    first: f64,
    /// Spacing of start orientations (deg).
    step: f64,
    /// `labels[s][i]`: index into the map's rests reached from start point s at orientation
    /// i, `None` when the run did not come to rest.
    labels: Vec<Vec<Option<usize>>>,
    /// `changes[s][i]`: where (deg, in [θᵢ, θᵢ₊₁)) the outcome at start point s changes
    /// between orientation i and i + 1, located by bisection.
    changes: Vec<Vec<Option<f64>>>,
}

impl Outcomes {
    /// Rest indices reached from `theta` (deg) over all start points (sorted, deduplicated),
    /// `None` when some run did not come to rest.
    pub(crate) fn images(&self, theta: f64) -> Option<Vec<usize>> {
        let n = self.labels.first().map_or(0, Vec::len);
        if n == 0 {
            return None;
        }
        let off = wrap_deg(theta - self.first);
        let i = ((off / self.step).floor() as usize).min(n - 1);
        let j = (i + 1) % n;
        let past = |b: f64| off >= wrap_deg(b - self.first);
        let mut out = self
            .labels
            .iter()
            .zip(&self.changes)
            .map(|(l, c)| match c[i] {
                Some(b) if past(b) => l[j],
                _ => l[i],
            })
            .collect::<Option<Vec<usize>>>()?;
        out.sort_unstable();
        out.dedup();
        Some(out)
    }

    /// Every located change of outcome (deg): the map's basin boundaries.
    fn boundaries(&self) -> Vec<f64> {
        let mut b: Vec<f64> = self.changes.iter().flatten().flatten().copied().collect();
        b.sort_by(f64::total_cmp);
        b.dedup_by(|a, b| cdist(*a, *b, 360.0) < 1e-6);
        b
    }
}

/// In-memory cache of dynamic maps, keyed by every bit that decides one (`cache_key`: the
/// whole key, so two different inputs never share a map).
#[derive(Debug, Default)]
pub struct MapCache {
    maps: Mutex<HashMap<Vec<u64>, StepMap>>,
    hits: AtomicUsize,
    misses: AtomicUsize,
}

impl MapCache {
    /// An empty cache.
    pub fn new() -> MapCache {
        MapCache::default()
    }

    /// The process-wide cache the planner uses.
    pub fn global() -> &'static MapCache {
        static GLOBAL: OnceLock<MapCache> = OnceLock::new();
        GLOBAL.get_or_init(MapCache::new)
    }

    /// Maps served from the cache so far.
    pub fn hits(&self) -> usize {
        self.hits.load(Ordering::Relaxed)
    }

    /// Maps computed so far.
    pub fn misses(&self) -> usize {
        self.misses.load(Ordering::Relaxed)
    }

    /// The dynamic map of a straight-node mode, from the cache or computed ([`line_map`]).
    pub fn line_map(
        &self,
        part: &Part,
        mode: &Mode,
        plate: &PlateModel,
        period: f64,
        backend: Backend,
        set: DynSettings,
    ) -> Result<StepMap, MapError> {
        let key = cache_key(part, mode, plate, period, backend, set);
        // A poisoned lock only means another thread panicked while inserting: the map
        // itself is still consistent (inserts are single calls).
        if let Some(m) = self.maps.lock().unwrap_or_else(|e| e.into_inner()).get(&key) {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok(m.clone());
        }
        let map = dynamic_line_map(part, mode, plate, period, backend, set)?;
        self.misses.fetch_add(1, Ordering::Relaxed);
        self.maps.lock().unwrap_or_else(|e| e.into_inner()).insert(key, map.clone());
        Ok(map)
    }
}

/// Everything that decides a dynamic map, as the bits of its numbers: the part's vertices, the
/// mode's law, gains and node, the plate size, the period and the settings.
fn cache_key(
    part: &Part,
    mode: &Mode,
    plate: &PlateModel,
    period: f64,
    backend: Backend,
    set: DynSettings,
) -> Vec<u64> {
    let mut key = Vec::new();
    let mut f = |x: f64| key.push(x.to_bits());
    for r in part.rings() {
        f(r.len() as f64);
        r.iter().for_each(|p| {
            f(p[0]);
            f(p[1]);
        });
        f(f64::NAN); // ring separator
    }
    match mode.law {
        Law::Sign => f(1.0),
        Law::Linear => f(2.0),
        Law::Sine { wavelength_mm } => {
            f(3.0);
            f(wavelength_mm);
        }
    }
    f(mode.gain_left);
    f(mode.gain_right);
    if let Node::Line { angle_deg, offset_mm } = mode.node {
        f(angle_deg);
        f(offset_mm);
    }
    f(plate.size_mm[0]);
    f(plate.size_mm[1]);
    f(period);
    f(set.orientations as f64);
    f(f64::from(set.refine));
    f(if backend == Backend::Fixed { 0.0 } else { 1.0 });
    key
}

/// Start points on the normal through the plate centre's foot on the node, on both sides:
/// half-way across (0.5 R), just beyond the part (R + 5 mm) and, except under the sign law, as
/// far as the plate allows (the part's centroid at least R from every edge). R = the part's
/// radius.
pub(crate) fn approach_starts(body: &Body, mode: &Mode, plate: &PlateModel) -> Vec<[f64; 2]> {
    let FieldModel::Line { xhat, c, .. } = FieldModel::new(mode, plate) else {
        return Vec::new();
    };
    let ctr = plate.center();
    let xi0 = xhat[0] * ctr[0] + xhat[1] * ctr[1] - c;
    let base = [ctr[0] - xi0 * xhat[0], ctr[1] - xi0 * xhat[1]];
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let mut out = Vec::new();
    for side in [-1.0, 1.0] {
        let d = [side * xhat[0], side * xhat[1]];
        let far = ray_in_box(base, d, [r, r], [w - r, h - r]);
        let mut dists = vec![0.5 * body.radius, body.radius + 5.0];
        // Under the sign law a part wholly on one side feels a uniform pull (no moment): from
        // afar it slides without turning to where the R + 5 mm start is.
        if far > body.radius + 6.0 && mode.law != Law::Sign {
            dists.push(far);
        }
        out.extend(dists.into_iter().map(|t| [base[0] + t * d[0], base[1] + t * d[1]]));
    }
    out
}

/// How far (≥ 0) one can go from `p` along unit `d` inside the box [lo, hi] (0 if outside).
fn ray_in_box(p: [f64; 2], d: [f64; 2], lo: [f64; 2], hi: [f64; 2]) -> f64 {
    let mut t = f64::INFINITY;
    for k in 0..2 {
        if d[k] > 1e-12 {
            t = t.min((hi[k] - p[k]) / d[k]);
        } else if d[k] < -1e-12 {
            t = t.min((lo[k] - p[k]) / d[k]);
        }
    }
    if t.is_finite() { t.max(0.0) } else { 0.0 }
}

/// The dynamic map of a straight-node mode (uncached; see [`MapCache::line_map`]).
pub fn dynamic_line_map(
    part: &Part,
    mode: &Mode,
    plate: &PlateModel,
    period: f64,
    backend: Backend,
    set: DynSettings,
) -> Result<StepMap, MapError> {
    let statics = line_map(part, mode, backend)?;
    // Every orientation at rest (statically) also means no moment while crossing.
    if statics.neutral {
        return Ok(statics);
    }
    let body = Body::with_samples(part, PLANNER_BODY_SAMPLES);
    let field = FieldModel::new(mode, plate);
    let p = SimParams::to_rest(&body, mode, &field, plate);
    let n = set.orientations.max(4);
    let step = 360.0 / n as f64;
    let first = 0.3 * step;
    let mut clusters = Clusters::new(period, CLUSTER_DEG);
    let starts = approach_starts(&body, mode, plate);
    // The runs are independent: simulated in parallel, gathered in order and clustered
    // sequentially, so the map does not depend on the thread count.
    let end = |pt: [f64; 2], th: f64| {
        let run = crate::motion::integrate::run(
            &body,
            &field,
            p,
            Pose { x: pt[0], y: pt[1], theta: th.to_radians() },
        );
        run.rested.then(|| run.pose.theta.to_degrees())
    };
    let finals: Vec<Vec<Option<f64>>> = starts
        .par_iter()
        .map(|&pt| (0..n).into_par_iter().map(|i| end(pt, first + i as f64 * step)).collect())
        .collect();
    let labels: Vec<Vec<Option<usize>>> = finals
        .iter()
        .map(|row| row.iter().map(|f| f.map(|t| clusters.label(t))).collect())
        .collect();
    // Does a run that ended at `f` (None: still moving) belong to outcome `a`?
    let same = |a: Option<usize>, f: Option<f64>| match (a, f) {
        (Some(a), Some(t)) => clusters.holds(a, t),
        (None, None) => true,
        _ => false,
    };
    let changes = change_points(&starts, &labels, (first, step, set.refine), &end, &same);
    let rests: Vec<f64> =
        clusters.means().into_iter().map(|m| snap(m, &statics.stable, period)).collect();
    let outcomes = Outcomes { first, step, labels, changes };
    let reached = reached_rests(&outcomes.labels, &rests);
    // The static unstable rests stay boundaries: they are equilibria whatever the approach,
    // and a part starting near one lingers there (its outcome can also change there without
    // the change showing modulo the period, e.g. a square's diagonal rests).
    let mut boundaries = outcomes.boundaries();
    boundaries.extend(&statics.boundaries);
    Ok(StepMap {
        stable: reached,
        boundaries,
        neutral: false,
        sampled: None,
        slack: step / 2f64.powi(set.refine as i32 + 1),
        dead_starts: 0,
        dead_points: Vec::new(),
        dynamic: Some(std::sync::Arc::new(DynamicImages { rests, outcomes })),
        evidence: None,
    })
}

/// Per start point and start orientation i of a dynamic map (`grid`: first orientation, step
/// and bisections, deg): where the outcome changes between orientations i and i + 1, found by
/// bisecting with `end` (a run's final orientation, `None` while still moving) and `same`
/// (does an end belong to a label); `None` where the two share an outcome. In parallel,
/// gathered in order.
fn change_points(
    starts: &[[f64; 2]],
    labels: &[Vec<Option<usize>>],
    (first, step, refine): (f64, f64, u32),
    end: &(dyn Fn([f64; 2], f64) -> Option<f64> + Sync),
    same: &(dyn Fn(Option<usize>, Option<f64>) -> bool + Sync),
) -> Vec<Vec<Option<f64>>> {
    starts
        .par_iter()
        .zip(labels)
        .map(|(&pt, l)| {
            let n = l.len();
            (0..n)
                .into_par_iter()
                .map(|i| {
                    let (a, b) = (l[i], l[(i + 1) % n]);
                    (a != b).then(|| {
                        let (mut lo, mut hi) =
                            (first + i as f64 * step, first + (i + 1) as f64 * step);
                        for _ in 0..refine {
                            let mid = 0.5 * (lo + hi);
                            if same(a, end(pt, mid)) { lo = mid } else { hi = mid }
                        }
                        wrap_deg(0.5 * (lo + hi))
                    })
                })
                .collect()
        })
        .collect()
}

/// The rests (`rests[label]`) some run of a dynamic map reached, in label order.
fn reached_rests(labels: &[Vec<Option<usize>>], rests: &[f64]) -> Vec<f64> {
    let mut ids: Vec<usize> = labels.iter().flatten().flatten().copied().collect();
    ids.sort_unstable();
    ids.dedup();
    ids.into_iter().map(|k| rests[k]).collect()
}

/// The exact static rest nearest a simulated one (within [`SNAP_DEG`], modulo the period),
/// else the simulated value.
fn snap(sim: f64, stable: &[f64], period: f64) -> f64 {
    stable
        .iter()
        .map(|&s| s.rem_euclid(period))
        .min_by(|a, b| cdist(*a, sim, period).total_cmp(&cdist(*b, sim, period)))
        .filter(|&s| cdist(s, sim, period) < SNAP_DEG)
        .unwrap_or(sim)
}

/// What a dynamic [`StepMap`] holds besides its rests and boundaries.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DynamicImages {
    /// Every rest reached (deg, mod the period), indexed by the outcome labels.
    rests: Vec<f64>,
    /// The measured outcomes.
    outcomes: Outcomes,
}

impl DynamicImages {
    /// Orientations (deg) reached from `theta`, `None` when some run did not come to rest.
    pub(crate) fn images(&self, theta: f64) -> Option<Vec<f64>> {
        Some(self.outcomes.images(theta)?.into_iter().map(|k| self.rests[k]).collect())
    }
}
