//! Sensorless plan synthesis (docs/plan.md, paper §6): the shortest sequence of modes that
//! brings every start orientation to one final orientation.
//!
//! 1. **Step maps.** Each mode gives a map θ ↦ θ' (plate frame) with its basin boundaries:
//!    - straight node of direction α, static ([`MapKind::Static`]; by default first,
//!      [`MapKind::Auto`]): the shared fixed-point analysis in the node frame,
//!      θ' = α − 90° + a(θ − α + 90°); boundaries = unstable rests (the f64 reference can be
//!      used instead, [`Backend::F64`], to check agreement);
//!    - straight nodes, [`MapKind::Dynamic`] ([`dynamic`]; by default when the static maps
//!      give no plan): measured by
//!      simulating the approach to the node from both sides for 72 start orientations; an
//!      orientation whose outcome depends on the side is mapped to every rest it reaches;
//!    - hyperbola and grid nodes: quasi-static simulation ([`crate::motion::integrate`]) from
//!      `sim_starts` start orientations at each start point of [`map_starts`] (the hyperbola's
//!      vertex or the plate centre, and the inset corners);
//!      final orientations are clustered (2°) into rests; an orientation whose rest depends on
//!      the start point maps to all of them; boundaries lie between neighbouring starts whose
//!      sets of rests differ;
//!    - a straight node along or beyond an edge ([`rim_line`]): simulated like a curved node,
//!      with the rim (the field pushes the part into the wall, which turns it onto a stable
//!      edge) and starts pushed against the walls.
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
//!
//! Planning stops at [`PlanOptions::deadline`] (`plan --max-time-s`, [`Deadline`]) with a
//! failure naming the stage reached, and the search expands at most
//! [`PlanOptions::max_states`] sets (`--max-states`; a failure says when it stopped there).
//!
//! For bulk feeding (`plan --copies N`) [`copies`] ranks the planner's candidate plans by how
//! many of N copies dropped together each orients per minute.

use crate::model::part::Part;
use crate::model::plate::{Node, PlateModel};
use crate::motion::body::Body;
use crate::motion::body::PLANNER_BODY_SAMPLES;
use crate::progress::Progress;

pub mod capture;
mod cluster;
pub mod collide;
mod confirm;
pub mod copies;
mod deadline;
pub mod dynamic;
pub mod edges;
mod failure;
pub mod feed;
pub mod goal;
mod input;
mod maps;
pub mod margin;
pub mod mode_margin;
mod options;
pub mod position;
mod result;
pub mod search;
mod settle;
mod symmetry;
pub mod whole;

pub(crate) use goal::{PartPlan, plan_parts_with};
pub use goal::{plan_parts, plan_parts_progress};
pub use search::Minimize;

pub use dynamic::{DynSettings, MapCache, MapKind};

pub use confirm::confirm;
pub(crate) use confirm::confirm_any;
pub use deadline::Deadline;
pub use edges::rim_line;
pub use failure::PlanFailure;
pub use input::{MAX_PLAN_VERTICES, check_input, plan_name};
pub(crate) use maps::MapError;
pub(crate) use maps::balance_offset;
pub use maps::{StepMap, line_map, map_starts, sampled_map};
pub use options::{Backend, FeedSearch, PlanOptions};
pub use result::{PlannedStep, Synthesis};
pub use settle::{Settle, settle_time};
pub(crate) use settle::{slowest_settled, start_points, step_duration_ms};
pub(crate) use symmetry::{central_symmetry_sentence, symmetry_note};
pub use symmetry::{plan_period, symmetry_centre, symmetry_order};

/// Everything the search needs, computed once per part and plate.
#[derive(Debug, Clone)]
pub struct Problem {
    /// One map per mode.
    pub maps: Vec<StepMap>,
    /// Period (deg).
    pub period: f64,
    /// The plate centre when every mode's field is centrally symmetric about it
    /// ([`symmetry_centre`]): named when 180° twins stay apart.
    pub symmetry_centre: Option<[f64; 2]>,
}

impl Problem {
    /// Builds the maps of every mode.
    pub fn new(part: &Part, plate: &PlateModel, opt: &PlanOptions) -> Result<Problem, PlanFailure> {
        Problem::with_progress(part, plate, opt, &crate::progress::Silent)
    }

    /// [`Self::new`], advancing `progress` by one after each mode's map.
    pub(crate) fn with_progress(
        part: &Part,
        plate: &PlateModel,
        opt: &PlanOptions,
        progress: &dyn Progress,
    ) -> Result<Problem, PlanFailure> {
        let period = plan_period(part, plate);
        let body = Body::with_samples(part, PLANNER_BODY_SAMPLES);
        let n = plate.modes.len();
        progress.stage(&format!("{}: step maps", part.name), n as u64);
        let maps = plate
            .modes
            .iter()
            .enumerate()
            .map(|(k, mode)| {
                deadline::check(opt.deadline, || {
                    format!("{}: step map {} of {n} ({})", part.name, k + 1, mode.name)
                })?;
                let map = match mode.node {
                    Node::Line { .. } => line_map_of(part, mode, plate, period, opt, opt.maps)
                        .map_err(PlanFailure::Model),
                    _ => Ok(margin::simulated_map(&body, mode, plate, opt, period)),
                };
                progress.advance(1);
                map
            })
            .collect::<Result<Vec<_>, _>>()?;
        progress.stage(&format!("{}: search, check, step durations", part.name), 0);
        Ok(Problem { maps, period, symmetry_centre: symmetry_centre(plate) })
    }

    /// Breadth-first search; returns mode indices and the predicted sets.
    pub fn search(&self, opt: &PlanOptions) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        self.search_without(opt, &[])
    }

    /// [`Self::search`] with some transitions (orientation, mode) ruled out: the shortest
    /// plan, the first found breadth-first ([`search`]).
    pub(crate) fn search_without(
        &self,
        opt: &PlanOptions,
        forbidden: &[(f64, usize)],
    ) -> Result<Vec<(usize, Vec<f64>)>, PlanFailure> {
        let one = PlanOptions { minimize: Minimize::Steps, extra_steps: 0, ..*opt };
        let s = search::Search::new(&[self], &one, &[forbidden.to_vec()]);
        let reach = s.reach();
        reach.in_time(opt)?;
        let Some(steps) = reach.shortest else {
            let why = self.explain_reach(&s, &reach, opt) + &reach.bound_note(opt);
            return Err(PlanFailure::NoPlan(why));
        };
        let path = s
            .select(&search::Target::default(), steps, &mut |_, _| 1, &mut |_| Vec::new())
            .ok_or_else(|| PlanFailure::NoPlan("the search found no plan twice".into()))?;
        Ok(path.into_iter().map(|(k, mut a)| (k, a.swap_remove(0))).collect())
    }
}

/// Plans: maps, search, durations, position ([`plan_parts`] for one part, its goal
/// [`PlanOptions::goal_deg`]); with a feed region, by tracking poses from it ([`feed::plan`], no
/// progress shown). When the maps of [`PlanOptions::maps`] give no plan, the other maps are
/// tried before giving up (`fallback`).
pub fn plan(part: &Part, plate: &PlateModel, opt: &PlanOptions) -> Result<Synthesis, PlanFailure> {
    if let Some(region) = &opt.feed {
        return feed::plan(part, plate, opt, region, &crate::progress::Silent);
    }
    plan_parts(std::slice::from_ref(part), plate, opt, &[opt.goal_deg])
}

/// The maps tried when those of `opt` give no plan: [`MapKind::Auto`] (static first) tries the
/// dynamic maps, which can find a plan where the static map's basin boundary is not where a
/// part arriving from afar meets it; [`MapKind::Dynamic`] tries the static ones (a measured
/// boundary can move to within the margin of a rest the static plan keeps, and the dynamic
/// check at its start points confirms that plan); [`MapKind::Static`] nothing.
pub(crate) fn fallback(opt: &PlanOptions) -> Option<MapKind> {
    match opt.maps {
        MapKind::Auto => Some(MapKind::Dynamic),
        MapKind::Dynamic => Some(MapKind::Static),
        MapKind::Static => None,
    }
}

/// Whether a search that found no plan (none at all, none reaching the goal orientation or
/// fixing the position) is tried again over the [`fallback`] maps: only when a straight node
/// is there to map differently.
pub(crate) fn falls_back(e: &PlanFailure, plate: &PlateModel, opt: &PlanOptions) -> bool {
    !matches!(e, PlanFailure::Model(_) | PlanFailure::OutOfTime { .. })
        && fallback(opt).is_some()
        && plate.modes.iter().any(|m| matches!(m.node, Node::Line { .. }))
}

/// Of two failures, first over `opt.maps` and then over its [`fallback`], the one reported:
/// the dynamic maps' (they name the boundaries a part arriving from afar meets, and which
/// orientation depends on the side it comes from).
pub(crate) fn reported(first: PlanFailure, second: PlanFailure, opt: &PlanOptions) -> PlanFailure {
    if opt.maps == MapKind::Dynamic { first } else { second }
}

/// `problem` with its straight-node maps replaced by those of `kind` (the simulated maps of
/// curved and grid nodes are kept).
pub(crate) fn remapped(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    problem: &Problem,
    kind: MapKind,
) -> Result<Problem, PlanFailure> {
    let maps = plate
        .modes
        .iter()
        .zip(&problem.maps)
        .map(|(mode, map)| {
            deadline::check(opt.deadline, || {
                format!("{}: dynamic map of {}", part.name, mode.name)
            })?;
            match mode.node {
                Node::Line { .. } => line_map_of(part, mode, plate, problem.period, opt, kind)
                    .map_err(PlanFailure::Model),
                _ => Ok(map.clone()),
            }
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Problem { maps, ..problem.clone() })
}

/// A straight-node map of `kind` ([`MapKind::Auto`] starts with the static one); a node the
/// part cannot rest across ([`rim_line`]: along or beyond an edge) is mapped by simulation
/// with the rim whatever the kind.
fn line_map_of(
    part: &Part,
    mode: &crate::model::plate::Mode,
    plate: &PlateModel,
    period: f64,
    opt: &PlanOptions,
    kind: MapKind,
) -> Result<StepMap, MapError> {
    let body = Body::with_samples(part, PLANNER_BODY_SAMPLES);
    if rim_line(body.radius, mode, plate) {
        return Ok(sampled_map(&body, mode, plate, opt.sim_starts, period));
    }
    match kind {
        MapKind::Static | MapKind::Auto => line_map(part, mode, opt.backend),
        MapKind::Dynamic => {
            MapCache::global().line_map(part, mode, plate, period, opt.backend, opt.dyn_maps)
        }
    }
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
