//! Figures: rest analysis (part, turn and alignment functions), plans and motion traces, and
//! Chladni figures of plate modes.

pub mod analysis;
pub mod plan;
pub mod plate;
