//! Synthetic photos of parts on the plate at known poses, for the tests, the bench and the
//! accuracy table of docs/plate.md: several parts on either face, seen in perspective from
//! the given corners, with lens blur, sensor noise and uneven light, from a seed.
//!
//! Each photo pixel is mapped back onto the plate by the homography of the corners; pixels
//! near an edge are averaged over 4 × 4 sub-samples (the coverage a real sensor integrates),
//! then the image is blurred (Gaussian, imageproc) and noise added.

use image::{GrayImage, Luma};
use imageproc::filter::gaussian_blur_f32;

use super::plot::placed;
use super::{Located, Template};
use chladni_core::model::geometry::segments_meet;
use chladni_core::model::part::{Part, inside};
use chladni_core::plate::photo::rectify::Homography;
use chladni_core::plate::photo::synth::Rng;

/// One part on the plate.
#[derive(Debug, Clone, PartialEq)]
pub struct Placed {
    /// Index into [`Photo::parts`].
    pub part: usize,
    /// Centroid (mm, plate frame).
    pub c: [f64; 2],
    /// Orientation (deg CCW).
    pub theta_deg: f64,
    /// Lies on its other face ([`Part::mirrored`]).
    pub flipped: bool,
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct Photo {
    /// Image size (px).
    pub px: (u32, u32),
    /// Plate size (mm).
    pub size_mm: [f64; 2],
    /// The plate's corners in the photo (px; bottom-left, bottom-right, top-right, top-left).
    pub corners: [[f64; 2]; 4],
    /// Part kinds.
    pub parts: Vec<Part>,
    /// Where they lie.
    pub placed: Vec<Placed>,
    /// Grey level of the plate, the parts and the surroundings (before the lighting).
    pub grey: [f64; 3],
    /// Lighting: the grey levels fall by up to this share across the photo.
    pub light_falloff: f64,
    /// Gaussian blur σ (px).
    pub blur_px: f64,
    /// Noise amplitude (grey levels, about 1σ).
    pub noise: f64,
    /// Seed.
    pub seed: u64,
}

impl Photo {
    /// The tests' standard photo: 1280 × 900 px of a 300 × 200 mm plate in perspective (about
    /// 0.27 mm per pixel), dark parts on a light plate against a dark background, σ = 0.8 px
    /// blur, 6 grey levels of noise, 25 % light fall-off.
    pub fn standard(parts: Vec<Part>, placed: Vec<Placed>, seed: u64) -> Photo {
        Photo {
            px: (1280, 900),
            size_mm: [300.0, 200.0],
            corners: [[70.0, 840.0], [1215.0, 860.0], [1170.0, 95.0], [110.0, 70.0]],
            parts,
            placed,
            grey: [205.0, 55.0, 30.0],
            light_falloff: 0.25,
            blur_px: 0.8,
            noise: 6.0,
            seed,
        }
    }

    /// The same with light parts on a dark plate against a light background.
    pub fn light_on_dark(mut self) -> Photo {
        self.grey = [60.0, 215.0, 170.0];
        self
    }
}

/// A placed part's rings (plate frame, mm), centroid and bounding radius.
type Shape = (Vec<Vec<[f64; 2]>>, [f64; 2], f64);

/// The rings of every placed part (plate frame, mm) and each part's bounding circle.
fn shapes(s: &Photo) -> Vec<Shape> {
    s.placed
        .iter()
        .map(|p| {
            let part = &s.parts[p.part];
            let face = if p.flipped { part.mirrored() } else { part.clone() };
            let rings = placed(&face, p.c, p.theta_deg);
            let r =
                rings[0].iter().map(|q| (q[0] - p.c[0]).hypot(q[1] - p.c[1])).fold(0.0, f64::max);
            (rings, p.c, r)
        })
        .collect()
}

/// What lies at plate point `q`: 0 plate, 1 part, 2 off the plate.
fn class(s: &Photo, shapes: &[Shape], q: [f64; 2]) -> usize {
    if !(q[0] >= 0.0 && q[1] >= 0.0 && q[0] <= s.size_mm[0] && q[1] <= s.size_mm[1]) {
        return 2;
    }
    // Squared distances: this runs for every pixel (and 16 times for one near an edge).
    let hit = shapes.iter().any(|(rings, c, r)| {
        (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2) <= r * r
            && inside(q, &rings[0])
            && !rings[1..].iter().any(|h| inside(q, h))
    });
    usize::from(hit)
}

/// Renders the photo.
pub fn render(s: &Photo) -> GrayImage {
    let (w, h) = s.px;
    let [bl, br, tr, tl] = s.corners;
    let (pw, ph) = (s.size_mm[0], s.size_mm[1]);
    let to_plate =
        Homography::from_points([bl, br, tr, tl], [[0.0, 0.0], [pw, 0.0], [pw, ph], [0.0, ph]])
            .expect("the synthetic corners form a quadrilateral");
    let shapes = shapes(s);
    // Plate size of a photo pixel at its largest (for the near-an-edge test).
    let pix_mm = (pw / (br[0] - bl[0]).abs().min((tr[0] - tl[0]).abs())) * 1.5;
    let near_edge = |q: [f64; 2]| {
        let plate =
            q[0].abs().min(q[1].abs()).min((q[0] - pw).abs()).min((q[1] - ph).abs()) < 2.0 * pix_mm;
        plate
            || shapes.iter().any(|(_, c, r)| {
                (q[0] - c[0]).powi(2) + (q[1] - c[1]).powi(2) <= (r + 2.0 * pix_mm).powi(2)
            })
    };
    let mut f = image::ImageBuffer::<Luma<f32>, Vec<f32>>::new(w, h);
    for (x, y, p) in f.enumerate_pixels_mut() {
        let centre = to_plate.map([f64::from(x) + 0.5, f64::from(y) + 0.5]);
        let v = if near_edge(centre) {
            let mut sum = 0.0;
            for k in 0..16 {
                let (u, v) = (
                    f64::from(x) + (f64::from(k % 4) + 0.5) / 4.0,
                    f64::from(y) + (f64::from(k / 4) + 0.5) / 4.0,
                );
                sum += s.grey[class(s, &shapes, to_plate.map([u, v]))];
            }
            sum / 16.0
        } else {
            s.grey[class(s, &shapes, centre)]
        };
        let light = 1.0
            - s.light_falloff
                * (0.6 * f64::from(x) / f64::from(w) + 0.4 * f64::from(y) / f64::from(h));
        p[0] = (v * light) as f32;
    }
    let blurred = if s.blur_px > 0.0 { gaussian_blur_f32(&f, s.blur_px as f32) } else { f };
    let mut rng = Rng(s.seed);
    GrayImage::from_fn(w, h, |x, y| {
        let n = s.noise * 2.0 * (rng.uniform() + rng.uniform() + rng.uniform() - 1.5);
        Luma([(f64::from(blurred.get_pixel(x, y)[0]) + n).round().clamp(0.0, 255.0) as u8])
    })
}

/// Whether two placed parts' outlines overlap or touch (a vertex of either inside the other,
/// or two edges meeting).
fn overlap(a: &[Vec<[f64; 2]>], b: &[Vec<[f64; 2]>]) -> bool {
    let (a, b) = (&a[0], &b[0]);
    let edges =
        |r: &Vec<[f64; 2]>| (0..r.len()).map(|k| (r[k], r[(k + 1) % r.len()])).collect::<Vec<_>>();
    let (ea, eb) = (edges(a), edges(b));
    a.iter().any(|p| inside(*p, b))
        || b.iter().any(|p| inside(*p, a))
        || ea.iter().any(|&(p, q)| eb.iter().any(|&(r, t)| segments_meet(p, q, r, t)))
}

/// `n` parts at random poses and faces, clear of each other by `gap_mm` and of the plate's
/// edge by 5 mm, then `touching` more, each placed against one of the first ones (moved
/// towards it until the outlines meet, to 0.02 mm).
pub fn random_poses(
    parts: &[Part],
    size_mm: [f64; 2],
    n: usize,
    touching: usize,
    gap_mm: f64,
    seed: u64,
) -> Vec<Placed> {
    let mut rng = Rng(seed);
    let mut out: Vec<Placed> = Vec::new();
    let radius = |p: &Placed| radius(parts, p);
    let mut tries = 0;
    while out.len() < n && tries < 10_000 {
        tries += 1;
        let kind = (rng.uniform() * parts.len() as f64) as usize % parts.len();
        let mut p = Placed {
            part: kind,
            c: [0.0; 2],
            theta_deg: 360.0 * rng.uniform(),
            flipped: rng.uniform() < 0.5,
        };
        let r = radius(&p) + 5.0;
        p.c = [
            r + (size_mm[0] - 2.0 * r) * rng.uniform(),
            r + (size_mm[1] - 2.0 * r) * rng.uniform(),
        ];
        if out
            .iter()
            .all(|o| (o.c[0] - p.c[0]).hypot(o.c[1] - p.c[1]) > radius(o) + radius(&p) + gap_mm)
        {
            out.push(p);
        }
    }
    let lone = out.len();
    for i in 0..touching.min(lone) {
        for _ in 0..50 {
            if let Some(p) = partner(parts, &out, i, &mut rng, size_mm, gap_mm) {
                out.push(p);
                break;
            }
        }
    }
    out
}

/// `placed` moved as between two photos of a camera loop: each part shifted by up to
/// `max_mm` in a random direction and turned by up to ±`max_deg`, on its face, kept on the
/// plate (5 mm clear of its edge) and `gap_mm` clear of the others (a part that finds no such
/// place in 50 draws stays where it was).
pub fn nudge(
    parts: &[Part],
    placed: &[Placed],
    size_mm: [f64; 2],
    (max_mm, max_deg): (f64, f64),
    gap_mm: f64,
    seed: u64,
) -> Vec<Placed> {
    let mut rng = Rng(seed);
    let mut out = placed.to_vec();
    for i in 0..out.len() {
        for _ in 0..50 {
            let (ang, d) = (std::f64::consts::TAU * rng.uniform(), max_mm * rng.uniform());
            let p = Placed {
                c: [out[i].c[0] + d * ang.cos(), out[i].c[1] + d * ang.sin()],
                theta_deg: out[i].theta_deg + max_deg * (2.0 * rng.uniform() - 1.0),
                ..out[i].clone()
            };
            let r = radius(parts, &p) + 5.0;
            let on = p.c[0] > r && p.c[1] > r && p.c[0] < size_mm[0] - r && p.c[1] < size_mm[1] - r;
            let clear = out.iter().enumerate().filter(|(j, _)| *j != i).all(|(_, o)| {
                (o.c[0] - p.c[0]).hypot(o.c[1] - p.c[1])
                    > radius(parts, o) + radius(parts, &p) + gap_mm
            });
            if on && clear {
                out[i] = p;
                break;
            }
        }
    }
    out
}

/// The bounding radius (mm) of a placed part.
fn radius(parts: &[Part], p: &Placed) -> f64 {
    let part = &parts[p.part];
    let c = part.centroid();
    part.outline.iter().map(|q| (q[0] - c[0]).hypot(q[1] - c[1])).fold(0.0, f64::max)
}

/// A random part against `out[i]` (moved towards it until the outlines meet, to 0.02 mm),
/// if it lands on the plate clear of every other part.
fn partner(
    parts: &[Part],
    out: &[Placed],
    i: usize,
    rng: &mut Rng,
    size_mm: [f64; 2],
    gap_mm: f64,
) -> Option<Placed> {
    let rings = |p: &Placed| {
        let part = if p.flipped { parts[p.part].mirrored() } else { parts[p.part].clone() };
        placed(&part, p.c, p.theta_deg)
    };
    let kind = (rng.uniform() * parts.len() as f64) as usize % parts.len();
    let base = &out[i];
    let ang = std::f64::consts::TAU * rng.uniform();
    let mut p = Placed {
        part: kind,
        c: base.c,
        theta_deg: 360.0 * rng.uniform(),
        flipped: rng.uniform() < 0.5,
    };
    let dir = [ang.cos(), ang.sin()];
    let (mut lo, mut hi) = (0.0, radius(parts, base) + radius(parts, &p) + 1.0);
    let at = |d: f64| [base.c[0] + d * dir[0], base.c[1] + d * dir[1]];
    let base_rings = rings(base);
    while hi - lo > 0.02 {
        let mid = 0.5 * (lo + hi);
        p.c = at(mid);
        if overlap(&base_rings, &rings(&p)) { lo = mid } else { hi = mid }
    }
    p.c = at(hi);
    let r = radius(parts, &p) + 3.0;
    let on_plate = p.c[0] > r && p.c[1] > r && p.c[0] < size_mm[0] - r && p.c[1] < size_mm[1] - r;
    let clear = out.iter().enumerate().filter(|(j, _)| *j != i).all(|(_, o)| {
        (o.c[0] - p.c[0]).hypot(o.c[1] - p.c[1]) > radius(parts, o) + radius(parts, &p) + gap_mm
    });
    (on_plate && clear).then_some(p)
}

/// The tests' and the bench's parts: an L and a right triangle (both chiral: their flipped face is another
/// shape) and a tab with a hole on its mirror axis (the same shape on both faces).
pub fn sample_parts() -> Vec<Part> {
    let hole: Vec<[f64; 2]> = (0..12)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / 12.0;
            [8.0 + 4.0 * a.cos(), 9.0 + 4.0 * a.sin()]
        })
        .collect();
    vec![
        Part::new(
            "ell".into(),
            vec![[0.0, 0.0], [40.0, 0.0], [40.0, 10.0], [12.0, 10.0], [12.0, 28.0], [0.0, 28.0]],
            vec![],
        )
        .unwrap(),
        Part::new("tri".into(), vec![[0.0, 0.0], [36.0, 0.0], [0.0, 22.0]], vec![]).unwrap(),
        Part::new(
            "tab".into(),
            vec![[0.0, 0.0], [30.0, 0.0], [30.0, 18.0], [0.0, 18.0]],
            vec![hole],
        )
        .unwrap(),
    ]
}

/// Errors (mm, deg) of the located part matching placed part `p`, folding the symmetry
/// period and a self-mirrored part's flip; `None` when no located part is within 5 mm or its
/// face is wrong.
pub fn pose_error(t: &[Template], found: &[Located], p: &Placed) -> Option<(f64, f64)> {
    let tm = &t[p.part];
    let (mut theta, mut flipped) = (p.theta_deg, p.flipped);
    if let (true, Some(turn)) = (flipped, tm.flip_turn_deg) {
        theta += turn;
        flipped = false;
    }
    let l = found.iter().filter(|l| l.kind == p.part).min_by(|a, b| {
        let d = |l: &&Located| (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]);
        d(a).total_cmp(&d(b))
    })?;
    let dist = (l.x_mm - p.c[0]).hypot(l.y_mm - p.c[1]);
    if dist > 5.0 || l.flipped != flipped {
        return None;
    }
    let d = (l.theta_deg - theta).rem_euclid(tm.period_deg);
    Some((dist, d.min(tm.period_deg - d)))
}
