//! Synthetic Chladni photos for tests and docs: sand grains scattered around known node lines
//! and curves on a plate with uneven lighting and sensor noise.

use image::{GrayImage, Luma};

use crate::plate::contour::{Polyline, distance_to};

/// Small deterministic PRNG (SplitMix64).
#[derive(Debug, Clone)]
pub struct Rng(pub u64);
impl Rng {
    /// Next 64 random bits.
    // Inlined: a rendered photo draws three per pixel (see `geometry::inside`).
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    #[inline]
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct Scene {
    /// Image size (pixels).
    pub px: (u32, u32),
    /// Plate size (mm).
    pub size_mm: [f64; 2],
    /// Node lines (angle_deg, offset_mm) in the convention of [`super::Line`].
    pub lines: Vec<(f64, f64)>,
    /// Curved nodes: polylines in plate coordinates (mm, origin at the bottom-left corner).
    pub curves: Vec<Polyline>,
    /// Width (1σ, mm) of the sand band around a node.
    pub sand_sigma_mm: f64,
    /// Peak grain density on a node (grains per pixel).
    pub density: f64,
    /// Density of stray grains elsewhere.
    pub stray: f64,
    /// Pixel noise amplitude (grey levels).
    pub noise: f64,
    /// Dark sand on a light plate instead of light sand on a dark plate.
    pub dark_sand: bool,
    /// Seed.
    pub seed: u64,
    /// Grain diameter (mm): 0 draws single-pixel grains (sand); lentils are ~4 mm disks,
    /// scattered so that they cover the same fraction of the plate.
    pub grain_mm: f64,
}

impl Scene {
    /// The tests' standard photo: 360×240 px of a 300×200 mm plate, light sand in a
    /// 3 mm band (σ) around the nodes, 2 % stray grains, ±25 grey levels of noise.
    pub fn standard(lines: Vec<(f64, f64)>, curves: Vec<Polyline>, seed: u64) -> Scene {
        Scene {
            px: (360, 240),
            size_mm: [300.0, 200.0],
            lines,
            curves,
            sand_sigma_mm: 3.0,
            density: 0.6,
            stray: 0.02,
            noise: 25.0,
            dark_sand: false,
            seed,
            grain_mm: 0.0,
        }
    }

    /// The tests' lentil photo: 720×480 px of the 300×200 mm plate, 4 mm lentils (10 px)
    /// with 80 % coverage on the node, bands σ = 5 mm wide, 1 % stray lentils.
    pub fn lentils(lines: Vec<(f64, f64)>, curves: Vec<Polyline>, seed: u64) -> Scene {
        Scene {
            px: (720, 480),
            grain_mm: 4.0,
            sand_sigma_mm: 5.0,
            density: 0.8,
            stray: 0.01,
            ..Scene::standard(lines, curves, seed)
        }
    }
}

/// Fraction of the plate covered by grains at distance `d` (mm) from the nearest node.
fn coverage(s: &Scene, d: f64) -> f64 {
    s.density * (-0.5 * (d / s.sand_sigma_mm).powi(2)).exp() + s.stray
}

/// Distance (mm) from plate point (x, y) (origin at the centre) to the nearest node.
fn node_distance(s: &Scene, x: f64, y: f64) -> f64 {
    s.lines
        .iter()
        .map(|&(a, o)| {
            let a = a.to_radians();
            (-a.sin() * x + a.cos() * y - o).abs()
        })
        .fold(f64::MAX, f64::min)
        .min(distance_to([x + s.size_mm[0] / 2.0, y + s.size_mm[1] / 2.0], &s.curves))
}

/// Lentils: disks of `grain_mm` whose centres fall with the density that covers the
/// same fraction of the plate as single-pixel sand would (`None` for sand).
fn lentil_mask(s: &Scene, rng: &mut Rng) -> Option<Vec<bool>> {
    if s.grain_mm <= 0.0 {
        return None;
    }
    let (w, h) = (s.px.0 as i64, s.px.1 as i64);
    let (sx, sy) = (s.size_mm[0] / w as f64, s.size_mm[1] / h as f64);
    let r = 0.5 * s.grain_mm;
    let disk_px = std::f64::consts::PI * r * r / (sx * sy);
    let (rx, ry) = ((r / sx).ceil() as i64, (r / sy).ceil() as i64);
    let mut mask = vec![false; (w * h) as usize];
    for row in 0..h {
        for col in 0..w {
            let x = (col as f64 + 0.5) * sx - s.size_mm[0] / 2.0;
            let y = s.size_mm[1] / 2.0 - (row as f64 + 0.5) * sy;
            if rng.uniform() >= coverage(s, node_distance(s, x, y)) / disk_px {
                continue;
            }
            for j in (row - ry).max(0)..(row + ry + 1).min(h) {
                for i in (col - rx).max(0)..(col + rx + 1).min(w) {
                    if ((i - col) as f64 * sx).hypot((j - row) as f64 * sy) <= r {
                        mask[(j * w + i) as usize] = true;
                    }
                }
            }
        }
    }
    Some(mask)
}

/// Renders the scene.
pub fn render(s: &Scene) -> GrayImage {
    let mut rng = Rng(s.seed);
    let (w, h) = s.px;
    let (sx, sy) = (s.size_mm[0] / w as f64, s.size_mm[1] / h as f64);
    let lentils = lentil_mask(s, &mut rng);
    let mut img = GrayImage::new(w, h);
    for row in 0..h {
        for col in 0..w {
            let x = (col as f64 + 0.5) * sx - s.size_mm[0] / 2.0;
            let y = s.size_mm[1] / 2.0 - (row as f64 + 0.5) * sy;
            // Lighting gradient across the plate plus noise.
            let light = 70.0 + 30.0 * (col as f64 / w as f64) - 15.0 * (row as f64 / h as f64);
            let noise = s.noise * (rng.uniform() + rng.uniform() + rng.uniform() - 1.5);
            let grain = match &lentils {
                Some(m) => m[(row * w + col) as usize],
                None => rng.uniform() < coverage(s, node_distance(s, x, y)),
            };
            let v = match (grain, s.dark_sand) {
                (false, false) => light + noise,
                (true, false) => 190.0 + 40.0 * rng.uniform() + noise,
                (false, true) => 255.0 - light + noise,
                (true, true) => 40.0 + 30.0 * rng.uniform() + noise,
            };
            img.put_pixel(col, row, Luma([v.round().clamp(0.0, 255.0) as u8]));
        }
    }
    img
}

/// Circle arc about `centre` (mm) of radius `r` from `from_deg` to `to_deg` (CCW), as `n`
/// segments.
pub fn arc(centre: [f64; 2], r: f64, from_deg: f64, to_deg: f64, n: usize) -> Polyline {
    (0..=n)
        .map(|k| {
            let a = (from_deg + (to_deg - from_deg) * k as f64 / n as f64).to_radians();
            [centre[0] + r * a.cos(), centre[1] + r * a.sin()]
        })
        .collect()
}

/// Branch c + R(α)·(a cosh t, b sinh t), t ∈ [−t_max, t_max], as `n` segments (the
/// hyperbola node of plate/model.rs).
pub fn hyperbola(centre: [f64; 2], angle_deg: f64, ab: [f64; 2], t_max: f64, n: usize) -> Polyline {
    let (s, c) = angle_deg.to_radians().sin_cos();
    (0..=n)
        .map(|k| {
            let t = -t_max + 2.0 * t_max * k as f64 / n as f64;
            let (u, v) = (ab[0] * t.cosh(), ab[1] * t.sinh());
            [centre[0] + c * u - s * v, centre[1] + s * u + c * v]
        })
        .collect()
}
