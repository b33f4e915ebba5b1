//! A mode shape sampled on a regular grid over the plate: what the solver produces, what a
//! plate file stores (`node = { grid … }`) and what the grid-mode field models read. It lives in
//! `model` so that the layers below `plate` (model, motion) use it without the solver.

/// A mode shape sampled on a regular grid covering the plate.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Samples along x.
    pub nx: usize,
    /// Samples along y.
    pub ny: usize,
    /// Plate size (mm).
    pub size_mm: [f64; 2],
    /// `values[j·nx + i] = φ(x_i, y_j)`, `x_i = i·W/(nx−1)`, `y_j = j·H/(ny−1)`;
    /// normalised so that max |φ| = 1 and the largest-magnitude sample is positive.
    pub values: Vec<f64>,
}

impl Grid {
    /// Sample value at grid point (i, j).
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.values[j * self.nx + i]
    }
    /// Plate coordinates (mm) of grid point (i, j).
    pub fn point(&self, i: usize, j: usize) -> [f64; 2] {
        [
            i as f64 * self.size_mm[0] / (self.nx - 1) as f64,
            j as f64 * self.size_mm[1] / (self.ny - 1) as f64,
        ]
    }
}
