//! Steering parts with a camera in the loop: the pure algorithms a closed loop calls each
//! cycle, testable without camera or controller (the loops, cameras and rig are elsewhere).
//! - [`model`]: the plate as the loop believes it: per mode a [`Correction`] (shift of its
//!   field, speed factor) on the given plate; predictions of a burst ([`Model::predict`],
//!   [`Model::predict_all`]).
//! - [`cost`]: a part's distance to its goal, mm plus [`cost::MM_PER_DEG`] per degree
//!   (modulo the part's symmetry period).
//! - [`choose`](mod@choose): the command (mode, burst) that most reduces the total cost,
//!   with a look-ahead.
//! - [`assign`](mod@assign): identical parts to goals (Hungarian, exact).
//! - [`fit`], [`correct`], [`learn`](mod@learn): a mode's correction fitted to observed
//!   bursts, online from the last bursts and offline with held-out bursts.
//! - [`policy`]: which burst to record next while learning; bringing parts home.
//! - [`reach`]: whether a goal pose is a rest some mode holds.
//! - [`present`]: presenting parts to a robot: which part to steer to a pick pose (the one
//!   predicted there soonest), and the cycle's objective that keeps the others out of the
//!   pick zone.
//! - [`sim`]: an in-process rig (a true plate and the closed loop) for tests and benches.
//!
//! Parts are predicted independently of each other (one part in the field, no part–part
//! contact): the loop keeps them apart (the cost of identical parts assigned to distinct goals
//! pulls them apart, and learning brings them home when they gather).

pub mod assign;
pub mod choose;
pub mod correct;
pub mod cost;
pub mod fit;
pub mod learn;
pub mod model;
pub mod policy;
pub mod present;
pub mod reach;
pub mod sim;
pub mod togo;

pub use assign::{assign, assign_goals};
pub use choose::{Command, Menu, choose};
pub use correct::Corrector;
pub use cost::PartGoal;
pub use fit::Burst;
pub use learn::{Learned, ModeReport, learn};
pub use model::{Correction, Model};
pub use reach::{Reach, reachable_orientation};

/// What the steering algorithms refuse, each naming the value and the fix.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SteerError {
    /// A mode index beyond the plate's modes.
    #[error("mode {index} is not on the plate: it has {count} modes, indices 0 to {count} − 1")]
    NoMode {
        /// The index given.
        index: usize,
        /// The plate's mode count.
        count: usize,
    },
    /// A burst length that is not a finite number > 0.
    #[error("burst length {burst_s} s: give a finite length > 0 s (e.g. 0.1 to 2 s)")]
    BadBurst {
        /// The length given.
        burst_s: f64,
    },
    /// No burst lengths.
    #[error("no burst lengths: give at least one (e.g. 0.1, 0.2, 0.4, 0.7, 1.2, 2 s)")]
    NoBursts,
    /// No parts.
    #[error("no parts to steer: give at least one part with its pose and goal")]
    NoParts,
    /// A part index beyond the bodies given.
    #[error(
        "part {index} of a burst is not among the {count} parts given: index them 0 to {count} − 1"
    )]
    NoPart {
        /// The index given.
        index: usize,
        /// How many bodies were given.
        count: usize,
    },
    /// A correction that cannot be applied.
    #[error(
        "mode {mode}: correction shift {shift_mm:?} mm, speed factor {speed_factor}: give a \
         finite shift and a finite speed factor > 0"
    )]
    BadCorrection {
        /// Mode index.
        mode: usize,
        /// Shift given (mm).
        shift_mm: [f64; 2],
        /// Speed factor given.
        speed_factor: f64,
    },
    /// Corrections not one per mode.
    #[error("{given} corrections for a plate of {modes} modes: give one per mode")]
    CorrectionCount {
        /// Corrections given.
        given: usize,
        /// Modes on the plate.
        modes: usize,
    },
    /// More parts than goals.
    #[error(
        "{parts} parts but {goals} goals: give each part a goal (at least as many goals as parts)"
    )]
    TooFewGoals {
        /// Parts.
        parts: usize,
        /// Goals.
        goals: usize,
    },
    /// An assignment cost matrix with rows of different lengths.
    #[error(
        "assignment costs: a row of {found} goals where the first has {expected}: give every part a cost for every goal"
    )]
    RaggedCosts {
        /// Length of the first row.
        expected: usize,
        /// Length of the offending row.
        found: usize,
    },
    /// An assignment cost that is not a finite number.
    #[error(
        "assignment cost {value}: every cost must be a finite number (check the poses and goals)"
    )]
    BadCost {
        /// The cost.
        value: f64,
    },
}

#[cfg(test)]
mod tests;
