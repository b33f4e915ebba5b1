//! What a command leaves to do, read from the modes' velocities at the parts: the drive time
//! a combination of modes would need to bring every part from where the command leaves it to
//! its goal, and the error no combination removes.
//!
//! Why: a cycle's choice by cost alone ([`crate::steer::cost`]) takes the command that
//! brings the parts nearest their goals now. With several parts that is often a dead end: the
//! command that brings the far part nearer takes the others off theirs, and from where the
//! nearest command leaves them no mode moves all of them the right way. Over a short time a
//! burst moves each part by its mode's velocity there times the burst's length, so a sequence
//! of bursts moves the parts by (nearly) the sum of their modes' velocities times their
//! lengths: the bursts left to drive are the non-negative lengths that best bring the
//! residual to zero, a bounded non-negative least-squares problem (3 rows per part, a
//! column per mode), solved by coordinate descent. A command is then valued by what it leaves:
//! that residual's cost plus the time to drive it.

use crate::model::angle::signed_diff;
use crate::model::pose::Pose;
use crate::steer::cost::{PartGoal, near_quadratic};

/// The longest drive (s) one mode's column may be given: the velocities hold near the
/// parts' poses only (a part under a mode runs to its node and stops).
pub const MODE_TIME_CAP_S: f64 = 4.0;

/// Coordinate-descent sweeps of the least-squares solve (12 modes converge in tens).
const SWEEPS: usize = 60;

/// Each mode's column: every part's velocity under it (mm/s along x and y, and its turn rate
/// in mm/s at the part's mm per degree), each row scaled by the square root of the part's
/// weight so that the solve weighs parts as the cost does.
#[derive(Debug, Clone)]
pub struct Velocities {
    cols: Vec<Vec<f64>>,
}

impl Velocities {
    /// From each mode's predicted poses after a short burst `burst_s` (`after[mode][part]`)
    /// from `parts`' poses.
    pub fn from_short_burst(parts: &[PartGoal], after: &[Vec<Pose>], burst_s: f64) -> Velocities {
        let cols = after
            .iter()
            .map(|poses| {
                parts
                    .iter()
                    .zip(poses)
                    .flat_map(|(p, q)| rows(p, p.pose, *q).map(|d| d / burst_s))
                    .collect()
            })
            .collect();
        Velocities { cols }
    }

    /// Mode `mode`'s column's length: how fast it moves the parts together (mm/s).
    pub fn speed(&self, mode: usize) -> f64 {
        self.cols.get(mode).map_or(0.0, |c| c.iter().map(|v| v * v).sum::<f64>().sqrt())
    }

    /// The bounded drive times (s, per mode, each in [0, [`MODE_TIME_CAP_S`]]) that best
    /// bring every part from `poses` to its goal, and the residual left (3 per part).
    pub fn solve(&self, parts: &[PartGoal], poses: &[Pose]) -> (Vec<f64>, Vec<f64>) {
        let mut r: Vec<f64> =
            parts.iter().zip(poses).flat_map(|(p, q)| rows(p, *q, p.goal)).collect();
        let mut t = vec![0.0; self.cols.len()];
        let norms: Vec<f64> = self.cols.iter().map(|c| c.iter().map(|v| v * v).sum()).collect();
        for _ in 0..SWEEPS {
            let mut moved = 0.0f64;
            for (m, col) in self.cols.iter().enumerate() {
                if norms[m] < 1e-12 {
                    continue;
                }
                let g: f64 = col.iter().zip(&r).map(|(a, b)| a * b).sum::<f64>() / norms[m];
                let new = (t[m] + g).clamp(0.0, MODE_TIME_CAP_S);
                let step = new - t[m];
                if step != 0.0 {
                    r.iter_mut().zip(col).for_each(|(ri, a)| *ri -= step * a);
                    t[m] = new;
                    moved = moved.max(step.abs());
                }
            }
            if moved < 1e-4 {
                break;
            }
        }
        (t, r)
    }

    /// What the parts at `poses` leave to do: the cost (mm) of the residual no combination
    /// of modes removes plus `mm_per_s` per second of the drive the combination needs, plus
    /// the keep-out costs at `poses` (a zone a part is in now is no combination's to mend).
    pub fn value(&self, parts: &[PartGoal], poses: &[Pose], mm_per_s: f64) -> f64 {
        let (t, r) = self.solve(parts, poses);
        let left: f64 = parts
            .iter()
            .zip(r.chunks_exact(3))
            .map(|(p, d)| {
                let w = p.weight.max(1e-12);
                p.weight
                    * near_quadratic(
                        (d[0] * d[0] + d[1] * d[1]).sqrt() / w.sqrt() + d[2].abs() / w.sqrt(),
                    )
            })
            .sum();
        let kept_out: f64 =
            parts.iter().zip(poses).filter_map(|(p, q)| p.keep_out.map(|k| k.cost_at(*q))).sum();
        left + kept_out + mm_per_s * t.iter().sum::<f64>()
    }
}

/// The move from `from` to `to` of part `p` as three rows: x, y (mm) and the turn (deg, the
/// shortest way modulo the part's symmetry period) in mm at the part's mm per degree, each
/// scaled by the square root of its weight.
fn rows(p: &PartGoal, from: Pose, to: Pose) -> [f64; 3] {
    let w = p.weight.max(0.0).sqrt();
    let turn = signed_diff(to.theta.to_degrees(), from.theta.to_degrees(), p.piece.period_deg);
    [w * (to.x - from.x), w * (to.y - from.y), w * p.mm_per_deg * turn]
}

#[cfg(test)]
mod tests {
    use super::{MODE_TIME_CAP_S, Velocities};
    use crate::model::part::Part;
    use crate::model::pose::Pose;
    use crate::steer::cost::{KeepOut, PartGoal, Piece};

    fn piece() -> Piece {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        Piece::new(&Part::load(&root.join("examples/parts/ordinary/u-channel.json")).unwrap())
    }

    /// Two parts at the origin and at (100, 0), positions only; three modes: the first moves
    /// both +x at 10 mm/s, the second the first part +y at 5 mm/s, the third both −x.
    fn setup(p: &Piece, goals: [[f64; 2]; 2]) -> (Vec<PartGoal<'_>>, Velocities) {
        let at = |x: f64, y: f64| Pose { x, y, theta: 0.0 };
        let parts = [(at(0.0, 0.0), goals[0]), (at(100.0, 0.0), goals[1])]
            .map(|(s, g)| PartGoal { mm_per_deg: 0.0, ..PartGoal::new(p, s, at(g[0], g[1])) })
            .to_vec();
        let cols = vec![
            vec![10.0, 0.0, 0.0, 10.0, 0.0, 0.0],
            vec![0.0, 5.0, 0.0, 0.0, 0.0, 0.0],
            vec![-10.0, 0.0, 0.0, -10.0, 0.0, 0.0],
        ];
        (parts, Velocities { cols })
    }

    #[test]
    fn a_reachable_residual_is_solved_exactly_with_non_negative_times() {
        let p = piece();
        let (parts, v) = setup(&p, [[15.0, 10.0], [115.0, 0.0]]);
        let poses: Vec<Pose> = parts.iter().map(|g| g.pose).collect();
        let (t, r) = v.solve(&parts, &poses);
        assert!((t[0] - 1.5).abs() < 1e-3 && (t[1] - 2.0).abs() < 1e-3 && t[2] < 1e-6, "{t:?}");
        assert!(r.iter().all(|e| e.abs() < 1e-2), "{r:?}");
        // Nothing left but the drive: 3.5 s at 1 mm/s, the residual's cost nearly 0.
        assert!((v.value(&parts, &poses, 1.0) - 3.5).abs() < 1e-2);
    }

    #[test]
    fn a_part_left_in_a_keep_out_zone_counts() {
        let p = piece();
        let (mut parts, v) = setup(&p, [[15.0, 10.0], [115.0, 0.0]]);
        let poses: Vec<Pose> = parts.iter().map(|g| g.pose).collect();
        let free = v.value(&parts, &poses, 1.0);
        // The second part's centroid 3 mm inside a zone around it, at 2 mm per mm.
        let zone = KeepOut { centre: [100.0, 0.0], radius_mm: 3.0, per_mm: 2.0 };
        parts[1].keep_out = Some(zone);
        assert!((v.value(&parts, &poses, 1.0) - free - 6.0).abs() < 1e-9);
    }

    #[test]
    fn what_no_mode_can_do_stays_in_the_residual() {
        let p = piece();
        // The parts pulled apart: the modes move them together only, so the best is to leave
        // them (the residual is ±20 mm along x) and time 0.
        let (parts, v) = setup(&p, [[-20.0, 0.0], [120.0, 0.0]]);
        let poses: Vec<Pose> = parts.iter().map(|g| g.pose).collect();
        let (t, r) = v.solve(&parts, &poses);
        assert!(t.iter().all(|x| x.abs() < 1e-6), "{t:?}");
        assert!((r[0] + 20.0).abs() < 1e-6 && (r[3] - 20.0).abs() < 1e-6, "{r:?}");
        // A goal beyond the cap: its time is the cap, the rest in the residual.
        let (parts, v) = setup(&p, [[0.0, 100.0], [100.0, 0.0]]);
        let (t, r) = v.solve(&parts, &poses);
        assert_eq!(t[1], MODE_TIME_CAP_S);
        assert!((r[1] - (100.0 - 5.0 * MODE_TIME_CAP_S)).abs() < 1e-6, "{r:?}");
    }
}
