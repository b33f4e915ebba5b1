//! Input checks the planner makes before any work: vertex count, part size and fit against
//! the plate, the plan name's length.

use chladni_shared::icd::plan::MAX_NAME;

use crate::model::part::Part;
use crate::model::plate::PlateModel;
use crate::motion::body::Body;
use crate::motion::contact::Rim;

/// Most vertices (all rings) a part may have for planning and simulation: the planner's cost
/// grows with the vertex count (the step maps analyse the whole outline hundreds of times).
/// Measured with `chladni plan` on the example triangle with N vertices along its edges (release
/// build, four-lines plate: 1000 → 1.0 s, 3000 → 2.6 s, 6000 → 4.5 s, 12000 → 7.2 s); see
/// docs/plan.md.
pub const MAX_PLAN_VERTICES: usize = 6_000;

/// A part and plate the planner refuses before any work (bad input, exit code 2).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PlanInputError {
    /// Too many vertices for a plan in reasonable time.
    #[error(
        "part {name}: {count} vertices, more than the planner's limit of {MAX_PLAN_VERTICES} \
         (planning time grows with the vertex count): simplify the outline"
    )]
    TooManyVertices {
        /// Part name.
        name: String,
        /// Its vertex count.
        count: usize,
    },
    /// The part cannot lie on the plate in any orientation.
    #[error(
        "part {name} is {width_mm:.1} mm wide at its narrowest, wider than the {w}×{h} mm plate \
         ({side} mm side): it cannot lie on the plate in any orientation; check that the part is \
         in mm and the plate's size_mm"
    )]
    TooLarge {
        /// Part name.
        name: String,
        /// Its smallest width over all directions (mm).
        width_mm: f64,
        /// Plate width (mm).
        w: f64,
        /// Plate height (mm).
        h: f64,
        /// The plate's shorter side (mm).
        side: f64,
    },
    /// Narrow enough, but too long for every turn of its bounding box ([`Rim::best_fit`]):
    /// the rim would have to hold it on two opposite sides at once, and no plan moves it.
    #[error(
        "part {name} fits the {w} × {h} mm plate in no orientation: even turned by {deg}° its \
         bounding box is {over_mm:.1} mm too large (a smaller part, or a larger plate)"
    )]
    NoFit {
        /// Part name.
        name: String,
        /// The turn (deg) at which its bounding box is least over the plate.
        deg: f64,
        /// By how much it is over there (mm).
        over_mm: f64,
        /// Plate width (mm).
        w: f64,
        /// Plate height (mm).
        h: f64,
    },
}

/// Checks a part against the planner's limits and the plate's size, before any work.
pub fn check_input(part: &Part, plate: &PlateModel) -> Result<(), PlanInputError> {
    let count = part.vertex_count();
    if count > MAX_PLAN_VERTICES {
        return Err(PlanInputError::TooManyVertices { name: part.name.clone(), count });
    }
    let [w, h] = plate.size_mm;
    let side = w.min(h);
    let width_mm = min_width(&part.outline);
    if width_mm > side {
        return Err(PlanInputError::TooLarge { name: part.name.clone(), width_mm, w, h, side });
    }
    let (deg, over_mm) = Rim::of(plate).best_fit(&Body::new(part));
    if over_mm > 0.0 {
        return Err(PlanInputError::NoFit { name: part.name.clone(), deg, over_mm, w, h });
    }
    Ok(())
}

/// The smallest width of a ring over 360 directions (0.5° apart; at most 0.004 % above the
/// true minimum, which only matters for a part that fits the plate within that margin).
fn min_width(ring: &[[f64; 2]]) -> f64 {
    (0..360)
        .map(|k| {
            let (s, c) = (k as f64 * 0.5).to_radians().sin_cos();
            let (lo, hi) = ring.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                let d = c * p[0] + s * p[1];
                (lo.min(d), hi.max(d))
            });
            hi - lo
        })
        .fold(f64::INFINITY, f64::min)
}

/// The plan name for a part name: at most [`MAX_NAME`] bytes (the controller stores no more),
/// cut at a character boundary, and a warning naming the cut when there was one.
pub fn plan_name(name: &str) -> (String, Option<String>) {
    if name.len() <= MAX_NAME {
        return (name.to_string(), None);
    }
    let mut end = MAX_NAME;
    while !name.is_char_boundary(end) {
        end -= 1;
    }
    let cut = name[..end].to_string();
    let warning = format!(
        "the part's name is {} bytes; a plan name holds at most {MAX_NAME} (the controller's \
         limit), so the plan is named \"{cut}\" (rename the part to choose)",
        name.len()
    );
    (cut, Some(warning))
}
