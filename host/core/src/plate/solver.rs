//! Free vibration of a thin rectangular Kirchhoff plate by the Rayleigh–Ritz method.
//!
//! Trial functions are products of normalised Legendre polynomials,
//! `w(x, y) = Σ q_ij p_i(ξ) p_j(η)` with `ξ = 2x/W − 1`, `η = 2y/H − 1` and
//! `p_i = √((2i+1)/2)·P_i`, so the mass matrix is a multiple of the identity. Boundary and
//! support conditions are imposed exactly as linear constraints `C q = 0` on the coefficients
//! (clamped edge: `w = ∂w/∂x = 0` along `x = 0`; hinge line: `w = 0` along `x = x_h`; rod: `w`
//! and both slopes zero at a point), by restricting the problem to the null space of `C`.
//! Point supports (`[plate] clamps_mm`) are one more row each, `w = 0` at the point: exact
//! elimination like the other supports, so no penalty stiffness has to be chosen and a
//! supported point is a node to rounding.
//! Free edges need nothing: the Ritz method satisfies natural boundary conditions on its own.
//! The problem is solved in non-dimensional form (`a = W`, `D = ρh = 1`), whose eigenvalues are
//! the frequency parameters `λ² = ω² a⁴ ρh / D`.

use crate::model::grid::Grid;
use nalgebra::{DMatrix, DVector, SymmetricEigen};

use crate::model::plate_file::{Boundary, Plate};

/// Polynomial degree count per direction used by default (`N × N` trial functions).
pub const DEFAULT_TERMS: usize = 14;

/// Modes with `λ` below this are rigid-body motions of an unsupported plate and are dropped.
pub const RIGID_LAMBDA: f64 = 1e-3;

/// One natural mode of a plate, as the solver finds it (the planner's typed mode is
/// [`crate::model::plate::Mode`]).
#[derive(Debug, Clone)]
pub struct SolvedMode {
    /// Natural frequency (Hz).
    pub freq_hz: f64,
    /// Frequency parameter `λ = ω a² √(ρh/D)` with `a` = plate size along x.
    pub lambda: f64,
    /// Ritz coefficients `q_ij` (index `i·N + j`, `i` along x).
    pub coeffs: Vec<f64>,
}

/// Result of a modal analysis.
#[derive(Debug, Clone)]
pub struct ModalSolution {
    /// Plate size (mm), x then y.
    pub size_mm: [f64; 2],
    /// Terms per direction.
    pub terms: usize,
    /// Elastic modes in ascending frequency (rigid-body modes removed).
    pub modes: Vec<SolvedMode>,
    /// Rigid-body motions of an unsupported plate (λ ≈ 0; empty when supported).
    pub rigid: Vec<SolvedMode>,
}

/// Geometry of the problem in non-dimensional units (lengths divided by `W`).
#[derive(Debug, Clone)]
pub struct Setup {
    /// Aspect ratio `H / W`.
    pub aspect: f64,
    /// Poisson ratio.
    pub poisson: f64,
    /// Support conditions.
    pub support: Support,
    /// Point supports (ξ, η): `w = 0` there.
    pub points: Vec<[f64; 2]>,
}

/// Support conditions in non-dimensional coordinates (`x/W`, `y/W`... expressed as ξ, η ∈ [−1, 1]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Support {
    /// Clamped along `x = 0`, other edges free.
    Cantilever,
    /// All edges free.
    Free,
    /// Free edges, `w = 0` along the hinge line `ξ = hinge_xi`, and a clamped point (the rod)
    /// at `(rod_xi, rod_eta)`: `w = ∂w/∂x = ∂w/∂y = 0` there.
    HingedRod {
        /// Hinge line position, ξ ∈ (−1, 1).
        hinge_xi: f64,
        /// Rod position ξ.
        rod_xi: f64,
        /// Rod position η.
        rod_eta: f64,
    },
}

/// Gauss–Legendre nodes and weights on [−1, 1] (Newton iteration on `P_n`).
pub(crate) fn gauss_legendre(n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut x = vec![0.0; n];
    let mut w = vec![0.0; n];
    for k in 0..n {
        let mut z = (std::f64::consts::PI * (k as f64 + 0.75) / (n as f64 + 0.5)).cos();
        for _ in 0..100 {
            let (p, dp) = legendre_and_derivative(n, z);
            let dz = p / dp;
            z -= dz;
            if dz.abs() < 1e-15 {
                break;
            }
        }
        let (_, dp) = legendre_and_derivative(n, z);
        x[k] = z;
        w[k] = 2.0 / ((1.0 - z * z) * dp * dp);
    }
    (x, w)
}

fn legendre_and_derivative(n: usize, z: f64) -> (f64, f64) {
    let (mut p0, mut p1) = (1.0, z);
    if n == 0 {
        return (1.0, 0.0);
    }
    for k in 1..n {
        let p2 = ((2 * k + 1) as f64 * z * p1 - k as f64 * p0) / (k + 1) as f64;
        p0 = p1;
        p1 = p2;
    }
    let dp = n as f64 * (z * p1 - p0) / (z * z - 1.0);
    (p1, dp)
}

/// Values, first and second derivatives of the normalised Legendre polynomials `p_0..p_{n-1}`
/// at `z` (valid on the closed interval, endpoints included).
pub fn basis(n: usize, z: f64) -> [Vec<f64>; 3] {
    let mut p = vec![0.0; n];
    let mut d1 = vec![0.0; n];
    let mut d2 = vec![0.0; n];
    if n > 0 {
        p[0] = 1.0;
    }
    if n > 1 {
        p[1] = z;
        d1[1] = 1.0;
    }
    for k in 1..n.saturating_sub(1) {
        let (a, b, c) = ((2 * k + 1) as f64, k as f64, (k + 1) as f64);
        p[k + 1] = (a * z * p[k] - b * p[k - 1]) / c;
        d1[k + 1] = (a * (p[k] + z * d1[k]) - b * d1[k - 1]) / c;
        d2[k + 1] = (a * (2.0 * d1[k] + z * d2[k]) - b * d2[k - 1]) / c;
    }
    for k in 0..n {
        let s = ((2 * k + 1) as f64 / 2.0).sqrt();
        p[k] *= s;
        d1[k] *= s;
        d2[k] *= s;
    }
    [p, d1, d2]
}

/// 1-D integrals `I[r][s][i][k] = ∫ p_i^(r) p_k^(s) dξ` for r, s ∈ {0, 1, 2}.
fn integrals(n: usize) -> Vec<Vec<DMatrix<f64>>> {
    let (xs, ws) = gauss_legendre(n + 2);
    let mut out = vec![vec![DMatrix::zeros(n, n); 3]; 3];
    for (&z, &wq) in xs.iter().zip(&ws) {
        let b = basis(n, z);
        for r in 0..3 {
            for s in 0..3 {
                for i in 0..n {
                    for k in 0..n {
                        out[r][s][(i, k)] += wq * b[r][i] * b[s][k];
                    }
                }
            }
        }
    }
    out
}

/// Stiffness matrix in non-dimensional form (W = 1, D = 1), for the unit-mass-normalised basis.
fn stiffness(n: usize, aspect: f64, nu: f64) -> DMatrix<f64> {
    let ii = integrals(n);
    // d/dx = 2 d/dξ (W = 1), d/dy = (2/H) d/dη; dx dy = (H/4) dξ dη.
    let (cx, cy) = (2.0f64, 2.0 / aspect);
    let jac = aspect / 4.0;
    let m = n * n;
    let mut k = DMatrix::zeros(m, m);
    for i in 0..n {
        for j in 0..n {
            let row = i * n + j;
            for p in 0..n {
                for q in 0..n {
                    let col = p * n + q;
                    let xx = cx.powi(4) * ii[2][2][(i, p)] * ii[0][0][(j, q)];
                    let yy = cy.powi(4) * ii[0][0][(i, p)] * ii[2][2][(j, q)];
                    let c2 = cx * cx * cy * cy;
                    let mixed = nu
                        * c2
                        * (ii[2][0][(i, p)] * ii[0][2][(j, q)]
                            + ii[0][2][(i, p)] * ii[2][0][(j, q)]);
                    let twist = 2.0 * (1.0 - nu) * c2 * ii[1][1][(i, p)] * ii[1][1][(j, q)];
                    k[(row, col)] = jac * (xx + yy + mixed + twist);
                }
            }
        }
    }
    k
}

/// Constraint rows `C` (one per row of the returned matrix) for the supports.
fn constraints(n: usize, support: Support, points: &[[f64; 2]]) -> DMatrix<f64> {
    let mut rows: Vec<Vec<f64>> = Vec::new();
    // Row for "Σ_i q_ij a_i = 0 for each j" (a condition along a whole line ξ = const).
    let line = |a: &[f64], rows: &mut Vec<Vec<f64>>| {
        for j in 0..n {
            let mut r = vec![0.0; n * n];
            for i in 0..n {
                r[i * n + j] = a[i];
            }
            rows.push(r);
        }
    };
    match support {
        Support::Free => {}
        Support::Cantilever => {
            let b = basis(n, -1.0);
            line(&b[0], &mut rows);
            line(&b[1], &mut rows);
        }
        Support::HingedRod { hinge_xi, rod_xi, rod_eta } => {
            let b = basis(n, hinge_xi);
            line(&b[0], &mut rows);
            let bx = basis(n, rod_xi);
            let by = basis(n, rod_eta);
            for (dx, dy) in [(0, 0), (1, 0), (0, 1)] {
                let mut r = vec![0.0; n * n];
                for i in 0..n {
                    for j in 0..n {
                        r[i * n + j] = bx[dx][i] * by[dy][j];
                    }
                }
                rows.push(r);
            }
        }
    }
    for &[xi, eta] in points {
        let (bx, by) = (basis(n, xi), basis(n, eta));
        rows.push((0..n * n).map(|k| bx[0][k / n] * by[0][k % n]).collect());
    }
    let m = n * n;
    DMatrix::from_fn(rows.len(), m, |r, c| rows[r][c])
}

/// Orthonormal basis (columns) of the null space of `c`.
fn null_space(c: &DMatrix<f64>, m: usize) -> DMatrix<f64> {
    if c.nrows() == 0 {
        return DMatrix::identity(m, m);
    }
    // Scale rows to unit length so one tolerance fits all constraint kinds.
    let mut c = c.clone();
    for mut r in c.row_iter_mut() {
        let norm = r.norm();
        if norm > 0.0 {
            r /= norm;
        }
    }
    let ctc = c.transpose() * &c;
    let eig = SymmetricEigen::new(ctc);
    let keep: Vec<usize> = (0..m).filter(|&i| eig.eigenvalues[i].abs() < 1e-9).collect();
    DMatrix::from_fn(m, keep.len(), |r, k| eig.eigenvectors[(r, keep[k])])
}

#[cfg(test)]
/// Non-dimensional modal analysis: returns `(λ, coefficients)` pairs ascending, elastic only.
pub(crate) fn solve_nondim(setup: &Setup, terms: usize) -> Vec<(f64, Vec<f64>)> {
    solve_nondim_all(setup, terms).into_iter().filter(|(lam, _)| *lam >= RIGID_LAMBDA).collect()
}

/// Every mode of the Ritz problem, rigid-body motions (λ ≈ 0) included, ascending.
pub(crate) fn solve_nondim_all(setup: &Setup, terms: usize) -> Vec<(f64, Vec<f64>)> {
    let n = terms;
    let m = n * n;
    let k = stiffness(n, setup.aspect, setup.poisson);
    let z = null_space(&constraints(n, setup.support, &setup.points), m);
    // Mass matrix = (H/4)·I in the normalised basis; Zᵀ Z = I.
    let mass = setup.aspect / 4.0;
    let kr = z.transpose() * &k * &z / mass;
    let kr = (&kr + kr.transpose()) * 0.5;
    let eig = SymmetricEigen::new(kr);
    let mut order: Vec<usize> = (0..eig.eigenvalues.len()).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]));
    order
        .into_iter()
        .map(|i| {
            let lam = eig.eigenvalues[i].max(0.0).sqrt();
            let v: DVector<f64> = &z * eig.eigenvectors.column(i);
            (lam, v.iter().copied().collect())
        })
        .collect()
}

impl Setup {
    /// The non-dimensional setup of a plate file's `[plate]` table.
    pub fn of(plate: &Plate) -> Self {
        let [w, h] = plate.size_mm;
        let support = match plate.boundary {
            Boundary::Cantilever => Support::Cantilever,
            Boundary::Free => Support::Free,
            Boundary::HingedRod => Support::HingedRod {
                hinge_xi: 2.0 * plate.hinge_x_mm / w - 1.0,
                rod_xi: 2.0 * plate.rod_mm[0] / w - 1.0,
                rod_eta: 2.0 * plate.rod_mm[1] / h - 1.0,
            },
        };
        let points =
            plate.clamps_mm.iter().map(|c| [2.0 * c[0] / w - 1.0, 2.0 * c[1] / h - 1.0]).collect();
        Setup { aspect: h / w, poisson: plate.poisson, support, points }
    }
}

/// Hz per unit of λ for a plate: `f = λ/(2π a²)·√(D/ρh)`.
pub(crate) fn hz_per_lambda(plate: &Plate) -> f64 {
    let a = plate.size_mm[0] * 1e-3;
    let h = plate.thickness_mm * 1e-3;
    let e = plate.youngs_modulus_gpa * 1e9;
    let d = e * h.powi(3) / (12.0 * (1.0 - plate.poisson * plate.poisson));
    let rho_h = plate.density_kg_m3 * h;
    (d / rho_h).sqrt() / (a * a) / (2.0 * std::f64::consts::PI)
}

/// Modal analysis of a plate: the first `count` elastic modes.
pub fn solve(plate: &Plate, count: usize, terms: usize) -> ModalSolution {
    let mut sol = solve_all(plate, terms);
    sol.modes.truncate(count);
    sol
}

/// Modal analysis of a plate: every mode of the Ritz problem, the rigid-body motions
/// (λ < [`RIGID_LAMBDA`]) in [`ModalSolution::rigid`]. The forced response
/// ([`crate::plate::drive`]) sums over all of them.
pub fn solve_all(plate: &Plate, terms: usize) -> ModalSolution {
    let scale = hz_per_lambda(plate);
    let (rigid, modes) = solve_nondim_all(&Setup::of(plate), terms)
        .into_iter()
        .map(|(lambda, coeffs)| SolvedMode { freq_hz: lambda * scale, lambda, coeffs })
        .partition(|m| m.lambda < RIGID_LAMBDA);
    ModalSolution { size_mm: plate.size_mm, terms, modes, rigid }
}

/// Grid points along x a sampled mode may have: at least 3 for a node to show, at most 401 to
/// keep a plate file readable (`--grid` of `plate modes` and `plate from-photo`).
pub const GRID_X_POINTS: std::ops::RangeInclusive<usize> = 3..=401;

/// Grid points (nx, ny) for `nx` along x, ny following the plate's aspect ratio.
pub fn grid_dims(nx: usize, size: [f64; 2]) -> (usize, usize) {
    let ny = (((nx - 1) as f64) * size[1] / size[0]).round() as usize + 1;
    (nx, ny.max(2))
}

/// `w(p) = Σ q_ij p_i(ξ) p_j(η)` of Ritz coefficients `q` (`terms` per direction) at plate
/// point `p` (mm) of a plate of `size` (mm).
pub(crate) fn value_at(q: &[f64], terms: usize, size: [f64; 2], p: [f64; 2]) -> f64 {
    let bx = basis(terms, 2.0 * p[0] / size[0] - 1.0);
    let by = basis(terms, 2.0 * p[1] / size[1] - 1.0);
    (0..terms * terms).map(|k| q[k] * bx[0][k / terms] * by[0][k % terms]).sum()
}

impl ModalSolution {
    /// Mode `index`'s shape at plate point `p` (mm), unnormalised Ritz units.
    #[cfg(test)]
    pub(crate) fn value_at(&self, index: usize, p: [f64; 2]) -> f64 {
        value_at(&self.modes[index].coeffs, self.terms, self.size_mm, p)
    }

    /// Samples mode `index` on an `nx × ny` grid (both ≥ 2).
    pub fn sample(&self, index: usize, nx: usize, ny: usize) -> Grid {
        sample_coeffs(&self.modes[index].coeffs, self.terms, self.size_mm, nx, ny)
    }
}

/// Samples Ritz coefficients `q` on an `nx × ny` grid (both ≥ 2), normalised as [`Grid`] says.
pub(crate) fn sample_coeffs(
    q: &[f64],
    terms: usize,
    size_mm: [f64; 2],
    nx: usize,
    ny: usize,
) -> Grid {
    let n = terms;
    let bx: Vec<Vec<f64>> =
        (0..nx).map(|i| basis(n, -1.0 + 2.0 * i as f64 / (nx - 1) as f64)[0].clone()).collect();
    let by: Vec<Vec<f64>> =
        (0..ny).map(|j| basis(n, -1.0 + 2.0 * j as f64 / (ny - 1) as f64)[0].clone()).collect();
    let mut values = Vec::with_capacity(nx * ny);
    for pj in &by {
        for pi in &bx {
            let mut s = 0.0;
            for i in 0..n {
                for j in 0..n {
                    s += q[i * n + j] * pi[i] * pj[j];
                }
            }
            values.push(s);
        }
    }
    let peak = values.iter().copied().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
    if peak != 0.0 {
        for v in &mut values {
            *v /= peak;
            // Exact zeros (constraint lines) come out as ±1e-16 noise: snap them.
            if v.abs() < 1e-9 {
                *v = 0.0;
            }
        }
    }
    Grid { nx, ny, size_mm, values }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square(support: Support) -> Vec<f64> {
        let setup = Setup { aspect: 1.0, poisson: 0.3, support, points: vec![] };
        solve_nondim(&setup, DEFAULT_TERMS).into_iter().map(|(l, _)| l).collect()
    }

    fn check(name: &str, got: &[f64], leissa: &[f64]) {
        for (k, (&g, &l)) in got.iter().zip(leissa).enumerate() {
            let err = (g - l) / l;
            println!("{name} mode {}: λ = {g:.4}, Leissa {l}, error {:+.3} %", k + 1, 100.0 * err);
            assert!(err.abs() < 0.01, "{name} mode {}: λ = {g}, Leissa {l}", k + 1);
        }
    }

    #[test]
    fn gauss_legendre_integrates_polynomials_exactly() {
        let (x, w) = gauss_legendre(5);
        let s: f64 = x.iter().zip(&w).map(|(x, w)| w * x.powi(8)).sum();
        assert!((s - 2.0 / 9.0).abs() < 1e-14);
        let b = basis(6, 0.3);
        // p_2(z) = √(5/2)·(3z² − 1)/2 and its derivatives.
        let s5 = (2.5f64).sqrt();
        assert!((b[0][2] - s5 * (3.0 * 0.09 - 1.0) / 2.0).abs() < 1e-14);
        assert!((b[1][2] - s5 * 3.0 * 0.3).abs() < 1e-14);
        assert!((b[2][2] - s5 * 3.0).abs() < 1e-14);
    }

    #[test]
    fn cantilever_square_matches_leissa() {
        let got = square(Support::Cantilever);
        check("cantilever", &got, &[3.492, 8.525, 21.43, 27.33, 31.11, 54.44]);
    }

    #[test]
    fn free_square_matches_leissa() {
        let got = square(Support::Free);
        check("free", &got, &[13.49, 19.79, 24.43, 35.02, 35.02, 61.53]);
    }

    #[test]
    fn hinged_rod_has_no_rigid_modes_and_rocking_about_hinge_is_suppressed() {
        let setup = Setup {
            aspect: 1.0,
            poisson: 0.3,
            support: Support::HingedRod { hinge_xi: 0.0, rod_xi: 0.5, rod_eta: 0.0 },
            points: vec![],
        };
        let modes = solve_nondim(&setup, 10);
        assert!(modes[0].0 > 1.0, "first λ {}", modes[0].0);
    }

    #[test]
    fn a_point_support_is_a_node_and_leaves_modes_already_zero_there_alone() {
        let free = Setup { aspect: 1.0, poisson: 0.3, support: Support::Free, points: vec![] };
        let centre = Setup { points: vec![[0.0, 0.0]], ..free.clone() };
        let (a, b) = (solve_nondim(&free, 12), solve_nondim(&centre, 12));
        let at = |q: &[f64], p: [f64; 2]| value_at(q, 12, [2.0, 2.0], [p[0] + 1.0, p[1] + 1.0]);
        // Every mode of the supported plate is a node at the support.
        for (lam, q) in &b[..8] {
            assert!(at(q, [0.0, 0.0]).abs() < 1e-9, "λ {lam}: w = {}", at(q, [0.0, 0.0]));
        }
        // By symmetry the free square's first mode (twisting, nodes along both mid-lines) is
        // zero at the centre: supporting it there changes nothing (λ = 13.468 on both plates;
        // the supported plate gains a lower one, the rigid translation turned into a bowl).
        assert!(at(&a[0].1, [0.0, 0.0]).abs() < 1e-9);
        assert!(b.iter().any(|m| (m.0 - a[0].0).abs() < 1e-6 * a[0].0), "{} not kept", a[0].0);
        // The plate's rigid translation is gone (two rigid rotations about the point remain).
        let rigid =
            |s: &Setup| solve_nondim_all(s, 12).iter().filter(|m| m.0 < RIGID_LAMBDA).count();
        assert_eq!((rigid(&free), rigid(&centre)), (3, 2));
        // Off the centre the support moves the nodes: a mode gains a node there.
        let off = Setup { points: vec![[0.4, -0.3]], ..free };
        let c = solve_nondim(&off, 12);
        assert!(c.iter().take(6).all(|(_, q)| at(q, [0.4, -0.3]).abs() < 1e-9));
        // Free mode 2 moves there, so no supported mode keeps its shape and frequency.
        assert!(at(&a[1].1, [0.4, -0.3]).abs() > 0.05);
        assert!(c.iter().all(|m| (m.0 - a[1].0).abs() > 1e-3 * a[1].0), "{:?}", &c[..4]);
    }
}
