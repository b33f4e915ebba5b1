//! The search over orientation sets, for one part or several at once (docs/plan.md).
//!
//! A state holds one set of orientation ids per part (each part has its own universe of
//! orientations, modulo its own period); a mode maps every part's set through that part's
//! [`StepMap`], so several parts are searched over the product of their orientation sets. A
//! state where every set is a single orientation ends a plan.
//!
//! Two passes, because the user may ask for more than "the first plan found":
//! 1. **Reach** (`Search::reach`): breadth-first over states, each visited once, down to one
//!    step more than the shortest plan ([`PlanOptions::extra_steps`]): which final
//!    orientations can be reached at all (what an unreachable `--goal-deg` is answered with).
//! 2. **Select** (`Search::select`): a uniform-cost search over (state, last mode, depth)
//!    down to the same depth, the cost being 1 per step ([`Minimize::Steps`]: breadth-first,
//!    today's behaviour) or the step's duration ([`Minimize::Time`]); the first plan in cost
//!    order that meets the goal orientations (and a fixed position when asked) wins, or with a
//!    goal position the one whose final position is nearest to it. The last mode is part of
//!    the state because the final position depends on the path, not only on the final set.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, VecDeque};

use super::{PlanFailure, PlanOptions, Problem, StepMap, deadline};
use crate::model::angle::cdist;

/// What the plan should be shortest in.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Minimize {
    /// Fewest steps (ties: the first found breadth-first).
    #[default]
    Steps,
    /// Least total duration (sum of the simulated step durations).
    Time,
}

/// One set of orientation ids per part.
pub(crate) type State = Vec<Vec<usize>>;

/// A plan as found: per step the mode and every part's predicted orientations after it.
pub(crate) type Path = Vec<(usize, Vec<Vec<f64>>)>;

/// One part's orientations (deg, mod its period) and their transitions under every mode.
#[derive(Debug, Clone)]
pub(crate) struct Universe {
    pub(crate) period: f64,
    pub(crate) vals: Vec<f64>,
    /// `trans[u][k]`: the ids `u` may go to under mode `k` (several for an ambiguous
    /// orientation of a dynamic map, [`StepMap::apply_all`]), `None` when not allowed.
    trans: Vec<Vec<Option<Vec<usize>>>>,
}

impl Universe {
    fn id(&mut self, v: f64) -> usize {
        let p = self.period;
        let v = v.rem_euclid(p);
        if let Some(i) = self.vals.iter().position(|&u| cdist(u, v, p) < 1e-3) {
            return i;
        }
        self.vals.push(v);
        self.vals.len() - 1
    }

    /// Fills the transitions of every known orientation, adding the images as they appear.
    fn close(&mut self, maps: &[StepMap], margin: f64, forbidden: &[(f64, usize)]) {
        while self.trans.len() < self.vals.len() {
            let u = self.vals[self.trans.len()];
            let row = (0..maps.len())
                .map(|k| {
                    let banned =
                        forbidden.iter().any(|&(f, fk)| fk == k && cdist(f, u, self.period) < 1e-3);
                    if banned {
                        return None;
                    }
                    let vs = maps[k].apply_all(u, margin).ok()?;
                    Some(vs.into_iter().map(|v| self.id(v)).collect())
                })
                .collect();
            self.trans.push(row);
        }
    }
}

/// One node of the reach pass: (state, parent index or `usize::MAX`, mode, depth).
pub(crate) type ReachNode = (State, usize, usize, usize);

/// What the reach pass found.
#[derive(Debug, Clone)]
pub(crate) struct Reach {
    /// Every state visited.
    pub(crate) nodes: Vec<ReachNode>,
    /// Steps of the shortest plan (`None`: no plan).
    pub(crate) shortest: Option<usize>,
    /// Final orientations (one per part) of the plans of at most `shortest + extra_steps`.
    pub(crate) finals: Vec<Vec<f64>>,
    /// The search stopped at [`PlanOptions::deadline`].
    pub(crate) out_of_time: bool,
    /// Sets were left unexpanded at [`PlanOptions::max_states`].
    pub(crate) capped: bool,
}

impl Reach {
    /// `Err(OutOfTime)` when the search stopped at the deadline.
    pub(crate) fn in_time(&self, opt: &PlanOptions) -> Result<(), PlanFailure> {
        match opt.deadline {
            Some(d) if self.out_of_time => Err(PlanFailure::OutOfTime {
                limit_s: d.limit_s(),
                stage: format!("the search over orientation sets ({} sets)", self.nodes.len()),
            }),
            _ => Ok(()),
        }
    }

    /// What a failure adds when the search hit its bound: the bound and the flag that lifts it.
    pub(crate) fn bound_note(&self, opt: &PlanOptions) -> String {
        if !self.capped {
            return String::new();
        }
        format!(
            "; the search stopped expanding at {} sets (--max-states {}; a larger value searches on)",
            opt.max_states, opt.max_states
        )
    }
}

/// The searches look at the clock every this many sets.
const CLOCK_EVERY: usize = 1024;

/// What a plan must meet besides ending in one orientation per part.
#[derive(Debug, Clone, Default)]
pub(crate) struct Target {
    /// Goal orientation per part (deg), `None`: any.
    pub(crate) deg: Vec<Option<f64>>,
    /// How close a final orientation must be to its goal (deg).
    pub(crate) tol_deg: f64,
    /// Every part's final position must be fixed.
    pub(crate) fix_position: bool,
    /// Part 0's final position nearest to this (mm); implies a fixed position.
    pub(crate) pos_mm: Option<[f64; 2]>,
}

impl Target {
    pub(crate) fn meets(&self, finals: &[f64], periods: &[f64]) -> bool {
        finals.iter().zip(periods).zip(&self.deg).all(|((&t, &p), g)| match g {
            Some(g) => cdist(t, *g, p) <= self.tol_deg,
            None => true,
        })
    }

    fn wants_position(&self) -> bool {
        self.fix_position || self.pos_mm.is_some()
    }
}

/// The search over the product of the parts' orientation sets.
pub(crate) struct Search<'a> {
    maps: Vec<&'a [StepMap]>,
    pub(crate) unis: Vec<Universe>,
    /// The first step's states, one per mode that may come first.
    first: Vec<(usize, State)>,
    opt: &'a PlanOptions,
}

/// A search node of the select pass.
struct Node {
    state: State,
    parent: usize,
    mode: usize,
    depth: usize,
    cost: u64,
}

impl<'a> Search<'a> {
    /// The universes of `problems` (one per part), with `forbidden[i]` transitions
    /// (orientation, mode) of part `i` ruled out.
    pub(crate) fn new(
        problems: &[&'a Problem],
        opt: &'a PlanOptions,
        forbidden: &[Vec<(f64, usize)>],
    ) -> Search<'a> {
        let unis = problems
            .iter()
            .map(|p| Universe { period: p.period, vals: Vec::new(), trans: Vec::new() })
            .collect();
        let mut s = Search {
            maps: problems.iter().map(|p| p.maps.as_slice()).collect(),
            unis,
            first: Vec::new(),
            opt,
        };
        s.first = s.first_states();
        for (i, u) in s.unis.iter_mut().enumerate() {
            let none = Vec::new();
            u.close(s.maps[i], opt.margin_deg, forbidden.get(i).unwrap_or(&none));
        }
        s
    }

    /// The first step's states: mode `k` takes every orientation to its stable rests (a mode
    /// neutral for some part, or without a stable rest, cannot come first).
    fn first_states(&mut self) -> Vec<(usize, State)> {
        let nm = self.maps.first().map_or(0, |m| m.len());
        let mut out = Vec::new();
        'modes: for k in 0..nm {
            let mut state = Vec::with_capacity(self.maps.len());
            for (i, maps) in self.maps.iter().enumerate() {
                let map = &maps[k];
                if map.neutral || map.stable.is_empty() {
                    continue 'modes;
                }
                let mut set: Vec<usize> = map.stable.iter().map(|&v| self.unis[i].id(v)).collect();
                set.sort_unstable();
                set.dedup();
                state.push(set);
            }
            out.push((k, state));
        }
        out
    }

    /// The image of a state under mode `k`; `None` when some orientation may not take it.
    fn image(&self, state: &State, k: usize) -> Option<State> {
        state
            .iter()
            .zip(&self.unis)
            .map(|(set, u)| {
                let mut img = Vec::with_capacity(set.len());
                for &v in set {
                    img.extend_from_slice(u.trans[v][k].as_deref()?);
                }
                img.sort_unstable();
                img.dedup();
                Some(img)
            })
            .collect()
    }

    fn finals(&self, state: &State) -> Option<Vec<f64>> {
        state
            .iter()
            .zip(&self.unis)
            .map(|(set, u)| (set.len() == 1).then(|| u.vals[set[0]]))
            .collect()
    }

    fn periods(&self) -> Vec<f64> {
        self.unis.iter().map(|u| u.period).collect()
    }

    /// Pass 1: breadth-first over states down to `shortest + extra_steps` steps.
    pub(crate) fn reach(&self) -> Reach {
        let mut nodes: Vec<ReachNode> = Vec::new();
        let mut seen: HashMap<State, usize> = HashMap::new();
        let mut queue = VecDeque::new();
        for (k, state) in self.first.clone() {
            if !seen.contains_key(&state) {
                seen.insert(state.clone(), nodes.len());
                queue.push_back(nodes.len());
                nodes.push((state, usize::MAX, k, 1));
            }
        }
        let (mut shortest, mut finals) = (None, Vec::new());
        let nm = self.maps.first().map_or(0, |m| m.len());
        let (mut out_of_time, mut capped) = (false, false);
        while let Some(i) = queue.pop_front() {
            if i % CLOCK_EVERY == 0 && deadline::passed(self.opt.deadline) {
                out_of_time = true;
                break;
            }
            let depth = nodes[i].3;
            if shortest.is_some_and(|d: usize| depth > d + self.opt.extra_steps) {
                break;
            }
            if let Some(f) = self.finals(&nodes[i].0) {
                shortest.get_or_insert(depth);
                finals.push(f);
            }
            if nodes.len() > self.opt.max_states {
                capped = true;
                continue;
            }
            for k in 0..nm {
                let Some(img) = self.image(&nodes[i].0, k) else { continue };
                if !seen.contains_key(&img) {
                    seen.insert(img.clone(), nodes.len());
                    queue.push_back(nodes.len());
                    nodes.push((img, i, k, depth + 1));
                }
            }
        }
        Reach { nodes, shortest, finals, out_of_time, capped }
    }

    /// Pass 2: the plan of least cost (`cost(mode, state before or None for the first step)`)
    /// of at most `max_depth` steps that meets `target`; `position(path)` gives every part's
    /// fixed final position (or `None`), asked only when the target needs it.
    pub(crate) fn select(
        &self,
        target: &Target,
        max_depth: usize,
        cost: &mut dyn FnMut(usize, Option<&State>) -> u64,
        position: &mut dyn FnMut(&Path) -> Vec<Option<[f64; 2]>>,
    ) -> Option<Path> {
        let track_mode = target.wants_position();
        let time = self.opt.minimize == Minimize::Time;
        let key =
            |n: &Node| (n.state.clone(), track_mode.then_some(n.mode), time.then_some(n.depth));
        let mut nodes: Vec<Node> = Vec::new();
        let mut best: HashMap<(State, Option<usize>, Option<usize>), u64> = HashMap::new();
        let mut heap = BinaryHeap::new();
        let push = |best: &mut HashMap<_, u64>,
                    nodes: &mut Vec<Node>,
                    heap: &mut BinaryHeap<Reverse<(u64, usize)>>,
                    n: Node| {
            let k = key(&n);
            if best.get(&k).is_some_and(|&c| c <= n.cost) {
                return;
            }
            best.insert(k, n.cost);
            heap.push(Reverse((n.cost, nodes.len())));
            nodes.push(n);
        };
        for (k, state) in self.first.clone() {
            let c = cost(k, None);
            push(
                &mut best,
                &mut nodes,
                &mut heap,
                Node { state, parent: usize::MAX, mode: k, depth: 1, cost: c },
            );
        }
        let periods = self.periods();
        let mut nearest: Option<(f64, u64, usize)> = None;
        let nm = self.maps.first().map_or(0, |m| m.len());
        while let Some(Reverse((c, i))) = heap.pop() {
            if i % CLOCK_EVERY == 0 && deadline::passed(self.opt.deadline) {
                return None;
            }
            if best.get(&key(&nodes[i])).is_some_and(|&b| b < c) {
                continue;
            }
            if let Some(f) = self.finals(&nodes[i].state)
                && target.meets(&f, &periods)
            {
                if !track_mode {
                    return Some(self.path(&nodes, i));
                }
                let path = self.path(&nodes, i);
                if let Some(path) = self.placed(path, (c, i), target, position, &mut nearest) {
                    return Some(path);
                }
            }
            if nodes[i].depth >= max_depth || nodes.len() > self.opt.max_states {
                continue;
            }
            for k in 0..nm {
                let Some(img) = self.image(&nodes[i].state, k) else { continue };
                let step = cost(k, Some(&nodes[i].state));
                let n = Node {
                    state: img,
                    parent: i,
                    mode: k,
                    depth: nodes[i].depth + 1,
                    cost: c + step,
                };
                push(&mut best, &mut nodes, &mut heap, n);
            }
        }
        nearest.map(|(_, _, i)| self.path(&nodes, i))
    }

    /// A path meeting the target when positions count (node `i` at cost `c`): the path itself
    /// when every part's position is known and no goal position is asked for; with a goal
    /// position, `nearest` keeps the node ending nearest to it (`None` returned).
    fn placed(
        &self,
        path: Path,
        (c, i): (u64, usize),
        target: &Target,
        position: &mut dyn FnMut(&Path) -> Vec<Option<[f64; 2]>>,
        nearest: &mut Option<(f64, u64, usize)>,
    ) -> Option<Path> {
        let pos = position(&path);
        if !pos.iter().all(Option::is_some) {
            return None;
        }
        match (target.pos_mm, pos.first().copied().flatten()) {
            (Some(g), Some(p)) => {
                let d = (p[0] - g[0]).hypot(p[1] - g[1]);
                // Positions within 0.5 mm are one node crossing: the cheaper wins.
                if nearest.is_none_or(|(bd, _, _)| d < bd - 0.5) {
                    *nearest = Some((d, c, i));
                }
                None
            }
            _ => Some(path),
        }
    }

    fn path(&self, nodes: &[Node], mut g: usize) -> Path {
        let mut path = Vec::new();
        loop {
            let n = &nodes[g];
            path.push((n.mode, self.degrees(&n.state)));
            if n.parent == usize::MAX {
                break;
            }
            g = n.parent;
        }
        path.reverse();
        path
    }

    /// Every part's orientations (deg) of a state.
    pub(crate) fn degrees(&self, state: &State) -> Vec<Vec<f64>> {
        state.iter().zip(&self.unis).map(|(s, u)| s.iter().map(|&v| u.vals[v]).collect()).collect()
    }
}
