//! Step maps: each mode's map θ ↦ θ' with its basin boundaries (docs/plan.md, "Step maps"):
//! the static straight-node map ([`line_map`]) and the simulated map of curved and grid
//! nodes ([`sampled_map`]); dynamic straight-node maps are [`super::dynamic`].

use crate::model::angle::wrap_deg;
use std::sync::atomic::{AtomicBool, Ordering};

use rayon::prelude::*;

use chladni_shared::analysis::field::Field;
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::{AnalysisError, Analyzer};
use chladni_shared::icd::units::deg_from_bam;

use super::cluster::{CLUSTER_DEG, Clusters};
use super::dynamic;
use super::edges::{on_plate_edge, rim_line};
use super::mode_margin::ModeMargin;
use super::options::Backend;
use super::symmetry::body_symmetry_order;
use crate::analysis::reference::{RefField, Reference};
use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::plate::{Edge, Mode, Node, PlateModel};
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::contact::Rim;
use crate::motion::field::FieldModel;
use crate::motion::integrate::SimParams;

/// One mode's orientation map.
#[derive(Debug, Clone)]
pub struct StepMap {
    /// Stable orientations (degrees, plate frame, [0, 360)).
    pub stable: Vec<f64>,
    /// Basin boundaries (degrees, [0, 360)).
    pub boundaries: Vec<f64>,
    /// Every orientation is at rest.
    pub neutral: bool,
    /// Simulated maps: start orientations (deg) and every rest reached from them over the
    /// start points (deg; empty: some run did not come to rest).
    pub(super) sampled: Option<Vec<(f64, Vec<f64>)>>,
    /// Extra distance to boundaries for sampled maps (half the start spacing).
    pub(super) slack: f64,
    /// Simulated grid maps: start points outside the mode's reach (no interior node
    /// reached; see [`sampled_map`]).
    pub dead_starts: usize,
    /// Which of [`map_starts`] those were (indices), for measurements that rerun the map's
    /// runs ([`super::margin::windowed_spread`]).
    pub(super) dead_points: Vec<usize>,
    /// Dynamic straight-node maps ([`dynamic`]): the measured outcome of every start
    /// orientation from either side of the node; `None` for every other map.
    pub(super) dynamic: Option<std::sync::Arc<dynamic::DynamicImages>>,
    /// The margin measured for this map ([`super::margin`]: grid modes when the margin is
    /// automatic); `None`: the options' fixed margin applies.
    pub evidence: Option<ModeMargin>,
}

impl StepMap {
    /// The map of a mode under which every orientation is at rest (e.g. a square, linear field).
    pub(super) fn neutral() -> Self {
        StepMap {
            stable: Vec::new(),
            boundaries: Vec::new(),
            neutral: true,
            sampled: None,
            slack: 0.0,
            dead_starts: 0,
            dead_points: Vec::new(),
            dynamic: None,
            evidence: None,
        }
    }
}

impl StepMap {
    /// Every orientation `theta` (deg) may reach: one for static and simulated maps, all
    /// the rests a dynamic map measured when the outcome depends on the side the part
    /// approaches from; `Err(distance)` when `theta` lies within `margin` of a basin boundary
    /// (distance 0: a simulated run from it did not come to rest).
    pub fn apply_all(&self, theta: f64, margin: f64) -> Result<Vec<f64>, f64> {
        match (&self.dynamic, &self.sampled) {
            (Some(d), _) if !self.neutral => {
                self.near_boundary(theta, margin)?;
                d.images(theta).ok_or(0.0)
            }
            (None, Some(s)) if !self.neutral => {
                self.near_boundary(theta, margin)?;
                match nearest_sample(s, theta) {
                    Some([]) => Err(0.0),
                    Some(v) => Ok(v.to_vec()),
                    None => Ok(vec![theta]),
                }
            }
            _ => self.apply(theta, margin).map(|v| vec![v]),
        }
    }

    /// `Err(distance)` when `theta` lies within `margin` (plus the map's slack) of a basin
    /// boundary; a map with a measured margin ([`Self::evidence`]) keeps that one instead.
    pub(crate) fn near_boundary(&self, theta: f64, margin: f64) -> Result<(), f64> {
        let margin = self.evidence.map_or(margin, |m| m.deg);
        let near =
            self.boundaries.iter().map(|&b| cdist(theta, b, 360.0)).fold(f64::INFINITY, f64::min);
        if near < margin + self.slack { Err(near) } else { Ok(()) }
    }

    /// The orientation reached from `theta` (deg), or `Err(distance)` when `theta` lies
    /// within `margin` of a basin boundary. A dynamic map's ambiguous orientation (several
    /// images, see [`Self::apply_all`]) gives `Err(0.0)`.
    pub fn apply(&self, theta: f64, margin: f64) -> Result<f64, f64> {
        if self.neutral {
            return Ok(wrap_deg(theta));
        }
        self.near_boundary(theta, margin)?;
        if self.dynamic.is_some() || self.sampled.is_some() {
            return match self.apply_all(theta, margin)?.as_slice() {
                [v] => Ok(*v),
                _ => Err(0.0),
            };
        }
        if let Some(&s) = self.stable.iter().find(|&&s| cdist(s, theta, 360.0) < 1e-3) {
            return Ok(s);
        }
        // The stable rest in the same arc between consecutive boundaries.
        let mut b: Vec<f64> = self.boundaries.clone();
        b.sort_by(f64::total_cmp);
        if b.is_empty() {
            return Ok(self.stable.first().copied().unwrap_or(theta));
        }
        let lo = b.iter().rev().find(|&&x| x <= wrap_deg(theta)).copied().unwrap_or(b[b.len() - 1]);
        let width = |x: f64| wrap_deg(x - lo);
        let next = b.iter().map(|&x| width(x)).filter(|&w| w > 0.0).fold(360.0, f64::min);
        Ok(self
            .stable
            .iter()
            .copied()
            .find(|&s| width(s) > 0.0 && width(s) < next)
            .unwrap_or(theta))
    }
}

/// The rests a simulated map recorded for the start orientation nearest `theta`.
fn nearest_sample(s: &[(f64, Vec<f64>)], theta: f64) -> Option<&[f64]> {
    s.iter()
        .min_by(|a, b| cdist(a.0, theta, 360.0).total_cmp(&cdist(b.0, theta, 360.0)))
        .map(|b| b.1.as_slice())
}

/// Why a straight-node map could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MapError {
    /// The mode's node is not a straight line (curved and grid nodes are mapped by simulation).
    #[error("{mode}: not a line node")]
    NotALine {
        /// The mode's name.
        mode: String,
    },
    /// The fixed-point analysis refused the part (outline, normalisation) for this mode.
    #[error("{mode}: cannot analyse: {error:?}")]
    Refused {
        /// The mode's name.
        mode: String,
        /// The shared analysis' error.
        error: AnalysisError,
    },
    /// The fixed-point analysis started but could not finish (no root bracketed, overflow).
    #[error("{mode}: analysis failed: {error:?}")]
    Failed {
        /// The mode's name.
        mode: String,
        /// The shared analysis' error.
        error: AnalysisError,
    },
}

/// A straight-node map from the shared fixed-point analysis or the f64 reference.
pub fn line_map(part: &Part, mode: &Mode, backend: Backend) -> Result<StepMap, MapError> {
    let Node::Line { angle_deg, .. } = mode.node else {
        return Err(MapError::NotALine { mode: mode.name.clone() });
    };
    let to_plate = |d: f64| wrap_deg(d + angle_deg - 90.0);
    let (mut stable, mut boundaries, neutral) = (Vec::new(), Vec::new(), false);
    match backend {
        Backend::Fixed => {
            let rings = part.to_fixed();
            let slices: Vec<&[Pt]> = rings.iter().map(Vec::as_slice).collect();
            let kind = mode.law.to_fixed();
            let field = Field {
                kind,
                gain_left: Fx::from_f64(mode.gain_left),
                gain_right: Fx::from_f64(mode.gain_right),
            };
            let an = Analyzer::new(&slices, field)
                .map_err(|error| MapError::Refused { mode: mode.name.clone(), error })?;
            let a = an
                .analyze()
                .map_err(|error| MapError::Failed { mode: mode.name.clone(), error })?;
            if a.neutral {
                return Ok(StepMap::neutral());
            }
            for r in &a.rests {
                let d = to_plate(deg_from_bam(r.angle));
                if r.stable { stable.push(d) } else { boundaries.push(d) }
            }
        }
        Backend::F64 => {
            let r = reference_for(part, mode);
            let (rests, neutral) = r.rests();
            if neutral {
                return Ok(StepMap::neutral());
            }
            for x in rests {
                let d = to_plate(x.deg);
                if x.stable { stable.push(d) } else { boundaries.push(d) }
            }
        }
    }
    Ok(StepMap {
        stable,
        boundaries,
        neutral,
        sampled: None,
        slack: 0.0,
        dead_starts: 0,
        dead_points: Vec::new(),
        dynamic: None,
        evidence: None,
    })
}

/// Where simulated maps start the part: the hyperbola's vertex (else the plate centre) and
/// the four plate corners inset by the part's radius, since a part may meet a curved node
/// anywhere and the outcome can depend on where. For a node the field pushes the part into
/// the rim from ([`rim_line`]) with a wall, also the four edge midpoints on the rim: each
/// start pose there is pushed against the wall ([`Rim::project`]), so the map records what
/// the rim does to a part dropped against it. (Not the corners themselves: a part pushed into
/// a corner touches two walls and can jam there at whatever orientation it arrived;
/// docs/plan.md, "The rim in the step maps".)
pub fn map_starts(body: &Body, mode: &Mode, plate: &PlateModel) -> Vec<[f64; 2]> {
    let first = match mode.node {
        Node::Hyperbola { center_mm, angle_deg, a_mm, .. } => {
            let (s, c) = angle_deg.to_radians().sin_cos();
            [center_mm[0] + a_mm * c, center_mm[1] + a_mm * s]
        }
        _ => plate.center(),
    };
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let mut out = vec![first, [r, r], [w - r, r], [w - r, h - r], [r, h - r]];
    if plate.edge == Edge::Wall && rim_line(body.radius, mode, plate) {
        out.extend([[w / 2.0, 0.0], [w, h / 2.0], [w / 2.0, h], [0.0, h / 2.0]]);
    }
    out
}

/// A map from simulation (any node kind): `n` start orientations at each of [`map_starts`].
/// Final orientations are clustered (2°, modulo the period); an orientation whose outcome
/// differs between start points maps to every rest it reached (the search carries the whole
/// set on, as for dynamic maps, [`StepMap::apply_all`]); one whose run does not come to rest
/// within 5000 T₀ (T₀: time to travel one radius at full pull) is treated as lying on a basin
/// boundary, and so is the place between neighbouring start orientations whose sets of rests
/// differ. A part of rotational symmetry order m (dividing `n`) is simulated from the first
/// n/m start orientations of each point only; the others are those runs turned.
///
/// The rim: a part the field pushes into a wall comes to rest against it on a stable edge
/// (the wall's reaction turns it: push alignment) and that rest is recorded like any other.
/// Grid modes only: a start point from which some run ends with the centroid within the
/// part's radius of the plate edge (or off it) reached no interior node (near a clamped edge
/// φ and ∂φ/∂x vanish, the pull falls off like x³ and parts drift onto the clamp); it lies
/// outside the mode's reach, is left out of the map and counted in [`StepMap::dead_starts`]
/// (docs/plan.md: recording those rim rests as well was tried and is not done yet).
pub fn sampled_map(body: &Body, mode: &Mode, plate: &PlateModel, n: usize, period: f64) -> StepMap {
    sampled_map_from(body, mode, plate, n, period, &[])
}

/// [`sampled_map`] with `extra` start points after those of [`map_starts`]: the drop points a
/// whole-plate plan did not hold from ([`super::whole`]), so that the map sees what the mode
/// does to a part dropped there.
pub(super) fn sampled_map_from(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    n: usize,
    period: f64,
    extra: &[[f64; 2]],
) -> StepMap {
    let (field, p) = map_run(body, mode, plate);
    let rim = Rim::of(plate);
    let thetas = map_thetas(n);
    let mut clusters = Clusters::new(period, CLUSTER_DEG);
    let mut labels: Vec<Vec<Option<usize>>> = Vec::new();
    let (mut dead_starts, mut dead_points) = (0, Vec::new());
    // A part of symmetry order m started at θ + 360°/m is the same body at the same place as
    // at θ: its run is that run turned by 360°/m (to rounding), so only the first n/m start
    // orientations of each point are simulated.
    let m = body_symmetry_order(body) as usize;
    let m = if m > 1 && n.is_multiple_of(m) { m } else { 1 };
    let (distinct, turn) = (n / m, std::f64::consts::TAU / m as f64);
    // Every start point's runs at once, in parallel (no wait for the slowest run of each
    // point), collected in order: the map does not depend on the thread count. Start poses
    // on the rim are pushed against its wall.
    let mut starts = map_starts(body, mode, plate);
    starts.extend_from_slice(extra);
    let poses: Vec<(usize, Pose)> = starts
        .iter()
        .enumerate()
        .flat_map(|(j, s)| {
            thetas[..distinct].iter().map(move |th| {
                (j, rim.project(body, Pose { x: s[0], y: s[1], theta: th.to_radians() }))
            })
        })
        .collect();
    let all = simulate_starts(body, mode, plate, &field, p, &poses, starts.len());
    for (point, simulated) in all.chunks(distinct.max(1)).enumerate() {
        // A skipped run (`None`) belongs to a start point outside the mode's reach.
        let Some(simulated) = simulated.iter().copied().collect::<Option<Vec<(Pose, bool)>>>()
        else {
            dead_starts += 1;
            dead_points.push(point);
            continue;
        };
        // (end pose, rested) for each of the n start orientations.
        let runs = (0..n).map(|i| {
            let (q, rested) = simulated[i % distinct];
            (Pose { theta: q.theta + (i / distinct) as f64 * turn, ..q }, rested)
        });
        if simulated.iter().any(|r| outside_reach(body, mode, plate, r.0)) {
            dead_starts += 1;
            dead_points.push(point);
            continue;
        }
        let label = runs
            .map(|(end, rested)| rested.then(|| clusters.label(end.theta.to_degrees())))
            .collect();
        labels.push(label);
    }
    let rep = clusters.means();
    let (boundaries, sampled) = combine(&labels, &thetas, &rep);
    StepMap {
        stable: rep,
        boundaries,
        neutral: false,
        sampled: Some(sampled),
        slack: 180.0 / n as f64,
        dead_starts,
        dead_points,
        dynamic: None,
        evidence: None,
    }
}

/// A simulated map's boundaries and samples from each start point's rest labels (`labels[p][i]`:
/// the rest reached from start point p at start orientation `thetas[i]`, `None` when that
/// run did not come to rest; `rep`: each label's orientation). Per start orientation the set
/// is every rest reached over the start points; a boundary lies half a step after a start
/// orientation whose set differs from the next one's (or that did not rest).
fn combine(
    labels: &[Vec<Option<usize>>],
    thetas: &[f64],
    rep: &[f64],
) -> (Vec<f64>, Vec<(f64, Vec<f64>)>) {
    let n = thetas.len();
    let combined = rest_sets(labels, n);
    let mut boundaries = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        if combined[i].is_none() || combined[i] != combined[j] {
            boundaries.push(wrap_deg(thetas[i] + 180.0 / n as f64));
        }
    }
    let sampled = thetas
        .iter()
        .zip(&combined)
        .map(|(&th, l)| (th, l.iter().flatten().map(|&k| rep[k]).collect()))
        .collect();
    (boundaries, sampled)
}

/// Per start orientation (`count` of them): every rest label reached over the start points
/// (sorted, deduplicated; `None` when some start point's run did not come to rest).
pub(super) fn rest_sets(labels: &[Vec<Option<usize>>], count: usize) -> Vec<Option<Vec<usize>>> {
    (0..count)
        .map(|i| {
            let mut set = labels.iter().map(|ls| ls[i]).collect::<Option<Vec<usize>>>()?;
            set.sort_unstable();
            set.dedup();
            Some(set)
        })
        .collect()
}

/// The runs of [`sampled_map`] from `poses` (start point index, start pose), in order, in
/// parallel: (end pose, rested). A start point is dropped whole once one of its runs ends
/// outside the mode's reach ([`outside_reach`]), so its runs not yet begun are skipped
/// (`None`): near a cantilever's clamp the pull vanishes and a run can creep for its whole
/// step budget. Which runs are skipped depends on the thread timing, the map does not: a
/// skipped run belongs to a dropped point.
pub(super) fn simulate_starts(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    field: &FieldModel,
    p: SimParams,
    poses: &[(usize, Pose)],
    points: usize,
) -> Vec<Option<(Pose, bool)>> {
    let dead: Vec<AtomicBool> = (0..points).map(|_| AtomicBool::new(false)).collect();
    let order = spread_order(poses);
    let ran: Vec<Option<(Pose, bool)>> = order
        .par_iter()
        .map(|&t| poses[t])
        .map(|(j, q)| {
            if dead[j].load(Ordering::Relaxed) {
                return None;
            }
            // A run of a point found dead meanwhile is called off: its outcome no longer counts.
            let r = crate::motion::integrate::run_while(body, field, p, q, &|| {
                !dead[j].load(Ordering::Relaxed)
            })?;
            if outside_reach(body, mode, plate, r.pose) {
                dead[j].store(true, Ordering::Relaxed);
            }
            Some((r.pose, r.rested && !r.lost))
        })
        .collect();
    let mut out = vec![None; poses.len()];
    for (&t, r) in order.iter().zip(ran) {
        out[t] = r;
    }
    out
}

/// The order [`simulate_starts`] runs `poses` in (indices into them): every start point's
/// k-th run before any point's (k+1)-th, and each point's start orientations in a
/// low-discrepancy order (golden-ratio steps over the circle), so that the first runs of every
/// point already cover the circle. A point outside the mode's reach is then found after a few
/// of its runs, not after the runs of the orientations before the ones that end on the plate
/// edge, and the rest of its runs are skipped. Only which runs are skipped changes, not the
/// map (they belong to a dropped point).
fn spread_order(poses: &[(usize, Pose)]) -> Vec<usize> {
    let golden = 0.5 * (5f64.sqrt() - 1.0);
    let mut first = std::collections::HashMap::new();
    let mut keyed: Vec<(f64, usize, usize)> = poses
        .iter()
        .enumerate()
        .map(|(t, &(j, _))| {
            let i = t - *first.entry(j).or_insert(t);
            ((i as f64 * golden).fract(), j, t)
        })
        .collect();
    keyed.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    keyed.into_iter().map(|k| k.2).collect()
}

/// The field and run settings of a simulated map's runs: with the rim, to rest or 5000 T₀
/// (T₀: time to travel one radius at full pull; [`sampled_map`]).
pub(super) fn map_run(body: &Body, mode: &Mode, plate: &PlateModel) -> (FieldModel, SimParams) {
    let field = FieldModel::new(mode, plate);
    let p = SimParams::to_rest(body, mode, &field, plate);
    (field, p)
}

/// A simulated map's `n` start orientations (deg): 0.3 of a step off 0° (so also off 45°,
/// 90°, ... for n = 36, 90, 360): a start point on the node (the plate centre often is) would
/// otherwise sample the symmetric unstable rests (0°, 90°, ...) exactly and report them as
/// rests. Its boundaries lie half a step after a start orientation.
pub(super) fn map_thetas(n: usize) -> Vec<f64> {
    (0..n).map(|i| (i as f64 + 0.3) * 360.0 / n as f64).collect()
}

/// Is a run that ended at `q` under a grid mode outside the mode's reach: the part ended on
/// the plate edge or off it instead of on an interior node (see [`sampled_map`])?
pub(crate) fn outside_reach(body: &Body, mode: &Mode, plate: &PlateModel, q: Pose) -> bool {
    matches!(mode.node, Node::Grid(_)) && on_plate_edge(body, plate, q)
}

/// The f64 reference analysis of `part` under a straight-node mode's field law and gains.
fn reference_for(part: &Part, mode: &Mode) -> Reference {
    Reference::new(
        part,
        RefField { law: mode.law, gain_left: mode.gain_left, gain_right: mode.gain_right },
    )
}

/// Centroid offset across a straight node at a rest orientation (mm, along x̂ = −n̂ from the
/// node line), by the f64 balance in the node frame.
pub(crate) fn balance_offset(part: &Part, mode: &Mode, theta_deg: f64) -> f64 {
    let Node::Line { angle_deg, .. } = mode.node else { return 0.0 };
    reference_for(part, mode).balance(theta_deg - angle_deg + 90.0).0
}
