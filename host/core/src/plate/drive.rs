//! The forced response of a plate driven at one point (`[plate] drive_mm`), at each resonance.
//!
//! A point force `F e^{iωt}` at `x_d` drives the plate into `w(x) = Σ_j a_j φ_j(x)` with
//! `a_j = φ_j(x_d) F / (ω_j² − ω² + 2iζ ω_j ω)` (modal superposition, mass-normalised modes,
//! uniform modal damping ζ). At a resonance ω = ω_k the modes of that frequency dominate by
//! `1/2ζ`: the response is, to O(ζ), their **projection of the drive onto the eigenspace**,
//! `u = Σ_{j: ω_j = ω_k} φ_j(x_d) φ_j`, in quadrature with the force. A single mode keeps its
//! shape (scaled by φ_k(x_d)); a degenerate pair (a square plate's) becomes the one
//! combination the drive point excites. The other modes add a part `v` in phase with the force,
//! of relative size O(ζ) ([`Resonance::quadrature`] measures it; it is not written). A mode
//! with a node at the drive point is not excited ([`MIN_EXCITATION`]).

use crate::model::plate::SAME_FREQ_HZ;
use crate::plate::solver::{ModalSolution, grid_dims, sample_coeffs, value_at};

/// A resonance whose response at the drive point is below this fraction of its peak is not
/// excited: the shaker would need 1/0.05 = 20 times the force it needs at an antinode, and the
/// O(ζ) part of the other modes would be as large as the resonance's own near the drive
/// point at ζ = 0.01 (the node pattern blurs).
pub const MIN_EXCITATION: f64 = 0.05;

/// Relative frequency difference under which two solver modes are one degenerate resonance
/// (rounding of the eigen solver; a symmetric plate's pairs agree to ~1e-12).
pub const DEGENERATE_REL: f64 = 1e-6;

/// One resonance as the drive point excites it.
#[derive(Debug, Clone)]
pub struct Resonance {
    /// Frequency (Hz).
    pub freq_hz: f64,
    /// Frequency parameter λ.
    pub lambda: f64,
    /// The solver modes (0-based indices into [`ModalSolution::modes`]) at this frequency.
    pub members: Vec<usize>,
    /// Ritz coefficients of the response shape `u` (the projection of the drive).
    pub coeffs: Vec<f64>,
    /// `|u(x_d)| / max |u|`: 1 at an antinode, 0 on a node.
    pub excitation: f64,
    /// `max |v| / max |u|` at [`crate::model::plate_file::Plate::damping_ratio`]: the part
    /// of the other modes, neglected in the written shape.
    pub quadrature: f64,
}

/// The forced responses of a drive point: the excited resonances and those it leaves out.
#[derive(Debug, Clone)]
pub struct Forced {
    /// Excited resonances, ascending.
    pub resonances: Vec<Resonance>,
    /// Resonances with excitation below [`MIN_EXCITATION`] (not written).
    pub dropped: Vec<Resonance>,
}

/// The solver modes grouped by frequency: each group one resonance (a degenerate pair or more
/// when several modes share a frequency to [`DEGENERATE_REL`] or [`SAME_FREQ_HZ`]).
pub fn groups(sol: &ModalSolution) -> Vec<Vec<usize>> {
    let mut out: Vec<Vec<usize>> = Vec::new();
    for (k, m) in sol.modes.iter().enumerate() {
        let joins = out.last().is_some_and(|g| {
            let f = sol.modes[g[0]].freq_hz;
            (m.freq_hz - f).abs() < SAME_FREQ_HZ.max(DEGENERATE_REL * f)
        });
        match out.last_mut() {
            Some(g) if joins => g.push(k),
            _ => out.push(vec![k]),
        }
    }
    out
}

/// The groups of [`groups`] that begin among the first `count` modes (a pair cut by `count`
/// is kept whole).
pub fn first_groups(sol: &ModalSolution, count: usize) -> Vec<Vec<usize>> {
    groups(sol).into_iter().filter(|g| g[0] < count).collect()
}

/// The largest |value| of Ritz coefficients on a 41-point-wide grid over the plate.
fn peak_abs(q: &[f64], sol: &ModalSolution) -> f64 {
    let (nx, ny) = grid_dims(41, sol.size_mm);
    let raw = sample_coeffs(q, sol.terms, sol.size_mm, nx, ny);
    // The sample is normalised; its peak's raw value is recovered at the peak's location.
    let (i, _) =
        raw.values.iter().enumerate().fold((0, 0.0f64), |(bi, bv), (i, v)| {
            if v.abs() > bv { (i, v.abs()) } else { (bi, bv) }
        });
    value_at(q, sol.terms, sol.size_mm, raw.point(i % nx, i / nx)).abs()
}

/// `Σ c_j q_j` over modes `(c_j, q_j)`.
fn combine<'a>(terms: impl Iterator<Item = (f64, &'a [f64])>, len: usize) -> Vec<f64> {
    let mut out = vec![0.0; len];
    for (c, q) in terms {
        for (o, v) in out.iter_mut().zip(q) {
            *o += c * v;
        }
    }
    out
}

/// The forced response at each resonance among the first `count` modes of `sol` (which must
/// hold every elastic mode and the rigid ones: [`crate::plate::solver::solve_all`]) for a drive
/// at `drive_mm` with modal damping `zeta`.
pub fn forced(sol: &ModalSolution, count: usize, drive_mm: [f64; 2], zeta: f64) -> Forced {
    let at = |q: &[f64]| value_at(q, sol.terms, sol.size_mm, drive_mm);
    let len = sol.terms * sol.terms;
    let (mut resonances, mut dropped) = (Vec::new(), Vec::new());
    for members in first_groups(sol, count) {
        let lam_k = sol.modes[members[0]].lambda;
        let u = combine(
            members.iter().map(|&j| (at(&sol.modes[j].coeffs), sol.modes[j].coeffs.as_slice())),
            len,
        );
        // The other modes' part in phase with the force: Im of i·2ζλ_k²/(λ_j² − λ_k² + 2iζλ_jλ_k).
        let others = sol.modes.iter().enumerate().filter(|(j, _)| !members.contains(j));
        let v = combine(
            others.map(|(_, m)| m).chain(&sol.rigid).map(|m| {
                let d = m.lambda * m.lambda - lam_k * lam_k;
                let den = d * d + 4.0 * zeta * zeta * (m.lambda * lam_k).powi(2);
                (at(&m.coeffs) * 2.0 * zeta * lam_k * lam_k * d / den, m.coeffs.as_slice())
            }),
            len,
        );
        let peak = peak_abs(&u, sol);
        let excitation = if peak > 0.0 { (at(&u).abs() / peak).min(1.0) } else { 0.0 };
        let quadrature = if peak > 0.0 { peak_abs(&v, sol) / peak } else { f64::INFINITY };
        let r = Resonance {
            freq_hz: sol.modes[members[0]].freq_hz,
            lambda: lam_k,
            members,
            coeffs: u,
            excitation,
            quadrature,
        };
        if excitation < MIN_EXCITATION { dropped.push(r) } else { resonances.push(r) }
    }
    Forced { resonances, dropped }
}

impl Forced {
    /// The excited resonances as a [`ModalSolution`] (one mode each, shape `u`), for sampling,
    /// plotting and node lines like the free modes.
    pub fn as_solution(&self, sol: &ModalSolution) -> ModalSolution {
        let modes = self
            .resonances
            .iter()
            .map(|r| crate::plate::solver::SolvedMode {
                freq_hz: r.freq_hz,
                lambda: r.lambda,
                coeffs: r.coeffs.clone(),
            })
            .collect();
        ModalSolution { size_mm: sol.size_mm, terms: sol.terms, modes, rigid: vec![] }
    }
}

/// "mode 4" or "modes 4+5" (1-based) for a group of solver modes.
pub fn members_label(members: &[usize]) -> String {
    let n: Vec<String> = members.iter().map(|k| (k + 1).to_string()).collect();
    format!("{} {}", if n.len() == 1 { "mode" } else { "modes" }, n.join("+"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::plate_file::PlateFile;
    use crate::plate::solver;

    fn plate(extra: &str) -> crate::model::plate_file::Plate {
        let text = format!(
            "[plate]\nname = \"sq\"\nsize_mm = [200.0, 200.0]\nthickness_mm = 2.0\n\
             youngs_modulus_gpa = 70.0\ndensity_kg_m3 = 2700.0\npoisson = 0.3\n\
             boundary = \"free\"\n{extra}"
        );
        PlateFile::parse(&text, "t").unwrap().plate.mechanics().unwrap()
    }

    #[test]
    fn a_square_free_plates_pair_is_one_resonance_the_projection_of_the_drive() {
        let p = plate("");
        let sol = solver::solve_all(&p, 12);
        let g = first_groups(&sol, 6);
        // Leissa's free square: 13.49, 19.79, 24.43, 35.02 (twice), 61.53 (twice, the 6th
        // mode's pair kept whole): five resonances.
        assert_eq!(g.iter().map(Vec::len).collect::<Vec<_>>(), vec![1, 1, 1, 2, 2], "{g:?}");
        let d = [60.0, 35.0];
        let f = forced(&sol, 6, d, 0.01);
        let pair = f.resonances.iter().chain(&f.dropped).find(|r| r.members.len() == 2).unwrap();
        // u = Σ φ_j(x_d) φ_j: a unit-norm φ in the pair's span orthogonal to u has no drive.
        let [a, b] = [pair.members[0], pair.members[1]];
        let (ca, cb) = (sol.value_at(a, d), sol.value_at(b, d));
        let ortho = combine(
            [(cb, sol.modes[a].coeffs.as_slice()), (-ca, sol.modes[b].coeffs.as_slice())]
                .into_iter(),
            144,
        );
        assert!(value_at(&ortho, 12, p.size_mm, d).abs() < 1e-12);
        let dot: f64 = ortho.iter().zip(&pair.coeffs).map(|(x, y)| x * y).sum();
        assert!(dot.abs() < 1e-12, "the response is orthogonal to what the drive misses");
        assert!(pair.excitation > MIN_EXCITATION, "{}", pair.excitation);
        // Light damping: the other modes' part is O(ζ).
        assert!(f.resonances.iter().all(|r| r.quadrature < 0.2), "{:?}", f.resonances);
    }

    #[test]
    fn a_drive_point_on_a_node_does_not_excite_that_mode() {
        let p = plate("");
        let sol = solver::solve_all(&p, 12);
        // Mode 1 of the free square is the twisting mode with nodes x = W/2 and y = H/2.
        let on_node = [100.0, 37.0];
        assert!(sol.value_at(0, on_node).abs() < 1e-9 * sol.value_at(0, [0.0, 0.0]).abs());
        let f = forced(&sol, 3, on_node, 0.01);
        assert_eq!(f.dropped.iter().map(|r| r.members.clone()).collect::<Vec<_>>(), vec![vec![0]]);
        assert!(f.dropped[0].excitation < 1e-6);
        let g = forced(&sol, 3, [40.0, 37.0], 0.01);
        assert_eq!(g.resonances[0].members, vec![0], "off the node it is excited");
    }
}
