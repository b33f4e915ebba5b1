//! The motion model's old home, kept as one path for its public items: the part
//! ([`crate::motion::body`]), the field models ([`crate::motion::field`]), the integrator
//! ([`crate::motion::integrate`]) and plan steps ([`crate::motion::steps`]) live in their own
//! modules (docs/motion.md).

pub use crate::motion::body::{BODY_SAMPLES, Body, Pose};
pub use crate::motion::contact::Rim;
pub use crate::motion::field::{DistTable, FieldModel, HYPERBOLA_PIECE, Wrench, grid_eval};
pub use crate::motion::integrate::{REST_LIMIT_T0, Run, STEP_TOL, SimParams, run, run_while, t0};
pub use crate::motion::steps::{NoModeAt, PlanStepsError, SimStep, plan_steps, simulate_plan};
