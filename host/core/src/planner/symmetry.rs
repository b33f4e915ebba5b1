//! Symmetry: a part's rotational symmetry order and the period orientations are taken
//! modulo (docs/plan.md, "Equivalence").

use crate::model::angle::cdist;
use crate::model::part::Part;
use crate::model::plate::PlateModel;
use crate::motion::body::Body;
use crate::motion::field::FieldModel;

/// Rotational symmetry order of a part (largest m such that turning it by 360°/m about its
/// centroid maps it onto itself, vertex for vertex, within 10⁻⁶ of its size).
pub fn symmetry_order(part: &Part) -> u32 {
    body_symmetry_order(&Body::new(part))
}

/// [`symmetry_order`] of a prepared part.
pub(crate) fn body_symmetry_order(body: &Body) -> u32 {
    let n = body.rings[0].len();
    let tol = 1e-6 * body.radius.max(1e-9);
    for m in (2..=n).rev() {
        if !n.is_multiple_of(m) {
            continue;
        }
        let (s, c) = (std::f64::consts::TAU / m as f64).sin_cos();
        let ok = body.rings.iter().all(|r| {
            r.iter().all(|p| {
                let q = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
                body.rings.iter().any(|o| o.iter().any(|v| (v[0] - q[0]).hypot(v[1] - q[1]) < tol))
            })
        });
        if ok {
            return m as u32;
        }
    }
    1
}

fn gcd(a: u32, b: u32) -> u32 {
    if b == 0 { a } else { gcd(b, a % b) }
}

/// The period P = 360°/m orientations are taken modulo: m = the part's rotational symmetry
/// order, doubled (lcm with 2) when every mode is a straight node with equal gains.
pub fn plan_period(part: &Part, plate: &PlateModel) -> f64 {
    let m_part = symmetry_order(part);
    // A node along an edge pushes the part into one wall: θ and θ + 180° rest on different
    // edges there ([`super::edges::rim_line`]).
    let radius = Body::new(part).radius;
    let all_sym = plate
        .modes
        .iter()
        .all(|m| m.is_symmetric_line() && !super::edges::rim_line(radius, m, plate));
    let m = if all_sym { m_part * 2 / gcd(m_part, 2) } else { m_part };
    360.0 / m as f64
}

/// Is every mode's field centrally symmetric about the plate centre c (f(2c − p) = −f(p))?
/// Then a pose and its twin turned 180° about c are moved alike by every mode, and no
/// sequence tells them apart. Sampled on a 31 × 21 grid over the plate, off the cells'
/// corners (a point on a diagonal through the centre is equidistant from two crossing lines,
/// and which is nearest would be a tie of rounding), to 10⁻³ of the largest force (a solver grid's rounding stays far below that; a drive point or clamp off
/// the centre far above).
pub(crate) fn centrally_symmetric(plate: &PlateModel) -> bool {
    let [w, h] = plate.size_mm;
    let c = plate.center();
    let pts: Vec<[f64; 2]> = (0..31)
        .flat_map(|i| {
            (0..21).map(move |j| [w * (i as f64 + 0.37) / 31.0, h * (j as f64 + 0.61) / 21.0])
        })
        .collect();
    plate.modes.iter().all(|mode| {
        let field = FieldModel::new(mode, plate);
        let (mut worst, mut max) = (0.0f64, 0.0f64);
        for p in &pts {
            let (a, b) = (field.at(*p), field.at([2.0 * c[0] - p[0], 2.0 * c[1] - p[1]]));
            worst = worst.max((a[0] + b[0]).hypot(a[1] + b[1]));
            max = max.max(a[0].hypot(a[1]));
        }
        worst <= 1e-3 * max.max(1e-12)
    })
}

/// The plate centre when every mode is centrally symmetric (`centrally_symmetric`) about it.
pub fn symmetry_centre(plate: &PlateModel) -> Option<[f64; 2]> {
    centrally_symmetric(plate).then(|| plate.center())
}

/// What breaks a 180° twin: something one-sided (the remedies every symmetry sentence names).
/// The drive point is named as what does not: a single mode keeps its shape wherever it is
/// driven, and the point only picks a degenerate pair's combination (docs/plate.md, "Drive
/// point"), so re-solving with another `drive_mm` gives the same fields. `feed`: the search
/// already ran from a feed region, so the remedy is another one.
fn one_sided_fixes(feed: bool) -> String {
    let side = if feed {
        "a feed region elsewhere (from this one the parts reach the pair)"
    } else {
        "parts dropped on one side (`--feed X0 Y0 X1 Y1`)"
    };
    format!(
        "what breaks it is one-sided: a support off the plate's centre and mid-lines \
         (`clamps_mm = [[x, y], …]` in [plate], then `chladni plate modes --write-modes`: a \
         clamp changes the modes themselves; `chladni plate suggest` tries clamp sets), {side}, \
         or a mode whose field pushes the part against the rim (`edge = \"wall\"` in [plate], the \
         default); not the drive point alone (`drive_mm`): a single mode keeps its shape \
         wherever the plate is driven, and the point only picks the combination a degenerate \
         pair takes"
    )
}

/// The sentence naming a plate's central symmetry about `centre` (mm) and what breaks it: one
/// home for the planner's failures ([`symmetry_note`]) and `plate suggest`'s refusal of a
/// centrally symmetric plate before any map is made.
pub(crate) fn central_symmetry_sentence(centre: [f64; 2]) -> String {
    format!(
        "every mode's field is centrally symmetric about the plate centre ({:.1}, {:.1}) mm, so \
         a pose and its twin turned 180° about the centre are moved alike by every sequence; \
         {}",
        centre[0],
        centre[1],
        one_sided_fixes(false)
    )
}

/// What to say when orientations 180° apart are left after every sequence (deg): the
/// symmetry that keeps them apart and what breaks it; `None` when no two of `set` are 180°
/// apart modulo the period `p`. `centre`: [`symmetry_centre`]; `feed`: the search ran from a
/// feed region (`--feed`), so its remedy is another region.
pub(crate) fn symmetry_note(
    centre: Option<[f64; 2]>,
    set: &[f64],
    p: f64,
    feed: bool,
) -> Option<String> {
    let twins = |a: f64, b: f64| cdist(a, b, p) > 1.0 && cdist(a + 180.0, b, p) < 1.0;
    let (a, b) = set.iter().find_map(|&a| set.iter().find(|&&b| twins(a, b)).map(|&b| (a, b)))?;
    Some(match centre {
        Some(c) => format!("{a:.2}° and {b:.2}° are 180° twins: {}", central_symmetry_sentence(c)),
        None => format!(
            "{a:.2}° and {b:.2}° are 180° twins: a part straddling a node whose field is the same \
             on both sides rests in such pairs wherever it was dropped; {}",
            one_sided_fixes(feed)
        ),
    })
}

#[cfg(test)]
mod tests {
    use super::{centrally_symmetric, symmetry_centre, symmetry_note};
    use crate::model::plate::PlateModel;
    use crate::model::plate_file::PlateFile;

    fn plate(modes: &str) -> PlateModel {
        let text = format!("[plate]\nname = \"t\"\nsize_mm = [300.0, 200.0]\n{modes}");
        PlateModel::from_file(&PlateFile::parse(&text, "t").unwrap()).unwrap()
    }

    const CROSS: &str = "[[mode]]\nfreq_hz = 60.0\nnode = { kind = \"lines\", lines = [{ angle_deg = \
                         0.0, offset_mm = 0.0 }, { angle_deg = 90.0, offset_mm = 0.0 }] }\n";

    #[test]
    fn a_cross_through_the_centre_is_centrally_symmetric_and_an_offset_or_unequal_node_is_not() {
        assert!(centrally_symmetric(&plate(CROSS)));
        let off = "[[mode]]\nfreq_hz = 70.0\nnode = { kind = \"line\", angle_deg = 0.0, offset_mm = 20.0 }\n";
        assert!(!centrally_symmetric(&plate(&format!("{CROSS}{off}"))));
        let uneven = "[[mode]]\nfreq_hz = 70.0\ngain_left = 1.0\ngain_right = 2.0\nnode = { kind = \
                      \"line\", angle_deg = 30.0 }\n";
        assert!(!centrally_symmetric(&plate(&format!("{CROSS}{uneven}"))));
    }

    #[test]
    fn the_note_names_the_symmetry_and_what_breaks_it() {
        let centre = symmetry_centre(&plate(CROSS));
        assert_eq!(centre, Some([150.0, 100.0]));
        let note = symmetry_note(centre, &[10.0, 50.0, 190.5], 360.0, false).unwrap();
        for want in [
            "10.00° and 190.50° are 180° twins",
            "centrally symmetric about the plate \
                      centre (150.0, 100.0) mm",
            "drive_mm",
            "clamps_mm",
            "--feed",
            "edge = \"wall\"",
        ] {
            assert!(note.contains(want), "{want}: {note}");
        }
        // The drive point is named as what does not break it (a single mode keeps its shape).
        assert!(note.contains("not the drive point alone (`drive_mm`)"), "{note}");
        let local = symmetry_note(None, &[10.0, 190.0], 360.0, false).unwrap();
        assert!(local.contains("straddling a node") && local.contains("clamps_mm"), "{local}");
        // From a feed region the remedy is another region, not `--feed` again.
        let fed = symmetry_note(None, &[10.0, 190.0], 360.0, true).unwrap();
        assert!(fed.contains("a feed region elsewhere") && !fed.contains("--feed"), "{fed}");
        // No twins, or twins that are one orientation modulo the period: nothing to say.
        assert_eq!(symmetry_note(centre, &[10.0, 50.0], 360.0, false), None);
        assert_eq!(symmetry_note(centre, &[10.0, 10.0], 180.0, false), None);
    }
}
