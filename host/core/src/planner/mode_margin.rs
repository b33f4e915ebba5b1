//! The margin a mode's steps keep from the basin boundaries of its map, and where it came
//! from: the data of a step map, made by [`super::margin`] from evidence or given.

/// The smallest evidence margin (deg): below it a boundary's move is not resolved by the
/// measurement (boundaries of simulated maps lie on the midpoints of their start spacing).
pub const MIN_MARGIN_DEG: f64 = 0.5;

/// The largest evidence margin (deg): a map whose boundaries move farther (or appear or
/// vanish) with the resolution is not resolved on its grid.
pub const MAX_MARGIN_DEG: f64 = 15.0;

/// Where a step's margin came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MarginSource {
    /// `--margin-deg` given by the user.
    Given,
    /// The default for a map without resampling evidence (no grid).
    Default,
    /// A grid mode's map without a basin boundary: nothing to keep a margin from.
    NoBoundaries,
    /// Measured: the mode's map made again on its grid resampled to `coarse` (nx, ny); its
    /// basin boundaries moved by `spread_deg` (infinite: a boundary appeared or vanished).
    Resampled {
        /// The largest distance of a boundary of either map from the other's nearest (deg).
        spread_deg: f64,
        /// The mode's grid (nx, ny).
        grid: [usize; 2],
        /// The resampled grid (nx, ny).
        coarse: [usize; 2],
    },
}

/// The margin a mode's steps keep, and its source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModeMargin {
    /// Margin (deg), before the map's sampling slack.
    pub deg: f64,
    /// Where it came from.
    pub source: MarginSource,
}

impl ModeMargin {
    /// The margin of a resampling measurement that moved the boundaries by `spread_deg`.
    pub(crate) fn from_spread(spread_deg: f64, grid: [usize; 2], coarse: [usize; 2]) -> ModeMargin {
        let deg = if spread_deg.is_finite() {
            spread_deg.clamp(MIN_MARGIN_DEG, MAX_MARGIN_DEG)
        } else {
            MAX_MARGIN_DEG
        };
        ModeMargin { deg, source: MarginSource::Resampled { spread_deg, grid, coarse } }
    }

    /// The source's short name in `plan --json` (`given`, `default`, `no_boundaries`,
    /// `resampled`).
    pub(crate) fn source_name(&self) -> &'static str {
        match self.source {
            MarginSource::Given => "given",
            MarginSource::Default => "default",
            MarginSource::NoBoundaries => "no_boundaries",
            MarginSource::Resampled { .. } => "resampled",
        }
    }

    /// What the margin is made of, in words (refusals and `plan`'s step lines).
    pub fn describe(&self) -> String {
        let d = self.deg;
        match self.source {
            MarginSource::Given => format!("--margin-deg {d}°"),
            MarginSource::Default => {
                format!("--margin-deg {d}°, the default: the map has no grid to resample")
            }
            MarginSource::NoBoundaries => {
                format!("margin {d:.2}°: the mode's map has no basin boundary")
            }
            MarginSource::Resampled { spread_deg, grid, coarse } => {
                let moved = if spread_deg.is_finite() {
                    format!("move {spread_deg:.2}°")
                } else {
                    "appear or vanish".into()
                };
                format!(
                    "margin {d:.2}° from evidence: the mode's basin boundaries {moved} when its \
                     {}×{} grid is resampled to {}×{}",
                    grid[0], grid[1], coarse[0], coarse[1]
                )
            }
        }
    }

    /// `{"deg": D, "source": S, "spread_deg": X}` for `plan --json` (spread only when
    /// measured; `null` when a boundary appeared or vanished).
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::json!({"deg": self.deg, "source": self.source_name()});
        if let MarginSource::Resampled { spread_deg, grid, coarse } = self.source {
            v["spread_deg"] = serde_json::json!(spread_deg.is_finite().then_some(spread_deg));
            v["grid"] = serde_json::json!(grid);
            v["resampled_grid"] = serde_json::json!(coarse);
        }
        v
    }
}
