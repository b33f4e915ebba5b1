//! `chladni simulate` of parts on the plate together: a plan for several parts drops them
//! all in each trial, and `--copies N` drops N copies of one part (bulk feeding), with
//! contacts between them (docs/motion.md, "Contacts between parts", "Bulk feeding").

use crate::cli::progress::Bar;
use std::process::ExitCode;

use chladni_core::model::feed_region::FeedRegion;
use chladni_core::model::part::Part;
use chladni_core::model::part::mirror::{Face, Faces};
use chladni_core::model::plan_file::PlanFile;
use chladni_core::model::plate::PlateModel;
use chladni_core::motion::body::Body;
use chladni_core::motion::bulk::{self, BulkReport, CannotPlace, Drop, Drops};
use chladni_core::motion::field::FieldModel;
use chladni_core::motion::montecarlo::Trials;
use chladni_core::motion::shape::Pieces;
use chladni_core::motion::steps::SimStep;

use super::{SimulateArgs, bad};

/// What every trial runs on: the plate, its fields, the plan's steps, where parts start.
pub(super) struct Sim<'a> {
    pub plate: &'a PlateModel,
    pub fields: &'a [FieldModel],
    pub steps: &'a [SimStep],
    pub feed: Option<&'a FeedRegion>,
}

/// A bar for `n` drops (hidden for JSON output).
fn drop_bar(n: u32, hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(n as u64);
    if let Ok(style) =
        indicatif::ProgressStyle::with_template("drops {wide_bar} {pos}/{len} [{elapsed}]")
    {
        bar.set_style(style);
    }
    bar
}

impl SimulateArgs {
    /// `n` drops of `bodies` from `seed`, each a run of the plan with contacts.
    fn drops(
        &self,
        bodies: &[&Body],
        sim: &Sim<'_>,
        (n, seed): (u32, u64),
    ) -> Result<Drops, CannotPlace> {
        let pieces: Vec<Pieces> = bodies.iter().map(|b| Pieces::of(b)).collect();
        let refs: Vec<&Pieces> = pieces.iter().collect();
        let d = Drop {
            bodies,
            pieces: &refs,
            plate: sim.plate,
            fields: sim.fields,
            steps: sim.steps,
            feed: sim.feed,
        };
        let bar = drop_bar(n, self.json);
        let out = bulk::run_drops(&d, n, seed, &Bar(bar.clone()));
        bar.finish_and_clear();
        out
    }

    /// A refused drop: the named error (and its JSON object with --json), exit 2.
    fn cannot_place(&self, e: &CannotPlace) -> anyhow::Error {
        if self.json {
            crate::cli::print_failure_value(chladni_media::shapes::plan::cannot_place_json(e));
        }
        bad(e.to_string())
    }

    /// A plan for several parts: every trial drops all of them together (one each, contacts
    /// between them); each face's trials, in the plan's order. A part planned on both faces
    /// lies face up in the first ⌈N/2⌉ drops and flipped in the other ⌊N/2⌋ (the seeds of
    /// [`face_trials`](super::face_trials)), every other part in all N. `None`: one part
    /// (on one face or on both: its faces never meet, so they run as separate trials).
    pub(super) fn together(
        &self,
        parts: &[Part],
        faces: &Faces,
        sim: &Sim<'_>,
    ) -> anyhow::Result<Option<Vec<Trials>>> {
        let sources = faces.of.iter().map(|o| o.source + 1).max().unwrap_or(0);
        if sources < 2 {
            return Ok(None);
        }
        let runs = super::face_trials(faces, self.trials, self.seed);
        let mut out = vec![Trials::default(); parts.len()];
        let mut overlap: f64 = 0.0;
        for (face, (n, seed)) in face_groups(faces, &runs) {
            // The entries on the plate in this group: the parts that do not flip, and the
            // flipping parts on this face.
            let on: Vec<usize> =
                (0..parts.len()).filter(|&i| faces.of[i].face.is_none_or(|f| f == face)).collect();
            let bodies: Vec<Body> = on.iter().map(|&i| Body::new(&parts[i])).collect();
            let refs: Vec<&Body> = bodies.iter().collect();
            let drops = self.drops(&refs, sim, (n, seed)).map_err(|e| self.cannot_place(&e))?;
            overlap = overlap.max(drops.max_overlap_mm);
            for (&i, t) in on.iter().zip(drops.per_body) {
                append(&mut out[i], t);
            }
        }
        if !self.json {
            let split = if faces.of.iter().any(|o| o.face.is_some()) {
                format!(
                    " (parts on both faces: face up in {}, flipped in {})",
                    self.trials.div_ceil(2),
                    self.trials / 2
                )
            } else {
                String::new()
            };
            println!(
                "together   {sources} parts in each of {} trials, seed {}{split}; deepest final \
                 overlap {overlap:.4} mm",
                self.trials, self.seed,
            );
        }
        Ok(Some(out))
    }

    /// `--copies N`: N copies of one part in each of `--trials` drops.
    pub(super) fn run_copies(
        &self,
        n: u32,
        parts: &[Part],
        faces: &Faces,
        sim: &Sim<'_>,
        views: &[PlanFile],
    ) -> anyhow::Result<ExitCode> {
        let (Some(part), Some(view), 1) = (parts.first(), views.first(), parts.len()) else {
            return Err(bad(format!(
                "--copies drops copies of one part on one face; {} parts or faces given{}",
                parts.len(),
                if faces.of.iter().any(|o| o.face.is_some()) { " (both faces)" } else { "" }
            )));
        };
        if self.plot.is_some() {
            return Err(bad("--plot draws one part; --copies drops several".into()));
        }
        let body = Body::new(part);
        let bodies = vec![&body; n as usize];
        let drops = self
            .drops(&bodies, sim, (self.trials, self.seed))
            .map_err(|e| self.cannot_place(&e))?;
        let report = BulkReport::new(&drops, view, sim.steps, self.seed, self.tol_deg);
        if self.json {
            println!("{}", serde_json::to_string(&report)?);
            return Ok(ExitCode::SUCCESS);
        }
        println!("part       {} × {n} copies", part.name);
        println!(
            "plan       {} step(s), {:.1} s, {} drops, seed {}",
            sim.steps.len(),
            report.plan_s,
            report.trials,
            self.seed
        );
        match (report.oriented, report.parts_per_min) {
            (Some(f), ppm) => println!(
                "oriented   {:.1} % within {}° of the predicted orientation; {} parts/min",
                100.0 * f,
                self.tol_deg,
                ppm.map_or("-".into(), |p| format!("{p:.2}"))
            ),
            (None, _) => println!("oriented   - (the plan file predicts no final orientation)"),
        }
        println!("lost       {} copies off an open edge", report.lost);
        println!("overlap    deepest final {:.4} mm", report.max_overlap_mm);
        Ok(ExitCode::SUCCESS)
    }
}

/// The groups of drops of a plan for several parts: with no part on both faces one group,
/// every part in all the trials; else the face-up group and the flipped group, each with
/// the trials and seed of that face (`runs`: [`face_trials`](super::face_trials)).
fn face_groups(faces: &Faces, runs: &[(u32, u64)]) -> Vec<(Face, (u32, u64))> {
    let of = |face: Face| faces.of.iter().position(|o| o.face == Some(face)).map(|i| runs[i]);
    match (of(Face::Up), of(Face::Flipped)) {
        (Some(up), Some(flipped)) => vec![(Face::Up, up), (Face::Flipped, flipped)],
        _ => vec![(Face::Up, runs.first().copied().unwrap_or_default())],
    }
}

/// Appends `more` trials to `to` (starts, finals, lost and poses at steps; a group's drops
/// keep no traces).
fn append(to: &mut Trials, more: Trials) {
    to.starts.extend(more.starts);
    to.finals.extend(more.finals);
    to.lost.extend(more.lost);
    to.examples.extend(more.examples);
    to.traces.extend(more.traces);
    if to.step_ends.is_empty() {
        to.step_ends = more.step_ends;
    }
}
