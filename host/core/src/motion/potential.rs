//! Force and moment on a part from a potential, as integrals along its outline.
//!
//! The fields of hyperbola and grid nodes are gradients: f = −∇Ψ with Ψ = k·G(ξ) (hyperbola,
//! ξ the signed distance to the branch, G' = g the field law) and Ψ = k·φ² (grid, k per sign
//! of φ). The divergence theorem turns the area integrals of the force and its moment into
//! integrals along the part's rings (outward normal n, r about the centroid):
//! F = −∮ Ψ n ds, M = ∫∫ r × f dA = −∮ Ψ (r × n) ds = ∮ Ψ (r · dr).
//! For a grid node Ψ is a polynomial of degree 12 in the edge parameter inside each grid cell
//! (Catmull–Rom bicubic φ, squared), so splitting every edge at the grid lines and using
//! 7-point Gauss–Legendre per piece (`boundary_wrench`, the tests' reference) is exact up to rounding; the
//! simulator uses 4 points per piece, 2 on pieces under a quarter of a cell
//! ([`Bicubic::outline_wrench`], within 10⁻⁶ of it, tested).
//! This replaced a midpoint rule over 160–400 interior cells, each needing φ and ∇φ, whose
//! error was about 3·10⁻³ of the largest force: fewer, better-placed points, and smaller
//! error (docs/plan.md, "Planning time"). A hyperbola's Ψ = k·G(ξ) is smooth on either side
//! of its node but has a kink on it (sign law, unequal gains): [`kinked_outline_wrench`] cuts
//! the edges there and integrates the pieces the same way.

use crate::model::grid::Grid;

#[cfg(test)]
/// 7-point Gauss–Legendre nodes on [0, 1] and weights (summing to 1): exact for degree 13.
const GL7: [(f64, f64); 7] = [
    (0.025_446_043_828_620_8, 0.064_742_483_084_434_85),
    (0.129_234_407_200_302_8, 0.139_852_695_744_638_33),
    (0.297_077_424_311_301_4, 0.190_915_025_252_559_47),
    (0.5, 0.208_979_591_836_734_7),
    (0.702_922_575_688_698_6, 0.190_915_025_252_559_47),
    (0.870_765_592_799_697_2, 0.139_852_695_744_638_33),
    (0.974_553_956_171_379_2, 0.064_742_483_084_434_85),
];

/// 4-point Gauss–Legendre nodes on [0, 1] and weights (summing to 1): exact for degree 7.
const GL4: [(f64, f64); 4] = [
    (0.069_431_844_202_973_7, 0.173_927_422_568_727),
    (0.330_009_478_207_571_9, 0.326_072_577_431_273),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273),
    (0.930_568_155_797_026_3, 0.173_927_422_568_727),
];

/// 3-point Gauss–Legendre nodes on [0, 1] and weights: exact for degree 5.
const GL3: [(f64, f64); 3] = [
    (0.112_701_665_379_258_3, 0.277_777_777_777_777_8),
    (0.5, 0.444_444_444_444_444_4),
    (0.887_298_334_620_741_7, 0.277_777_777_777_777_8),
];

/// 2-point Gauss–Legendre nodes on [0, 1] and weights: exact for degree 3.
const GL2: [(f64, f64); 2] = [(0.211_324_865_405_187_1, 0.5), (0.788_675_134_594_812_9, 0.5)];

/// A grid-wrench piece at most this long (in cells) takes [`GL2`] instead of [`GL4`]: its
/// error shrinks as the fifth power of the length, and a round hole of short edges stays
/// within the same 5·10⁻⁸ of the exact rule as with 4 points everywhere (test
/// `grid_outline_wrench_matches_the_exact_boundary_integral`; at 0.5 cells: 7.7·10⁻⁸).
const SHORT: f64 = 0.25;

/// The rule a grid mode's wrench is integrated by: along the outline, each piece of an edge
/// inside one cell by Gauss–Legendre points ([`Bicubic::outline_wrench`]), and for the fast
/// rule small holes by their moment rule (`motion::field`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Quadrature {
    /// 4 points a piece, 2 on pieces under a quarter of a cell; every hole by its outline:
    /// within 10⁻⁶ of the exact integral, the reference the fast rule is tested against.
    Reference,
    /// 3 points a piece, 2 under a quarter cell; holes within `SMALL_HOLE` of a cell by their
    /// moment rule: the motion model's rule (its error against the reference is measured in
    /// `motion::field`'s tests: 1.2·10⁻⁴ of the largest speed at worst).
    Fast,
}

/// A Catmull–Rom bicubic interpolant of grid samples, as per-cell polynomial coefficients:
/// the same surface as [`crate::motion::field::grid_eval`] (to rounding), evaluated with one
/// look-up of 16 coefficients instead of 16 clamped sample reads and 10 spline evaluations.
#[derive(Debug, Clone)]
pub struct Bicubic {
    nx: usize,
    ny: usize,
    hx: f64,
    hy: f64,
    /// Per cell (i, j) at `j·(nx−1) + i`: c[a·4 + b] multiplies tu^a·tv^b.
    cells: Vec<[f64; 16]>,
}

/// Catmull–Rom basis: the coefficients (of t⁰, t¹, t², t³) of the spline through p1, p2 with
/// neighbours p0, p3, as weights on (p0, p1, p2, p3).
const CR: [[f64; 4]; 4] =
    [[0.0, 1.0, 0.0, 0.0], [-0.5, 0.0, 0.5, 0.0], [1.0, -2.5, 2.0, -0.5], [-0.5, 1.5, -1.5, 0.5]];

impl Bicubic {
    /// The interpolant of `g` (at least 2 × 2 samples; samples beyond the edges repeat the
    /// edge samples, as `grid_eval` clamps them).
    pub fn new(g: &Grid) -> Bicubic {
        let (nx, ny) = (g.nx, g.ny);
        let at = |i: isize, j: isize| {
            g.at(i.clamp(0, nx as isize - 1) as usize, j.clamp(0, ny as isize - 1) as usize)
        };
        let mut cells = Vec::with_capacity((nx - 1) * (ny - 1));
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let p: [[f64; 4]; 4] = std::array::from_fn(|r| {
                    std::array::from_fn(|s| {
                        at(i as isize - 1 + s as isize, j as isize - 1 + r as isize)
                    })
                });
                // Row polynomials in tu, then each power of tu as a spline in tv.
                let row: [[f64; 4]; 4] = std::array::from_fn(|r| {
                    std::array::from_fn(|a| (0..4).map(|s| CR[a][s] * p[r][s]).sum())
                });
                let mut c = [0.0; 16];
                for a in 0..4 {
                    for b in 0..4 {
                        c[a * 4 + b] = (0..4).map(|r| CR[b][r] * row[r][a]).sum();
                    }
                }
                cells.push(c);
            }
        }
        Bicubic {
            nx,
            ny,
            hx: g.size_mm[0] / (nx - 1) as f64,
            hy: g.size_mm[1] / (ny - 1) as f64,
            cells,
        }
    }

    /// Cell spacing (mm).
    pub fn spacing(&self) -> [f64; 2] {
        [self.hx, self.hy]
    }

    /// The cell holding `p` (clamped to the plate) and the local coordinates in it.
    fn locate(&self, p: [f64; 2]) -> (&[f64; 16], f64, f64) {
        let u = (p[0] / self.hx).clamp(0.0, (self.nx - 1) as f64);
        let v = (p[1] / self.hy).clamp(0.0, (self.ny - 1) as f64);
        let i = (u as usize).min(self.nx - 2);
        let j = (v as usize).min(self.ny - 2);
        (&self.cells[j * (self.nx - 1) + i], u - i as f64, v - j as f64)
    }

    /// φ at a plate point.
    pub fn value(&self, p: [f64; 2]) -> f64 {
        let (c, tu, tv) = self.locate(p);
        cell_value(c, tu, tv)
    }

    /// φ and ∇φ at a plate point (the derivative of the clamped coordinate is the edge
    /// cell's, as in `grid_eval`).
    pub fn eval(&self, p: [f64; 2]) -> (f64, [f64; 2]) {
        let (c, tu, tv) = self.locate(p);
        let (mut col, mut dcol) = ([0.0; 4], [0.0; 4]);
        for a in 0..4 {
            let k = &c[a * 4..a * 4 + 4];
            col[a] = ((k[3] * tv + k[2]) * tv + k[1]) * tv + k[0];
            dcol[a] = (3.0 * k[3] * tv + 2.0 * k[2]) * tv + k[1];
        }
        let val = ((col[3] * tu + col[2]) * tu + col[1]) * tu + col[0];
        let du = (3.0 * col[3] * tu + 2.0 * col[2]) * tu + col[1];
        let dv = ((dcol[3] * tu + dcol[2]) * tu + dcol[1]) * tu + dcol[0];
        (val, [du / self.hx, dv / self.hy])
    }
}

impl Bicubic {
    /// Force (x, y) and moment of f = −∇(k φ²) (k = `k[0]` where φ < 0, `k[1]` where φ > 0)
    /// on `rings` (relative to the centroid) turned by (sin θ, cos θ) and moved to `origin`:
    /// `boundary_wrench` specialised to the grid. Each vertex is turned once, and each edge
    /// walks the cells it crosses in order (`edge_integrals`): no sort, no allocation, no
    /// rounding call per piece.
    pub fn outline_wrench<'r>(
        &self,
        rings: impl IntoIterator<Item = &'r Vec<[f64; 2]>>,
        origin: [f64; 2],
        (sin, cos): (f64, f64),
        k: [f64; 2],
        rule: Quadrature,
    ) -> [f64; 3] {
        let (mut fx, mut fy, mut m) = (0.0, 0.0, 0.0);
        let turn = |p: [f64; 2]| [cos * p[0] - sin * p[1], sin * p[0] + cos * p[1]];
        let (ihx, ihy) = (1.0 / self.hx, 1.0 / self.hy);
        for ring in rings {
            let Some(&first) = ring.first() else { continue };
            let first = turn(first);
            let mut ra = first;
            for e in 0..ring.len() {
                let rb = ring.get(e + 1).map_or(first, |&p| turn(p));
                let d = [rb[0] - ra[0], rb[1] - ra[1]];
                // Grid coordinates along the edge: (ua + s·du, va + s·dv), s ∈ [0, 1].
                let a = [(origin[0] + ra[0]) * ihx, (origin[1] + ra[1]) * ihy];
                let (i0, i1) = self.edge_integrals(a, [d[0] * ihx, d[1] * ihy], k, rule);
                fx -= i0 * d[1];
                fy += i0 * d[0];
                m += i0 * (ra[0] * d[0] + ra[1] * d[1]) + i1 * (d[0] * d[0] + d[1] * d[1]);
                ra = rb;
            }
        }
        [fx, fy, m]
    }

    /// ∫ k φ² ds and ∫ k φ² s ds over s ∈ [0, 1] along the segment a + s·d (grid coordinates):
    /// the segment is cut where it crosses a grid line, found by stepping from cell to cell
    /// (a digital differential analyser), and each piece, inside one cell's polynomial,
    /// integrated with 4-point Gauss–Legendre by the reference `rule`, 3-point by the fast one,
    /// and 2-point by both on a piece shorter than [`SHORT`] of a cell. Outside
    /// the plate φ is the clamped coordinate's, as in `grid_eval`; the grid lines beyond the
    /// plate still cut pieces.
    fn edge_integrals(
        &self,
        a: [f64; 2],
        d: [f64; 2],
        k: [f64; 2],
        rule: Quadrature,
    ) -> (f64, f64) {
        let (umax, vmax) = ((self.nx - 1) as f64, (self.ny - 1) as f64);
        let (imax, jmax) = (self.nx as i64 - 2, self.ny as i64 - 2);
        let (mut x, mut y) = (Crossings::new(a[0], d[0]), Crossings::new(a[1], d[1]));
        let (mut i0, mut i1) = (0.0, 0.0);
        let mut s0 = 0.0;
        // Every crossing moves one cell: the segment spans at most |du| + |dv| + 2 of them.
        let most = (d[0].abs() + d[1].abs()).min(1e6) as usize + 4;
        for _ in 0..most {
            let s1 = x.next.min(y.next).min(1.0);
            let h = s1 - s0;
            if h > 0.0 {
                let (ic, jc) = (x.cell.clamp(0, imax), y.cell.clamp(0, jmax));
                let c = &self.cells[jc as usize * (self.nx - 1) + ic as usize];
                let (i, j) = (ic as f64, jc as f64);
                let mut point = |t: f64, wt: f64| {
                    let s = s0 + t * h;
                    let tu = (a[0] + s * d[0]).clamp(0.0, umax) - i;
                    let tv = (a[1] + s * d[1]).clamp(0.0, vmax) - j;
                    let phi = cell_value(c, tu, tv);
                    let v = wt * h * k[usize::from(phi > 0.0)] * phi * phi;
                    i0 += v;
                    i1 += v * s;
                };
                if h * h * (d[0] * d[0] + d[1] * d[1]) <= SHORT * SHORT {
                    for (t, wt) in GL2 {
                        point(t, wt);
                    }
                } else if rule == Quadrature::Fast {
                    for (t, wt) in GL3 {
                        point(t, wt);
                    }
                } else {
                    for (t, wt) in GL4 {
                        point(t, wt);
                    }
                }
            }
            if s1 >= 1.0 {
                break;
            }
            if x.next <= y.next {
                x.cross();
            } else {
                y.cross();
            }
            s0 = s1;
        }
        (i0, i1)
    }
}

/// φ of one cell's polynomial at local coordinates (tu, tv).
fn cell_value(c: &[f64; 16], tu: f64, tv: f64) -> f64 {
    let col = |a: usize| ((c[a * 4 + 3] * tv + c[a * 4 + 2]) * tv + c[a * 4 + 1]) * tv + c[a * 4];
    ((col(3) * tu + col(2)) * tu + col(1)) * tu + col(0)
}

/// ⌊a⌋ as an integer without a call into libm (`f64::floor` is one on the baseline x86-64
/// target, a measurable share of the wrench): exact for |a| < 2⁶³; saturates beyond, where
/// the cell is clamped to the grid anyway; NaN gives 0.
fn floor(a: f64) -> i64 {
    let t = a as i64;
    if (t as f64) > a { t.saturating_sub(1) } else { t }
}

/// The grid lines one coordinate of a segment crosses, in order of the edge parameter: the
/// cell the segment is in along this axis, and the parameter of the next line.
struct Crossings {
    /// Cell index (unclamped: negative or beyond the grid off the plate).
    cell: i64,
    /// Edge parameter of the next grid line (∞ when the coordinate does not change).
    next: f64,
    a: f64,
    inv: f64,
    step: i64,
}

impl Crossings {
    fn new(a: f64, da: f64) -> Crossings {
        // Far off the grid (or not finite) nothing is crossed that matters: every cell there
        // clamps to the edge one, and the cell index stays far from overflowing.
        if da == 0.0 || !da.is_finite() || !a.is_finite() || a.abs() >= 1e15 {
            return Crossings { cell: floor(a), next: f64::INFINITY, a, inv: 0.0, step: 0 };
        }
        let inv = 1.0 / da;
        // Going down from a grid line, the segment is in the cell below it.
        let (cell, step) = if da > 0.0 { (floor(a), 1) } else { (-floor(-a) - 1, -1) };
        let mut c = Crossings { cell, next: 0.0, a, inv, step };
        c.next = c.line_param();
        c
    }

    /// The edge parameter where the segment leaves the current cell.
    fn line_param(&self) -> f64 {
        let line = if self.step > 0 { self.cell + 1 } else { self.cell };
        (line as f64 - self.a) * self.inv
    }

    /// Moves into the next cell.
    fn cross(&mut self) {
        self.cell += self.step;
        self.next = self.line_param();
    }
}

/// Force (x, y) and moment of f = −∇Ψ with Ψ = `psi(ξ)`, ξ = `xi(p)` a continuous function
/// of the plate point (a signed distance to a curved node) and Ψ smooth on either side of
/// ξ = 0 (a kink there: the sign law, or different gains across the node), on `rings`
/// (relative to the centroid) turned by (sin θ, cos θ) and moved to `origin`. Each edge is cut
/// into pieces of at most `max_piece` mm, a piece whose ends lie on different sides of the
/// node again where ξ = 0 (regula falsi), and each piece integrated with 4-point
/// Gauss–Legendre: the hyperbola's outline rule (accuracy: test
/// `hyperbola_outline_wrench_matches_the_area_integral` in `motion::sim`).
pub fn kinked_outline_wrench(
    rings: &[Vec<[f64; 2]>],
    origin: [f64; 2],
    (sin, cos): (f64, f64),
    max_piece: f64,
    xi: impl Fn([f64; 2]) -> f64,
    psi: impl Fn(f64) -> f64,
) -> [f64; 3] {
    let (mut fx, mut fy, mut m) = (0.0, 0.0, 0.0);
    let turn = |p: [f64; 2]| [cos * p[0] - sin * p[1], sin * p[0] + cos * p[1]];
    for ring in rings {
        let n = ring.len();
        for e in 0..n {
            let (ra, rb) = (turn(ring[e]), turn(ring[(e + 1) % n]));
            let d = [rb[0] - ra[0], rb[1] - ra[1]];
            let a = [origin[0] + ra[0], origin[1] + ra[1]];
            let at = |s: f64| xi([a[0] + s * d[0], a[1] + s * d[1]]);
            let (mut i0, mut i1) = (0.0, 0.0);
            let mut piece = |s0: f64, s1: f64| {
                let h = s1 - s0;
                for (x, wt) in GL4 {
                    let s = s0 + x * h;
                    let v = wt * h * psi(at(s));
                    i0 += v;
                    i1 += v * s;
                }
            };
            let parts = (d[0].hypot(d[1]) / max_piece).ceil().max(1.0);
            let (mut s0, mut x0) = (0.0, at(0.0));
            for q in 1..=parts as usize {
                let s1 = q as f64 / parts;
                let x1 = at(s1);
                if (x0 < 0.0) != (x1 < 0.0) {
                    let c = node_crossing(&at, (s0, x0), (s1, x1));
                    piece(s0, c);
                    piece(c, s1);
                } else {
                    piece(s0, s1);
                }
                (s0, x0) = (s1, x1);
            }
            fx -= i0 * d[1];
            fy += i0 * d[0];
            m += i0 * (ra[0] * d[0] + ra[1] * d[1]) + i1 * (d[0] * d[0] + d[1] * d[1]);
        }
    }
    [fx, fy, m]
}

/// Where ξ(s) = 0 between two edge parameters with ξ of opposite signs (Illinois regula
/// falsi, to 10⁻¹⁰ of the edge or |ξ| < 10⁻⁹ mm).
fn node_crossing(
    xi: &impl Fn(f64) -> f64,
    (mut s0, mut x0): (f64, f64),
    (mut s1, mut x1): (f64, f64),
) -> f64 {
    for _ in 0..50 {
        let s = (s0 * x1 - s1 * x0) / (x1 - x0);
        let x = xi(s);
        if x.abs() < 1e-9 || (s1 - s0).abs() < 1e-10 {
            return s;
        }
        if (x < 0.0) != (x1 < 0.0) {
            (s0, x0) = (s1, x1);
        } else {
            x0 *= 0.5;
        }
        (s1, x1) = (s, x);
    }
    (s0 * x1 - s1 * x0) / (x1 - x0)
}

#[cfg(test)]
/// Where the segment a → b crosses the lines x = i·h[0] and y = j·h[1] (edge parameters in
/// (0, 1), ascending, with 0 and 1 at the ends). `h` = ∞ splits nothing.
fn splits(a: [f64; 2], b: [f64; 2], h: [f64; 2], out: &mut Vec<f64>) {
    out.clear();
    out.push(0.0);
    for d in 0..2 {
        let (lo, hi) = (a[d].min(b[d]), a[d].max(b[d]));
        if !h[d].is_finite() || hi - lo <= 0.0 {
            continue;
        }
        let mut k = (lo / h[d]).floor() + 1.0;
        while k * h[d] < hi {
            out.push((k * h[d] - a[d]) / (b[d] - a[d]));
            k += 1.0;
        }
    }
    out.sort_by(f64::total_cmp);
    out.push(1.0);
}

#[cfg(test)]
/// Force (x, y) and moment about the pose's centroid, F = −∮ Ψ n ds and M = ∮ Ψ (r · dr), over
/// `rings` placed at (x, y) (outline CCW, holes CW; relative to the centroid, already turned).
/// Every edge is split at the lines of the `cells` spacing and where it is longer than
/// `max_piece`, and each piece integrated with 7-point Gauss–Legendre.
pub(crate) fn boundary_wrench(
    rings: &[Vec<[f64; 2]>],
    origin: [f64; 2],
    cells: [f64; 2],
    max_piece: f64,
    psi: impl Fn([f64; 2]) -> f64,
) -> [f64; 3] {
    let (mut fx, mut fy, mut m) = (0.0, 0.0, 0.0);
    let mut ts = Vec::with_capacity(16);
    for ring in rings {
        let n = ring.len();
        for e in 0..n {
            let (ra, rb) = (ring[e], ring[(e + 1) % n]);
            let a = [origin[0] + ra[0], origin[1] + ra[1]];
            let b = [origin[0] + rb[0], origin[1] + rb[1]];
            let d = [rb[0] - ra[0], rb[1] - ra[1]];
            splits(a, b, cells, &mut ts);
            let len = d[0].hypot(d[1]);
            // ∮ Ψ ds along the edge and ∮ Ψ s ds (s: edge parameter), both per unit parameter.
            let (mut i0, mut i1) = (0.0, 0.0);
            for w in ts.windows(2) {
                let span = w[1] - w[0];
                if span <= 0.0 {
                    continue;
                }
                let parts = (span * len / max_piece).ceil().max(1.0);
                let h = span / parts;
                for q in 0..parts as usize {
                    let s0 = w[0] + q as f64 * h;
                    for (x, wt) in GL7 {
                        let s = s0 + x * h;
                        let v = wt * h * psi([a[0] + s * d[0], a[1] + s * d[1]]);
                        i0 += v;
                        i1 += v * s;
                    }
                }
            }
            // n ds = (dy, −dx) ds; r·dr = (ra + s d)·d ds.
            fx -= i0 * d[1];
            fy += i0 * d[0];
            m += i0 * (ra[0] * d[0] + ra[1] * d[1]) + i1 * (d[0] * d[0] + d[1] * d[1]);
        }
    }
    [fx, fy, m]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::field::grid_eval;

    fn grid() -> Grid {
        let (nx, ny) = (17, 12);
        let values = (0..ny)
            .flat_map(|j| {
                (0..nx).map(move |i| {
                    let (x, y) = (i as f64 / (nx - 1) as f64, j as f64 / (ny - 1) as f64);
                    (3.0 * x + 0.4).sin() * (2.0 * y - 0.3).cos() + 0.3 * x * y * y
                })
            })
            .collect();
        Grid { nx, ny, size_mm: [300.0, 200.0], values }
    }

    #[test]
    fn bicubic_cells_match_the_catmull_rom_evaluation() {
        let g = grid();
        let b = Bicubic::new(&g);
        let mut worst = [0.0f64; 3];
        for k in 0..2000 {
            // Over the plate and a little beyond (clamped), including grid lines.
            let p = [
                (k as f64 * 0.618_034 % 1.0) * 320.0 - 10.0,
                (k as f64 * 0.414_21 % 1.0) * 220.0 - 10.0,
            ];
            let (v0, d0) = grid_eval(&g, p);
            let (v1, d1) = b.eval(p);
            worst[0] = worst[0].max((v0 - v1).abs());
            worst[1] = worst[1].max((d0[0] - d1[0]).abs().max((d0[1] - d1[1]).abs()));
            worst[2] = worst[2].max((b.value(p) - v1).abs());
        }
        assert!(worst[0] < 1e-12 && worst[1] < 1e-13 && worst[2] < 1e-14, "{worst:?}");
    }

    #[test]
    fn grid_outline_wrench_matches_the_exact_boundary_integral() {
        let g = grid();
        let b = Bicubic::new(&g);
        let k = [0.8, 1.3];
        // A quadrilateral with a triangular hole and a round one of 18 short edges (both
        // CW), relative to an arbitrary origin: long edges cut into pieces of every length
        // at the grid lines, and edges far shorter than a cell (the 2-point rule's).
        let round: Vec<[f64; 2]> = (0..18)
            .map(|q| {
                let a = -(q as f64) * std::f64::consts::TAU / 18.0;
                [12.0 + 3.0 * a.cos(), 4.0 + 3.0 * a.sin()]
            })
            .collect();
        let rings = vec![
            vec![[-20.0, -10.0], [22.0, -12.0], [15.0, 14.0], [-18.0, 9.0]],
            vec![[-5.0, -3.0], [0.0, 5.0], [6.0, -4.0]],
            round,
        ];
        let mut worst = 0.0f64;
        for n in 0..50 {
            let th = n as f64 * 0.37;
            let (sin, cos) = th.sin_cos();
            // Some poses overhang the plate edge (φ is clamped there).
            let origin =
                [(n as f64 * 0.618_034 % 1.0) * 320.0 - 10.0, (n as f64 * 0.414_214 % 1.0) * 200.0];
            let turned: Vec<Vec<[f64; 2]>> = rings
                .iter()
                .map(|r| {
                    r.iter().map(|p| [cos * p[0] - sin * p[1], sin * p[0] + cos * p[1]]).collect()
                })
                .collect();
            let exact = boundary_wrench(&turned, origin, b.spacing(), f64::INFINITY, |p| {
                let v = b.value(p);
                k[usize::from(v > 0.0)] * v * v
            });
            let fast = b.outline_wrench(&rings, origin, (sin, cos), k, Quadrature::Reference);
            // Scale: area (~900 mm²) × largest Ψ (~2), moments × radius.
            for (i, (e, f)) in exact.iter().zip(fast).enumerate() {
                let scale = if i == 2 { 2000.0 * 30.0 } else { 2000.0 };
                worst = worst.max((e - f).abs() / scale);
            }
        }
        println!("largest relative difference from the exact integral: {worst:.1e}");
        assert!(worst < 1e-6, "{worst}");
    }

    #[test]
    fn poses_far_off_the_grid_or_not_finite_end_without_overflow() {
        let b = Bicubic::new(&grid());
        let ring = vec![vec![[-20.0, -10.0], [22.0, -12.0], [15.0, 14.0], [-18.0, 9.0]]];
        let turn = (0.3f64.sin(), 0.3f64.cos());
        // Far off the plate φ is the nearest edge's (clamped): finite, like a pose just off
        // it. (Stepping past grid lines by 10⁻¹² of the edge, as the walk once did, never
        // ends at 10²⁰ mm, where consecutive lines round to the same parameter.)
        for origin in [[1e20, -1e20], [-3e18, 50.0], [1e15, 1e15], [-400.0, 900.0]] {
            let w = b.outline_wrench(&ring, origin, turn, [1.0, 1.0], Quadrature::Fast);
            assert!(w.iter().all(|v| v.is_finite()), "{origin:?}: {w:?}");
        }
        // A pose that is not finite gives no number, and returns.
        let w = b.outline_wrench(&ring, [f64::NAN, 10.0], turn, [1.0, 1.0], Quadrature::Fast);
        assert!(w.iter().any(|v| v.is_nan()), "{w:?}");
        // At ∞ it returns too (a cell walk from there would never end).
        let _ = b.outline_wrench(&ring, [f64::INFINITY, 10.0], turn, [1.0, 1.0], Quadrature::Fast);
    }

    #[test]
    fn boundary_integral_of_a_polynomial_potential_is_exact() {
        // Ψ = x² y (f = −(2xy, x²)) over the unit-free square [1, 3] × [2, 5], centroid (2, 3.5).
        let ring = vec![[-1.0, -1.5], [1.0, -1.5], [1.0, 1.5], [-1.0, 1.5]];
        let [fx, fy, m] =
            boundary_wrench(&[ring], [2.0, 3.5], [0.7, 0.9], 1.0, |p| p[0] * p[0] * p[1]);
        // ∫∫ −2xy = −(x²)|₁³ (y²/2)|₂⁵ = −8·10.5; ∫∫ −x² = −(26/3)·3;
        // M = ∫∫ (x − 2)(−x²) − (y − 3.5)(−2xy) dA.
        let fx_exact = -8.0 * 10.5;
        let fy_exact = -26.0;
        let mx = -(81.0 / 4.0 - 1.0 / 4.0 - 2.0 * 26.0 / 3.0) * 3.0;
        let my = 2.0 * 4.0 * ((125.0 - 8.0) / 3.0 - 3.5 * 10.5);
        for (got, want) in [(fx, fx_exact), (fy, fy_exact), (m, mx + my)] {
            assert!((got - want).abs() < 1e-10, "{got} vs {want}");
        }
    }
}
