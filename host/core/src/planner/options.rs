//! Planner settings ([`PlanOptions`]) and the straight-node model choice ([`Backend`]).

use super::deadline::Deadline;
use super::dynamic::{DynSettings, MapKind};
use super::feed;
use super::search::Minimize;

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
    /// Where parts are dropped: plan by tracking poses from there ([`feed`]) instead of
    /// over orientation sets.
    pub feed: Option<feed::FeedRegion>,
    /// Settings of the feed-region search.
    pub feed_search: feed::FeedSearch,
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
            feed_search: feed::FeedSearch::default(),
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
