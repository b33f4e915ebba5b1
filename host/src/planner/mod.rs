//! Sensorless plan synthesis (docs/plan.md, paper §6): the shortest sequence of modes that
//! brings every start orientation to one final orientation.
//!
//! 1. **Step maps.** Each mode gives a map θ ↦ θ' (plate frame) with its basin boundaries:
//!    - straight node of direction α: the shared fixed-point analysis in the node frame,
//!      θ' = α − 90° + a(θ − α + 90°); boundaries = unstable rests (the f64 reference can be
//!      used instead, [`Backend::F64`], to check agreement);
//!    - hyperbola and grid nodes: quasi-static simulation ([`crate::motion::sim`]) from `sim_starts`
//!      start orientations at one start point (hyperbola: its vertex; grid: the plate centre);
//!      final orientations are clustered (2°) into rests, boundaries lie between neighbouring
//!      starts that end in different rests.
//! 2. **Equivalence.** Orientations are taken modulo the period P = 360°/m, m = the part's
//!    rotational symmetry order, doubled (lcm with 2) when every mode is a straight node with
//!    equal gains (t(θ + 180°) = t(θ)).
//! 3. **Search.** After the first step only the stable rests remain; breadth-first search
//!    over sets of those (sorted index sets, visited once) finds the shortest sequence ending
//!    in a single orientation. A step is only allowed if no orientation of the current set lies
//!    within `margin_deg` of one of that step's basin boundaries (the first step acts on all
//!    orientations and has no such constraint).
//! 4. **Durations.** Each step is simulated from its predicted start orientations (every 15°
//!    for the first step) and from the plate corners farthest from the node; duration = the
//!    slowest settle time × `safety`, plus the ramp, rounded up to 10 ms.
//! 5. **Position.** A straight node fixes the centroid's coordinate across it; if the last
//!    two steps are perpendicular straight nodes and the earlier one leaves all predicted
//!    orientations at the same offset, the centroid is fixed where they cross.
//!
//! With a feed region ([`PlanOptions::feed`]) planning tracks poses instead ([`feed`]): on
//! plates with several curved node lines the rest depends on the start position, which the
//! orientation-set search can only treat as ambiguity.

use std::collections::{HashMap, VecDeque};

use rayon::prelude::*;

use chladni_shared::analysis::field::Field;
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::Analyzer;
use chladni_shared::icd::plan::MAX_NAME;
use chladni_shared::icd::units::deg_from_bam;

use crate::analysis::reference::{RefField, Reference};
use crate::model::part::Part;
use crate::model::plan_file::{PlanFile, StepJson};
use crate::model::plate::{Mode, Node, PlateModel};
use crate::motion::sim::{self, Body, FieldModel, Pose, SimParams};

pub mod feed;

/// Which model computes straight-node maps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// Q31.32 shared analysis (what the firmware computes).
    Fixed,
    /// The f64 reference.
    F64,
}

/// Planner settings.
#[derive(Debug, Clone, Copy)]
pub struct PlanOptions {
    /// Robustness margin (degrees).
    pub margin_deg: f64,
    /// Settle time safety factor.
    pub safety: f64,
    /// Straight-node model.
    pub backend: Backend,
    /// Start orientations for simulated (hyperbola, grid) maps.
    pub sim_starts: usize,
    /// Simulate step durations (off: 1000 ms per step, for quick checks).
    pub durations: bool,
    /// Most sets the search visits.
    pub max_states: usize,
    /// Where parts are dropped: plan by tracking poses from there ([`feed`]) instead of
    /// over orientation sets.
    pub feed: Option<feed::FeedRegion>,
    /// Settings of the feed-region search.
    pub feed_search: feed::FeedSearch,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            margin_deg: 3.0,
            safety: 1.5,
            backend: Backend::Fixed,
            sim_starts: 90,
            durations: true,
            max_states: 200_000,
            feed: None,
            feed_search: feed::FeedSearch::default(),
        }
    }
}

/// One mode's orientation map.
#[derive(Debug, Clone)]
pub struct StepMap {
    /// Stable orientations (degrees, plate frame, [0, 360)).
    pub stable: Vec<f64>,
    /// Basin boundaries (degrees, [0, 360)).
    pub boundaries: Vec<f64>,
    /// Every orientation is at rest.
    pub neutral: bool,
    /// Simulated maps: start orientations (deg) and the rest each reached (deg).
    sampled: Option<Vec<(f64, f64)>>,
    /// Extra distance to boundaries for sampled maps (half the start spacing).
    slack: f64,
    /// Simulated grid maps: start points outside the mode's reach (no interior node
    /// reached; see [`sampled_map`]).
    pub dead_starts: usize,
}

impl StepMap {
    /// The map of a mode under which every orientation is at rest (e.g. a square, linear field).
    fn neutral() -> Self {
        StepMap {
            stable: Vec::new(),
            boundaries: Vec::new(),
            neutral: true,
            sampled: None,
            slack: 0.0,
            dead_starts: 0,
        }
    }
}

/// Circular distance on a circle of circumference `p`.
pub fn cdist(a: f64, b: f64, p: f64) -> f64 {
    let d = (a - b).rem_euclid(p);
    d.min(p - d)
}

impl StepMap {
    /// The orientation reached from `theta` (deg), or `Err(distance)` when `theta` lies
    /// within `margin` of a basin boundary.
    pub fn apply(&self, theta: f64, margin: f64) -> Result<f64, f64> {
        if self.neutral {
            return Ok(theta.rem_euclid(360.0));
        }
        let near =
            self.boundaries.iter().map(|&b| cdist(theta, b, 360.0)).fold(f64::INFINITY, f64::min);
        if near < margin + self.slack {
            return Err(near);
        }
        if let Some(s) = &self.sampled {
            let best = s
                .iter()
                .min_by(|a, b| cdist(a.0, theta, 360.0).total_cmp(&cdist(b.0, theta, 360.0)));
            return match best {
                Some(b) if b.1.is_nan() => Err(0.0),
                Some(b) => Ok(b.1),
                None => Ok(theta),
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
        let lo = b
            .iter()
            .rev()
            .find(|&&x| x <= theta.rem_euclid(360.0))
            .copied()
            .unwrap_or(b[b.len() - 1]);
        let width = |x: f64| (x - lo).rem_euclid(360.0);
        let next = b.iter().map(|&x| width(x)).filter(|&w| w > 0.0).fold(360.0, f64::min);
        Ok(self
            .stable
            .iter()
            .copied()
            .find(|&s| width(s) > 0.0 && width(s) < next)
            .unwrap_or(theta))
    }
}

/// Rotational symmetry order of a part (largest m such that turning it by 360°/m about its
/// centroid maps it onto itself, vertex for vertex, within 10⁻⁶ of its size).
pub fn symmetry_order(part: &Part) -> u32 {
    let body = Body::new(part);
    let n = part.outline.len();
    let tol = 1e-6 * body.radius.max(1e-9);
    for m in (2..=n).rev() {
        if !n.is_multiple_of(m) {
            continue;
        }
        let (s, c) = (std::f64::consts::TAU / m as f64).sin_cos();
        let ok = body.rings.iter().all(|r| {
            r.iter().all(|p| {
                let q = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
                body.rings.iter().any(|o| o.iter().any(|v| (v[0] - q[0]).hypot(v[1] - q[1]) < tol))
            })
        });
        if ok {
            return m as u32;
        }
    }
    1
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// A straight-node map from the shared fixed-point analysis or the f64 reference.
pub fn line_map(part: &Part, mode: &Mode, backend: Backend) -> Result<StepMap, String> {
    let Node::Line { angle_deg, .. } = mode.node else {
        return Err("not a line node".into());
    };
    let to_plate = |d: f64| (d + angle_deg - 90.0).rem_euclid(360.0);
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
                .map_err(|e| format!("{}: cannot analyse: {e:?}", mode.name))?;
            let a = an.analyze().map_err(|e| format!("{}: analysis failed: {e:?}", mode.name))?;
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
    Ok(StepMap { stable, boundaries, neutral, sampled: None, slack: 0.0, dead_starts: 0 })
}

/// Where simulated maps start the part: the hyperbola's vertex (else the plate centre) and
/// the four plate corners inset by the part's radius, since a part may meet a curved node
/// anywhere and the outcome can depend on where.
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
    vec![first, [r, r], [w - r, r], [w - r, h - r], [r, h - r]]
}

/// A map from simulation (any node kind): `n` start orientations at each of [`map_starts`].
/// Final orientations are clustered (2°, modulo the period); an orientation whose outcome
/// differs between start points is ambiguous and treated as lying on a basin boundary, and
/// so is one whose run does not come to rest within 5000 T₀ (T₀: time to travel one radius
/// at full pull).
///
/// Grid modes only: a start point from which some run ends with the centroid within half the
/// part's radius of the plate edge reached no interior node (near a clamped edge φ and ∂φ/∂x
/// vanish, the pull falls off like x³ and parts drift onto the clamp); it lies outside the
/// mode's reach, is left out of the map and counted in [`StepMap::dead_starts`].
pub fn sampled_map(body: &Body, mode: &Mode, plate: &PlateModel, n: usize, period: f64) -> StepMap {
    let field = FieldModel::new(mode, plate);
    let t0 = body.radius / (mode.speed_mm_s * field.max_gain());
    let p = SimParams { speed: mode.speed_mm_s, t_limit: 5000.0 * t0, run_to_limit: false };
    // 0.3 of a step off 0° (so also off 45°, 90°, ... for n = 36, 90, 360): a start point on
    // the node (the plate centre often is) would
    // otherwise sample the symmetric unstable rests (0°, 90°, ...) exactly and report them as
    // rests.
    let thetas: Vec<f64> = (0..n).map(|i| (i as f64 + 0.3) * 360.0 / n as f64).collect();
    let mut reps: Vec<(f64, f64, usize)> = Vec::new(); // (first, sum of offsets, count)
    let mut labels: Vec<Vec<Option<usize>>> = Vec::new();
    let on_edge = |q: Pose| on_plate_edge(body, plate, q);
    let mut dead_starts = 0;
    for start in map_starts(body, mode, plate) {
        // In parallel, collected in order (the map does not depend on the thread count).
        let runs: Vec<sim::Run> = thetas
            .par_iter()
            .map(|&th| {
                sim::run(body, &field, p, Pose { x: start[0], y: start[1], theta: th.to_radians() })
            })
            .collect();
        if matches!(mode.node, Node::Grid(_)) && runs.iter().any(|r| on_edge(r.pose)) {
            dead_starts += 1;
            continue;
        }
        let mut label = Vec::with_capacity(n);
        for r in &runs {
            if !r.rested {
                label.push(None);
                continue;
            }
            let fc = r.pose.theta.to_degrees().rem_euclid(period);
            match reps.iter().position(|r| cdist(r.0 + r.1 / r.2 as f64, fc, period) < 2.0) {
                Some(k) => {
                    let r = &mut reps[k];
                    let mut d = fc - r.0;
                    if d > period / 2.0 {
                        d -= period;
                    } else if d < -period / 2.0 {
                        d += period;
                    }
                    r.1 += d;
                    r.2 += 1;
                    label.push(Some(k));
                }
                None => {
                    reps.push((fc, 0.0, 1));
                    label.push(Some(reps.len() - 1));
                }
            }
        }
        labels.push(label);
    }
    let rep: Vec<f64> = reps.iter().map(|r| (r.0 + r.1 / r.2 as f64).rem_euclid(period)).collect();
    let combined: Vec<Option<usize>> = (0..n)
        .map(|i| {
            let l = labels.first()?[i];
            labels.iter().all(|ls| ls[i] == l).then_some(l)?
        })
        .collect();
    let mut boundaries = Vec::new();
    for i in 0..n {
        let j = (i + 1) % n;
        if combined[i].is_none() || combined[i] != combined[j] {
            boundaries.push((thetas[i] + 180.0 / n as f64).rem_euclid(360.0));
        }
    }
    let sampled =
        thetas.iter().zip(&combined).map(|(&th, l)| (th, l.map_or(f64::NAN, |l| rep[l]))).collect();
    StepMap {
        stable: rep,
        boundaries,
        neutral: false,
        sampled: Some(sampled),
        slack: 180.0 / n as f64,
        dead_starts,
    }
}

/// Does a part that ended at `q` sit on the plate's edge (centroid within its radius of
/// it) rather than on an interior node?
pub(crate) fn on_plate_edge(body: &Body, plate: &PlateModel, q: Pose) -> bool {
    let [w, h] = plate.size_mm;
    let edge = body.radius;
    q.x < edge || q.y < edge || q.x > w - edge || q.y > h - edge
}

/// One planned step.
#[derive(Debug, Clone)]
pub struct PlannedStep {
    /// Mode index into the plate model.
    pub mode: usize,
    /// Orientations before the step (deg, mod period); empty = all.
    pub before: Vec<f64>,
    /// Orientations after it.
    pub after: Vec<f64>,
    /// Step duration (ms), ramp included.
    pub duration_ms: u32,
    /// What the settle simulation measured (all zero without `PlanOptions::durations`).
    pub settle: Settle,
}

/// A synthesised plan.
#[derive(Debug, Clone)]
pub struct Synthesis {
    /// Steps.
    pub steps: Vec<PlannedStep>,
    /// Final orientation (deg, in [0, period)).
    pub final_orientation_deg: f64,
    /// Period (deg).
    pub period_deg: f64,
    /// Final centroid position when fixed.
    pub final_position_mm: Option<[f64; 2]>,
    /// Feed-region plans: what their confirmation measured.
    pub feed: Option<feed::FeedCheck>,
}

/// Why no plan was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanFailure {
    /// Exhaustive search ended without a single orientation.
    #[error("no plan with these modes: {0}")]
    NoPlan(String),
    /// A mode cannot be analysed for this part.
    #[error("{0}")]
    Model(String),
}

/// The image of a set of orientation ids under mode `k` (sorted, deduplicated); `None` when
/// some orientation has no allowed transition.
fn set_image(set: &[usize], trans: &[Vec<Option<usize>>], k: usize) -> Option<Vec<usize>> {
    let mut img = set.iter().map(|&u| trans[u][k]).collect::<Option<Vec<usize>>>()?;
    img.sort_unstable();
    img.dedup();
    Some(img)
}

/// The steps from a start set to search node `g`: (mode, orientations after it).
fn path_to(
    nodes: &[(Vec<usize>, usize, usize)],
    uni: &[f64],
    mut g: usize,
) -> Vec<(usize, Vec<f64>)> {
    let mut path = Vec::new();
    loop {
        let (set, parent, k) = &nodes[g];
        path.push((*k, set.iter().map(|&u| uni[u]).collect()));
        if *parent == usize::MAX {
            break;
        }
        g = *parent;
    }
    path.reverse();
    path
}

/// Most vertices (all rings) a part may have for planning and simulation: the planner's cost
/// grows with the vertex count (the step maps analyse the whole outline hundreds of times).
/// Measured with `chladni plan` on the example triangle with N vertices along its edges (release
/// build, four-lines plate: 1000 → 1.0 s, 3000 → 2.6 s, 6000 → 4.5 s, 12000 → 7.2 s); see
/// docs/plan.md.
pub const MAX_PLAN_VERTICES: usize = 6_000;

/// A part and plate the planner refuses before any work (bad input, exit code 2).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanInputError {
    /// Too many vertices for a plan in reasonable time.
    #[error(
        "part {name}: {count} vertices, more than the planner's limit of {MAX_PLAN_VERTICES} \
         (planning time grows with the vertex count): simplify the outline"
    )]
    TooManyVertices {
        /// Part name.
        name: String,
        /// Its vertex count.
        count: usize,
    },
    /// The part cannot lie on the plate in any orientation.
    #[error(
        "part {name} is {width_mm:.1} mm wide at its narrowest, wider than the {w}×{h} mm plate \
         ({side} mm side): it cannot lie on the plate in any orientation; check that the part is \
         in mm and the plate's size_mm"
    )]
    TooLarge {
        /// Part name.
        name: String,
        /// Its smallest width over all directions (mm).
        width_mm: f64,
        /// Plate width (mm).
        w: f64,
        /// Plate height (mm).
        h: f64,
        /// The plate's shorter side (mm).
        side: f64,
    },
}

/// Checks a part against the planner's limits and the plate's size, before any work.
pub fn check_input(part: &Part, plate: &PlateModel) -> Result<(), PlanInputError> {
    let count = part.vertex_count();
    if count > MAX_PLAN_VERTICES {
        return Err(PlanInputError::TooManyVertices { name: part.name.clone(), count });
    }
    let [w, h] = plate.size_mm;
    let side = w.min(h);
    let width_mm = min_width(&part.outline);
    if width_mm > side {
        return Err(PlanInputError::TooLarge { name: part.name.clone(), width_mm, w, h, side });
    }
    Ok(())
}

/// The smallest width of a ring over 360 directions (0.5° apart; at most 0.004 % above the
/// true minimum, which only matters for a part that fits the plate within that margin).
fn min_width(ring: &[[f64; 2]]) -> f64 {
    (0..360)
        .map(|k| {
            let (s, c) = (k as f64 * 0.5).to_radians().sin_cos();
            let (lo, hi) = ring.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                let d = c * p[0] + s * p[1];
                (lo.min(d), hi.max(d))
            });
            hi - lo
        })
        .fold(f64::INFINITY, f64::min)
}

/// The plan name for a part name: at most [`MAX_NAME`] bytes (the controller stores no more),
/// cut at a character boundary, and a warning naming the cut when there was one.
pub fn plan_name(name: &str) -> (String, Option<String>) {
    if name.len() <= MAX_NAME {
        return (name.to_string(), None);
    }
    let mut end = MAX_NAME;
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    let cut = name[..end].to_string();
    let warning = format!(
        "the part's name is {} bytes; a plan name holds at most {MAX_NAME} (the controller's \
         limit), so the plan is named \"{cut}\" (rename the part to choose)",
        name.len()
    );
    (cut, Some(warning))
}

/// The period P = 360°/m orientations are taken modulo: m = the part's rotational symmetry
/// order, doubled (lcm with 2) when every mode is a straight node with equal gains.
pub fn plan_period(part: &Part, plate: &PlateModel) -> f64 {
    let m_part = symmetry_order(part);
    let all_sym = plate.modes.iter().all(Mode::is_symmetric_line);
    let m = if all_sym { m_part * 2 / gcd(m_part, 2) } else { m_part };
    360.0 / m as f64
}

/// Everything the search needs, computed once per part and plate.
#[derive(Debug, Clone)]
pub struct Problem {
    /// One map per mode.
    pub maps: Vec<StepMap>,
    /// Period (deg).
    pub period: f64,
}

impl Problem {
    /// Builds the maps of every mode.
    pub fn new(part: &Part, plate: &PlateModel, opt: &PlanOptions) -> Result<Problem, PlanFailure> {
        let period = plan_period(part, plate);
        let body = Body::with_samples(part, 160);
        let maps = plate
            .modes
            .iter()
            .map(|mode| match mode.node {
                Node::Line { .. } => line_map(part, mode, opt.backend).map_err(PlanFailure::Model),
                _ => Ok(sampled_map(&body, mode, plate, opt.sim_starts, period)),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Problem { maps, period })
    }

    /// Breadth-first search; returns mode indices and the predicted sets.
    pub fn search(&self, opt: &PlanOptions) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        self.search_without(opt, &[])
    }

    /// [`Self::search`] with some transitions (orientation, mode) ruled out.
    pub fn search_without(
        &self,
        opt: &PlanOptions,
        forbidden: &[(f64, usize)],
    ) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        let p = self.period;
        let mut uni: Vec<f64> = Vec::new();
        let id = |uni: &mut Vec<f64>, v: f64| -> usize {
            let v = v.rem_euclid(p);
            if let Some(i) = uni.iter().position(|&u| cdist(u, v, p) < 1e-3) {
                i
            } else {
                uni.push(v);
                uni.len() - 1
            }
        };
        let nm = self.maps.len();
        // trans[u][mode]
        let mut trans: Vec<Vec<Option<usize>>> = Vec::new();
        let mut starts: Vec<(usize, Vec<usize>)> = Vec::new();
        for (k, map) in self.maps.iter().enumerate() {
            if map.neutral || map.stable.is_empty() {
                continue;
            }
            let mut set: Vec<usize> = map.stable.iter().map(|&s| id(&mut uni, s)).collect();
            set.sort_unstable();
            set.dedup();
            starts.push((k, set));
        }
        let close = |uni: &mut Vec<f64>, trans: &mut Vec<Vec<Option<usize>>>| {
            while trans.len() < uni.len() {
                let u = uni[trans.len()];
                let row = (0..nm)
                    .map(|k| {
                        if forbidden.iter().any(|&(f, fk)| fk == k && cdist(f, u, p) < 1e-3) {
                            return None;
                        }
                        self.maps[k].apply(u, opt.margin_deg).ok().map(|v| id(uni, v))
                    })
                    .collect();
                trans.push(row);
            }
        };
        close(&mut uni, &mut trans);
        // BFS over sets.
        let mut nodes: Vec<(Vec<usize>, usize, usize)> = Vec::new(); // (set, parent, mode)
        let mut seen: HashMap<Vec<usize>, usize> = HashMap::new();
        let mut queue = VecDeque::new();
        for (k, set) in starts {
            if !seen.contains_key(&set) {
                seen.insert(set.clone(), nodes.len());
                queue.push_back(nodes.len());
                nodes.push((set, usize::MAX, k));
            }
        }
        let mut goal = None;
        while let Some(i) = queue.pop_front() {
            if nodes[i].0.len() == 1 {
                goal = Some(i);
                break;
            }
            if nodes.len() > opt.max_states {
                break;
            }
            for k in 0..nm {
                let Some(img) = set_image(&nodes[i].0, &trans, k) else {
                    continue;
                };
                if !seen.contains_key(&img) {
                    seen.insert(img.clone(), nodes.len());
                    queue.push_back(nodes.len());
                    nodes.push((img, i, k));
                }
            }
            close(&mut uni, &mut trans);
        }
        let Some(g) = goal else {
            return Err(PlanFailure::NoPlan(self.explain(&nodes, &uni, opt)));
        };
        Ok(path_to(&nodes, &uni, g))
    }

    fn explain(
        &self,
        nodes: &[(Vec<usize>, usize, usize)],
        uni: &[f64],
        opt: &PlanOptions,
    ) -> String {
        let p = self.period;
        let Some(best) = nodes.iter().min_by_key(|n| n.0.len()) else {
            return "every mode leaves the part free to turn (neutral) or has no stable orientation".into();
        };
        let set: Vec<f64> = best.0.iter().map(|&u| uni[u]).collect();
        let list = set.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
        let mut why = Vec::new();
        for (k, map) in self.maps.iter().enumerate() {
            if map.neutral {
                why.push(format!("mode {} is neutral (keeps every orientation)", k + 1));
                continue;
            }
            let blocked =
                set.iter().find_map(|&t| map.apply(t, opt.margin_deg).err().map(|d| (t, d)));
            match blocked {
                Some((t, d)) => why.push(format!(
                    "mode {} would put {t:.2}° only {d:.2}° from a basin boundary (margin {}°)",
                    k + 1,
                    opt.margin_deg
                )),
                None => {
                    let mut img: Vec<f64> = set
                        .iter()
                        .filter_map(|&t| map.apply(t, opt.margin_deg).ok())
                        .map(|v| v.rem_euclid(p))
                        .collect();
                    img.sort_by(f64::total_cmp);
                    img.dedup_by(|a, b| cdist(*a, *b, p) < 1e-3);
                    why.push(format!(
                        "mode {} keeps them apart ({})",
                        k + 1,
                        img.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ")
                    ));
                }
            }
        }
        format!(
            "orientations {list} (mod {p}°) stay apart after every sequence ({} sets searched): {}",
            nodes.len(),
            why.join("; ")
        )
    }
}

/// Inset plate corners (by the part radius) farthest from a straight node on each side, or
/// the corners, edge midpoints and centre for curved and grid nodes.
fn start_points(body: &Body, mode: &Mode, plate: &PlateModel) -> Vec<[f64; 2]> {
    let [w, h] = plate.size_mm;
    let r = body.radius.min(w / 2.0).min(h / 2.0);
    let corners = [[r, r], [w - r, r], [w - r, h - r], [r, h - r]];
    match FieldModel::new(mode, plate) {
        FieldModel::Line { xhat, c, .. } => {
            let xi = |p: &[f64; 2]| xhat[0] * p[0] + xhat[1] * p[1] - c;
            let lo = corners.iter().min_by(|a, b| xi(a).total_cmp(&xi(b))).copied();
            let hi = corners.iter().max_by(|a, b| xi(a).total_cmp(&xi(b))).copied();
            lo.into_iter().chain(hi).collect()
        }
        // Curved and grid nodes: corners, edge midpoints and the centre (the pull, and so
        // the settle time, varies over the plate).
        _ => {
            let mid =
                [[w / 2.0, r], [w - r, h / 2.0], [w / 2.0, h - r], [r, h / 2.0], plate.center()];
            corners.iter().chain(&mid).copied().collect()
        }
    }
}

/// What [`settle_time`] measured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Settle {
    /// The slowest start (s), lingering ones left out.
    pub settle_s: f64,
    /// Starts slower than 10× the median: they linger near an unstable rest (metastable;
    /// their time is unbounded in the model).
    pub lingering: usize,
    /// Start points simulated.
    pub points: usize,
    /// Grid modes: start points from which the part ended on the plate edge instead of a
    /// node (outside the mode's reach, e.g. at a cantilever's clamp; left out of the settle
    /// time).
    pub ends_on_edge: Vec<[f64; 2]>,
}

/// Simulated settle time of a step from the given orientations (deg), from the start points
/// of [`start_points`]: the slowest start, except lingering ones and those that end on the
/// plate edge (see [`Settle`]).
pub fn settle_time(body: &Body, mode: &Mode, plate: &PlateModel, orientations: &[f64]) -> Settle {
    let field = FieldModel::new(mode, plate);
    let p = SimParams { speed: mode.speed_mm_s, t_limit: 3600.0, run_to_limit: false };
    let mut times = Vec::new();
    let points = start_points(body, mode, plate);
    let mut ends_on_edge = Vec::new();
    for &pt in &points {
        let runs: Vec<sim::Run> = orientations
            .par_iter()
            .map(|&th| {
                sim::run(body, &field, p, Pose { x: pt[0], y: pt[1], theta: th.to_radians() })
            })
            .collect();
        // Grid modes: a corner outside the mode's reach (see [`sampled_map`]) never reaches a
        // node; its drift onto the clamp is no settle time.
        if matches!(mode.node, Node::Grid(_))
            && runs.iter().any(|r| on_plate_edge(body, plate, r.pose))
        {
            ends_on_edge.push(pt);
            continue;
        }
        times.extend(runs.iter().map(|r| r.settle_s));
    }
    let (settle_s, lingering) = slowest_settled(times);
    Settle { settle_s, lingering, points: points.len(), ends_on_edge }
}

/// The slowest of some settle times (s) and how many were left out as lingering (slower than
/// 10× the median: near an unstable rest, where the model's time is unbounded).
pub(crate) fn slowest_settled(mut times: Vec<f64>) -> (f64, usize) {
    times.sort_by(f64::total_cmp);
    let median = times.get(times.len() / 2).copied().unwrap_or(0.0);
    let kept = times.iter().filter(|&&t| t <= 10.0 * median.max(1e-3)).count();
    (times[..kept].last().copied().unwrap_or(0.0), times.len() - kept)
}

/// A step's duration (ms): settle time × safety, rounded up to 10 ms, plus the ramp; at
/// least 100 ms.
pub(crate) fn step_duration_ms(settle_s: f64, safety: f64, ramp_ms: u32) -> u32 {
    let ms = (settle_s * safety * 1000.0 / 10.0).ceil() as u32 * 10;
    (ms + ramp_ms).max(100)
}

/// Does the simulation take orientation `u` to `v` (mod `period`, within 1°) under a straight
/// node, approaching from either side, from beyond the part's radius and from half-way across?
pub fn confirm(body: &Body, mode: &Mode, plate: &PlateModel, u: f64, v: f64, period: f64) -> bool {
    let field = FieldModel::new(mode, plate);
    let FieldModel::Line { xhat, c, .. } = field else { return true };
    let ctr = plate.center();
    let xi0 = xhat[0] * ctr[0] + xhat[1] * ctr[1] - c;
    let base = [ctr[0] - xi0 * xhat[0], ctr[1] - xi0 * xhat[1]];
    let p = SimParams { speed: mode.speed_mm_s, t_limit: 3600.0, run_to_limit: false };
    let r = body.radius;
    [-(r + 5.0), -0.5 * r, 0.5 * r, r + 5.0].iter().all(|&xi| {
        let start =
            Pose { x: base[0] + xi * xhat[0], y: base[1] + xi * xhat[1], theta: u.to_radians() };
        let end = sim::run(body, &field, p, start).pose.theta.to_degrees();
        cdist(end, v, period) < 1.0
    })
}

/// Plans: maps, search, durations, position; with a feed region, by tracking poses from it
/// ([`feed::plan`], no progress shown).
pub fn plan(part: &Part, plate: &PlateModel, opt: &PlanOptions) -> Result<Synthesis, PlanFailure> {
    if let Some(region) = &opt.feed {
        return feed::plan(part, plate, opt, region, &indicatif::ProgressBar::hidden());
    }
    let problem = Problem::new(part, plate, opt)?;
    plan_with(part, plate, opt, &problem)
}

/// [`plan`] with the maps already built.
pub fn plan_with(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    problem: &Problem,
) -> Result<Synthesis, PlanFailure> {
    let body = Body::with_samples(part, 160);
    // Search, then check every straight-node transition of the plan dynamically (approaching
    // the node from either side, from afar and from half-way across); a transition the
    // simulation does not confirm is ruled out and the search repeated.
    let mut forbidden: Vec<(f64, usize)> = Vec::new();
    let path = loop {
        let path = problem.search_without(opt, &forbidden)?;
        let mut bad = Vec::new();
        for w in path.windows(2) {
            let (k, mode) = (w[1].0, &plate.modes[w[1].0]);
            if !matches!(mode.node, Node::Line { .. }) {
                continue;
            }
            for &u in &w[0].1 {
                let Ok(v) = problem.maps[k].apply(u, opt.margin_deg) else { continue };
                if !confirm(&body, mode, plate, u, v, problem.period) {
                    bad.push((u, k));
                }
            }
        }
        if bad.is_empty() || forbidden.len() > 200 {
            break path;
        }
        forbidden.extend(bad);
    };
    let mut steps = Vec::new();
    let mut before: Vec<f64> = Vec::new();
    for (k, after) in &path {
        let mode = &plate.modes[*k];
        let settle = if opt.durations {
            let starts: Vec<f64> = if before.is_empty() {
                let map = &problem.maps[*k];
                (0..24)
                    .map(|i| i as f64 * 15.0)
                    .filter(|&t| map.apply(t, opt.margin_deg).is_ok())
                    .collect()
            } else {
                before.clone()
            };
            settle_time(&body, mode, plate, &starts)
        } else {
            Settle::default()
        };
        let duration_ms = if opt.durations {
            step_duration_ms(settle.settle_s, opt.safety, mode.ramp_ms)
        } else {
            1000
        };
        steps.push(PlannedStep {
            mode: *k,
            before: before.clone(),
            after: after.clone(),
            duration_ms,
            settle,
        });
        before = after.clone();
    }
    let final_orientation_deg = path.last().map_or(0.0, |p| p.1[0]).rem_euclid(problem.period);
    let final_position_mm = final_position(part, plate, &steps, final_orientation_deg);
    Ok(Synthesis {
        steps,
        final_orientation_deg,
        period_deg: problem.period,
        final_position_mm,
        feed: None,
    })
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
fn balance_offset(part: &Part, mode: &Mode, theta_deg: f64) -> f64 {
    let Node::Line { angle_deg, .. } = mode.node else { return 0.0 };
    reference_for(part, mode).balance(theta_deg - angle_deg + 90.0).0
}

fn final_position(
    part: &Part,
    plate: &PlateModel,
    steps: &[PlannedStep],
    theta: f64,
) -> Option<[f64; 2]> {
    let n = steps.len();
    if n < 2 {
        return None;
    }
    let (a, b) = (&plate.modes[steps[n - 2].mode], &plate.modes[steps[n - 1].mode]);
    let (Node::Line { angle_deg: aa, offset_mm: oa }, Node::Line { angle_deg: ab, offset_mm: ob }) =
        (&a.node, &b.node)
    else {
        return None;
    };
    if ((aa - ab).to_radians().cos()).abs() > (0.5f64).to_radians().sin() {
        return None;
    }
    let offs: Vec<f64> = steps[n - 2].after.iter().map(|&t| balance_offset(part, a, t)).collect();
    if offs.iter().any(|o| (o - offs[0]).abs() > 0.5) {
        return None;
    }
    let sb = balance_offset(part, b, theta);
    // n̂·(p − c) = offset − s for each line.
    let c = plate.center();
    let na = [-aa.to_radians().sin(), aa.to_radians().cos()];
    let nb = [-ab.to_radians().sin(), ab.to_radians().cos()];
    let (ra, rb) = (oa - offs[0], ob - sb);
    let det = na[0] * nb[1] - na[1] * nb[0];
    let x = (ra * nb[1] - rb * na[1]) / det;
    let y = (na[0] * rb - nb[0] * ra) / det;
    Some([((c[0] + x) * 1000.0).round() / 1000.0, ((c[1] + y) * 1000.0).round() / 1000.0])
}

impl Synthesis {
    /// The steps as the simulator runs them (each at its mode's own amplitude).
    pub fn sim_steps(&self) -> Vec<sim::SimStep> {
        self.steps.iter().map(|s| sim::SimStep::new(s.mode, s.duration_ms, 1.0)).collect()
    }

    /// The plan file (device steps plus predictions).
    pub fn to_file(&self, plate: &PlateModel, name: &str) -> PlanFile {
        let (name, _) = plan_name(name);
        PlanFile {
            name,
            repeat: 1,
            steps: self
                .steps
                .iter()
                .map(|s| {
                    let m = &plate.modes[s.mode];
                    StepJson::open_loop(
                        m.freq_hz,
                        s.duration_ms,
                        m.amplitude,
                        m.ramp_ms.min(s.duration_ms),
                    )
                })
                .collect(),
            final_orientation_deg: Some((self.final_orientation_deg * 1e4).round() / 1e4),
            period_deg: Some(self.period_deg),
            final_position_mm: self.final_position_mm,
        }
    }
}
