//! Identical parts to goals: the assignment of least total cost, exactly, by the Hungarian
//! method (Kuhn–Munkres with potentials, O(n²·m) for n parts and m ≥ n goals): exact for any
//! number of parts, a few microseconds for 10.

use crate::model::pose::Pose;
use crate::steer::SteerError;
use crate::steer::cost::PartGoal;

/// For each row of `cost` (`cost[part][goal]`, every row as long, at least as many goals as
/// parts), the goal it takes: distinct goals of least total cost.
pub fn assign(cost: &[Vec<f64>]) -> Result<Vec<usize>, SteerError> {
    let n = cost.len();
    let m = cost.first().map_or(0, Vec::len);
    if let Some(row) = cost.iter().find(|r| r.len() != m) {
        return Err(SteerError::RaggedCosts { expected: m, found: row.len() });
    }
    if n > m {
        return Err(SteerError::TooFewGoals { parts: n, goals: m });
    }
    if let Some(v) = cost.iter().flatten().find(|v| !v.is_finite()) {
        return Err(SteerError::BadCost { value: *v });
    }
    Ok(hungarian(cost, n, m))
}

/// The Hungarian method on rows 1..=n, columns 1..=m (index 0 is the virtual start).
fn hungarian(cost: &[Vec<f64>], n: usize, m: usize) -> Vec<usize> {
    let (mut u, mut v) = (vec![0.0; n + 1], vec![0.0; m + 1]);
    // row_of[j]: the row matched to column j (0: none).
    let mut row_of = vec![0usize; m + 1];
    let mut way = vec![0usize; m + 1];
    for i in 1..=n {
        row_of[0] = i;
        let mut j0 = 0;
        let mut minv = vec![f64::INFINITY; m + 1];
        let mut used = vec![false; m + 1];
        loop {
            used[j0] = true;
            let i0 = row_of[j0];
            let (mut delta, mut j1) = (f64::INFINITY, 0);
            for j in 1..=m {
                if used[j] {
                    continue;
                }
                let cur = cost[i0 - 1][j - 1] - u[i0] - v[j];
                if cur < minv[j] {
                    minv[j] = cur;
                    way[j] = j0;
                }
                if minv[j] < delta {
                    delta = minv[j];
                    j1 = j;
                }
            }
            for j in 0..=m {
                if used[j] {
                    u[row_of[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if row_of[j0] == 0 {
                break;
            }
        }
        // Augment along the alternating path back to the virtual column.
        while j0 != 0 {
            let j1 = way[j0];
            row_of[j0] = row_of[j1];
            j0 = j1;
        }
    }
    let mut goal_of = vec![0; n];
    for j in 1..=m {
        if row_of[j] != 0 {
            goal_of[row_of[j] - 1] = j - 1;
        }
    }
    goal_of
}

/// The goals of identical parts: each part (with its pose, body and symmetry period) takes
/// the goal of `goals` that the least-cost assignment gives it ([`PartGoal::cost_at`] with
/// each candidate goal). Returns the parts with their goals set.
pub fn assign_goals<'a>(
    parts: &[PartGoal<'a>],
    goals: &[Pose],
) -> Result<Vec<PartGoal<'a>>, SteerError> {
    let cost: Vec<Vec<f64>> = parts
        .iter()
        .map(|p| goals.iter().map(|g| PartGoal { goal: *g, ..*p }.cost_at(p.pose)).collect())
        .collect();
    let goal_of = if parts.is_empty() { Vec::new() } else { assign(&cost)? };
    Ok(parts.iter().zip(goal_of).map(|(p, g)| PartGoal { goal: goals[g], ..*p }).collect())
}
