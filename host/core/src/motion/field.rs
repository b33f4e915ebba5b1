//! The field models of a mode (docs/motion.md): the force per unit area at a plate point and
//! its integral over a part (force and moment about the centroid). Force and moment:
//! - straight nodes: exact, per polygon edge (split at the node, Green's theorem
//!   ∫∫ g dA = ∮ G dη, ∫∫ η g dA = ∮ η G dη along each piece, 5-point Gauss–Legendre, exact
//!   for the sign and linear laws);
//! - several straight lines of one mode (`lines`): the field at a point is the nearest
//!   line's (law and gains across that line), by the midpoint rule over interior sample
//!   points of the part (about [`crate::motion::body::BODY_SAMPLES`] cells);
//! - hyperbola nodes: f = −k·g(ξ)·∇ξ is the gradient of k·G(ξ) (ξ the signed distance to the
//!   branch, tabulated once per branch and plate: Newton on its parameter), so force and
//!   moment are integrals of k·G(ξ) along the outline, cut where it crosses the node
//!   ([`crate::motion::potential::kinked_outline_wrench`]; 2·10⁻⁴ of the largest force from
//!   a fine area integral, against 4·10⁻² for the 160-cell midpoint rule it replaced);
//! - grid nodes: f = −gain·∇(φ²)/max|∇(φ²)| with Catmull–Rom bicubic φ is a gradient, so
//!   force and moment are integrals of φ² along the part's outline, cell by cell
//!   ([`crate::motion::potential`]): no interior samples, and far more accurate than them.
//!
//! Units: mm, rad.

use crate::analysis::reference::GL;
use crate::model::field::Law;
use crate::model::plate::{Mode, Node, PlateModel};
use std::collections::HashMap;
use std::sync::{Arc, Mutex, OnceLock};

use crate::model::grid::Grid;
use crate::model::pose::Pose;
use crate::motion::body::Body;
use crate::motion::potential::{Bicubic, Quadrature, kinked_outline_wrench};

/// Longest outline piece of the hyperbola's outline rule, as a fraction of the part's
/// radius (4 Gauss points per piece). Its error against pieces of R/50 is below 5·10⁻⁵ of
/// the largest force from R/4 to R alike (the bilinear distance table's kinks at every cell
/// line set that floor; test `hyperbola_outline_pieces_are_converged`), so R/2 halves the
/// table reads of R/4 at no measurable cost.
pub(crate) const HYPERBOLA_PIECE: f64 = 0.5;

/// A hole whose radius is at most this fraction of a grid cell enters the grid's fast wrench
/// by its four-point moment rule instead of its outline. At a whole cell the wrench stays
/// within its bound, but the keyed gear's bore (not centrally symmetric) moves the gear's
/// weak turning moment enough to end its runs 0.2–0.5° from the reference's; at half a cell
/// every run ends with the reference's (tests `the_fast_grid_wrench_is_within_…` and
/// `runs_by_the_fast_grid_wrench_end_where_the_reference_ends_them`).
pub(crate) const SMALL_HOLE: f64 = 0.5;

/// A mode's field, ready to evaluate.
#[derive(Debug, Clone)]
pub enum FieldModel {
    /// Straight node: unit normal x̂ of the node frame (towards the "right" side), the
    /// node's value of x̂·p, direction ŷ.
    Line {
        /// x̂ = −n̂ (points to the right of the node direction).
        xhat: [f64; 2],
        /// x̂·p on the node.
        c: f64,
        /// Law.
        law: Law,
        /// Gains left (ξ < 0), right (ξ > 0).
        k: [f64; 2],
    },
    /// Several straight lines: the nearest one pulls ([`Node::Lines`]).
    Lines {
        /// (x̂, x̂·p on the node) of each line, as in [`FieldModel::Line`].
        lines: Vec<([f64; 2], f64)>,
        /// Law.
        law: Law,
        /// Gains left (ξ < 0), right (ξ > 0) of each line.
        k: [f64; 2],
    },
    /// Hyperbola branch.
    Hyperbola {
        /// Centre.
        center: [f64; 2],
        /// (cos α, sin α).
        axis: [f64; 2],
        /// Semi-axes.
        a: f64,
        /// Semi-axis b.
        b: f64,
        /// Law.
        law: Law,
        /// Gains inside (centre side), outside (convex side).
        k: [f64; 2],
        /// ξ and normal tabulated over the plate (bilinear), exact outside.
        table: std::sync::Arc<DistTable>,
    },
    /// Sampled φ.
    Grid {
        /// The samples.
        grid: Grid,
        /// Their Catmull–Rom interpolant, per cell.
        cells: std::sync::Arc<Bicubic>,
        /// gain / max |∇φ²| for φ < 0 and φ > 0.
        k: [f64; 2],
        /// The rule of [`FieldModel::wrench`]: [`Quadrature::Fast`] (the motion model's) or
        /// [`Quadrature::Reference`] ([`FieldModel::reference`]).
        rule: Quadrature,
    },
}

/// Force (x, y) per unit… integrated over the part, and moment about the centroid.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Wrench {
    /// Force x.
    pub fx: f64,
    /// Force y.
    pub fy: f64,
    /// Moment (CCW positive).
    pub m: f64,
}

fn catmull(p: [f64; 4], t: f64) -> (f64, f64) {
    let a = -0.5 * p[0] + 1.5 * p[1] - 1.5 * p[2] + 0.5 * p[3];
    let b = p[0] - 2.5 * p[1] + 2.0 * p[2] - 0.5 * p[3];
    let c = -0.5 * p[0] + 0.5 * p[2];
    let d = p[1];
    (((a * t + b) * t + c) * t + d, (3.0 * a * t + 2.0 * b) * t + c)
}

/// φ and ∇φ at a plate point by Catmull–Rom bicubic interpolation (clamped to the plate).
pub fn grid_eval(g: &Grid, p: [f64; 2]) -> (f64, [f64; 2]) {
    let hx = g.size_mm[0] / (g.nx - 1) as f64;
    let hy = g.size_mm[1] / (g.ny - 1) as f64;
    let u = (p[0] / hx).clamp(0.0, (g.nx - 1) as f64);
    let v = (p[1] / hy).clamp(0.0, (g.ny - 1) as f64);
    let i = (u.floor() as usize).min(g.nx - 2);
    let j = (v.floor() as usize).min(g.ny - 2);
    let (tu, tv) = (u - i as f64, v - j as f64);
    let at = |ii: isize, jj: isize| {
        let ii = ii.clamp(0, g.nx as isize - 1) as usize;
        let jj = jj.clamp(0, g.ny as isize - 1) as usize;
        g.at(ii, jj)
    };
    let mut rows = [(0.0, 0.0); 4];
    for (r, row) in rows.iter_mut().enumerate() {
        let jj = j as isize - 1 + r as isize;
        let i0 = i as isize;
        *row = catmull([at(i0 - 1, jj), at(i0, jj), at(i0 + 1, jj), at(i0 + 2, jj)], tu);
    }
    let (val, dv) = catmull([rows[0].0, rows[1].0, rows[2].0, rows[3].0], tv);
    let (du, _) = catmull([rows[0].1, rows[1].1, rows[2].1, rows[3].1], tv);
    (val, [du / hx, dv / hy])
}

/// Closest point parameter t on the branch (a cosh t, b sinh t) to local (u, v).
fn hyperbola_t(a: f64, b: f64, u: f64, v: f64) -> f64 {
    let mut t = (v / b).asinh();
    let alt = (u.max(a) / a).acosh().copysign(v);
    let d = |t: f64| (a * t.cosh() - u).powi(2) + (b * t.sinh() - v).powi(2);
    if d(alt) < d(t) {
        t = alt;
    }
    for _ in 0..30 {
        let (sh, ch) = (t.sinh(), t.cosh());
        let g = (a * ch - u) * a * sh + (b * sh - v) * b * ch;
        let h = a * a * sh * sh + (a * ch - u) * a * ch + b * b * ch * ch + (b * sh - v) * b * sh;
        let step = if h > 0.0 { g / h } else { g.signum() * 0.1 };
        let step = step.clamp(-0.5, 0.5);
        t = (t - step).clamp(-12.0, 12.0);
        if step.abs() < 1e-12 {
            break;
        }
    }
    t
}

/// Signed distance ξ (positive on the convex side) to the hyperbola branch and the unit
/// normal towards that side, exactly (Newton on the branch parameter).
fn hyperbola_exact(
    center: [f64; 2],
    axis: [f64; 2],
    a: f64,
    b: f64,
    p: [f64; 2],
) -> (f64, [f64; 2]) {
    let (dx, dy) = (p[0] - center[0], p[1] - center[1]);
    let u = axis[0] * dx + axis[1] * dy;
    let v = -axis[1] * dx + axis[0] * dy;
    let t = hyperbola_t(a, b, u, v);
    let (qu, qv) = (a * t.cosh(), b * t.sinh());
    let dist = (u - qu).hypot(v - qv);
    let outside = u > 0.0 && (u / a).powi(2) - (v / b).powi(2) > 1.0;
    let xi = if outside { dist } else { -dist };
    let (nu, nv) = (t.cosh() / a, -t.sinh() / b);
    let nn = nu.hypot(nv);
    let (nu, nv) = (nu / nn, nv / nn);
    (xi, [axis[0] * nu - axis[1] * nv, axis[1] * nu + axis[0] * nv])
}

/// A straight node's frame: x̂ = −n̂ (n̂ = (−sin α, cos α)) and x̂·p on the line, which lies
/// at n̂·(p − ctr) = offset.
fn line_frame(angle_deg: f64, offset_mm: f64, ctr: [f64; 2]) -> ([f64; 2], f64) {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let nhat = [-s, c];
    let xhat = [s, -c];
    (xhat, -(offset_mm + nhat[0] * ctr[0] + nhat[1] * ctr[1]))
}

/// Cells per side of a [`DistTable`] tile.
const TILE: usize = 16;

/// A tabulated distance field (bilinear interpolation), filled lazily tile by tile.
///
/// The table spans the plate and a wide margin, but parts only ever visit a band along the
/// branch and their paths to it: computing all of its ~300 000 points (a Newton solve each)
/// took 0.16 s, serially, before the first run could start, more than the runs of a whole
/// triangle map. Each tile of `TILE`² cells is computed on first use instead (its points
/// exactly as the whole table computed them, so the field is the same bit for bit).
#[derive(Debug)]
pub struct DistTable {
    lo: [f64; 2],
    step: f64,
    nx: usize,
    ny: usize,
    /// The branch: centre, axis (cos α, sin α), semi-axes a, b.
    branch: ([f64; 2], [f64; 2], f64, f64),
    /// Tiles in rows of `tiles_x`.
    tiles_x: usize,
    tiles: Vec<OnceLock<Tile>>,
}

/// Points per tile row.
const TILE_PTS: usize = TILE + 1;

/// One tile's (TILE + 1)² points, row by row: ξ and the unit normal (fixed-size arrays: the
/// cell's corner indices are provably in range, no bounds checks in the hot read).
#[derive(Debug)]
struct Tile {
    xi: Box<[f64; TILE_PTS * TILE_PTS]>,
    n: Box<[[f64; 2]; TILE_PTS * TILE_PTS]>,
}

impl DistTable {
    /// The tile holding cell (i, j) (computed now if it is new) and the index of the cell's
    /// first corner in it.
    fn tile(&self, i: usize, j: usize) -> (&Tile, usize) {
        let (ti, tj) = (i / TILE, j / TILE);
        let tile = self.tiles[tj * self.tiles_x + ti].get_or_init(|| {
            let (center, axis, a, b) = self.branch;
            let mut xi = Box::new([0.0; TILE_PTS * TILE_PTS]);
            let mut n = Box::new([[0.0; 2]; TILE_PTS * TILE_PTS]);
            for q in 0..TILE_PTS * TILE_PTS {
                let (i, j) = (ti * TILE + q % TILE_PTS, tj * TILE + q / TILE_PTS);
                let p = [self.lo[0] + i as f64 * self.step, self.lo[1] + j as f64 * self.step];
                (xi[q], n[q]) = hyperbola_exact(center, axis, a, b, p);
            }
            Tile { xi, n }
        });
        (tile, (j % TILE) * TILE_PTS + i % TILE)
    }

    /// The cell holding `p` and the local coordinates in it, `None` off the table.
    fn locate(&self, p: [f64; 2]) -> Option<(usize, usize, f64, f64)> {
        let u = (p[0] - self.lo[0]) / self.step;
        let v = (p[1] - self.lo[1]) / self.step;
        if !(u >= 0.0 && v >= 0.0 && u < (self.nx - 1) as f64 && v < (self.ny - 1) as f64) {
            return None;
        }
        let (i, j) = (u as usize, v as usize);
        Some((i, j, u - i as f64, v - j as f64))
    }

    /// ξ alone (bilinear), `None` off the table.
    fn xi(&self, p: [f64; 2]) -> Option<f64> {
        let (i, j, fu, fv) = self.locate(p)?;
        let (t, k) = self.tile(i, j);
        let (x0, x1) = (t.xi[k], t.xi[k + 1]);
        let (x2, x3) = (t.xi[k + TILE_PTS], t.xi[k + TILE_PTS + 1]);
        Some((x0 + fu * (x1 - x0)) * (1.0 - fv) + (x2 + fu * (x3 - x2)) * fv)
    }

    /// The table of a hyperbola branch on a plate, one per branch and plate size (the
    /// planner builds a mode's field many times; its tiles are kept).
    fn cached(center: [f64; 2], axis: [f64; 2], a: f64, b: f64, size: [f64; 2]) -> Arc<DistTable> {
        type Cache = Mutex<HashMap<[u64; 8], Arc<DistTable>>>;
        static CACHE: OnceLock<Cache> = OnceLock::new();
        let key =
            [center[0], center[1], axis[0], axis[1], a, b, size[0], size[1]].map(f64::to_bits);
        let cache = CACHE.get_or_init(Cache::default);
        // A poisoned lock only means another thread panicked between whole inserts.
        let mut map = cache.lock().unwrap_or_else(|e| e.into_inner());
        let table =
            map.entry(key).or_insert_with(|| Arc::new(DistTable::new(center, axis, a, b, size)));
        Arc::clone(table)
    }

    /// ξ and the normal on a 1 mm grid (finer for small plates) over the plate and a margin
    /// of half its larger side: parts creeping along a branch can leave the plate when its
    /// edge is open (`[plate] edge = "open"`), and points off the table need a Newton solve
    /// each.
    fn new(center: [f64; 2], axis: [f64; 2], a: f64, b: f64, [w, h]: [f64; 2]) -> DistTable {
        let step = (w.max(h) / 300.0).min(1.0);
        let margin = (0.5 * w.max(h)).max(20.0);
        let lo = [-margin, -margin];
        let nx = ((w + 2.0 * margin) / step) as usize + 2;
        let ny = ((h + 2.0 * margin) / step) as usize + 2;
        // Cells 0..nx − 1 (and rows alike) in tiles of TILE.
        let tiles_x = (nx - 1).div_ceil(TILE);
        let tiles_y = (ny - 1).div_ceil(TILE);
        let tiles = (0..tiles_x * tiles_y).map(|_| OnceLock::new()).collect();
        DistTable { lo, step, nx, ny, branch: (center, axis, a, b), tiles_x, tiles }
    }

    fn eval(&self, p: [f64; 2]) -> Option<(f64, [f64; 2])> {
        let (i, j, fu, fv) = self.locate(p)?;
        let (t, k) = self.tile(i, j);
        let wts = [
            (k, (1.0 - fu) * (1.0 - fv)),
            (k + 1, fu * (1.0 - fv)),
            (k + TILE_PTS, (1.0 - fu) * fv),
            (k + TILE_PTS + 1, fu * fv),
        ];
        let (mut xi, mut n) = (0.0, [0.0, 0.0]);
        for (k, w) in wts {
            xi += w * t.xi[k];
            n[0] += w * t.n[k][0];
            n[1] += w * t.n[k][1];
        }
        let nn = n[0].hypot(n[1]).max(1e-12);
        Some((xi, [n[0] / nn, n[1] / nn]))
    }
}

impl FieldModel {
    /// The field of a mode on a plate.
    pub fn new(mode: &Mode, plate: &PlateModel) -> FieldModel {
        let ctr = plate.center();
        match &mode.node {
            Node::Line { angle_deg, offset_mm } => {
                let (xhat, cval) = line_frame(*angle_deg, *offset_mm, ctr);
                FieldModel::Line {
                    xhat,
                    c: cval,
                    law: mode.law,
                    k: [mode.gain_left, mode.gain_right],
                }
            }
            Node::Lines(lines) => FieldModel::Lines {
                lines: lines.iter().map(|l| line_frame(l.angle_deg, l.offset_mm, ctr)).collect(),
                law: mode.law,
                k: [mode.gain_left, mode.gain_right],
            },
            Node::Hyperbola { center_mm, angle_deg, a_mm, b_mm } => {
                let (s, c) = angle_deg.to_radians().sin_cos();
                let (center, axis, a, b) = (*center_mm, [c, s], *a_mm, *b_mm);
                let table = DistTable::cached(center, axis, a, b, plate.size_mm);
                FieldModel::Hyperbola {
                    center,
                    axis,
                    a,
                    b,
                    law: mode.law,
                    k: [mode.gain_left, mode.gain_right],
                    table,
                }
            }
            Node::Grid(g) => {
                let hx = g.size_mm[0] / (g.nx - 1) as f64;
                let hy = g.size_mm[1] / (g.ny - 1) as f64;
                let mut max = 0.0f64;
                for j in 0..g.ny {
                    for i in 0..g.nx {
                        let p = [i as f64 * hx, j as f64 * hy];
                        let (v, d) = grid_eval(g, p);
                        max = max.max(2.0 * v.abs() * d[0].hypot(d[1]));
                    }
                }
                let max = max.max(1e-12);
                FieldModel::Grid {
                    grid: g.clone(),
                    cells: std::sync::Arc::new(Bicubic::new(g)),
                    k: [mode.gain_left / max, mode.gain_right / max],
                    rule: Quadrature::Fast,
                }
            }
        }
    }

    /// Force per unit area at a plate point (not used for line nodes' exact integrals).
    pub fn at(&self, p: [f64; 2]) -> [f64; 2] {
        match self {
            FieldModel::Line { xhat, c, law, k } => {
                let xi = xhat[0] * p[0] + xhat[1] * p[1] - c;
                let f = -k[usize::from(xi > 0.0)] * law.g(xi);
                [f * xhat[0], f * xhat[1]]
            }
            FieldModel::Lines { lines, law, k } => {
                let xi = |(xhat, c): &([f64; 2], f64)| xhat[0] * p[0] + xhat[1] * p[1] - c;
                let nearest = lines.iter().min_by(|a, b| xi(a).abs().total_cmp(&xi(b).abs()));
                let Some(line) = nearest else { return [0.0, 0.0] };
                let (x, xhat) = (xi(line), line.0);
                let f = -k[usize::from(x > 0.0)] * law.g(x);
                [f * xhat[0], f * xhat[1]]
            }
            FieldModel::Hyperbola { center, axis, a, b, law, k, table } => {
                let (xi, n) =
                    table.eval(p).unwrap_or_else(|| hyperbola_exact(*center, *axis, *a, *b, p));
                let f = -k[usize::from(xi > 0.0)] * law.g(xi);
                [f * n[0], f * n[1]]
            }
            FieldModel::Grid { cells, k, .. } => {
                let (v, d) = cells.eval(p);
                let s = -2.0 * v * k[usize::from(v > 0.0)];
                [s * d[0], s * d[1]]
            }
        }
    }

    /// Total force and moment on the body at a pose.
    pub fn wrench(&self, body: &Body, pose: Pose) -> Wrench {
        let (s, c) = pose.theta.sin_cos();
        match self {
            FieldModel::Line { xhat, c: cval, law, k } => {
                // Node frame: ξ = x̂·p − c (across), η = ŷ·p (along), ŷ = (−x̂_y... ) so that
                // (x̂, ŷ) is right-handed: ŷ = (−x̂.y, x̂.x).
                let yhat = [-xhat[1], xhat[0]];
                let xi_c = xhat[0] * pose.x + xhat[1] * pose.y - cval;
                let (mut f, mut m) = (0.0, 0.0);
                for ring in &body.rings {
                    let n = ring.len();
                    let loc = |p: [f64; 2]| {
                        let r = [c * p[0] - s * p[1], s * p[0] + c * p[1]];
                        (xi_c + xhat[0] * r[0] + xhat[1] * r[1], yhat[0] * r[0] + yhat[1] * r[1])
                    };
                    let mut prev = loc(ring[n - 1]);
                    for &p in ring {
                        let cur = loc(p);
                        let mut piece = |a: (f64, f64), b: (f64, f64)| {
                            let side = usize::from(a.0 + b.0 > 0.0);
                            let dy = 0.5 * (b.1 - a.1);
                            if dy == 0.0 {
                                return;
                            }
                            let (mut pf, mut pm) = (0.0, 0.0);
                            for (u, w) in GL {
                                let t = 0.5 * (u + 1.0);
                                let x = a.0 + t * (b.0 - a.0);
                                let y = a.1 + t * (b.1 - a.1);
                                let gg = law.big_g(x);
                                pf += w * gg;
                                pm += w * y * gg;
                            }
                            f -= k[side] * pf * dy;
                            m += k[side] * pm * dy;
                        };
                        if (prev.0 > 0.0 && cur.0 < 0.0) || (prev.0 < 0.0 && cur.0 > 0.0) {
                            let t = prev.0 / (prev.0 - cur.0);
                            let mid = (0.0, prev.1 + t * (cur.1 - prev.1));
                            piece(prev, mid);
                            piece(mid, cur);
                        } else {
                            piece(prev, cur);
                        }
                        prev = cur;
                    }
                }
                Wrench { fx: f * xhat[0], fy: f * xhat[1], m }
            }
            FieldModel::Grid { cells, k, rule: Quadrature::Fast, .. } => {
                self.grid_wrench(cells, *k, body, pose, (s, c))
            }
            FieldModel::Grid { cells, k, rule: Quadrature::Reference, .. } => {
                let o = [pose.x, pose.y];
                let [fx, fy, m] =
                    cells.outline_wrench(&body.rings, o, (s, c), *k, Quadrature::Reference);
                Wrench { fx, fy, m }
            }
            FieldModel::Hyperbola { center, axis, a, b, law, k, table } => {
                // f = −∇(k G(ξ)): along the outline (see [`crate::motion::potential`]), ξ from
                // the table (exact off it).
                let xi = |p: [f64; 2]| {
                    table.xi(p).unwrap_or_else(|| hyperbola_exact(*center, *axis, *a, *b, p).0)
                };
                let psi = |x: f64| k[usize::from(x > 0.0)] * law.big_g(x);
                let piece = HYPERBOLA_PIECE * body.radius;
                let [fx, fy, m] =
                    kinked_outline_wrench(&body.rings, [pose.x, pose.y], (s, c), piece, xi, psi);
                Wrench { fx, fy, m }
            }
            FieldModel::Lines { .. } => self.sampled_wrench(body, pose),
        }
    }

    /// The same field with the reference rule for its wrench: a grid mode's outline integral
    /// within 10⁻⁶ of exact, every hole by its outline, which the fast rule is tested against
    /// (the other fields have one rule).
    pub fn reference(mut self) -> FieldModel {
        if let FieldModel::Grid { rule, .. } = &mut self {
            *rule = Quadrature::Reference;
        }
        self
    }

    /// The grid's fast rule: f = −∇(k φ²) along the outline ([`crate::motion::potential`],
    /// 3 points a piece), a hole within [`SMALL_HOLE`] of a cell by its four-point moment rule
    /// ([`crate::motion::body::HoleRule`]: the wrench of the filled outline minus the hole's).
    /// `(s, c)`: the pose's (sin θ, cos θ), which [`FieldModel::wrench`] has already computed.
    fn grid_wrench(
        &self,
        cells: &Bicubic,
        k: [f64; 2],
        body: &Body,
        pose: Pose,
        (s, c): (f64, f64),
    ) -> Wrench {
        let [hx, hy] = cells.spacing();
        let small = SMALL_HOLE * hx.min(hy);
        let rule = |i: usize| body.holes.get(i).copied().flatten().filter(|h| h.radius <= small);
        let rings =
            body.rings.iter().enumerate().filter(|&(i, _)| rule(i).is_none()).map(|(_, r)| r);
        let [mut fx, mut fy, mut m] =
            cells.outline_wrench(rings, [pose.x, pose.y], (s, c), k, Quadrature::Fast);
        for h in (0..body.rings.len()).filter_map(rule) {
            for q in h.points {
                let r = [c * q[0] - s * q[1], s * q[0] + c * q[1]];
                let f = self.at([pose.x + r[0], pose.y + r[1]]);
                fx -= h.weight * f[0];
                fy -= h.weight * f[1];
                m -= h.weight * (r[0] * f[1] - r[1] * f[0]);
            }
        }
        Wrench { fx, fy, m }
    }

    /// Force and moment by the midpoint rule over the body's interior samples (the rule for
    /// hyperbola and several-line nodes; the reference the exact rules are tested against).
    pub(crate) fn sampled_wrench(&self, body: &Body, pose: Pose) -> Wrench {
        let (s, c) = pose.theta.sin_cos();
        let mut w = Wrench::default();
        for &(q, wt) in &body.samples {
            let r = [c * q[0] - s * q[1], s * q[0] + c * q[1]];
            let f = self.at([pose.x + r[0], pose.y + r[1]]);
            w.fx += wt * f[0];
            w.fy += wt * f[1];
            w.m += wt * (r[0] * f[1] - r[1] * f[0]);
        }
        w
    }

    /// Distance (mm) from a plate point to the mode's nearest node: exact for straight and
    /// hyperbolic nodes, |φ| / |∇φ| (first order) on a grid; infinite where a grid's field is
    /// flat and not zero.
    pub(crate) fn node_distance(&self, p: [f64; 2]) -> f64 {
        let xi = |(xhat, c): &([f64; 2], f64)| (xhat[0] * p[0] + xhat[1] * p[1] - c).abs();
        match self {
            FieldModel::Line { xhat, c, .. } => xi(&(*xhat, *c)),
            FieldModel::Lines { lines, .. } => lines.iter().map(xi).fold(f64::INFINITY, f64::min),
            FieldModel::Hyperbola { center, axis, a, b, table, .. } => {
                let (d, _) =
                    table.eval(p).unwrap_or_else(|| hyperbola_exact(*center, *axis, *a, *b, p));
                d.abs()
            }
            FieldModel::Grid { cells, .. } => {
                let (v, d) = cells.eval(p);
                if v == 0.0 { 0.0 } else { v.abs() / d[0].hypot(d[1]) }
            }
        }
    }

    /// Largest gain.
    pub(crate) fn max_gain(&self) -> f64 {
        match self {
            FieldModel::Line { k, .. }
            | FieldModel::Lines { k, .. }
            | FieldModel::Hyperbola { k, .. } => k[0].max(k[1]),
            FieldModel::Grid { .. } => 1.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::part::Part;
    use crate::model::plate::Node;
    use crate::motion::body::Body;
    use crate::motion::testkit::solver_plates;
    use crate::motion::testkit::{example_parts, holed_part, law_scale, mode, plate, rect};

    /// Poses spread over a plate (a golden-ratio spiral, each turned differently), the
    /// centroid at least `inset` from every edge.
    fn spread_poses(size: [f64; 2], inset: f64, n: usize) -> Vec<Pose> {
        let (w, h) = ((size[0] - 2.0 * inset).max(0.0), (size[1] - 2.0 * inset).max(0.0));
        (0..n)
            .map(|i| {
                let f = i as f64;
                Pose {
                    x: inset + (f * 0.618_034 % 1.0) * w,
                    y: inset + (f * 0.414_214 % 1.0) * h,
                    theta: f * 0.77,
                }
            })
            .collect()
    }

    #[test]
    fn runs_by_the_fast_grid_wrench_end_where_the_reference_ends_them() {
        // Every mode of the three solver plates, every example and ordinary part (each face),
        // one start each (spread over the plate, inside the rim): the run to rest by the fast
        // rule ends within 0.05 mm and 0.05° of the run by the reference rule — or, where the
        // rest is so flat that the reference's own end moves further when its start moves by
        // 0.01 mm or 0.01° (the run stops somewhere in a band where the pull is below the
        // rest tolerance), within that.
        use crate::motion::integrate::{SimParams, run};
        use rayon::prelude::*;
        let parts = example_parts();
        let mut jobs = Vec::new();
        for plate in solver_plates() {
            for k in 0..plate.modes.len() {
                for (n, part) in parts.iter().enumerate() {
                    jobs.push((plate.clone(), k, part, n));
                }
            }
        }
        let apart = |a: Pose, b: Pose| {
            ((a.x - b.x).hypot(a.y - b.y), (a.theta - b.theta).to_degrees().abs())
        };
        let ends: Vec<_> = jobs
            .par_iter()
            .map(|(plate, k, part, n)| {
                let fast = FieldModel::new(&plate.modes[*k], plate);
                let reference = fast.clone().reference();
                let body = Body::with_samples(part, 16);
                let start = spread_poses(plate.size_mm, body.radius, 64)[(k * 29 + n * 7) % 64];
                let p = SimParams::to_rest(&body, &plate.modes[*k], &fast, plate);
                let end = |f: &FieldModel, q: Pose| run(&body, f, p, q).pose;
                let want = end(&reference, start);
                let (mm, deg) = apart(end(&fast, start), want);
                let mut floor = (0.05f64, 0.05f64);
                if mm > 0.05 || deg > 0.05 {
                    let nudged = [
                        Pose { x: start.x + 0.01, ..start },
                        Pose { theta: start.theta + 0.01f64.to_radians(), ..start },
                    ];
                    for q in nudged {
                        let (m, d) = apart(end(&reference, q), want);
                        floor = (floor.0.max(m), floor.1.max(d));
                    }
                }
                let name = format!("{} mode {k} {}", plate.name, part.name);
                (mm, deg, floor, format!("{name}: {mm:.4} mm {deg:.4}° (floor {floor:.4?})"))
            })
            .collect();
        let flat: Vec<&String> =
            ends.iter().filter(|e| e.0 > 0.05 || e.1 > 0.05).map(|e| &e.3).collect();
        let over: Vec<&String> =
            ends.iter().filter(|e| e.0 > e.2.0 || e.1 > e.2.1).map(|e| &e.3).collect();
        println!("{} runs; beyond 0.05 mm or 0.05° in a flat rest: {flat:?}", ends.len());
        assert!(over.is_empty(), "{over:?}");
    }

    #[test]
    fn the_fast_grid_wrench_is_within_its_bound_of_the_reference_on_the_solver_plates() {
        // Every mode of the three solver plates, every example and ordinary part (each face),
        // 48 poses with the part on the plate. The error is that of the velocity of the part's
        // farthest point (|ΔF|/A + |ΔM|·R/J, the integrator's measure: angles as arc length
        // at R) against the largest centroid speed of that part under that mode (max |F|/A).
        let parts = example_parts();
        let mut worst = (0.0f64, String::new());
        for plate in solver_plates() {
            for (k, mode) in plate.modes.iter().enumerate() {
                let fast = FieldModel::new(mode, &plate);
                let reference = fast.clone().reference();
                for part in &parts {
                    let body = Body::with_samples(part, 16);
                    let poses = spread_poses(plate.size_mm, body.radius, 48);
                    let pairs: Vec<(Wrench, Wrench)> = poses
                        .iter()
                        .map(|&q| (reference.wrench(&body, q), fast.wrench(&body, q)))
                        .collect();
                    let big_f = pairs.iter().map(|(r, _)| r.fx.hypot(r.fy)).fold(0.0, f64::max);
                    let arm = body.radius * body.area / body.polar;
                    for (r, f) in &pairs {
                        let e =
                            ((r.fx - f.fx).hypot(r.fy - f.fy) + (r.m - f.m).abs() * arm) / big_f;
                        if e > worst.0 {
                            worst = (e, format!("{} mode {k} {}", plate.name, part.name));
                        }
                    }
                }
            }
        }
        println!("largest relative error of the fast grid wrench: {:.2e} ({})", worst.0, worst.1);
        assert!(worst.0 <= 1e-3, "{worst:?}");
    }

    #[test]
    fn exact_line_wrench_matches_sampled_integral() {
        let body = Body::new(&rect());
        for law in ["sign", "linear"] {
            let m = mode(&format!(
                "freq_hz = 50.0\nfield = \"{law}\"\ngain_right = 1.7\nnode = {{ kind = \"line\", angle_deg = 30.0, offset_mm = 5.0 }}"
            ));
            let f = FieldModel::new(&m, &plate(&m));
            let pose = Pose { x: 150.0, y: 100.0, theta: 0.4 };
            let exact = f.wrench(&body, pose);
            let num = f.sampled_wrench(&body, pose);
            let scale = body.area * (1.0 + body.radius / 10.0);
            assert!((exact.fx - num.fx).abs() < 0.03 * scale, "{law} {exact:?} {num:?}");
            assert!((exact.fy - num.fy).abs() < 0.03 * scale, "{law} {exact:?} {num:?}");
            assert!(
                (exact.m - num.m).abs() < 0.03 * scale * body.radius,
                "{law} {exact:?} {num:?}"
            );
        }
    }

    #[test]
    fn grid_wrench_along_the_outline_matches_the_area_integral() {
        // A mode-like φ with several node lines, and a part with a hole.
        let (nx, ny) = (41, 28);
        let values = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    let (x, y) = (i as f64 / (nx - 1) as f64, j as f64 / (ny - 1) as f64);
                    (2.5 * std::f64::consts::PI * x).cos() * (1.5 * std::f64::consts::PI * y).cos()
                        + 0.2 * x
                })
            })
            .collect();
        let mut m =
            mode("freq_hz = 50.0\ngain_left = 0.7\nnode = { kind = \"line\", angle_deg = 0.0 }");
        m.node = Node::Grid(Grid { nx, ny, size_mm: [300.0, 200.0], values });
        let f = FieldModel::new(&m, &plate(&m));
        let holed = holed_part();
        let mut worst = [0.0f64; 4];
        for part in [rect(), holed] {
            let fine = Body::with_samples(&part, 40_000);
            let body = Body::with_samples(&part, 160);
            let scale = fine.area;
            for k in 0..40 {
                let pose = Pose {
                    x: 40.0 + (k as f64 * 0.618_034 % 1.0) * 220.0,
                    y: 40.0 + (k as f64 * 0.414_214 % 1.0) * 120.0,
                    theta: k as f64 * 0.7,
                };
                let (exact, num) = (f.wrench(&body, pose), f.sampled_wrench(&fine, pose));
                let old = f.sampled_wrench(&body, pose);
                worst[0] =
                    worst[0].max((exact.fx - num.fx).abs().max((exact.fy - num.fy).abs()) / scale);
                worst[1] = worst[1].max((exact.m - num.m).abs() / scale / fine.radius);
                worst[2] =
                    worst[2].max((old.fx - num.fx).abs().max((old.fy - num.fy).abs()) / scale);
                worst[3] = worst[3].max((old.m - num.m).abs() / scale / fine.radius);
                // The fine midpoint rule's own error is O(h²) (h ≈ 0.1–0.2 mm here).
                assert!((exact.fx - num.fx).abs() < 2e-4 * scale, "{pose:?} {exact:?} {num:?}");
                assert!((exact.fy - num.fy).abs() < 2e-4 * scale, "{pose:?} {exact:?} {num:?}");
                assert!(
                    (exact.m - num.m).abs() < 2e-4 * scale * fine.radius,
                    "{pose:?} {exact:?} {num:?}"
                );
            }
        }
        eprintln!(
            "outline vs fine area integral: F {:.1e}, M {:.1e}; 160 midpoints: F {:.1e}, M {:.1e}",
            worst[0], worst[1], worst[2], worst[3]
        );
    }

    #[test]
    fn hyperbola_outline_wrench_matches_the_area_integral() {
        let holed = holed_part();
        let mut worst = [0.0f64; 4];
        for (law, extra) in [("linear", ""), ("sign", ""), ("sine", "wavelength_mm = 80.0\n")] {
            let m = mode(&format!(
                "freq_hz = 50.0\nfield = \"{law}\"\n{extra}gain_left = 1.8\nnode = {{ kind = \"hyperbola\", center_mm = [60.0, 100.0], angle_deg = 10.0, a_mm = 70.0, b_mm = 60.0 }}"
            ));
            let f = FieldModel::new(&m, &plate(&m));
            for part in [rect(), holed.clone()] {
                let fine = Body::with_samples(&part, 40_000);
                let body = Body::with_samples(&part, 160);
                let scale = fine.area * f.max_gain() * law_scale(m.law);
                for k in 0..30 {
                    // Centroids on, near and off the branch, over the plate and beyond it.
                    let t = -1.2 + 2.4 * (k as f64 * 0.618_034 % 1.0);
                    let off = -15.0 + 30.0 * (k as f64 * 0.414_214 % 1.0);
                    let (ca, sa) = (10f64.to_radians().cos(), 10f64.to_radians().sin());
                    let (u, v) = (70.0 * t.cosh() + off, 60.0 * t.sinh());
                    let pose = Pose {
                        x: 60.0 + ca * u - sa * v,
                        y: 100.0 + sa * u + ca * v,
                        theta: k as f64 * 0.7,
                    };
                    let (exact, num) = (f.wrench(&body, pose), f.sampled_wrench(&fine, pose));
                    let old = f.sampled_wrench(&body, pose);
                    let df = |w: Wrench| (w.fx - num.fx).abs().max((w.fy - num.fy).abs()) / scale;
                    let dm = |w: Wrench| (w.m - num.m).abs() / scale / fine.radius;
                    worst = [
                        worst[0].max(df(exact)),
                        worst[1].max(dm(exact)),
                        worst[2].max(df(old)),
                        worst[3].max(dm(old)),
                    ];
                }
            }
        }
        eprintln!(
            "hyperbola outline vs fine area integral: F {:.1e}, M {:.1e}; 160 midpoints: F {:.1e}, M {:.1e}",
            worst[0], worst[1], worst[2], worst[3]
        );
        // Relative to the largest force (area × gain × the law's pull at one radius).
        assert!(worst[0] < 1e-3 && worst[1] < 1e-3, "{worst:?}");
        assert!(worst[0] < worst[2] && worst[1] < worst[3], "{worst:?}");
    }

    #[test]
    fn hyperbola_outline_pieces_are_converged() {
        // The outline rule at HYPERBOLA_PIECE against the same rule at R/50: the error of the
        // piece length alone (the area-integral test above is limited by its reference).
        let part =
            Part::new("t".into(), vec![[0.0, 0.0], [30.0, 0.0], [8.0, 20.0]], vec![]).unwrap();
        let mut worst = 0.0f64;
        for (law, extra) in [("linear", ""), ("sign", ""), ("sine", "wavelength_mm = 80.0\n")] {
            let m = mode(&format!(
                "freq_hz = 50.0\nfield = \"{law}\"\n{extra}gain_left = 1.8\nnode = {{ kind = \"hyperbola\", center_mm = [60.0, 100.0], angle_deg = 10.0, a_mm = 70.0, b_mm = 60.0 }}"
            ));
            let f = FieldModel::new(&m, &plate(&m));
            let FieldModel::Hyperbola { law, k, table, center, axis, a, b } = &f else {
                unreachable!()
            };
            let xi = |p: [f64; 2]| {
                table.xi(p).unwrap_or_else(|| hyperbola_exact(*center, *axis, *a, *b, p).0)
            };
            let psi = |x: f64| k[usize::from(x > 0.0)] * law.big_g(x);
            for body in [Body::with_samples(&rect(), 160), Body::with_samples(&part, 160)] {
                let scale = body.area * f.max_gain() * law_scale(*law);
                for n in 0..60 {
                    let t = -1.5 + 3.0 * (n as f64 * 0.618_034 % 1.0);
                    let off = -25.0 + 50.0 * (n as f64 * 0.414_214 % 1.0);
                    let (u, v) = (70.0 * t.cosh() + off, 60.0 * t.sinh());
                    let (ca, sa) = (10f64.to_radians().cos(), 10f64.to_radians().sin());
                    let o = [60.0 + ca * u - sa * v, 100.0 + sa * u + ca * v];
                    let sc = (n as f64 * 0.9).sin_cos();
                    let r = body.radius;
                    let [x0, y0, m0] =
                        kinked_outline_wrench(&body.rings, o, sc, HYPERBOLA_PIECE * r, xi, psi);
                    let [x1, y1, m1] = kinked_outline_wrench(&body.rings, o, sc, 0.02 * r, xi, psi);
                    worst = worst
                        .max((x0 - x1).abs().max((y0 - y1).abs()) / scale)
                        .max((m0 - m1).abs() / scale / r);
                }
            }
        }
        eprintln!("hyperbola outline pieces {HYPERBOLA_PIECE} R vs R/50: {worst:.1e}");
        assert!(worst < 1e-4, "{worst}");
    }

    /// A straight node's distance is exact; a grid's is |φ| / |∇φ|: zero on the hinged-rod
    /// plate's hinge line x = 150 mm in every mode, and off the line not zero in every mode.
    #[test]
    fn node_distance_is_zero_on_a_node_and_not_off_it() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let plate = PlateModel::load(&root.join("examples/plates/four-lines.toml")).unwrap();
        let f = FieldModel::new(&plate.modes[0], &plate);
        let d = f.node_distance([140.0, 37.0]);
        assert!((d - 10.0).abs() < 1e-9 && f.node_distance([150.0, 37.0]) < 1e-9, "{d}");
        let hinged =
            PlateModel::load(&root.join("examples/plates/hinged-rod-6-modes.toml")).unwrap();
        let fields: Vec<FieldModel> =
            hinged.modes.iter().map(|m| FieldModel::new(m, &hinged)).collect();
        for y in [10.0, 50.0, 100.0, 170.0] {
            for (k, f) in fields.iter().enumerate() {
                assert!(f.node_distance([150.0, y]) < 0.1, "mode {} at y = {y}", k + 1);
            }
        }
        assert!(fields.iter().any(|f| f.node_distance([60.0, 50.0]) > 10.0));
    }

    #[test]
    fn lazy_distance_table_matches_the_exact_distance_at_its_points() {
        let m = mode(
            "freq_hz = 50.0\nnode = { kind = \"hyperbola\", center_mm = [60.0, 100.0], angle_deg = 10.0, a_mm = 70.0, b_mm = 60.0 }",
        );
        let f = FieldModel::new(&m, &plate(&m));
        let FieldModel::Hyperbola { table, center, axis, a, b, .. } = &f else { unreachable!() };
        // Grid points (corners of cells in different tiles, on tile seams too) read back
        // exactly; between them the bilinear value lies within the corners' range.
        for k in 0..400 {
            let (i, j) = ((k * 37) % 590, (k * 53) % 490);
            let p = [table.lo[0] + i as f64 * table.step, table.lo[1] + j as f64 * table.step];
            let exact = hyperbola_exact(*center, *axis, *a, *b, p).0;
            assert_eq!(table.xi(p), Some(exact), "{p:?}");
            let q = [p[0] + 0.5 * table.step, p[1] + 0.25 * table.step];
            let x = table.xi(q).unwrap();
            assert!((x - hyperbola_exact(*center, *axis, *a, *b, q).0).abs() < 0.01, "{q:?}");
        }
        assert_eq!(table.xi([-1e4, 0.0]), None);
    }
}
