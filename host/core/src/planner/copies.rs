//! Plans for bulk feeding (`chladni plan --copies N`; docs/motion.md, "Bulk feeding"): of the
//! plans the planner offers for one part, the one that orients the most copies per minute
//! when N copies are dropped together.
//!
//! The planner's shortest plan gathers the part at one orientation; the other orientations it
//! can reach ([`Synthesis::reachable_deg`]) and the plan least in time ([`Minimize::Time`]) are
//! plans too, and with N parts in contact they can differ a lot in throughput: a plan whose
//! last mode holds parts along a line lets them line up, one that gathers them at a point makes
//! them jam. Each candidate is scored by [`crate::motion::bulk`]: the same seeded drops of N
//! copies through the candidate's steps, oriented copies per minute of its plan time. The
//! planner itself is only called through its public entry ([`planner::plan`]).

use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::plan_file::PlanFile;
use crate::model::plate::PlateModel;
use crate::motion::body::Body;
use crate::motion::bulk::{BulkReport, CannotPlace, Drop, run_drops};
use crate::motion::field::FieldModel;
use crate::motion::shape::Pieces;
use crate::motion::steps::{PlanStepsError, plan_steps};
use crate::planner::{self, Minimize, PlanOptions, Synthesis};
use crate::progress::Progress;

/// Drops of N copies that score each candidate.
pub const RANK_DROPS: u32 = 3;
/// Seed of the scoring drops (the same starts for every candidate).
pub const RANK_SEED: u64 = 1;
/// An oriented copy: within this of the candidate's predicted orientation (deg).
pub const RANK_TOL_DEG: f64 = 5.0;

/// Why the candidates cannot be scored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CopiesError {
    /// N copies do not fit on the plate.
    #[error(transparent)]
    Place(#[from] CannotPlace),
    /// A candidate's steps do not run on the plate (a planner fault: its own plan).
    #[error("a candidate plan does not run on its plate: {0}")]
    Steps(#[from] PlanStepsError),
}

/// One candidate: the planner's synthesis, its plan file and its bulk score.
#[derive(Debug, Clone)]
pub struct Scored {
    /// The plan.
    pub syn: Synthesis,
    /// Its plan file.
    pub file: PlanFile,
    /// N copies dropped through it.
    pub report: BulkReport,
}

/// The candidates, scored, and which one is chosen.
#[derive(Debug, Clone)]
pub struct Ranked {
    /// Every candidate, the planner's own plan first.
    pub candidates: Vec<Scored>,
    /// Index of the chosen one: the most oriented parts per minute (ties: the earlier).
    pub chosen: usize,
}

/// The plans worth scoring: `first` (the planner's answer to `opt`), then, when `opt` asks for
/// no goal, one plan for each other orientation `first` can reach, and the plan least in
/// time. Orientations the planner cannot plan for are skipped; equal step sequences kept once.
pub fn candidates(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    first: Synthesis,
) -> Vec<Synthesis> {
    let mut out = vec![first];
    let first = &out[0];
    let mut tries: Vec<PlanOptions> = Vec::new();
    if opt.goal_deg.is_none() && opt.feed.is_none() {
        for &r in &first.reachable_deg {
            if cdist(r, first.final_orientation_deg, first.period_deg) > 1e-6 {
                tries.push(PlanOptions { goal_deg: Some(r), ..*opt });
            }
        }
    }
    if opt.minimize != Minimize::Time && opt.feed.is_none() {
        tries.push(PlanOptions { minimize: Minimize::Time, ..*opt });
    }
    for o in tries {
        let Ok(syn) = planner::plan(part, plate, &o) else { continue };
        let key = |s: &Synthesis| -> Vec<(usize, u32)> {
            s.steps.iter().map(|p| (p.mode, p.duration_ms)).collect()
        };
        if !out.iter().any(|s| key(s) == key(&syn)) {
            out.push(syn);
        }
    }
    out
}

/// Scores every candidate with `copies` copies of `part` (`drops` drops from [`RANK_SEED`];
/// the CLI takes [`RANK_DROPS`]) and chooses the most oriented parts per minute; `progress` after each drop
/// (candidates × drops in all).
pub fn rank(
    part: &Part,
    plate: &PlateModel,
    syns: Vec<Synthesis>,
    (copies, drops): (usize, u32),
    progress: &dyn Progress,
) -> Result<Ranked, CopiesError> {
    let fields: Vec<FieldModel> = plate.modes.iter().map(|m| FieldModel::new(m, plate)).collect();
    let body = Body::new(part);
    let pieces = Pieces::of(&body);
    let (bodies, refs) = (vec![&body; copies], vec![&pieces; copies]);
    let mut candidates = Vec::with_capacity(syns.len());
    for syn in syns {
        let file = syn.to_file(plate, &part.name);
        let steps = plan_steps(&file, plate)?;
        let d = Drop {
            bodies: &bodies,
            pieces: &refs,
            plate,
            fields: &fields,
            steps: &steps,
            feed: None,
        };
        let drops = run_drops(&d, drops, RANK_SEED, progress)?;
        let report = BulkReport::new(&drops, &file, &steps, RANK_SEED, RANK_TOL_DEG);
        candidates.push(Scored { syn, file, report });
    }
    let ppm = |s: &Scored| s.report.parts_per_min.unwrap_or(-1.0);
    let mut chosen = 0;
    for (i, c) in candidates.iter().enumerate() {
        if ppm(c) > ppm(&candidates[chosen]) {
            chosen = i;
        }
    }
    Ok(Ranked { candidates, chosen })
}

#[cfg(test)]
/// Why `plan --copies` gave no plan.
#[derive(Debug, Clone, thiserror::Error)]
pub(crate) enum BulkPlanError {
    /// The planner found none.
    #[error(transparent)]
    Plan(#[from] crate::planner::PlanFailure),
    /// The candidates could not be scored.
    #[error(transparent)]
    Copies(#[from] CopiesError),
}

#[cfg(test)]
/// [`planner::plan`], then the candidates ranked for `copies` copies over `drops` drops.
pub(crate) fn plan_for_copies(
    part: &Part,
    plate: &PlateModel,
    opt: &PlanOptions,
    (copies, drops): (usize, u32),
) -> Result<Ranked, BulkPlanError> {
    let first = planner::plan(part, plate, opt)?;
    let syns = candidates(part, plate, opt, first);
    Ok(rank(part, plate, syns, (copies, drops), &crate::progress::Silent)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example(dir: &str, name: &str) -> std::path::PathBuf {
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples").join(dir).join(name)
    }

    /// The rectangle on four-lines: the planner's own plan (90°, one step on the 60 Hz line)
    /// and the plans to its other reachable orientations orient different numbers of 3 copies
    /// per minute; the chosen one is never below the planner's own, and is the best scored.
    #[test]
    fn the_chosen_plan_orients_at_least_as_many_copies_per_minute_as_the_planners_own() {
        let part = Part::load(&example("parts", "rectangle.json")).unwrap();
        let plate = PlateModel::load(&example("plates", "four-lines.toml")).unwrap();
        let r = plan_for_copies(&part, &plate, &PlanOptions::default(), (3, 1)).unwrap();
        assert!(r.candidates.len() >= 2, "{} candidates", r.candidates.len());
        let ppm: Vec<f64> =
            r.candidates.iter().map(|c| c.report.parts_per_min.unwrap_or(-1.0)).collect();
        let best = ppm.iter().copied().fold(f64::MIN, f64::max);
        assert_eq!(ppm[r.chosen], best, "{ppm:?}");
        assert!(ppm[r.chosen] >= ppm[0], "{ppm:?}");
        assert!(ppm.iter().any(|&p| p != ppm[0]), "the candidates should differ: {ppm:?}");
        for c in &r.candidates {
            assert_eq!(c.report.copies, 3);
            assert!(c.report.max_overlap_mm < 0.05, "{}", c.report.max_overlap_mm);
        }
    }
}
