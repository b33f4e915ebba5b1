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

impl Grid {
    /// The mode shape moved by `shift` (mm), sampled on the same grid: φ'(p) = φ(p − shift).
    /// A point whose source falls off the plate takes φ extended linearly from the nearest
    /// edge point (its value and slope there), so a shift of a few mm leaves the edge's
    /// gradient in place instead of flattening it. Normalised again (max |φ'| = 1, the
    /// largest sample positive).
    pub fn shifted(&self, shift: [f64; 2]) -> Grid {
        let mut values = Vec::with_capacity(self.values.len());
        for j in 0..self.ny {
            for i in 0..self.nx {
                let p = self.point(i, j);
                let src = [p[0] - shift[0], p[1] - shift[1]];
                values.push(self.extended(src));
            }
        }
        let peak =
            values.iter().copied().fold(0.0f64, |m, v| if v.abs() > m.abs() { v } else { m });
        if peak != 0.0 {
            values.iter_mut().for_each(|v| *v /= peak);
        }
        Grid { nx: self.nx, ny: self.ny, size_mm: self.size_mm, values }
    }

    /// φ at `p`, on the plate or off it: off it, the nearest edge point's value plus the
    /// slope there (a one-cell difference inwards: the interpolation's own derivative at the
    /// last sample is half the true slope, its missing neighbour being clamped) times the
    /// distance out.
    fn extended(&self, p: [f64; 2]) -> f64 {
        let eval = |q: [f64; 2]| crate::motion::field::grid_eval(self, q).0;
        let edge = [p[0].clamp(0.0, self.size_mm[0]), p[1].clamp(0.0, self.size_mm[1])];
        let cell = [self.size_mm[0] / (self.nx - 1) as f64, self.size_mm[1] / (self.ny - 1) as f64];
        let at_edge = eval(edge);
        let mut v = at_edge;
        for axis in 0..2 {
            let out = p[axis] - edge[axis];
            if out != 0.0 {
                let mut inside = edge;
                inside[axis] -= cell[axis].copysign(out);
                v += (at_edge - eval(inside)) / cell[axis] * out.abs();
            }
        }
        v
    }
}
