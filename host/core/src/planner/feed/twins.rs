//! The 180° twins a failed feed-region search leaves, measured rather than assumed: where in
//! the feed region the starts of each twin come from, and whether the pair is a local symmetry
//! of the modes or an artefact of the search.
//!
//! The test: take a rest pose of a twin, turn the part 180° in place and run both under every
//! mode. A part straddling a straight-ish node whose field φ² is the same on both sides turns
//! to lie along it with either end first: the turned part then ends 180° from where the
//! original ends (and, where the field is the same at points mirrored through the rest, at
//! the original's mirror image through it). When every mode keeps the pair 180° apart from both
//! twins' rests, the pair is physical: no next step parts it. When some mode does not, the
//! pair is not forced by the modes: the search's coarse picture (sparse starts, clustering)
//! left it. A pair forced at a rest that lies on a node of every mode (a hinged-rod plate's
//! hinge line) is said to be so, with how many modes leave the part where it rests: no later
//! step takes it off, so what parts the pair must act before the part gets there.

use super::{Search, Tagged, of_part, orientations, spread};
use crate::model::angle::cdist;
use crate::model::pose::Pose;
use crate::planner::symmetry_note;

/// How far from 180° apart (deg) the two ends may be for a mode to keep the pair: the
/// simulation's 5° tolerance (`simulate --tol-deg`), far from the 2° within which a sequence
/// would have to bring them together; integration error alone moves it by about 2° (measured:
/// the hinged-rod crank lever, 2.1°).
const KEEP_DEG: f64 = 5.0;
/// Within this (mm) of the original's mirror image through the rest the turned end counts as
/// mirrored (the cluster distance).
const TWIN_MM: f64 = 2.0;
/// Within this (deg) of a twin's orientation an end belongs to it (the search's tolerance).
const TWIN_DEG: f64 = 2.0;

/// The twins' starts: how many, from how many start points, their start orientations
/// (circular mean and largest distance from it, deg).
struct From {
    count: usize,
    points: usize,
    mean_deg: f64,
    dev_deg: f64,
}

/// The twin test at one rest pose: the modes (of those where both runs count) that keep the
/// part turned 180° in place 180° from the original's end, how many of them also end it at the
/// original's mirror image through the rest position, and the modes that do not keep the
/// pair, with how far off 180° apart (deg). When the rest lies on a node of every mode
/// ([`on_every_node`]): the modes whose run of the original ends on such a node again, within
/// [`KEEP_DEG`] of the rest's orientation, and the most any of them turned it (deg).
struct Test {
    at: Pose,
    kept: Vec<(usize, f64)>,
    mirrored: usize,
    broken: Vec<(usize, f64)>,
    shared_node: Option<(usize, f64)>,
}

/// Whether a plate point lies within the cluster distance ([`TWIN_MM`]) of a node of every
/// mode ([`crate::motion::field::FieldModel::node_distance`]), as every point of a hinged-rod
/// plate's hinge line does.
fn on_every_node(search: &Search, p: Pose) -> bool {
    (search.tracker.sim.fields.iter()).all(|f| f.node_distance([p.x, p.y]) < TWIN_MM)
}

/// The measured sentence on the closest sequence's 180° pair of a one-part search, or `None`
/// (several parts, no pair 180° apart, or a start of the sequence that does not count).
pub(super) fn twins(search: &mut Search, starts: &[Tagged]) -> Option<String> {
    let periods = search.tracker.sim.periods.clone();
    let (_, seq, o) = search.tally.best.clone()?;
    if periods.len() != 1 {
        return None;
    }
    let p = periods[0];
    // Every start through the closest sequence, no clustering (memoised runs): clustering can
    // hide a twin that a start between the cluster's poses reaches.
    let mut ends = starts.to_vec();
    for &k in &seq {
        let runs = search.tracker.rests(k, &ends)?;
        ends = ends.iter().zip(&runs).map(|(q, r)| (q.0, r.pose)).collect();
    }
    let all = orientations(&of_part(&ends, 0), p);
    let pair = |a: f64, b: f64| cdist(a, b, p) > 1.0 && cdist(a + 180.0, b, p) < 1.0;
    let (a, b) = all.iter().find_map(|&a| all.iter().find(|&&b| pair(a, b)).map(|&b| (a, b)))?;
    let hidden = o[0].len() < all.len();
    let near = |q: &Tagged, t: f64| cdist(q.1.theta.to_degrees(), t, p) < TWIN_DEG;
    let from = |t: f64| -> From {
        let idx: Vec<usize> = (0..ends.len()).filter(|&i| near(&ends[i], t)).collect();
        let sel: Vec<Tagged> = idx.iter().map(|&i| starts[i]).collect();
        let mut pts: Vec<[u64; 2]> =
            sel.iter().map(|q| [q.1.x.to_bits(), q.1.y.to_bits()]).collect();
        pts.sort_unstable();
        pts.dedup();
        let (mean_deg, dev_deg) = spread(&of_part(&sel, 0), 360.0);
        From { count: sel.len(), points: pts.len(), mean_deg, dev_deg }
    };
    let (fa, fb) = (from(a), from(b));
    let rep = |t: f64| ends.iter().find(|q| near(q, t)).copied();
    let tests: Vec<Test> =
        [rep(a), rep(b)].into_iter().flatten().map(|r| test(search, r)).collect();
    let mut msg = sentence((a, b), (&fa, &fb), &tests, starts.len(), (&seq, p));
    if hidden {
        let list = all.iter().map(|v| format!("{v:.1}°")).collect::<Vec<_>>().join(", ");
        msg = format!(
            "tracked without clustering, modes {} leave {list}; {msg}",
            mode_list(seq.iter().copied())
        );
    }
    Some(msg)
}

/// Runs the rest pose `r` and the part turned 180° in place under every mode and compares the
/// turned run's end with the original's end turned 180° (and mirrored through the rest).
fn test(search: &mut Search, r: Tagged) -> Test {
    let (i, at) = r;
    let nm = search.tracker.sim.plate.modes.len();
    let turned = (i, Pose { theta: at.theta + std::f64::consts::PI, ..at });
    let jobs: Vec<(usize, Tagged)> = (0..nm).flat_map(|k| [(k, r), (k, turned)]).collect();
    let outs = search.tracker.outcomes(&jobs, false);
    let p = search.tracker.sim.periods[i];
    let shared = on_every_node(search, at);
    let (mut kept, mut mirrored, mut broken) = (Vec::new(), 0, Vec::new());
    let (mut stays, mut turned_most) = (0, 0.0f64);
    for k in 0..nm {
        let (o, t) = (&outs[2 * k], &outs[2 * k + 1]);
        if !search.tracker.sim.ok(i, o) || !search.tracker.sim.ok(i, t) {
            continue;
        }
        let turned_by = cdist(o.pose.theta.to_degrees(), at.theta.to_degrees(), p);
        if shared && turned_by < KEEP_DEG && on_every_node(search, o.pose) {
            stays += 1;
            turned_most = turned_most.max(turned_by);
        }
        let (mx, my) = (2.0 * at.x - o.pose.x, 2.0 * at.y - o.pose.y);
        let dth = cdist(t.pose.theta.to_degrees(), o.pose.theta.to_degrees() + 180.0, p);
        let dpos = (t.pose.x - mx).hypot(t.pose.y - my);
        if dth < KEEP_DEG {
            kept.push((k, dth));
            mirrored += usize::from(dpos < TWIN_MM);
        } else {
            broken.push((k, dth));
        }
    }
    let shared_node = shared.then_some((stays, turned_most));
    Test { at, kept, mirrored, broken, shared_node }
}

/// `modes 1, 3`.
fn mode_list(ks: impl Iterator<Item = usize>) -> String {
    ks.map(|k| (k + 1).to_string()).collect::<Vec<_>>().join(", ")
}

/// The failure's sentence: where each twin's starts come from, and what the twin test found.
fn sentence(
    (a, b): (f64, f64),
    (fa, fb): (&From, &From),
    tests: &[Test],
    n: usize,
    (seq, p): (&[usize], f64),
) -> String {
    let whence = |t: f64, f: &From| {
        format!(
            "{t:.1}° from {} of {n} starts ({} start points; start orientations {:.0}° ± {:.0}°)",
            f.count, f.points, f.mean_deg, f.dev_deg
        )
    };
    let after = mode_list(seq.iter().copied());
    let mut msg = format!("after modes {after}: {}, {}", whence(a, fa), whence(b, fb));
    let broken: Vec<&(usize, f64)> = tests.iter().flat_map(|t| &t.broken).collect();
    let at = |t: &Test| format!("({:.1}, {:.1}) mm", t.at.x, t.at.y);
    let places = tests.iter().map(at).collect::<Vec<_>>().join(" and ");
    if broken.is_empty() && tests.iter().all(|t| !t.kept.is_empty()) {
        let nm = tests[0].kept.len();
        let mirrored = tests.iter().map(|t| t.mirrored).min().unwrap_or(0);
        let off = tests.iter().flat_map(|t| &t.kept).map(|k| k.1).fold(0.0, f64::max);
        msg += &format!(
            "; measured, a local symmetry: turned 180° in place at its rest {places}, the part \
             ends 180° from the original's end under all {nm} modes (at most {off:.1}° off, bound {KEEP_DEG}°; under \
             {mirrored} also at its mirror image through the rest, within {TWIN_MM} mm), so no \
             next step parts the pair"
        );
        let held = |t: &Test| t.shared_node.filter(|s| s.0 == t.kept.len()).map(|s| s.1);
        if let Some(turned) = tests.iter().map(held).try_fold(0.0f64, |m, h| h.map(|h| m.max(h))) {
            // The generic remedies do not apply: a clamp or a drive point leaves a support
            // line a node of every mode (measured on the hinged rod, docs/plan.md).
            msg += &format!(
                "; both rests lie within {TWIN_MM} mm of a node every mode shares (as a \
                 hinged-rod plate's hinge line does), and under each of the {nm} modes the part \
                 ends on it again, turned by at most {turned:.1}°: no later step takes it off, so \
                 what parts the pair must keep the part from reaching that node; {a:.2}° and \
                 {b:.2}° are 180° twins on it: a drive point leaves every mode's nodes where they \
                 are, and so does a clamp when the node is a support line (a hinge); what parts \
                 them is a feed region from which the modes bring the part to rest before it \
                 reaches the node, or another plate"
            );
        } else if let Some(note) = symmetry_note(None, &[a, b], p, true) {
            msg += &format!("; {note}");
        }
    } else {
        let worst = broken.iter().map(|b| b.1).fold(0.0, f64::max);
        let ks = mode_list({
            let mut k: Vec<usize> = broken.iter().map(|b| b.0).collect();
            k.sort_unstable();
            k.dedup();
            k.into_iter()
        });
        msg += &format!(
            "; measured, not a symmetry of every mode: turned 180° at its rest {places}, the part \
             does not end 180° from the original's end under modes {ks} (up to {worst:.1}° off), \
             so the pair is left by the search (its tracked starts and clustering), not forced \
             by the modes"
        );
    }
    msg
}

#[cfg(test)]
mod tests {
    use super::super::{Search, Tally, Tracker};
    use super::*;
    use crate::model::part::Part;
    use crate::model::plate::PlateModel;
    use crate::motion::body::Body;
    use std::collections::HashSet;

    /// On a straight node with the same field on both sides (four-lines' "vertical", x = 150
    /// mm) the triangle turned 180° at its rest stays a rest, turned and mirrored: that mode
    /// keeps the pair. A node with unequal gains (`gain_left` ≠ `gain_right`) is one-sided: some
    /// mode of the plate does not keep it, so the test reports the pair as not forced.
    #[test]
    fn the_twin_test_tells_an_even_node_from_a_one_sided_one() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate = PlateModel::load(&path.join("../../examples/plates/four-lines.toml")).unwrap();
        let part = Part::load(&path.join("../../examples/parts/triangle.json")).unwrap();
        let tracker = Tracker::new(
            vec![Body::with_samples(&part, crate::motion::body::PLANNER_BODY_SAMPLES)],
            &plate,
            vec![360.0],
        );
        let mut s =
            Search { tracker, deadline: None, seen: HashSet::new(), tally: Tally::default() };
        let start = (0, Pose { x: 140.0, y: 100.0, theta: 0.5 });
        let rest = s.tracker.rests(0, &[start]).unwrap()[0].pose;
        assert!((rest.x - 150.0).abs() < 15.0, "rests across the node: {rest:?}");
        let t = test(&mut s, (0, rest));
        let on = t.kept.iter().find(|k| k.0 == 0).expect("the even node keeps the pair");
        assert!(on.1 < 1.0, "{on:?}");
        assert!(t.mirrored >= 1);
        // "horizontal", gains 1.8 and 1.0: the turned part ends where the original does.
        assert!(t.broken.iter().any(|b| b.0 == 1 && b.1 > 90.0), "{:?}", t.broken);
        let msg = sentence((10.0, 190.0), (&from(3), &from(2)), &[t], 5, (&[0], 360.0));
        assert!(msg.contains("not a symmetry of every mode"), "{msg}");
    }

    /// The hinged-rod crank lever's pair (docs/plan.md, "The step bound"): its rest at
    /// (150, 50) mm lies on the hinge line, a node of every mode, and every mode ends the part
    /// on that line again, so the sentence says no later step takes it off. 100 mm to the
    /// left, off the hinge, not every mode has a node.
    #[test]
    fn a_rest_on_a_node_every_mode_shares_is_named() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let plate =
            PlateModel::load(&path.join("../../examples/plates/hinged-rod-6-modes.toml")).unwrap();
        let part =
            Part::load(&path.join("../../examples/parts/ordinary/crank-lever.json")).unwrap();
        let tracker = Tracker::new(
            vec![Body::with_samples(&part, crate::motion::body::PLANNER_BODY_SAMPLES)],
            &plate,
            vec![360.0],
        );
        let mut s =
            Search { tracker, deadline: None, seen: HashSet::new(), tally: Tally::default() };
        let up = std::f64::consts::FRAC_PI_2;
        assert!(!on_every_node(&s, Pose { x: 50.0, y: 50.0, theta: up }));
        let tests: Vec<Test> = [up, 3.0 * up]
            .iter()
            .map(|&theta| test(&mut s, (0, Pose { x: 150.0, y: 50.0, theta })))
            .collect();
        for t in &tests {
            assert!(t.broken.is_empty(), "every mode keeps the pair: {:?}", t.broken);
            let (stays, turned) = t.shared_node.expect("the hinge line is a node of every mode");
            assert_eq!(stays, t.kept.len());
            assert!(turned < KEEP_DEG, "{turned}");
        }
        let msg = sentence((90.0, 270.0), (&from(3), &from(2)), &tests, 5, (&[0], 360.0));
        assert!(msg.contains("a node every mode shares") && msg.contains("no later step"), "{msg}");
        // Its remedy is its own: not the clamps and drive point of a local symmetry.
        assert!(msg.contains("90.00° and 270.00° are 180° twins on it"), "{msg}");
        assert!(msg.contains("a feed region from which") && !msg.contains("clamps_mm"), "{msg}");
    }

    fn from(count: usize) -> From {
        From { count, points: 1, mean_deg: 0.0, dev_deg: 0.0 }
    }
}
