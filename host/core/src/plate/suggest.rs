//! `chladni plate suggest`: where to drive and clamp a plate so that a part gets a plan.
//!
//! A small fixed list of candidates, clamp set by clamp set (supports at edges and near
//! corners, off the plate's mid-lines; no clamp last), each with a few drive points off both
//! mid-lines and diagonals: for each, the solver's forced response at the first resonances
//! ([`crate::plate::drive`]; a hinged-rod plate's forced rocking ahead, as `plate modes
//! --write-modes` writes them) becomes a plate file in memory, and the planner's public entry
//! points (`planner::check_input`, `planner::plan_parts`, as `chladni plan` calls them over the
//! whole plate: both faces of a part that flips, and the whole-plate check of
//! [`planner::whole`] with `chladni plan`'s default rounds) say whether a plan exists. A plan
//! the whole-plate check refuses is a row of its own ([`Why::NotWholePlate`], with the share of
//! the drops it held from), so that every plan a row lists is one `chladni plan` gives on the
//! plate file written from that row's drive point and clamps.
//!
//! What keeps it inside its budget:
//! - one modal solve per clamp set (the drive point only changes the forcing);
//! - a drive point that excites the same single modes as one tried before on the same clamps
//!   gives the same plate file up to each mode's sign and scale (a single mode's response is
//!   φ_k(x_d) φ_k, and the planner's grid field depends on φ² normalised), so its row takes
//!   that row's outcome ([`Row::same_as`]) instead of planning again (the whole-plate check
//!   included: it runs the same plan on the same fields);
//! - a plate whose every mode is centrally symmetric ([`planner::symmetry_centre`]) moves a pose
//!   and its twin turned 180° about the centre alike: a part whose period does not divide 180°
//!   has no whole-plate plan there, said without mapping ([`Why::Symmetric`]);
//! - a time budget: no new candidate starts after it, and the plan under way stops there (the
//!   planner's deadline, [`planner::Deadline`]), except the first candidate that is planned,
//!   so that one row has the planner's answer.

use crate::progress::Progress;
use std::time::{Duration, Instant};

use crate::model::modes_file;
use crate::model::part::{Part, mirror};
use crate::model::plate::PlateModel;
use crate::model::plate_file::{ModeEntry, Plate, PlateFile};
use crate::planner::whole::{NotWhole, WholePlate};
use crate::planner::{self, PlanFailure, PlanOptions};
use crate::plate::solver::{self, ModalSolution};
use crate::plate::{drive, rocking};

/// Drive points tried, as fractions of [W, H]: off the mid-lines and diagonals, so no
/// symmetry of a rectangular plate maps one onto a node of every mode.
pub(crate) const DRIVE_FRACTIONS: [[f64; 2]; 3] = [[0.3, 0.37], [0.69, 0.28], [0.4, 0.73]];

/// Clamp sets tried, as fractions of [W, H], in this order: one support near a corner, one on
/// an edge off its middle (a node on the rim, a wall the field pushes parts against), in turn
/// round the plate, then two supports, then none. Clamps first: on a centrally symmetric
/// plate φ² stays symmetric whatever the drive point (docs/plate.md, "Drive point"), a support
/// off the centre and off both mid-lines is what breaks a pose's 180° twin and its mirror
/// image, so a short budget is spent where plans are.
pub(crate) const CLAMP_FRACTIONS: [&[[f64; 2]]; 7] = [
    &[[0.1, 0.12]],
    &[[0.3, 0.0]],
    &[[0.88, 0.1]],
    &[[0.0, 0.35]],
    &[[0.12, 0.9]],
    &[[0.1, 0.12], [0.88, 0.1]],
    &[],
];

/// One drive point and clamp set.
#[derive(Debug, Clone, PartialEq)]
pub struct Candidate {
    /// Drive point (mm).
    pub drive_mm: [f64; 2],
    /// Point supports (mm).
    pub clamps_mm: Vec<[f64; 2]>,
}

/// A plan found for a candidate (`--json`: `crate::shapes::plate::suggest_json`).
#[derive(Debug, Clone, PartialEq)]
pub struct Found {
    /// Plan steps.
    pub steps: usize,
    /// Total duration (s).
    pub total_s: f64,
    /// Predicted final orientation (deg, modulo the period).
    pub final_orientation_deg: f64,
    /// The part's symmetry period (deg).
    pub period_deg: f64,
    /// What the whole-plate check gave (`Synthesis::whole_plate`): held from every drop, or
    /// not checked (both faces); `None` with `--refine-rounds 0`.
    pub whole_plate: Option<WholePlate>,
}

/// What the whole-plate check gave a plan it refused ([`Why::NotWholePlate`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Held {
    /// Drops run over the plate.
    pub drops: usize,
    /// Drops the last plan held from.
    pub held: usize,
    /// The largest block of drop cells the last plan held from, as a `--feed` region (mm:
    /// x0, y0, x1, y1).
    pub feed_mm: Option<[f64; 4]>,
}

impl Held {
    /// From the planner's failure.
    pub fn of(n: &NotWhole) -> Held {
        Held { drops: n.drops, held: n.drops.saturating_sub(n.failed), feed_mm: n.feed_mm }
    }

    /// held / drops.
    pub fn share(&self) -> f64 {
        self.held as f64 / self.drops.max(1) as f64
    }
}

/// Why a candidate gives no plan (`--json`'s `why`: [`Why::name`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Why {
    /// Every mode is centrally symmetric and the part's period does not divide 180°: a pose
    /// and its 180° twin end apart whatever the sequence (found before any map is made).
    Symmetric,
    /// The drive point excites none of the first modes.
    NotExcited,
    /// The in-memory plate file is not a plate model (`PlateModel::from_file`).
    PlateModel,
    /// The part does not fit the plate or the planner's limits (`planner::check_input`).
    Part,
    /// A mode cannot be mapped for this part ([`PlanFailure::Model`]).
    Map,
    /// The search found no sequence ([`PlanFailure::NoPlan`] and the goal failures).
    NoSequence,
    /// A plan was found, but no plan the whole-plate check tried holds from every drop over
    /// the plate ([`PlanFailure::NotWholePlate`]): `chladni plan` refuses it so.
    NotWholePlate(Held),
    /// The time budget stopped the planning of this candidate.
    OutOfTime,
}

impl Why {
    /// The snake_case name `--json` and the table print.
    pub fn name(self) -> &'static str {
        match self {
            Why::Symmetric => "symmetric",
            Why::NotExcited => "not_excited",
            Why::PlateModel => "plate_model",
            Why::Part => "part",
            Why::Map => "map",
            Why::NoSequence => "no_sequence",
            Why::NotWholePlate(_) => "not_whole_plate",
            Why::OutOfTime => "out_of_time",
        }
    }
}

/// What one candidate gave.
#[derive(Debug, Clone, PartialEq)]
pub enum Outcome {
    /// A plan.
    Plan(Found),
    /// No plan: why, and the planner's (or the model's) message.
    NoPlan {
        /// The kind of failure.
        why: Why,
        /// The message.
        reason: String,
    },
    /// Not tried: the time budget ran out first.
    NotTried,
}

/// A row of the table.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// The candidate.
    pub candidate: Candidate,
    /// Its outcome.
    pub outcome: Outcome,
    /// Resonances written for it (after unexcited ones are left out; the forced rocking of a
    /// hinged-rod plate counts).
    pub modes: usize,
    /// Wall time spent on this row (s): the modal solve when its clamp set is new, the forced
    /// response and the planning.
    pub wall_s: f64,
    /// The row (0-based) with the same plate file up to sign and scale, whose outcome this
    /// one takes without planning again.
    pub same_as: Option<usize>,
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
    /// The planner's options (`refine_rounds`: the whole-plate check, as `plan
    /// --refine-rounds`).
    pub plan: PlanOptions,
}

/// The candidates for a plate of `size` (mm): every clamp set with the first drive point,
/// then with the second, …, so that a short budget tries every clamp set once (the drive
/// point matters less: it only selects which modes are excited).
pub fn candidates(size: [f64; 2]) -> Vec<Candidate> {
    let mm = |f: [f64; 2]| {
        [(f[0] * size[0] * 10.0).round() / 10.0, (f[1] * size[1] * 10.0).round() / 10.0]
    };
    DRIVE_FRACTIONS
        .iter()
        .flat_map(|&d| {
            CLAMP_FRACTIONS.iter().map(move |c| Candidate {
                drive_mm: mm(d),
                clamps_mm: c.iter().map(|&f| mm(f)).collect(),
            })
        })
        .collect()
}

/// The forced responses as `[[mode]]` entries (the entries `plate modes --write-modes`
/// writes for a drive point, less a hinged-rod plate's forced rocking).
pub(crate) fn forced_entries(
    forced: &drive::Forced,
    all: &ModalSolution,
    grid: usize,
) -> Vec<ModeEntry> {
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

/// A clamp set's modal solve, kept for its later candidates.
struct Solved {
    clamps_mm: Vec<[f64; 2]>,
    plate: Plate,
    all: ModalSolution,
}

/// What a tried candidate's plate file was, to spot a later one that gives the same file.
struct Tried {
    row: usize,
    clamps_mm: Vec<[f64; 2]>,
    members: Vec<Vec<usize>>,
}

impl Tried {
    /// Whether this row's outcome is the one of a candidate on `clamps` exciting `members`:
    /// same clamps, single modes only (a degenerate pair's shape depends on the drive point),
    /// and the same modes, or fewer when this row has no sequence (the searches over fewer
    /// modes are a part of its search) or is symmetric (fewer modes stay symmetric); never a
    /// row the budget stopped.
    fn answers(&self, clamps: &[[f64; 2]], members: &[Vec<usize>], row: &Row) -> bool {
        let single = members.iter().all(|g| g.len() == 1);
        let fewer =
            matches!(row.outcome, Outcome::NoPlan { why: Why::NoSequence | Why::Symmetric, .. })
                && !members.is_empty()
                && members.iter().all(|g| self.members.contains(g));
        // A row the budget stopped has no answer to give.
        let answered = !matches!(row.outcome, Outcome::NoPlan { why: Why::OutOfTime, .. });
        self.clamps_mm == clamps && single && answered && (self.members == members || fewer)
    }
}

/// Tries every candidate on `part` (advancing `progress` after each), in order, until the budget
/// is spent; the rest are [`Outcome::NotTried`], but for those whose plate file is one
/// already tried (same clamps, same single modes excited: [`Row::same_as`]), which cost no
/// planning.
pub fn run(
    file: &PlateFile,
    plate: &Plate,
    part: &Part,
    set: &Settings,
    progress: &dyn Progress,
) -> Vec<Row> {
    let start = Instant::now();
    let budget = planner::Deadline::after_s(set.budget.as_secs_f64());
    let limited = PlanOptions { deadline: set.plan.deadline.or(Some(budget)), ..set.plan };
    let mut solved: Vec<Solved> = Vec::new();
    let mut tried: Vec<Tried> = Vec::new();
    let mut planned_once = false;
    let mut rows: Vec<Row> = Vec::new();
    for candidate in candidates(plate.size_mm) {
        let t = Instant::now();
        let spent = start.elapsed() > set.budget;
        let new_set = !solved.iter().any(|s| s.clamps_mm == candidate.clamps_mm);
        if spent && new_set {
            rows.push(Row {
                candidate,
                outcome: Outcome::NotTried,
                modes: 0,
                wall_s: 0.0,
                same_as: None,
            });
            progress.advance(1);
            continue;
        }
        if new_set {
            let p = Plate { clamps_mm: candidate.clamps_mm.clone(), ..plate.clone() };
            let all = solver::solve_all(&p, set.terms);
            solved.push(Solved { clamps_mm: candidate.clamps_mm.clone(), plate: p, all });
        }
        let s = solved.iter().find(|s| s.clamps_mm == candidate.clamps_mm).expect("solved above");
        let forced = drive::forced(&s.all, set.count, candidate.drive_mm, plate.damping_ratio);
        let members: Vec<Vec<usize>> =
            forced.resonances.iter().map(|r| r.members.clone()).collect();
        let hinged = plate.boundary == crate::model::plate_file::Boundary::HingedRod;
        let modes = members.len() + usize::from(hinged && !members.is_empty());
        let twin = tried.iter().find(|t| t.answers(&candidate.clamps_mm, &members, &rows[t.row]));
        let (outcome, same_as) = match twin {
            Some(t) => (rows[t.row].outcome.clone(), Some(t.row)),
            None if spent => (Outcome::NotTried, None),
            None => {
                let opt = if planned_once { &limited } else { &set.plan };
                let (outcome, planned) =
                    try_candidate(file, s, &candidate, &forced, part, set, opt);
                planned_once |= planned;
                tried.push(Tried {
                    row: rows.len(),
                    clamps_mm: candidate.clamps_mm.clone(),
                    members,
                });
                (outcome, None)
            }
        };
        let modes = if outcome == Outcome::NotTried { 0 } else { modes };
        rows.push(Row { candidate, outcome, modes, wall_s: t.elapsed().as_secs_f64(), same_as });
        progress.advance(1);
    }
    rows
}

/// One candidate's plate file in memory and its outcome; `true` when the planner ran (the
/// cheap refusals before it do not count as the one plan the budget lets finish).
fn try_candidate(
    file: &PlateFile,
    s: &Solved,
    cand: &Candidate,
    forced: &drive::Forced,
    part: &Part,
    set: &Settings,
    opt: &PlanOptions,
) -> (Outcome, bool) {
    let no = |why: Why, reason: String| Outcome::NoPlan { why, reason };
    if forced.resonances.is_empty() {
        let r = format!(
            "drive_mm = {:?} mm excites none of the first {} modes (it lies on their nodes)",
            cand.drive_mm, set.count
        );
        return (no(Why::NotExcited, r), false);
    }
    let mut table = file.plate.clone();
    table.drive_mm = Some(cand.drive_mm);
    table.clamps_mm = (!cand.clamps_mm.is_empty()).then(|| cand.clamps_mm.clone());
    let rock = match rocking::rocking_mode(&s.plate, &forced.as_solution(&s.all), None) {
        Ok(r) => r,
        Err(e) => return (no(Why::PlateModel, e.to_string()), false),
    };
    let mode = rock.into_iter().chain(forced_entries(forced, &s.all, set.grid)).collect();
    let model = match PlateModel::from_file(&PlateFile { plate: table, mode, learned: None }) {
        Ok(m) => m,
        Err(e) => return (no(Why::PlateModel, e.to_string()), false),
    };
    // Both faces of a part that flips, as `chladni plan` plans it.
    let faces = mirror::faces(std::slice::from_ref(part), false).parts;
    if let Some(e) = faces.iter().find_map(|f| planner::check_input(f, &model).err()) {
        return (no(Why::Part, e.to_string()), false);
    }
    if let Some(reason) = symmetric_refusal(part, &model) {
        return (no(Why::Symmetric, reason), false);
    }
    (plan_on(&model, &faces, opt), true)
}

/// The refusal of a plate whose every mode is centrally symmetric for a part whose period
/// does not divide 180° (a pose and its twin turned 180° about the centre end 180° apart
/// modulo the period, whatever the sequence); `None` otherwise.
pub(crate) fn symmetric_refusal(part: &Part, model: &PlateModel) -> Option<String> {
    let c = planner::symmetry_centre(model)?;
    let p = planner::plan_period(part, model);
    let k = 180.0 / p;
    if (k - k.round()).abs() < 1e-9 {
        return None;
    }
    Some(format!(
        "no whole-plate plan for {} (period {p}°, so a pose and its twin turned 180° are two \
         orientations): {}",
        part.name,
        planner::central_symmetry_sentence(c)
    ))
}

/// Whether the faces of a part (one, or both of a part that flips) get a whole-plate plan on
/// `model`, checked over the whole plate as `opt.refine_rounds` says.
fn plan_on(model: &PlateModel, faces: &[Part], opt: &PlanOptions) -> Outcome {
    outcome(planner::plan_parts(faces, model, opt, &vec![None; faces.len()]))
}

/// A row's outcome from the planner's answer: a plan with what the whole-plate check gave, or
/// the typed failure (a plan the check refused is [`Why::NotWholePlate`] with its share).
fn outcome(planned: Result<planner::Synthesis, PlanFailure>) -> Outcome {
    let no = |why: Why, reason: String| Outcome::NoPlan { why, reason };
    match planned {
        Ok(syn) => {
            // Both faces: the face-up part's prediction (the first of `syn.parts`).
            let (theta, period) = syn.predicted(0);
            Outcome::Plan(Found {
                steps: syn.steps.len(),
                total_s: syn.steps.iter().map(|s| f64::from(s.duration_ms)).sum::<f64>() / 1e3,
                final_orientation_deg: theta,
                period_deg: period,
                whole_plate: syn.whole_plate,
            })
        }
        Err(PlanFailure::NotWholePlate(n)) => {
            no(Why::NotWholePlate(Held::of(&n)), PlanFailure::NotWholePlate(n).to_string())
        }
        Err(PlanFailure::OutOfTime { stage, .. }) => {
            no(Why::OutOfTime, format!("the time budget (--budget-s) ran out at {stage}"))
        }
        Err(e @ PlanFailure::Model(_)) => no(Why::Map, e.to_string()),
        Err(e) => no(Why::NoSequence, e.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn candidates_are_on_the_plate_off_its_mid_lines_and_every_clamp_set_comes_first_once() {
        let c = candidates([300.0, 200.0]);
        assert_eq!(c.len(), DRIVE_FRACTIONS.len() * CLAMP_FRACTIONS.len());
        for k in &c {
            let d = k.drive_mm;
            assert!(d[0] > 0.0 && d[0] < 300.0 && d[1] > 0.0 && d[1] < 200.0);
            assert!((d[0] - 150.0).abs() > 10.0 && (d[1] - 100.0).abs() > 10.0, "{d:?}");
        }
        // Every clamp set once before any comes again (a short budget tries each).
        let n = CLAMP_FRACTIONS.len();
        for (k, w) in c.chunks(n).enumerate() {
            assert!(w.iter().all(|x| x.drive_mm == w[0].drive_mm), "round {k}");
            for (i, x) in w.iter().enumerate() {
                assert_eq!(x.clamps_mm, c[i].clamps_mm, "round {k}");
            }
        }
    }

    #[test]
    fn a_plan_the_whole_plate_check_refuses_is_a_not_whole_plate_row_with_its_share() {
        let n = NotWhole {
            part: "rectangle".into(),
            drops: 48,
            failed: 36,
            region_mm: [21.0, 25.0, 179.0, 175.0],
            ends: "36 inside the plate at another orientation".into(),
            rounds: 1,
            max_rounds: 3,
            feed_mm: Some([33.3, 20.6, 100.0, 100.0]),
            capture: None,
            together: false,
        };
        let message = PlanFailure::NotWholePlate(Box::new(n.clone())).to_string();
        let got = outcome(Err(PlanFailure::NotWholePlate(Box::new(n))));
        let Outcome::NoPlan { why: Why::NotWholePlate(h), reason } = got else { panic!("{got:?}") };
        assert_eq!((h.drops, h.held, h.feed_mm), (48, 12, Some([33.3, 20.6, 100.0, 100.0])));
        assert_eq!(h.share(), 0.25);
        assert_eq!(reason, message, "the planner's own message, feed block included");
        assert!(reason.contains("try --feed"), "{reason}");
        assert_eq!(Why::NotWholePlate(h).name(), "not_whole_plate");
        // A plan keeps what the check gave.
        let w = WholePlate {
            drops: 48,
            held: 48,
            rounds: 2,
            checked: true,
            parts: Vec::new(),
            together: false,
        };
        let syn = planner::Synthesis { whole_plate: Some(w.clone()), ..Default::default() };
        let Outcome::Plan(f) = outcome(Ok(syn)) else { panic!("a plan") };
        assert_eq!(f.whole_plate, Some(w));
    }

    /// The free 300 × 200 plate's forced modes from `drive`, with `clamps`, as a plate model.
    fn free_plate(clamps: &str, drive: [f64; 2]) -> PlateModel {
        let text = format!(
            "[plate]\nname = \"free\"\nsize_mm = [300.0, 200.0]\nthickness_mm = 2.0\n\
             youngs_modulus_gpa = 70.0\ndensity_kg_m3 = 2700.0\npoisson = 0.33\n\
             boundary = \"free\"\n{clamps}"
        );
        let file = PlateFile::parse(&text, "t").unwrap();
        let plate = file.plate.mechanics().unwrap();
        let all = solver::solve_all(&plate, 10);
        let forced = drive::forced(&all, 4, drive, plate.damping_ratio);
        let mode = forced_entries(&forced, &all, 31);
        PlateModel::from_file(&PlateFile { plate: file.plate, mode, learned: None }).unwrap()
    }

    #[test]
    fn a_free_plate_without_clamps_is_refused_for_a_part_without_a_half_turn_symmetry() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/parts");
        let l = Part::load(&root.join("l-shape.json")).unwrap();
        let rect = Part::load(&root.join("rectangle.json")).unwrap();
        // Whatever the drive point, φ² of the free rectangle is centrally symmetric.
        for d in [[90.0, 74.0], [207.0, 56.0]] {
            let plain = free_plate("", d);
            let why = symmetric_refusal(&l, &plain).expect("refused");
            // The planner's sentence (one home), with the part's period and the remedies.
            let c = planner::central_symmetry_sentence([150.0, 100.0]);
            assert!(why.ends_with(&c) && why.contains("period 360°"), "{why}");
            assert!(why.contains("(150.0, 100.0) mm") && why.contains("clamps_mm"), "{why}");
            // A rectangle's twin is itself (period 180°): not refused.
            assert_eq!(symmetric_refusal(&rect, &plain), None);
        }
        // One support off the centre breaks it.
        let clamped = free_plate("clamps_mm = [[30.0, 24.0]]\n", [90.0, 74.0]);
        assert_eq!(symmetric_refusal(&l, &clamped), None);
    }
}
