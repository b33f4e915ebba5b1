//! Sensorless plan synthesis (docs/plan.md, paper §6): the shortest sequence of modes that
//! brings every start orientation to one final orientation.
//!
//! 1. **Step maps.** Each mode gives a map θ ↦ θ' (plate frame) with its basin boundaries:
//!    - straight node of direction α, static ([`MapKind::Static`]): the shared fixed-point analysis in the node frame,
//!      θ' = α − 90° + a(θ − α + 90°); boundaries = unstable rests (the f64 reference can be
//!      used instead, [`Backend::F64`], to check agreement);
//!    - straight nodes, by default ([`MapKind::Dynamic`], [`dynamic`]): measured by
//!      simulating the approach to the node from both sides for 72 start orientations; an
//!      orientation whose outcome depends on the side is mapped to every rest it reaches;
//!    - hyperbola and grid nodes: quasi-static simulation ([`crate::motion::sim`]) from `sim_starts`
//!      start orientations at one start point (hyperbola: its vertex; grid: the plate centre);
//!      final orientations are clustered (2°) into rests, boundaries lie between neighbouring
//!      starts that end in different rests.
//! 2. **Equivalence.** Orientations are taken modulo the period P = 360°/m, m = the part's
//!    rotational symmetry order, doubled (lcm with 2) when every mode is a straight node with
//!    equal gains (t(θ + 180°) = t(θ)).
//! 3. **Search** ([`search`]). After the first step only the stable rests remain; the search
//!    runs over sets of those (sorted index sets; for several parts, one set per part) and
//!    finds the shortest sequence ending in a single orientation (per part), or, with a goal
//!    ([`PlanOptions::goal_deg`], `fix_position`, `goal_pos_mm`, `minimize`), the best plan
//!    of at most one step more that meets it ([`goal`]). A step is only allowed if no
//!    orientation of the current set lies within `margin_deg` of one of that step's basin
//!    boundaries (the first step acts on all orientations and has no such constraint).
//! 4. **Durations.** Each step is simulated from its predicted start orientations (every 15°
//!    for the first step) and from the plate corners farthest from the node; duration = the
//!    slowest settle time × `safety`, plus the ramp, rounded up to 10 ms.
//! 5. **Position** ([`position`]). A straight node moves the centroid across itself only: the
//!    places it can be are projected onto each node line in turn; the position is fixed when
//!    they shrink to a point (perpendicular last two nodes).
//!
//! With a feed region ([`PlanOptions::feed`]) planning tracks poses instead ([`feed`]): on
//! plates with several curved node lines the rest depends on the start position, which the
//! orientation-set search can only treat as ambiguity.

use rayon::prelude::*;

use chladni_shared::analysis::field::Field;
use chladni_shared::analysis::fx::Fx;
use chladni_shared::analysis::geometry::Pt;
use chladni_shared::analysis::rest::Analyzer;
use chladni_shared::icd::plan::MAX_NAME;
use chladni_shared::icd::units::deg_from_bam;

use crate::analysis::reference::{RefField, Reference};
use crate::model::part::Part;
use crate::model::plan_file::{PartPrediction, PlanFile, StepJson};
use crate::model::plate::{Mode, Node, PlateModel};
use crate::motion::sim::{self, Body, FieldModel, Pose, Rim, SimParams};

pub mod dynamic;
pub mod feed;
pub mod goal;
pub mod position;
pub mod search;

pub use goal::{PartPlan, plan_parts, plan_parts_with};
pub use search::Minimize;

pub use dynamic::{DynSettings, MapCache, MapKind};

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
    /// Straight-node maps: measured by simulating the approach from both sides
    /// ([`MapKind::Dynamic`], default) or the static alignment function ([`MapKind::Static`]).
    pub maps: MapKind,
    /// Settings of dynamic maps.
    pub dyn_maps: DynSettings,
    /// What the chosen plan is shortest in.
    pub minimize: Minimize,
    /// Plans may have this many steps more than the shortest when that meets the goal.
    pub extra_steps: usize,
    /// Goal orientation of the (first) part (deg, modulo its period).
    pub goal_deg: Option<f64>,
    /// Only plans that fix the final position.
    pub fix_position: bool,
    /// Among plans that fix the position, the one ending nearest to this (mm).
    pub goal_pos_mm: Option<[f64; 2]>,
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
            maps: MapKind::default(),
            dyn_maps: DynSettings::default(),
            minimize: Minimize::Steps,
            extra_steps: 1,
            goal_deg: None,
            fix_position: false,
            goal_pos_mm: None,
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
    /// Dynamic straight-node maps ([`dynamic`]): the measured outcome of every start
    /// orientation from either side of the node; `None` for every other map.
    dynamic: Option<std::sync::Arc<dynamic::DynamicImages>>,
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
            dynamic: None,
        }
    }
}

/// Circular distance on a circle of circumference `p`.
pub fn cdist(a: f64, b: f64, p: f64) -> f64 {
    let d = (a - b).rem_euclid(p);
    d.min(p - d)
}

impl StepMap {
    /// Every orientation `theta` (deg) may reach: one for static and simulated maps, all
    /// the rests a dynamic map measured when the outcome depends on the side the part
    /// approaches from; `Err(distance)` when `theta` lies within `margin` of a basin boundary
    /// (distance 0: a simulated run from it did not come to rest).
    pub fn apply_all(&self, theta: f64, margin: f64) -> Result<Vec<f64>, f64> {
        match &self.dynamic {
            Some(d) if !self.neutral => {
                self.near_boundary(theta, margin)?;
                d.images(theta).ok_or(0.0)
            }
            _ => self.apply(theta, margin).map(|v| vec![v]),
        }
    }

    /// `Err(distance)` when `theta` lies within `margin` (plus the map's slack) of a basin
    /// boundary.
    fn near_boundary(&self, theta: f64, margin: f64) -> Result<(), f64> {
        let near =
            self.boundaries.iter().map(|&b| cdist(theta, b, 360.0)).fold(f64::INFINITY, f64::min);
        if near < margin + self.slack { Err(near) } else { Ok(()) }
    }

    /// The orientation reached from `theta` (deg), or `Err(distance)` when `theta` lies
    /// within `margin` of a basin boundary. A dynamic map's ambiguous orientation (several
    /// images, see [`Self::apply_all`]) gives `Err(0.0)`.
    pub fn apply(&self, theta: f64, margin: f64) -> Result<f64, f64> {
        if self.neutral {
            return Ok(theta.rem_euclid(360.0));
        }
        self.near_boundary(theta, margin)?;
        if self.dynamic.is_some() {
            return match self.apply_all(theta, margin)?.as_slice() {
                [v] => Ok(*v),
                _ => Err(0.0),
            };
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
    body_symmetry_order(&Body::new(part))
}

/// [`symmetry_order`] of a prepared part.
fn body_symmetry_order(body: &Body) -> u32 {
    let n = body.rings[0].len();
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
    Ok(StepMap {
        stable,
        boundaries,
        neutral,
        sampled: None,
        slack: 0.0,
        dead_starts: 0,
        dynamic: None,
    })
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
/// at full pull). A part of rotational symmetry order m (dividing `n`) is simulated from the
/// first n/m start orientations of each point only; the others are those runs turned.
///
/// Grid modes only: a start point from which some run ends with the centroid within half the
/// part's radius of the plate edge reached no interior node (near a clamped edge φ and ∂φ/∂x
/// vanish, the pull falls off like x³ and parts drift onto the clamp); it lies outside the
/// mode's reach, is left out of the map and counted in [`StepMap::dead_starts`].
pub fn sampled_map(body: &Body, mode: &Mode, plate: &PlateModel, n: usize, period: f64) -> StepMap {
    let field = FieldModel::new(mode, plate);
    let t0 = body.radius / (mode.speed_mm_s * field.max_gain());
    let p = SimParams {
        speed: mode.speed_mm_s,
        t_limit: 5000.0 * t0,
        run_to_limit: false,
        rim: Some(Rim::of(plate)),
    };
    // 0.3 of a step off 0° (so also off 45°, 90°, ... for n = 36, 90, 360): a start point on
    // the node (the plate centre often is) would
    // otherwise sample the symmetric unstable rests (0°, 90°, ...) exactly and report them as
    // rests.
    let thetas: Vec<f64> = (0..n).map(|i| (i as f64 + 0.3) * 360.0 / n as f64).collect();
    let mut reps: Vec<(f64, f64, usize)> = Vec::new(); // (first, sum of offsets, count)
    let mut labels: Vec<Vec<Option<usize>>> = Vec::new();
    let on_edge = |q: Pose| on_plate_edge(body, plate, q);
    let mut dead_starts = 0;
    // A part of symmetry order m started at θ + 360°/m is the same body at the same place as
    // at θ: its run is that run turned by 360°/m (to rounding), so only the first n/m start
    // orientations of each point are simulated.
    let m = body_symmetry_order(body) as usize;
    let m = if m > 1 && n.is_multiple_of(m) { m } else { 1 };
    let (distinct, turn) = (n / m, std::f64::consts::TAU / m as f64);
    // Every start point's runs at once, in parallel (no wait for the slowest run of each
    // point), collected in order: the map does not depend on the thread count.
    let poses: Vec<Pose> = map_starts(body, mode, plate)
        .iter()
        .flat_map(|s| {
            thetas[..distinct].iter().map(|th| Pose { x: s[0], y: s[1], theta: th.to_radians() })
        })
        .collect();
    let all: Vec<(Pose, bool)> = poses
        .par_iter()
        .map(|&q| {
            let r = sim::run(body, &field, p, q);
            (r.pose, r.rested)
        })
        .collect();
    for simulated in all.chunks(distinct.max(1)) {
        // (end pose, rested) for each of the n start orientations.
        let runs = (0..n).map(|i| {
            let (q, rested) = simulated[i % distinct];
            (Pose { theta: q.theta + (i / distinct) as f64 * turn, ..q }, rested)
        });
        if matches!(mode.node, Node::Grid(_)) && simulated.iter().any(|r| on_edge(r.0)) {
            dead_starts += 1;
            continue;
        }
        let mut label = Vec::with_capacity(n);
        for (end, rested) in runs {
            if !rested {
                label.push(None);
                continue;
            }
            let fc = end.theta.to_degrees().rem_euclid(period);
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
        dynamic: None,
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
#[derive(Debug, Clone, Default)]
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
    /// The goal orientation asked for (deg).
    pub goal_deg: Option<f64>,
    /// Final orientations that plans of at most `max_steps` steps reach (deg; empty for
    /// feed-region plans).
    pub reachable_deg: Vec<f64>,
    /// The longest plan considered: the shortest plan's steps + [`PlanOptions::extra_steps`].
    pub max_steps: usize,
    /// With `fix_position` / `goal_pos_mm`: the largest distance (mm) of a simulated final
    /// centroid from the predicted position.
    pub position_check_mm: Option<f64>,
    /// Several parts: one prediction per part (empty for a single part).
    pub parts: Vec<PartPlan>,
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
    /// No plan of at most `max_steps` steps ends at the goal orientation.
    #[error(
        "{part}: no plan of at most {max_steps} steps ends at {goal_deg}° (mod {period_deg}°, \
         within {tol_deg}°); reachable final orientations: {}{}",
        list_deg(reachable_deg),
        nearest_deg.map(|n| format!("; nearest {n:.2}°")).unwrap_or_default()
    )]
    GoalUnreachable {
        /// The part whose goal is out of reach.
        part: String,
        /// Its goal (deg).
        goal_deg: f64,
        /// Its period (deg).
        period_deg: f64,
        /// How near a final orientation must be to the goal (deg, the margin).
        tol_deg: f64,
        /// The longest plan considered.
        max_steps: usize,
        /// What is reachable (deg; for several parts, with the other parts at their goals).
        reachable_deg: Vec<f64>,
        /// The reachable orientation nearest to the goal.
        nearest_deg: Option<f64>,
    },
    /// No plan that meets the orientation goals fixes the final position.
    #[error(
        "{part}: no plan of at most {max_steps} steps fixes the final position (to within \
         {tol_mm} mm): a straight node moves the part only across itself, so the last two \
         straight nodes must be perpendicular, or non-parallel ones alternated until the \
         spread along them is below {tol_mm} mm"
    )]
    PositionNotFixed {
        /// The part.
        part: String,
        /// The longest plan considered.
        max_steps: usize,
        /// The position tolerance (mm).
        tol_mm: f64,
    },
    /// The simulation does not confirm the predicted final position.
    #[error(
        "{part}: the plan's predicted position ({:.2}, {:.2}) mm is not confirmed: simulated \
         starts end up to {worst_mm:.2} mm from it",
        predicted_mm[0], predicted_mm[1]
    )]
    PositionNotConfirmed {
        /// The part.
        part: String,
        /// The predicted position (mm).
        predicted_mm: [f64; 2],
        /// The largest simulated distance from it (mm).
        worst_mm: f64,
    },
    /// Several parts: every part has a plan alone, but no sequence brings all of them to one
    /// orientation each.
    #[error(
        "no sequence brings every part to one orientation ({searched} states searched); the \
         closest keeps {}",
        apart.iter().map(|(n, d, p)| format!("{n} at {} (mod {p}°)", list_deg(d))).collect::<Vec<_>>().join(", ")
    )]
    PartsApart {
        /// The parts left with several orientations in the closest state: (name,
        /// orientations in deg, period).
        apart: Vec<(String, Vec<f64>, f64)>,
        /// States searched.
        searched: usize,
    },
}

/// `a°, b°, …` (two decimals).
fn list_deg(v: &[f64]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    v.iter().map(|d| format!("{d:.2}°")).collect::<Vec<_>>().join(", ")
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
                Node::Line { .. } => match opt.maps {
                    MapKind::Static => line_map(part, mode, opt.backend),
                    MapKind::Dynamic => MapCache::global().line_map(
                        part,
                        mode,
                        plate,
                        period,
                        opt.backend,
                        opt.dyn_maps,
                    ),
                }
                .map_err(PlanFailure::Model),
                _ => Ok(sampled_map(&body, mode, plate, opt.sim_starts, period)),
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Problem { maps, period })
    }

    /// Breadth-first search; returns mode indices and the predicted sets.
    pub fn search(&self, opt: &PlanOptions) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        self.search_without(opt, &[])
    }

    /// [`Self::search`] with some transitions (orientation, mode) ruled out: the shortest
    /// plan, the first found breadth-first ([`search`]).
    pub fn search_without(
        &self,
        opt: &PlanOptions,
        forbidden: &[(f64, usize)],
    ) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        let one = PlanOptions { minimize: Minimize::Steps, extra_steps: 0, ..*opt };
        let s = search::Search::new(&[self], &one, &[forbidden.to_vec()]);
        let reach = s.reach();
        let Some(steps) = reach.shortest else {
            let nodes: Vec<(Vec<usize>, usize, usize)> =
                reach.nodes.iter().map(|n| (n.0[0].clone(), n.1, n.2)).collect();
            return Err(PlanFailure::NoPlan(self.explain(&nodes, &s.unis[0].vals, opt)));
        };
        let path = s
            .select(&search::Target::default(), steps, &mut |_, _| 1, &mut |_| Vec::new())
            .ok_or_else(|| PlanFailure::NoPlan("the search found no plan twice".into()))?;
        Ok(path.into_iter().map(|(k, mut a)| (k, a.swap_remove(0))).collect())
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
                set.iter().find_map(|&t| map.apply_all(t, opt.margin_deg).err().map(|d| (t, d)));
            match blocked {
                Some((t, _)) if map.near_boundary(t, opt.margin_deg).is_ok() => why.push(format!(
                    "mode {}: a simulated approach from {t:.2}° does not come to rest",
                    k + 1
                )),
                Some((t, d)) => why.push(format!(
                    "mode {} would put {t:.2}° only {d:.2}° from a basin boundary (margin {}°)",
                    k + 1,
                    opt.margin_deg
                )),
                None => why.push(keeps_apart(k, map, &set, opt.margin_deg, p)),
            }
        }
        format!(
            "orientations {list} (mod {p}°) stay apart after every sequence ({} sets searched): {}",
            nodes.len(),
            why.join("; ")
        )
    }
}

/// Why mode `k` leaves the orientations `set` apart: their images, and which orientation a
/// dynamic map sends to several rests depending on the side the part approaches from.
fn keeps_apart(k: usize, map: &StepMap, set: &[f64], margin: f64, p: f64) -> String {
    let images: Vec<(f64, Vec<f64>)> =
        set.iter().filter_map(|&t| Some((t, map.apply_all(t, margin).ok()?))).collect();
    let mut img: Vec<f64> = images.iter().flat_map(|(_, v)| v).map(|v| v.rem_euclid(p)).collect();
    img.sort_by(f64::total_cmp);
    img.dedup_by(|a, b| cdist(*a, *b, p) < 1e-3);
    let fmt = |v: &[f64]| v.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
    let mut msg = format!("mode {} keeps them apart ({})", k + 1, fmt(&img));
    if let Some((t, v)) = images.iter().find(|(_, v)| v.len() > 1) {
        msg += &format!(
            ", sending {t:.2}° to {} depending on the side it approaches the node from",
            fmt(v).replacen(", ", " or ", 1)
        );
    }
    msg
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
    /// Starts set apart by a gap in the settle times ([`slowest_settled`]): they linger near
    /// an unstable rest (metastable; their time is unbounded in the model).
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
    let p = SimParams {
        speed: mode.speed_mm_s,
        t_limit: 3600.0,
        run_to_limit: false,
        rim: Some(Rim::of(plate)),
    };
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

/// Ratio between consecutive sorted settle times, above the median, beyond which the slower
/// starts count as lingering (see [`slowest_settled`]).
pub const LINGER_GAP: f64 = 3.0;

/// The slowest of some settle times (s) and how many were left out as lingering: those above
/// the first gap of more than [`LINGER_GAP`]× between consecutive sorted times above the
/// median. A part near an unstable rest leaves it after a time that grows without bound as
/// it starts closer (metastable), so such starts stand apart from the rest; parts creeping
/// along a node settle over a continuum of times with no such gap and all count. A fixed
/// threshold (formerly 10× the median) fell inside such a continuum, and integration error
/// then decided which creeping runs counted; a gap of 3× is far wider than that error.
pub(crate) fn slowest_settled(mut times: Vec<f64>) -> (f64, usize) {
    times.sort_by(f64::total_cmp);
    let mid = times.len() / 2;
    let kept = (mid..times.len())
        .find(|&i| times.get(i + 1).is_some_and(|&next| next > LINGER_GAP * times[i].max(1e-3)))
        .map_or(times.len(), |i| i + 1);
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
    confirm_any(body, mode, plate, u, &[v], period)
}

/// [`confirm`] for several possible images: every approach must end within 1° of one of them.
pub fn confirm_any(
    body: &Body,
    mode: &Mode,
    plate: &PlateModel,
    u: f64,
    images: &[f64],
    period: f64,
) -> bool {
    let field = FieldModel::new(mode, plate);
    let FieldModel::Line { xhat, c, .. } = field else { return true };
    let ctr = plate.center();
    let xi0 = xhat[0] * ctr[0] + xhat[1] * ctr[1] - c;
    let base = [ctr[0] - xi0 * xhat[0], ctr[1] - xi0 * xhat[1]];
    let p = SimParams {
        speed: mode.speed_mm_s,
        t_limit: 3600.0,
        run_to_limit: false,
        rim: Some(Rim::of(plate)),
    };
    let r = body.radius;
    [-(r + 5.0), -0.5 * r, 0.5 * r, r + 5.0].iter().all(|&xi| {
        let start =
            Pose { x: base[0] + xi * xhat[0], y: base[1] + xi * xhat[1], theta: u.to_radians() };
        let end = sim::run(body, &field, p, start).pose.theta.to_degrees();
        images.iter().any(|&v| cdist(end, v, period) < 1.0)
    })
}

/// Plans: maps, search, durations, position; with a feed region, by tracking poses from it
/// ([`feed::plan`], no progress shown). With [`MapKind::Dynamic`] maps and no plan over them,
/// the static maps (with the dynamic check) are tried before giving up, and the failure
/// reported is the dynamic maps' one.
pub fn plan(part: &Part, plate: &PlateModel, opt: &PlanOptions) -> Result<Synthesis, PlanFailure> {
    if let Some(region) = &opt.feed {
        return feed::plan(part, plate, opt, region, &indicatif::ProgressBar::hidden());
    }
    let problem = Problem::new(part, plate, opt)?;
    let plan = plan_with(part, plate, opt, &problem);
    // Dynamic maps hold the margin to every measured boundary, which can rule out a plan
    // the static maps find and the dynamic check confirms at its start points (the boundary
    // moves with the approach, sometimes to within the margin): then that plan is taken
    // rather than none, so the default finds every plan the static maps find.
    match plan {
        Err(e) if falls_back(&e, plate, opt) => {
            let st = PlanOptions { maps: MapKind::Static, ..*opt };
            let statics = static_problem(part, plate, opt, &problem)?;
            plan_with(part, plate, &st, &statics).map_err(|_| e)
        }
        other => other,
    }
}

/// Whether a search over dynamic maps that found no plan (none at all, none reaching the goal
/// orientation or fixing the position) is tried again over static maps.
pub(crate) fn falls_back(e: &PlanFailure, plate: &PlateModel, opt: &PlanOptions) -> bool {
    !matches!(e, PlanFailure::Model(_))
        && opt.maps == MapKind::Dynamic
        && plate.modes.iter().any(|m| matches!(m.node, Node::Line { .. }))
}

/// `problem` with its straight-node maps replaced by the static ones (the simulated maps of
/// curved and grid nodes are kept).
pub(crate) fn static_problem(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    problem: &Problem,
) -> Result<Problem, PlanFailure> {
    let maps = plate
        .modes
        .iter()
        .zip(&problem.maps)
        .map(|(mode, map)| match mode.node {
            Node::Line { .. } => line_map(part, mode, opt.backend),
            _ => Ok(map.clone()),
        })
        .collect::<Result<Vec<_>, _>>()
        .map_err(PlanFailure::Model)?;
    Ok(Problem { maps, period: problem.period })
}

/// [`plan`] with the maps already built: the search ([`search`]) for the goal of `opt`, then a
/// dynamic check of the plan's transitions, durations and position ([`goal`]).
pub fn plan_with(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    problem: &Problem,
) -> Result<Synthesis, PlanFailure> {
    plan_parts_with(&[part], plate, opt, &[problem], &[opt.goal_deg])
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

impl Synthesis {
    /// The steps as the simulator runs them (each at its mode's own amplitude).
    pub fn sim_steps(&self) -> Vec<sim::SimStep> {
        self.steps.iter().map(|s| sim::SimStep::new(s.mode, s.duration_ms, 1.0)).collect()
    }

    /// The plan file (device steps plus predictions).
    pub fn to_file(&self, plate: &PlateModel, name: &str) -> PlanFile {
        let (name, _) = plan_name(name);
        let mut file = PlanFile {
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
            final_orientation_deg: Some(r4(self.final_orientation_deg)),
            period_deg: Some(self.period_deg),
            final_position_mm: self.final_position_mm,
            goal_deg: self.goal_deg,
            reachable_deg: (!self.reachable_deg.is_empty())
                .then(|| self.reachable_deg.iter().copied().map(r4).collect()),
            parts: None,
        };
        if !self.parts.is_empty() {
            // Several parts: the predictions are per part; none is "the" final orientation.
            file.final_orientation_deg = None;
            file.period_deg = None;
            file.final_position_mm = None;
            file.goal_deg = None;
            file.reachable_deg = None;
            file.parts = Some(
                self.parts
                    .iter()
                    .map(|p| PartPrediction {
                        name: p.name.clone(),
                        final_orientation_deg: Some(r4(p.final_orientation_deg)),
                        period_deg: Some(p.period_deg),
                        final_position_mm: p.final_position_mm,
                        goal_deg: p.goal_deg,
                        reachable_deg: Some(p.reachable_deg.iter().copied().map(r4).collect()),
                        face: None,
                    })
                    .collect(),
            );
        }
        file
    }
}

/// Rounds to 10⁻⁴ (the plan file's resolution for orientations).
fn r4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

#[cfg(test)]
mod tests {
    use super::slowest_settled;

    #[test]
    fn lingering_starts_are_those_beyond_a_gap() {
        // Most starts settle in 50–90 s; creeping ones over a continuum up to 40× that
        // (consecutive ratios ≤ 1.3): all count, however far above the median.
        let mut times: Vec<f64> = (0..60).map(|i| 50.0 + 0.7 * i as f64).collect();
        let mut t = 100.0;
        while t < 3000.0 {
            times.push(t);
            t *= 1.3;
        }
        let slowest = *times.last().unwrap();
        assert_eq!(slowest_settled(times.clone()), (slowest, 0));
        // Two starts set apart by a gap of more than 3×: left out, whatever their times.
        for far in [3.2 * slowest, 100.0 * slowest] {
            let mut with = times.clone();
            with.extend([far, 1.1 * far]);
            assert_eq!(slowest_settled(with), (slowest, 2), "{far}");
        }
        // A gap below the median is no cut (the fast half may settle at once).
        let mut fast: Vec<f64> = vec![0.0; 10];
        fast.extend((0..11).map(|i| 40.0 + i as f64));
        assert_eq!(slowest_settled(fast), (50.0, 0));
        assert_eq!(slowest_settled(Vec::new()), (0.0, 0));
    }
}
