//! What the planner returns: the planned steps, the synthesis and its plan file.

use super::feed;
use super::goal::PartPlan;
use super::input::plan_name;
use super::mode_margin::ModeMargin;
use super::settle::Settle;
use crate::model::plan_file::{PartPrediction, PlanFile, StepJson, r4};
use crate::model::plate::PlateModel;

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
    /// The margin the step kept from its map's basin boundaries, and its source
    /// ([`super::margin`]).
    pub margin: ModeMargin,
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
    /// The longest plan considered: the shortest plan's steps + [`PlanOptions::extra_steps`](crate::planner::PlanOptions::extra_steps).
    pub max_steps: usize,
    /// With `fix_position` / `goal_pos_mm`: the largest distance (mm) of a simulated final
    /// centroid from the predicted position.
    pub position_check_mm: Option<f64>,
    /// Several parts: one prediction per part (empty for a single part).
    pub parts: Vec<PartPlan>,
    /// Whole-plate plans on grid modes: what the drops over the plate gave
    /// ([`super::whole`]); `None` when not checked.
    pub whole_plate: Option<super::whole::WholePlate>,
}

impl Synthesis {
    /// Part `i`'s predicted final orientation and its period (deg): its own prediction in
    /// [`Synthesis::parts`], or the plan's when there is none (one part).
    pub fn predicted(&self, i: usize) -> (f64, f64) {
        self.parts.get(i).map_or((self.final_orientation_deg, self.period_deg), |p| {
            (p.final_orientation_deg, p.period_deg)
        })
    }

    /// The steps as the simulator runs them (each at its mode's own amplitude).
    pub fn sim_steps(&self) -> Vec<crate::motion::steps::SimStep> {
        self.steps
            .iter()
            .map(|s| crate::motion::steps::SimStep::new(s.mode, s.duration_ms, 1.0))
            .collect()
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
