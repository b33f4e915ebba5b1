//! `chladni plan --copies N`: the planner's candidates ranked by oriented parts per minute of
//! N copies dropped together ([`chladni_core::planner::copies`]); the CLI only wires and prints.

use crate::cli::progress::Bar;
use chladni_core::model::part::Part;
use chladni_core::model::plate::PlateModel;
use chladni_core::planner::copies::{
    self as bulk_plan, RANK_DROPS, RANK_SEED, RANK_TOL_DEG, Ranked,
};
use chladni_core::planner::{PlanOptions, Synthesis};

use super::{PlanArgs, bad};

/// A bar over the scoring drops (hidden for JSON output).
fn drops_bar(n: u64, hidden: bool) -> indicatif::ProgressBar {
    if hidden {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(n);
    if let Ok(style) = indicatif::ProgressStyle::with_template(
        "copies: scoring candidate plans {wide_bar} {pos}/{len} drops [{elapsed}]",
    ) {
        bar.set_style(style);
    }
    bar
}

impl PlanArgs {
    /// With `--copies N`: the candidates of `syn` scored and the best chosen (`None`
    /// without the flag). One part on one face only (checked before planning).
    pub(super) fn for_copies(
        &self,
        parts: &[Part],
        plate: &PlateModel,
        opt: &PlanOptions,
        syn: Synthesis,
    ) -> anyhow::Result<(Synthesis, Option<Ranked>)> {
        let (Some(n), [part]) = (self.copies, parts) else { return Ok((syn, None)) };
        let syns = bulk_plan::candidates(part, plate, opt, syn);
        let bar = drops_bar(syns.len() as u64 * u64::from(RANK_DROPS), self.json);
        let ranked =
            bulk_plan::rank(part, plate, syns, (n as usize, RANK_DROPS), &Bar(bar.clone()));
        bar.finish_and_clear();
        let ranked = ranked.map_err(|e| bad(format!("--copies {n}: {e}")))?;
        let chosen = ranked.candidates[ranked.chosen].syn.clone();
        Ok((chosen, Some(ranked)))
    }

    /// `--copies` refused with several parts or faces and with `--feed` (before planning).
    pub(super) fn check_copies(&self, faces: usize) -> anyhow::Result<()> {
        if self.copies.is_some() && faces > 1 {
            return Err(bad(format!(
                "--copies ranks plans for copies of one part on one face; {faces} parts or faces \
                 to plan"
            )));
        }
        if self.copies.is_some() && self.feed.is_some() {
            return Err(bad("--copies ranks orientation-set plans: not with --feed".into()));
        }
        Ok(())
    }
}

/// The plan's JSON with the bulk numbers: its shape is the library's.
pub(super) use chladni_media::shapes::plan::with_bulk;

/// The candidates as lines under the plan table.
pub(super) fn print_bulk(ranked: &Option<Ranked>) {
    let Some(r) = ranked else { return };
    let n = r.candidates[r.chosen].report.copies;
    println!(
        "copies     {n} dropped together, {RANK_DROPS} drops, seed {RANK_SEED}, oriented within \
         {RANK_TOL_DEG}°:"
    );
    for (i, s) in r.candidates.iter().enumerate() {
        let pct = s.report.oriented.map_or("-".into(), |f| format!("{:.1} %", 100.0 * f));
        let ppm = s.report.parts_per_min.map_or("-".into(), |p| format!("{p:.2}"));
        println!(
            "  {} θ = {:>8.3}°  {:>7.1} s  oriented {pct:>7}  lost {}  {ppm} parts/min",
            if i == r.chosen { "chosen" } else { "      " },
            s.syn.final_orientation_deg,
            s.report.plan_s,
            s.report.lost
        );
    }
}
