//! A plan checked against a photo of its result (`chladni verify`, `POST /api/verify`;
//! docs/plate.md "Checking a run from a photo"): each part [`locate`](super::locate) found is
//! compared with what the plan predicts for its kind and face: its orientation within a
//! tolerance, modulo the part's symmetry and the plan's period; its position, where the plan
//! fixes one; and its face (a part planned for one face that lies on the other is off). Blobs
//! that hold parts whose poses cannot be seen (a cluster, a partly hidden part, a misfit) count
//! as parts that are not verified; blobs that match no part are listed and not counted.
//!
//! The judgement is [`Check::judge`], pure data: the CLI and the cell load the plan and the
//! parts once ([`Check::new`]) and judge each photo's [`Report`].

use image::{GrayImage, Rgb, RgbImage};
use imageproc::drawing::draw_line_segment_mut;
use serde::Serialize;

use super::plot::placed;
use super::{Located, Report, Template, Unknown, Why};
use chladni_core::model::angle::signed_diff;
use chladni_core::model::part::Part;
use chladni_core::model::part::mirror::{self, Face};
use chladni_core::model::plan_file::PlanFile;

/// A part is oriented when it lies within this of the predicted orientation (deg): the same
/// default as `chladni simulate --tol-deg`, so that a photo and a simulation count alike.
pub const DEFAULT_TOL_DEG: f64 = 5.0;
/// A part is in place when its centroid lies within this of a predicted position (mm): twice
/// the region the planner fixes a position to (`planner::position::POSITION_TOL_MM`), a
/// photo's pose being good to about 0.1 mm.
pub const DEFAULT_TOL_MM: f64 = 2.0 * chladni_core::planner::position::POSITION_TOL_MM;

/// Why a plan cannot be checked against these parts.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum VerifyError {
    /// The plan's entries and the parts (with their faces) do not pair up.
    #[error("the plan is for {planned} part(s) or face(s), the parts given make {given}{hint}")]
    PartsMismatch {
        /// Entries in the plan.
        planned: usize,
        /// Parts and faces given.
        given: usize,
        /// The likely fix.
        hint: &'static str,
    },
    /// A plan entry's face is not the face the parts give it.
    #[error(
        "plan entry {entry} ({name}) is for {planned}, the parts given make it {given}: give the \
         parts in the plan's order, the same files it was planned with"
    )]
    FaceMismatch {
        /// Entry index.
        entry: usize,
        /// Its name.
        name: String,
        /// The face in the plan.
        planned: String,
        /// The face the parts give.
        given: String,
    },
    /// The plan predicts neither an orientation nor a position for a part.
    #[error(
        "the plan predicts no final orientation or position for {0}: there is nothing to check \
         (plan it with `chladni plan`, which writes the prediction)"
    )]
    NoPrediction(String),
    /// A tolerance that is not a positive number.
    #[error("--tol-{0} {1}: a tolerance must be a finite positive number")]
    Tolerance(&'static str, f64),
}

impl VerifyError {
    /// The error's name in `--json` output and the cell's answers.
    pub fn name(&self) -> &'static str {
        match self {
            VerifyError::PartsMismatch { .. } => "plan_parts_mismatch",
            VerifyError::FaceMismatch { .. } => "plan_face_mismatch",
            VerifyError::NoPrediction(_) => "no_prediction",
            VerifyError::Tolerance(..) => "bad_tolerance",
        }
    }
}

/// What the plan predicts for one part kind on one face.
#[derive(Debug, Clone, PartialEq)]
pub struct Expectation {
    /// Index of the part among those given (the [`Located::kind`]).
    pub kind: usize,
    /// The face the entry is for (`None`: the part as drawn, or either face of a part that
    /// is its own mirror image).
    pub face: Option<Face>,
    /// Predicted orientation (deg).
    pub orientation_deg: Option<f64>,
    /// Orientations equal modulo this (deg): the plan's period and the part's symmetry.
    pub period_deg: f64,
    /// Predicted centroid (mm), where the plan fixes it.
    pub position_mm: Option<[f64; 2]>,
}

/// The plan's predictions for the parts given, and the tolerances: what a photo is judged by.
#[derive(Debug, Clone)]
pub struct Check {
    /// One per plan entry, in the plan's order.
    pub expected: Vec<Expectation>,
    /// The parts' templates, as [`locate`](super::locate) takes them.
    pub templates: Vec<Template>,
    /// Orientation tolerance (deg).
    pub tol_deg: f64,
    /// Position tolerance (mm).
    pub tol_mm: f64,
}

/// The period both `a` and `b` (deg) repeat with: 360°/lcm of their orders, or `a` when `b`
/// is no whole fraction of a turn.
fn common_period(a: f64, b: f64) -> f64 {
    let order = |p: f64| {
        let m = (360.0 / p).round();
        (m >= 1.0 && (360.0 / m - p).abs() < 1e-6).then_some(m as u64)
    };
    match (order(a), order(b)) {
        (Some(m), Some(k)) => {
            let gcd = |mut x: u64, mut y: u64| {
                while y != 0 {
                    (x, y) = (y, x % y);
                }
                x
            };
            360.0 / (m / gcd(m, k) * k) as f64
        }
        _ => a,
    }
}

fn face_name(f: Option<Face>) -> String {
    f.map_or("no face (the part as drawn)".to_string(), |f| f.to_string())
}

impl Check {
    /// The predictions of `plan` for `parts` (given in the plan's order, as `chladni
    /// simulate` takes them); a plan made for both faces gives each part without a mirror axis
    /// two entries, face up and flipped.
    pub fn new(
        plan: &PlanFile,
        parts: &[Part],
        tol_deg: f64,
        tol_mm: f64,
    ) -> Result<Check, VerifyError> {
        for (name, v) in [("deg", tol_deg), ("mm", tol_mm)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(VerifyError::Tolerance(name, v));
            }
        }
        let entries = plan.parts.as_deref().unwrap_or_default();
        let both = entries.iter().any(|p| p.face == Some(Face::Flipped));
        let faces = mirror::faces(parts, both);
        let planned = plan.parts.as_ref().map_or(1, Vec::len);
        if planned != faces.of.len() {
            let hint = if both || faces.of.iter().all(|o| o.face.is_none()) {
                " (give the parts the plan was made for, in its order)"
            } else {
                "; a part file says \"flips\": true but the plan is for one face"
            };
            return Err(VerifyError::PartsMismatch { planned, given: faces.of.len(), hint });
        }
        for (entry, (p, o)) in entries.iter().zip(&faces.of).enumerate() {
            if p.face != o.face {
                return Err(VerifyError::FaceMismatch {
                    entry,
                    name: p.name.clone(),
                    planned: face_name(p.face),
                    given: face_name(o.face),
                });
            }
        }
        let templates: Vec<Template> = parts.iter().map(Template::new).collect();
        let mut expected = Vec::new();
        for (i, o) in faces.of.iter().enumerate() {
            let Some(view) = plan.for_part(i) else { continue };
            let t = &templates[o.source];
            if view.final_orientation_deg.is_none() && view.final_position_mm.is_none() {
                return Err(VerifyError::NoPrediction(faces.parts[i].name.clone()));
            }
            let plan_period = view.period_deg.filter(|p| p.is_finite() && *p > 0.0);
            expected.push(Expectation {
                kind: o.source,
                face: o.face,
                orientation_deg: view.final_orientation_deg,
                period_deg: plan_period.map_or(t.period_deg, |p| common_period(t.period_deg, p)),
                position_mm: view.final_position_mm,
            });
        }
        Ok(Check { expected, templates, tol_deg, tol_mm })
    }
}

/// Why a part is off.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Miss {
    /// It lies on a face the plan is not for.
    WrongFace,
    /// Its orientation is outside the tolerance.
    Orientation,
    /// Its centroid is farther than the tolerance from the predicted position.
    Position,
    /// Its pose cannot be seen (a cluster, partly hidden, or its outline does not fit).
    NotSeen,
    /// Which face is up cannot be told from the photo (`Located::face_certain` false).
    FaceUnknown,
}

/// One part found, judged.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Checked {
    /// The part as located.
    #[serde(flatten)]
    pub located: Located,
    /// As the plan predicts.
    pub ok: bool,
    /// Why not, in words naming the part, the values and the tolerance.
    pub reason: Option<String>,
    /// Why not, by name.
    pub miss: Option<Miss>,
    /// The predicted orientation (deg), if any.
    pub planned_deg: Option<f64>,
    /// Its orientation's distance from the prediction (deg, modulo the period).
    pub orientation_error_deg: Option<f64>,
    /// Its centroid's distance from the predicted position (mm), if one is predicted.
    pub position_error_mm: Option<f64>,
}

/// A blob that holds parts whose poses cannot be seen: counted, never oriented.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Unseen {
    /// The blob.
    #[serde(flatten)]
    pub blob: Unknown,
    /// How many parts it is taken for.
    pub parts: usize,
    /// Why they are not verified.
    pub reason: String,
}

/// The verdict on a photo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    /// Every part found is as the plan predicts.
    Ok,
    /// At least one part is off, or cannot be seen.
    Off,
    /// No part was found on the plate.
    Empty,
}

/// The result of checking one photo.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Verification {
    /// The verdict.
    pub result: Outcome,
    /// Parts on the plate: those located and those in blobs whose poses cannot be seen.
    pub found: usize,
    /// Parts as the plan predicts.
    pub oriented: usize,
    /// `oriented / found`; `None` when nothing was found.
    pub success_rate: Option<f64>,
    /// The orientation tolerance (deg).
    pub tolerance_deg: f64,
    /// The position tolerance (mm).
    pub tolerance_mm: f64,
    /// Each located part, judged.
    pub parts: Vec<Checked>,
    /// Blobs holding parts whose poses cannot be seen.
    pub unseen: Vec<Unseen>,
    /// Blobs that are no given part (not counted).
    pub unknown: Vec<Unknown>,
}

impl Check {
    /// The plan's entry for a part of kind `kind` on face `flipped`, or `None` when the plan is
    /// for the other face only.
    fn entry(&self, kind: usize, flipped: bool) -> Option<&Expectation> {
        let face = if flipped { Face::Flipped } else { Face::Up };
        let mut of_kind = self.expected.iter().filter(|e| e.kind == kind);
        of_kind.clone().find(|e| e.face == Some(face)).or_else(|| {
            // A one-face entry is for the part as drawn; a part that is its own mirror image
            // is always reported face up.
            of_kind.find(|e| e.face.is_none() && !flipped)
        })
    }

    /// One located part against the plan.
    fn judge_part(&self, l: &Located) -> Checked {
        let mut c = Checked {
            located: l.clone(),
            ok: false,
            reason: None,
            miss: None,
            planned_deg: None,
            orientation_error_deg: None,
            position_error_mm: None,
        };
        if !l.face_certain {
            c.miss = Some(Miss::FaceUnknown);
            c.reason = Some(format!(
                "{} at ({:.1}, {:.1}) mm: both its faces fit the photo about equally (score \
                 {:.2}), so which side is up cannot be told and the pose is not verified; \
                 photograph the plate closer (smaller pixels)",
                l.part, l.x_mm, l.y_mm, l.score
            ));
            return c;
        }
        let Some(e) = self.entry(l.kind, l.flipped) else {
            c.miss = Some(Miss::WrongFace);
            c.reason = Some(format!(
                "{} at ({:.1}, {:.1}) mm lies {}, and the plan is for the other face only (plan \
                 with --both-faces when parts may land either way up)",
                l.part,
                l.x_mm,
                l.y_mm,
                if l.flipped { "flipped" } else { "face up" }
            ));
            return c;
        };
        c.planned_deg = e.orientation_deg;
        let mut reasons = Vec::new();
        if let Some(t) = e.orientation_deg {
            let err = signed_diff(l.theta_deg, t, e.period_deg).abs();
            c.orientation_error_deg = Some(err);
            if err > self.tol_deg {
                c.miss = Some(Miss::Orientation);
                reasons.push(format!(
                    "θ {:.1}° is {err:.1}° from the planned {t:.1}° (modulo {}°; tolerance {}°)",
                    l.theta_deg, e.period_deg, self.tol_deg
                ));
            }
        }
        if let Some(p) = e.position_mm {
            let d = (l.x_mm - p[0]).hypot(l.y_mm - p[1]);
            c.position_error_mm = Some(d);
            if d > self.tol_mm {
                c.miss = c.miss.or(Some(Miss::Position));
                reasons.push(format!(
                    "its centroid ({:.1}, {:.1}) mm is {d:.1} mm from the planned ({:.1}, {:.1}) \
                     mm (tolerance {} mm)",
                    l.x_mm, l.y_mm, p[0], p[1], self.tol_mm
                ));
            }
        }
        c.ok = reasons.is_empty();
        if !c.ok {
            c.reason = Some(format!("{}: {}", l.part, reasons.join("; ")));
        }
        c
    }

    /// The parts a blob holds whose poses cannot be seen (none for an unmatched blob).
    fn unseen(u: &Unknown) -> Option<Unseen> {
        let name = u.part.as_deref().unwrap_or("a part");
        let at = format!("at ({:.1}, {:.1}) mm", u.x_mm, u.y_mm);
        let (parts, reason) = match u.why {
            Why::Unmatched => return None,
            Why::Cluster => {
                let n = u.count.unwrap_or(2);
                (n, format!("{n} × {name} {at} touch and cannot be told apart: poses not seen"))
            }
            Why::Partial => {
                (1, format!("{name} {at} is partly hidden or over the plate's edge: pose not seen"))
            }
            Why::Misfit => {
                (1, format!("{name} {at}: the outline does not fit the blob: pose not seen"))
            }
        };
        Some(Unseen { blob: u.clone(), parts, reason })
    }

    /// Judges what [`locate`](super::locate) found in a photo.
    pub fn judge(&self, report: &Report) -> Verification {
        let parts: Vec<Checked> = report.parts.iter().map(|l| self.judge_part(l)).collect();
        let unseen: Vec<Unseen> = report.unknown.iter().filter_map(Check::unseen).collect();
        let unknown = report.unknown.iter().filter(|u| u.why == Why::Unmatched).cloned().collect();
        let found = parts.len() + unseen.iter().map(|u| u.parts).sum::<usize>();
        let oriented = parts.iter().filter(|c| c.ok).count();
        let result = match found {
            0 => Outcome::Empty,
            n if n == oriented => Outcome::Ok,
            _ => Outcome::Off,
        };
        Verification {
            result,
            found,
            oriented,
            success_rate: (found > 0).then(|| oriented as f64 / found as f64),
            tolerance_deg: self.tol_deg,
            tolerance_mm: self.tol_mm,
            parts,
            unseen,
            unknown,
        }
    }
}

/// Colour of a part as planned, of one that is off, and of a blob whose parts are not seen.
const OK_RGB: [u8; 3] = [0, 200, 60];
const OFF_RGB: [u8; 3] = [230, 30, 30];
const UNSEEN_RGB: [u8; 3] = [255, 150, 0];

/// The figure of a verification (`verify --plot`, the cell's dashboard): the rectified view
/// `img` (plate height `h_mm`) with each located part's outline at its pose, 3 px wide, green
/// when as planned and red when off, and an orange cross on each blob whose parts are not
/// seen.
pub fn draw(
    img: &GrayImage,
    report: &Report,
    v: &Verification,
    templates: &[Template],
    h_mm: f64,
) -> RgbImage {
    let pix = report.pixel_mm;
    let mut out = RgbImage::from_fn(img.width(), img.height(), |x, y| {
        let g = img.get_pixel(x, y)[0];
        Rgb([g, g, g])
    });
    let px = |q: [f64; 2]| ((q[0] / pix) as f32, ((h_mm - q[1]) / pix) as f32);
    let mut line = |a: (f32, f32), b: (f32, f32), colour: [u8; 3]| {
        for (dx, dy) in [(0.0, 0.0), (1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)] {
            draw_line_segment_mut(
                &mut out,
                (a.0 + dx, a.1 + dy),
                (b.0 + dx, b.1 + dy),
                Rgb(colour),
            );
        }
    };
    for c in &v.parts {
        let l = &c.located;
        let Some(t) = templates.get(l.kind) else { continue };
        let part = if l.flipped { t.mirrored.as_ref().unwrap_or(&t.part) } else { &t.part };
        let colour = if c.ok { OK_RGB } else { OFF_RGB };
        for ring in placed(part, [l.x_mm, l.y_mm], l.theta_deg) {
            for k in 0..ring.len() {
                line(px(ring[k]), px(ring[(k + 1) % ring.len()]), colour);
            }
        }
    }
    for u in &v.unseen {
        let (x, y) = px([u.blob.x_mm, u.blob.y_mm]);
        line((x - 10.0, y - 10.0), (x + 10.0, y + 10.0), UNSEEN_RGB);
        line((x - 10.0, y + 10.0), (x + 10.0, y - 10.0), UNSEEN_RGB);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use chladni_core::model::plan_file::PartPrediction;

    fn tri() -> Part {
        Part::new("tri".into(), vec![[0.0, 0.0], [36.0, 0.0], [0.0, 22.0]], vec![]).unwrap()
    }

    fn square() -> Part {
        Part::new("sq".into(), vec![[0.0, 0.0], [20.0, 0.0], [20.0, 20.0], [0.0, 20.0]], vec![])
            .unwrap()
    }

    fn plan(orientation: f64, period: f64, position: Option<[f64; 2]>) -> PlanFile {
        PlanFile {
            final_orientation_deg: Some(orientation),
            period_deg: Some(period),
            final_position_mm: position,
            ..PlanFile::default()
        }
    }

    fn located(kind: usize, name: &str, x: f64, y: f64, theta: f64, flipped: bool) -> Located {
        Located {
            part: name.into(),
            x_mm: x,
            y_mm: y,
            theta_deg: theta,
            flipped,
            face_certain: true,
            score: 0.95,
            rms_px: 0.2,
            touching: false,
            kind,
        }
    }

    fn report(parts: Vec<Located>, unknown: Vec<Unknown>) -> Report {
        Report {
            parts,
            unknown,
            corners: [[0.0; 2]; 4],
            corners_found: false,
            pixel_mm: 0.3,
            parts_dark: true,
            levels: super::super::Levels { parts_dark: true, threshold: 0.6, contrast: 0.7 },
        }
    }

    #[test]
    fn orientation_position_and_face_are_each_judged_and_named() {
        let check =
            Check::new(&plan(110.0, 360.0, Some([150.0, 100.0])), &[tri()], 5.0, 2.0).unwrap();
        let v = check.judge(&report(
            vec![
                located(0, "tri", 150.5, 100.2, 113.0, false),
                located(0, "tri", 150.0, 100.0, 150.0, false),
                located(0, "tri", 160.0, 100.0, 110.0, false),
                located(0, "tri", 150.0, 100.0, 110.0, true),
            ],
            vec![],
        ));
        let misses: Vec<Option<Miss>> = v.parts.iter().map(|c| c.miss).collect();
        assert_eq!(
            misses,
            [None, Some(Miss::Orientation), Some(Miss::Position), Some(Miss::WrongFace)]
        );
        assert!(v.parts[1].reason.as_ref().unwrap().contains("40.0° from the planned 110.0°"));
        assert!(v.parts[2].reason.as_ref().unwrap().contains("10.0 mm from the planned"));
        assert!(v.parts[3].reason.as_ref().unwrap().contains("--both-faces"));
        assert_eq!((v.found, v.oriented, v.result), (4, 1, Outcome::Off));
        assert_eq!(v.success_rate, Some(0.25));
    }

    #[test]
    fn a_face_the_photo_cannot_tell_is_never_ok() {
        let check = Check::new(&plan(110.0, 360.0, None), &[tri()], 5.0, 2.0).unwrap();
        let mut l = located(0, "tri", 150.0, 100.0, 110.0, false);
        l.face_certain = false;
        let v = check.judge(&report(vec![l], vec![]));
        assert_eq!((v.found, v.oriented, v.result), (1, 0, Outcome::Off));
        assert_eq!(v.parts[0].miss, Some(Miss::FaceUnknown));
        assert!(v.parts[0].reason.as_ref().unwrap().contains("cannot be told"));
    }

    #[test]
    fn the_symmetry_and_the_plans_period_fold_together() {
        // A square repeats every 90°; a plan period of 180° does not undo that.
        let check = Check::new(&plan(10.0, 180.0, None), &[square()], 5.0, 2.0).unwrap();
        assert_eq!(check.expected[0].period_deg, 90.0);
        let v = check.judge(&report(vec![located(0, "sq", 50.0, 50.0, 88.0, false)], vec![]));
        assert_eq!(v.result, Outcome::Off);
        let v = check.judge(&report(vec![located(0, "sq", 50.0, 50.0, 12.0, false)], vec![]));
        assert_eq!(v.result, Outcome::Ok);
        assert_eq!(common_period(360.0, 180.0), 180.0);
        assert_eq!(common_period(120.0, 180.0), 60.0);
        assert_eq!(common_period(360.0, 7.3), 360.0);
    }

    #[test]
    fn a_plan_for_both_faces_judges_each_face_by_its_entry() {
        let entry = |name: &str, deg, face| PartPrediction {
            name: name.into(),
            final_orientation_deg: Some(deg),
            period_deg: Some(360.0),
            face: Some(face),
            ..PartPrediction::default()
        };
        let p = PlanFile {
            parts: Some(vec![
                entry("tri", 30.0, Face::Up),
                entry("tri (flipped)", 200.0, Face::Flipped),
            ]),
            ..PlanFile::default()
        };
        let check = Check::new(&p, &[tri()], 5.0, 2.0).unwrap();
        let v = check.judge(&report(
            vec![
                located(0, "tri", 50.0, 50.0, 31.0, false),
                located(0, "tri", 90.0, 50.0, 198.0, true),
            ],
            vec![],
        ));
        assert_eq!((v.result, v.oriented), (Outcome::Ok, 2));
        // The same plan against a one-face part list is refused by name.
        let one =
            PlanFile { parts: Some(vec![entry("tri", 30.0, Face::Up)]), ..PlanFile::default() };
        let e = Check::new(&one, &[tri(), square()], 5.0, 2.0).unwrap_err();
        assert_eq!(e.name(), "plan_parts_mismatch");
        let e = Check::new(&PlanFile::default(), &[tri()], 5.0, 2.0).unwrap_err();
        assert_eq!(e.name(), "no_prediction");
        let e = Check::new(&plan(1.0, 360.0, None), &[tri()], f64::NAN, 2.0).unwrap_err();
        assert_eq!(e.name(), "bad_tolerance");
    }

    #[test]
    fn clusters_count_as_unseen_parts_and_unmatched_blobs_not_at_all() {
        let check = Check::new(&plan(110.0, 360.0, None), &[tri()], 5.0, 2.0).unwrap();
        let blob = |why, count| Unknown {
            why,
            part: Some("tri".into()),
            count,
            area_mm2: 800.0,
            x_mm: 40.0,
            y_mm: 40.0,
        };
        let v = check.judge(&report(
            vec![located(0, "tri", 150.0, 100.0, 111.0, false)],
            vec![blob(Why::Cluster, Some(2)), blob(Why::Unmatched, None)],
        ));
        assert_eq!((v.found, v.oriented, v.result), (3, 1, Outcome::Off));
        assert!(v.unseen[0].reason.contains("2 × tri"));
        assert_eq!(v.unknown.len(), 1);
        let empty = check.judge(&report(vec![], vec![blob(Why::Unmatched, None)]));
        assert_eq!((empty.result, empty.success_rate), (Outcome::Empty, None));
    }
}
