//! Why no plan was found ([`PlanFailure`]) and the explanation of a search that ended
//! without one.

use super::Problem;
use super::maps::{MapError, StepMap};
use super::margin::margin_of;
use super::options::PlanOptions;
use super::symmetry::symmetry_note;
use crate::model::angle::cdist;

/// Why no plan was found.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanFailure {
    /// Exhaustive search ended without a single orientation.
    #[error("no plan with these modes: {0}")]
    NoPlan(String),
    /// A mode cannot be analysed for this part (its straight-node map could not be made).
    #[error(transparent)]
    Model(#[from] MapError),
    /// No plan of at most `max_steps` steps ends at the goal orientation.
    #[error(
        "{part}: no plan of at most {max_steps} steps ends at {goal_deg}° (mod {period_deg}°, \
         within {tol_deg}°); reachable final orientations: {}{}",
        list_deg(reachable_deg),
        nearest_deg.map(|n| format!("; nearest {n:.2}°")).unwrap_or_default()
    )]
    GoalUnreachable {
        /// The part whose goal is out of reach.
        part: String,
        /// Its goal (deg).
        goal_deg: f64,
        /// Its period (deg).
        period_deg: f64,
        /// How near a final orientation must be to the goal (deg, the margin).
        tol_deg: f64,
        /// The longest plan considered.
        max_steps: usize,
        /// What is reachable (deg; for several parts, with the other parts at their goals).
        reachable_deg: Vec<f64>,
        /// The reachable orientation nearest to the goal.
        nearest_deg: Option<f64>,
    },
    /// No plan that meets the orientation goals fixes the final position.
    #[error(
        "{part}: no plan of at most {max_steps} steps fixes the final position (to within \
         {tol_mm} mm): a straight node moves the part only across itself, so the last two \
         straight nodes must be perpendicular, or non-parallel ones alternated until the \
         spread along them is below {tol_mm} mm"
    )]
    PositionNotFixed {
        /// The part.
        part: String,
        /// The longest plan considered.
        max_steps: usize,
        /// The position tolerance (mm).
        tol_mm: f64,
    },
    /// The simulation does not confirm the predicted final position.
    #[error(
        "{part}: the plan's predicted position ({:.2}, {:.2}) mm is not confirmed: simulated \
         starts end up to {worst_mm:.2} mm from it",
        predicted_mm[0], predicted_mm[1]
    )]
    PositionNotConfirmed {
        /// The part.
        part: String,
        /// The predicted position (mm).
        predicted_mm: [f64; 2],
        /// The largest simulated distance from it (mm).
        worst_mm: f64,
    },
    /// Several parts: every part has a plan alone, but no sequence brings all of them to one
    /// orientation each.
    #[error(
        "no sequence{} brings every part to one orientation ({searched} states searched); the \
         closest keeps {}",
        max_steps.map(|n| format!(" of up to {n} mode(s) (--max-steps {n})")).unwrap_or_default(),
        apart.iter().map(|(n, d, p)| format!("{n} at {} (mod {p}°)", list_deg(d))).collect::<Vec<_>>().join(", ")
    )]
    PartsApart {
        /// The parts left with several orientations in the closest state: (name,
        /// orientations in deg, period).
        apart: Vec<(String, Vec<f64>, f64)>,
        /// States searched.
        searched: usize,
        /// The longest sequence searched when the search has a step bound (the feed-region
        /// search, `--max-steps`); `None` for the search over orientation sets, which has none.
        max_steps: Option<usize>,
    },
    /// A whole-plate plan on grid modes that does not hold from every drop point, after
    /// refining the maps with those drops ([`super::whole`]).
    #[error(transparent)]
    NotWholePlate(Box<super::whole::NotWhole>),
    /// The time limit ([`super::Deadline`], `--max-time-s`) ran out before an answer.
    #[error(
        "no answer within {limit_s} s (--max-time-s {limit_s}): stopped at {stage}; give it \
         longer with a larger --max-time-s"
    )]
    OutOfTime {
        /// The limit (s).
        limit_s: f64,
        /// What the planner was doing.
        stage: String,
    },
}

/// `a°, b°, …` (two decimals).
fn list_deg(v: &[f64]) -> String {
    if v.is_empty() {
        return "none".into();
    }
    v.iter().map(|d| format!("{d:.2}°")).collect::<Vec<_>>().join(", ")
}

impl Problem {
    /// Why `search` (of this problem alone, or with it first) reached no plan: [`Self::explain`]
    /// of the first part's sets the search reached.
    pub(crate) fn explain_reach(
        &self,
        search: &super::search::Search<'_>,
        reach: &super::search::Reach,
        opt: &PlanOptions,
    ) -> String {
        let nodes: Vec<(Vec<usize>, usize, usize)> =
            reach.nodes.iter().map(|n| (n.0[0].clone(), n.1, n.2)).collect();
        self.explain(&nodes, &search.unis[0].vals, opt)
    }

    /// Why the search over `nodes` (sets of ids into `uni`) found no plan: the smallest set
    /// left, and what each mode does to it.
    pub(crate) fn explain(
        &self,
        nodes: &[(Vec<usize>, usize, usize)],
        uni: &[f64],
        opt: &PlanOptions,
    ) -> String {
        let p = self.period;
        let Some(best) = nodes.iter().min_by_key(|n| n.0.len()) else {
            return "every mode leaves the part free to turn (neutral) or has no stable orientation".into();
        };
        let set: Vec<f64> = best.0.iter().map(|&u| uni[u]).collect();
        let list = set.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
        let mut why = Vec::new();
        // Each margin rule once, with the modes it blocked (1-based).
        let mut rules: Vec<(String, Vec<usize>)> = Vec::new();
        for (k, map) in self.maps.iter().enumerate() {
            if map.neutral {
                why.push(format!("mode {} is neutral (keeps every orientation)", k + 1));
                continue;
            }
            let blocked =
                set.iter().find_map(|&t| map.apply_all(t, opt.margin_deg).err().map(|d| (t, d)));
            match blocked {
                Some((t, _)) if map.near_boundary(t, opt.margin_deg).is_ok() => why.push(format!(
                    "mode {}: a simulated approach from {t:.2}° does not come to rest",
                    k + 1
                )),
                Some((t, d)) => {
                    let (kept, rule) = margin_rule(map, opt);
                    why.push(format!(
                        "mode {} may not act on {t:.2}° ({d:.2}° from a basin boundary, under \
                         its {kept})",
                        k + 1
                    ));
                    match rules.iter_mut().find(|r| r.0 == rule) {
                        Some(r) => r.1.push(k + 1),
                        None => rules.push((rule, vec![k + 1])),
                    }
                }
                None => why.push(keeps_apart(k, map, &set, opt.margin_deg, p)),
            }
        }
        let rules = if rules.is_empty() {
            String::new()
        } else {
            let each: Vec<String> =
                rules.iter().map(|(rule, ks)| format!("{}: {rule}", modes_label(ks))).collect();
            format!(" ({})", each.join("; "))
        };
        let note = symmetry_note(self.symmetry_centre, &set, p, false)
            .map(|n| format!(". {n}"))
            .unwrap_or_default();
        format!(
            "orientations {list} (mod {p}°) stay apart after every sequence ({} sets searched): \
             {}{rules}{note}",
            nodes.len(),
            why.join("; ")
        )
    }
}

/// The margin rule a map's steps obey, stated: its margin and where it came from
/// ([`margin_of`]: `--margin-deg`, its default, or the mode's resampling evidence), plus the
/// map's sampling allowance (simulated maps: half the spacing of their start orientations;
/// dynamic maps: the bisection's resolution), how far a sampled boundary may lie from where it
/// was found.
/// Returns the distance kept (`5.00°`) and the rule.
fn margin_rule(map: &StepMap, opt: &PlanOptions) -> (String, String) {
    let slack = map.slack;
    let m = margin_of(map, opt.margin_deg, opt.margin_auto);
    let (margin, what) = (m.deg, m.describe());
    let (kept, made_of) = if slack > 1e-9 {
        (
            format!("{:.2}°", margin + slack),
            format!("{what} plus {slack:.2}°, how far the map's sampled boundaries may be off"),
        )
    } else {
        (format!("{margin}°"), what)
    };
    let rule = format!(
        "a step keeps every orientation at least {kept} ({made_of}) from its basin boundaries"
    );
    (kept, rule)
}

/// `mode 2` or `modes 2, 4` (1-based mode numbers).
fn modes_label(ks: &[usize]) -> String {
    let list = ks.iter().map(usize::to_string).collect::<Vec<_>>().join(", ");
    if ks.len() == 1 { format!("mode {list}") } else { format!("modes {list}") }
}

/// Why mode `k` leaves the orientations `set` apart: their images, and which orientation a
/// dynamic map sends to several rests depending on the side the part approaches from.
fn keeps_apart(k: usize, map: &StepMap, set: &[f64], margin: f64, p: f64) -> String {
    let images: Vec<(f64, Vec<f64>)> =
        set.iter().filter_map(|&t| Some((t, map.apply_all(t, margin).ok()?))).collect();
    let mut img: Vec<f64> = images.iter().flat_map(|(_, v)| v).map(|v| v.rem_euclid(p)).collect();
    img.sort_by(f64::total_cmp);
    img.dedup_by(|a, b| cdist(*a, *b, p) < 1e-3);
    let fmt = |v: &[f64]| v.iter().map(|v| format!("{v:.2}°")).collect::<Vec<_>>().join(", ");
    let mut msg = format!("mode {} keeps them apart ({})", k + 1, fmt(&img));
    if let Some((t, v)) = images.iter().find(|(_, v)| v.len() > 1) {
        msg += &format!(
            ", sending {t:.2}° to {} depending on the side it approaches the node from",
            fmt(v).replacen(", ", " or ", 1)
        );
    }
    msg
}
