//! `chladni simulate` of parts on the plate together: a plan for several parts drops them
//! all in each trial, and `--copies N` drops N copies of one part (bulk feeding), with
//! contacts between them (docs/motion.md, "Contacts between parts", "Bulk feeding").

use std::process::ExitCode;

use chladni::model::feed_region::FeedRegion;
use chladni::model::part::Part;
use chladni::model::part::mirror::Faces;
use chladni::model::plan_file::PlanFile;
use chladni::model::plate::PlateModel;
use chladni::motion::bulk::{self, BulkReport, CannotPlace, Drop, Drops};
use chladni::motion::montecarlo::Trials;
use chladni::motion::shape::Pieces;
use chladni::motion::sim::{Body, FieldModel, SimStep};

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
    /// The drops of `bodies` from the seed, each a run of the plan with contacts.
    fn drops(&self, bodies: &[&Body], sim: &Sim<'_>) -> Result<Drops, CannotPlace> {
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
        let bar = drop_bar(self.trials, self.json);
        let out = bulk::run_drops(&d, self.trials, self.seed, || bar.inc(1));
        bar.finish_and_clear();
        out
    }

    /// A refused drop: the named error (and its JSON object with --json), exit 2.
    fn cannot_place(&self, e: &CannotPlace) -> anyhow::Error {
        if self.json {
            crate::cli::print_failure_value(chladni::shapes::plan::cannot_place_json(e));
        }
        bad(e.to_string())
    }

    /// A plan for several parts, none of them on both faces: every trial drops all of them
    /// together (one each); each part's trials, in the plan's order. `None`: one part, or
    /// faces (a part lands on one face or the other, so its faces run as separate trials).
    pub(super) fn together(
        &self,
        parts: &[Part],
        faces: &Faces,
        sim: &Sim<'_>,
    ) -> anyhow::Result<Option<Vec<Trials>>> {
        if parts.len() < 2 || faces.of.iter().any(|o| o.face.is_some()) {
            return Ok(None);
        }
        let bodies: Vec<Body> = parts.iter().map(Body::new).collect();
        let refs: Vec<&Body> = bodies.iter().collect();
        let drops = self.drops(&refs, sim).map_err(|e| self.cannot_place(&e))?;
        if !self.json {
            println!(
                "together   {} parts in each of {} trials, seed {}; deepest final overlap {:.4} mm",
                parts.len(),
                self.trials,
                self.seed,
                drops.max_overlap_mm
            );
        }
        Ok(Some(drops.per_body))
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
        let drops = self.drops(&bodies, sim).map_err(|e| self.cannot_place(&e))?;
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
