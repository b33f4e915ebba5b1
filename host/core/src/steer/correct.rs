//! Online correction: after each burst, the driven mode's [`Correction`] is refitted to that
//! mode's last bursts, so the loop's predictions follow what the plate really does.
//!
//! The rule: each mode keeps its last [`Corrector::window`] bursts (default 6). After a burst
//! of mode m, m's correction is fitted to m's window by the shared fit
//! ([`crate::steer::fit`]: Levenberg–Marquardt, two iterations from the current
//! correction) with a prior centred on the given plate (shift 0, factor 1; spreads 6 mm and
//! 0.7 in ln factor, about ×2): with one burst of one part the three parameters are not all
//! determined, and the prior keeps the undetermined ones where the plate file put them; with
//! a full window the data outweigh it. The window forgets: a plate that warms up and drifts
//! is followed. A single part that bounced is dropped by the fit's outlier rule.

use std::collections::VecDeque;

use crate::steer::SteerError;
use crate::steer::cost::Piece;
use crate::steer::fit::{Burst, Prior, Problem};
use crate::steer::model::{Correction, Model};

/// The online corrector: each mode's recent bursts.
#[derive(Debug, Clone)]
pub struct Corrector {
    /// Bursts kept per mode.
    pub window: usize,
    /// Levenberg–Marquardt iterations per update.
    pub iterations: usize,
    /// The prior every update is pulled towards.
    pub prior: Prior,
    recent: Vec<VecDeque<Burst>>,
}

/// The online prior: the given plate, spreads 6 mm and 0.7 (ln factor).
pub const ONLINE_PRIOR: Prior = Prior {
    centre: Correction { shift_mm: [0.0, 0.0], speed_factor: 1.0 },
    shift_mm: 6.0,
    ln_factor: 0.7,
};

impl Corrector {
    /// A corrector for `modes` modes: window 6, 2 iterations per update (each update starts
    /// from the last, so they add up), [`ONLINE_PRIOR`].
    pub fn new(modes: usize) -> Corrector {
        Corrector {
            window: 6,
            iterations: 2,
            prior: ONLINE_PRIOR,
            recent: vec![VecDeque::new(); modes],
        }
    }

    /// The bursts of mode `mode` in the window (oldest first).
    pub fn recent(&self, mode: usize) -> impl Iterator<Item = &Burst> {
        self.recent.get(mode).into_iter().flatten()
    }

    /// Records `burst` (its parts by index into `pieces`) and refits its mode's
    /// correction in `model`. Returns the new correction.
    pub fn observe(
        &mut self,
        model: &mut Model,
        pieces: &[Piece],
        burst: Burst,
    ) -> Result<Correction, SteerError> {
        check_burst(model, pieces, &burst)?;
        let mode = burst.mode;
        if self.recent.len() < model.mode_count() {
            self.recent.resize(model.mode_count(), VecDeque::new());
        }
        let queue = &mut self.recent[mode];
        queue.push_back(burst);
        while queue.len() > self.window.max(1) {
            queue.pop_front();
        }
        let problem =
            Problem::new(model.given(), mode, pieces, queue.iter().collect(), Some(self.prior));
        let (c, _) = problem.fit(model.correction(mode)?, self.iterations);
        model.set_correction(mode, c)?;
        Ok(c)
    }
}

/// A burst usable with `model` and `pieces`: a known mode, a length > 0, known parts.
pub(crate) fn check_burst(model: &Model, pieces: &[Piece], b: &Burst) -> Result<(), SteerError> {
    model.check_mode(b.mode)?;
    crate::steer::model::check_bursts(&[b.burst_s])?;
    match b.parts.iter().find(|(i, _, _)| *i >= pieces.len()) {
        Some((i, _, _)) => Err(SteerError::NoPart { index: *i, count: pieces.len() }),
        None => Ok(()),
    }
}
