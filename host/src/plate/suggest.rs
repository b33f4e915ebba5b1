//! `chladni plate suggest`: where to drive and clamp a plate so that a part gets a plan.
//!
//! A small fixed grid of candidates (drive points off the plate's symmetry lines, no clamp or
//! point supports near the corners): for each, the solver's forced response at the first
//! resonances ([`crate::plate::drive`]) becomes a plate file in memory, and the planner's
//! public entry points (`planner::check_input`, `planner::plan_parts`, as `chladni plan` calls
//! them over the whole plate) say whether a plan exists. One modal solve per clamp set; the
//! work is bounded by the candidate count and a time budget after which no new candidate
//! starts and the planning of the one under way stops (the planner's deadline,
//! [`planner::Deadline`]; not the first candidate's, so that one row has an answer).

use std::time::{Duration, Instant};

use crate::model::modes_file;
use crate::model::part::Part;
use crate::model::plate::PlateModel;
use crate::model::plate_file::{ModeEntry, Plate, PlateFile};
use crate::planner::{self, PlanFailure, PlanOptions};
use crate::plate::drive;
use crate::plate::solver::{self, ModalSolution};

/// Drive points tried, as fractions of [W, H]: off the mid-lines and diagonals, so no
/// symmetry of a rectangular plate maps one onto a node of every mode.
pub const DRIVE_FRACTIONS: [[f64; 2]; 3] = [[0.3, 0.37], [0.69, 0.28], [0.4, 0.73]];

/// Clamp sets tried, as fractions of [W, H]: one support near a corner (three corners), two
/// supports on one side, none. Clamps first: on a centrally symmetric plate φ² stays
/// symmetric whatever the drive point (docs/plate.md, "Drive point"), a support off the
/// centre is what breaks a pose's 180° twin, so a short budget is spent where plans are.
pub const CLAMP_FRACTIONS: [&[[f64; 2]]; 5] =
    [&[[0.1, 0.12]], &[[0.88, 0.1]], &[[0.12, 0.9]], &[[0.1, 0.12], [0.88, 0.1]], &[]];

/// One drive point and clamp set.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Drive point (mm).
    pub drive_mm: [f64; 2],
    /// Point supports (mm).
    pub clamps_mm: Vec<[f64; 2]>,
}

/// A plan found for a candidate.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Found {
    /// Plan steps.
    pub steps: usize,
    /// Total duration (s).
    pub total_s: f64,
    /// Predicted final orientation (deg, modulo the period).
    pub final_orientation_deg: f64,
    /// The part's symmetry period (deg).
    pub period_deg: f64,
}

/// What one candidate gave.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum Outcome {
    /// A plan.
    Plan(Found),
    /// No plan: the planner's (or the model's) reason.
    NoPlan {
        /// The message.
        reason: String,
    },
    /// Not tried: the time budget ran out first.
    NotTried,
}

/// A row of the table.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Row {
    /// The candidate.
    #[serde(flatten)]
    pub candidate: Candidate,
    /// Its outcome.
    #[serde(flatten)]
    pub outcome: Outcome,
    /// Resonances written for it (after unexcited ones are left out).
    pub modes: usize,
}

/// How the search runs.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Solver modes per candidate (`plate modes --count`).
    pub count: usize,
    /// Ritz terms per direction.
    pub terms: usize,
    /// Grid points along x of the written mode shapes.
    pub grid: usize,
    /// No candidate starts after this.
    pub budget: Duration,
    /// The planner's options.
    pub plan: PlanOptions,
}

/// The candidates for a plate of `size` (mm), clamp set by clamp set.
pub fn candidates(size: [f64; 2]) -> Vec<Candidate> {
    let mm = |f: [f64; 2]| {
        [(f[0] * size[0] * 10.0).round() / 10.0, (f[1] * size[1] * 10.0).round() / 10.0]
    };
    CLAMP_FRACTIONS
        .iter()
        .flat_map(|c| {
            DRIVE_FRACTIONS.iter().map(move |&d| Candidate {
                drive_mm: mm(d),
                clamps_mm: c.iter().map(|&f| mm(f)).collect(),
            })
        })
        .collect()
}

/// The forced responses as `[[mode]]` entries (the entries `plate modes --write-modes`
/// writes for a drive point, less a hinged-rod plate's forced rocking).
pub fn forced_entries(forced: &drive::Forced, all: &ModalSolution, grid: usize) -> Vec<ModeEntry> {
    let sol = forced.as_solution(all);
    let (nx, ny) = solver::grid_dims(grid, all.size_mm);
    forced
        .resonances
        .iter()
        .enumerate()
        .map(|(k, r)| {
            modes_file::grid_mode(
                &drive::members_label(&r.members),
                r.freq_hz,
                r.lambda,
                &sol.sample(k, nx, ny),
            )
        })
        .collect()
}

/// Tries every candidate on `part` (calling `tick` after each), in order, until the budget
/// is spent; the rest are [`Outcome::NotTried`].
pub fn run(
    file: &PlateFile,
    plate: &Plate,
    part: &Part,
    set: &Settings,
    mut tick: impl FnMut(),
) -> Vec<Row> {
    let start = Instant::now();
    // The plan under way when the budget runs out stops there too, but for the first
    // candidate's: some row gets an answer, whatever the budget.
    let budget = planner::Deadline::after_s(set.budget.as_secs_f64());
    let opt = PlanOptions { deadline: set.plan.deadline.or(Some(budget)), ..set.plan };
    let mut solved: Option<(Vec<[f64; 2]>, ModalSolution)> = None;
    let mut rows = Vec::new();
    for cand in candidates(plate.size_mm) {
        if start.elapsed() > set.budget {
            rows.push(Row { candidate: cand, outcome: Outcome::NotTried, modes: 0 });
            tick();
            continue;
        }
        if solved.as_ref().is_none_or(|(c, _)| *c != cand.clamps_mm) {
            let p = Plate { clamps_mm: cand.clamps_mm.clone(), ..plate.clone() };
            solved = Some((cand.clamps_mm.clone(), solver::solve_all(&p, set.terms)));
        }
        let all = &solved.as_ref().expect("solved above").1;
        let forced = drive::forced(all, set.count, cand.drive_mm, plate.damping_ratio);
        let mut table = file.plate.clone();
        table.drive_mm = Some(cand.drive_mm);
        table.clamps_mm = (!cand.clamps_mm.is_empty()).then(|| cand.clamps_mm.clone());
        let mode = forced_entries(&forced, all, set.grid);
        let modes = mode.len();
        let opt = if rows.is_empty() { &set.plan } else { &opt };
        let outcome = plan_on(&PlateFile { plate: table, mode }, part, opt);
        rows.push(Row { candidate: cand, outcome, modes });
        tick();
    }
    rows
}

/// Whether `part` gets a whole-plate plan on `file`'s modes.
fn plan_on(file: &PlateFile, part: &Part, opt: &PlanOptions) -> Outcome {
    let no = |reason: String| Outcome::NoPlan { reason };
    let model = match PlateModel::from_file(file) {
        Ok(m) => m,
        Err(e) => return no(e.to_string()),
    };
    if let Err(e) = planner::check_input(part, &model) {
        return no(e.to_string());
    }
    match planner::plan_parts(std::slice::from_ref(part), &model, opt, &[None]) {
        Ok(syn) => Outcome::Plan(Found {
            steps: syn.steps.len(),
            total_s: syn.steps.iter().map(|s| f64::from(s.duration_ms)).sum::<f64>() / 1000.0,
            final_orientation_deg: syn.final_orientation_deg,
            period_deg: syn.period_deg,
        }),
        Err(PlanFailure::OutOfTime { stage, .. }) => {
            no(format!("the time budget (--budget-s) ran out at {stage}"))
        }
        Err(e) => no(e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_on_the_plate_off_its_mid_lines_and_one_solve_per_clamp_set() {
        let c = candidates([300.0, 200.0]);
        assert_eq!(c.len(), DRIVE_FRACTIONS.len() * CLAMP_FRACTIONS.len());
        for k in &c {
            let d = k.drive_mm;
            assert!(d[0] > 0.0 && d[0] < 300.0 && d[1] > 0.0 && d[1] < 200.0);
            assert!((d[0] - 150.0).abs() > 10.0 && (d[1] - 100.0).abs() > 10.0, "{d:?}");
        }
        // Clamp sets come in runs, so the modal solve is reused within a run.
        let changes = c.windows(2).filter(|w| w[0].clamps_mm != w[1].clamps_mm).count();
        assert_eq!(changes, CLAMP_FRACTIONS.len() - 1);
    }
}
