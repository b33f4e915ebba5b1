//! Planner settings ([`PlanOptions`]) and the straight-node model choice ([`Backend`]).

use super::deadline::Deadline;
use super::dynamic::{DynSettings, MapKind};
use super::search::Minimize;
use crate::model::feed_region::FeedRegion;

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
    /// Robustness margin (degrees): every mode's with `margin_auto` off; with it on, the
    /// margin of maps without resampling evidence ([`super::margin`]).
    pub margin_deg: f64,
    /// Margins from evidence ([`super::margin`], default): each grid mode's map keeps the
    /// margin its resampling measured; off (`--margin-deg D` given) every map keeps
    /// `margin_deg`.
    pub margin_auto: bool,
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
    /// Where parts are dropped: plan by tracking poses from there ([`super::feed`]) instead of
    /// over orientation sets.
    pub feed: Option<FeedRegion>,
    /// Settings of the feed-region search.
    pub feed_search: FeedSearch,
    /// Straight-node maps: the static alignment function ([`MapKind::Static`]), measured by
    /// simulating the approach from both sides ([`MapKind::Dynamic`]), or static first and
    /// dynamic when that gives no plan ([`MapKind::Auto`], default).
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
    /// Stop with [`super::PlanFailure::OutOfTime`] after this ([`Deadline`]); `None`: no limit.
    pub deadline: Option<Deadline>,
    /// Whole-plate plans on grid modes: how many times the maps are refined with the drop
    /// points a plan did not hold from ([`super::whole`]); 0: no whole-plate check.
    pub refine_rounds: usize,
}

impl Default for PlanOptions {
    fn default() -> Self {
        PlanOptions {
            margin_deg: 3.0,
            margin_auto: true,
            safety: 1.5,
            backend: Backend::Fixed,
            sim_starts: 90,
            durations: true,
            max_states: 200_000,
            feed: None,
            feed_search: FeedSearch::default(),
            maps: MapKind::default(),
            dyn_maps: DynSettings::default(),
            minimize: Minimize::Steps,
            extra_steps: 1,
            goal_deg: None,
            fix_position: false,
            goal_pos_mm: None,
            deadline: None,
            refine_rounds: 0,
        }
    }
}

/// Feed-region search settings.
#[derive(Debug, Clone, Copy)]
pub struct FeedSearch {
    /// Most steps (`plan --max-steps`).
    pub depth: usize,
    /// Start positions per side of the feed region (n × n grid; 1: its centre).
    pub points: usize,
    /// Start orientations per position.
    pub starts: usize,
    /// Every tracked pose must end within this of one orientation (deg, mod the period).
    pub tol_deg: f64,
    /// Most sequences of the shortest length confirmed.
    pub candidates: usize,
    /// Refinement rounds: when every candidate of a depth fails the check, the checked starts
    /// that ended off are added to the tracked starts and the search runs again (runs stay
    /// memoised), at most this many times.
    pub refine: usize,
}

impl FeedSearch {
    /// The feed-region search's default most steps (`plan --max-steps`). Levels past the
    /// fourth borrow runs, which keeps a 6-step search of an ordinary part within about
    /// a minute, and the search is level by level, so every plan of 4 steps or fewer is the one a
    /// bound of 4 finds (docs/plan.md, "The step bound").
    pub const DEFAULT_DEPTH: usize = 6;
}

impl Default for FeedSearch {
    fn default() -> Self {
        FeedSearch {
            depth: FeedSearch::DEFAULT_DEPTH,
            points: 3,
            starts: 24,
            tol_deg: 2.0,
            candidates: 8,
            refine: 2,
        }
    }
}
