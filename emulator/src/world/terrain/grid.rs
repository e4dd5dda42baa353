//! A regular grid of elevations in map coordinates, interpolated bilinearly.
//!
//! Edge rule: a query outside the grid takes the value at the nearest grid point (the
//! edge continues flat outward), so the surface stays continuous and its slope is zero
//! beyond the edge.

/// Elevations (m above the reference sphere) on a square-celled grid; node `(i, j)` is
/// at `e = e0_m + i * spacing_m`, `n = n0_m + j * spacing_m`, stored row by row in `n`.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    nx: usize,
    ny: usize,
    e0_m: f64,
    n0_m: f64,
    spacing_m: f64,
    h_m: Vec<f64>,
    /// Upper bound of the bilinear surface's gradient magnitude anywhere.
    max_gradient: f64,
    min_m: f64,
    max_m: f64,
}

/// Elevation and its map gradient at one point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Elevation, m.
    pub h_m: f64,
    /// dh/de (m/m).
    pub dh_de: f64,
    /// dh/dn (m/m).
    pub dh_dn: f64,
}

impl Grid {
    /// A grid from its samples; `None` if the sizes disagree, it has fewer than 2 x 2
    /// nodes, the spacing is not positive and finite, or a sample is not finite.
    pub fn new(
        nx: usize,
        ny: usize,
        e0_m: f64,
        n0_m: f64,
        spacing_m: f64,
        h_m: Vec<f64>,
    ) -> Option<Self> {
        let sizes_ok = nx >= 2 && ny >= 2 && nx.checked_mul(ny) == Some(h_m.len());
        let numbers_ok = spacing_m.is_finite()
            && spacing_m > 0.0
            && e0_m.is_finite()
            && n0_m.is_finite()
            && h_m.iter().all(|h| h.is_finite());
        if !(sizes_ok && numbers_ok) {
            return None;
        }
        let mut g = Self {
            nx,
            ny,
            e0_m,
            n0_m,
            spacing_m,
            h_m,
            max_gradient: 0.0,
            min_m: 0.0,
            max_m: 0.0,
        };
        g.refresh_bounds();
        Some(g)
    }

    /// Recomputes the gradient and elevation bounds after the samples changed.
    fn refresh_bounds(&mut self) {
        // The bilinear patch's de-slope is a blend of its two e-edges' differences (and
        // likewise in n), so the largest edge differences bound the gradient.
        let (mut ge, mut gn) = (0.0f64, 0.0f64);
        for j in 0..self.ny {
            for i in 0..self.nx {
                let h = self.at(i, j);
                if i + 1 < self.nx {
                    ge = ge.max((self.at(i + 1, j) - h).abs());
                }
                if j + 1 < self.ny {
                    gn = gn.max((self.at(i, j + 1) - h).abs());
                }
            }
        }
        self.max_gradient = ge.hypot(gn) / self.spacing_m;
        self.min_m = self.h_m.iter().copied().fold(f64::INFINITY, f64::min);
        self.max_m = self.h_m.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    }

    /// Node count along e.
    pub fn nx(&self) -> usize {
        self.nx
    }

    /// Node count along n.
    pub fn ny(&self) -> usize {
        self.ny
    }

    /// Node spacing, m.
    pub fn spacing_m(&self) -> f64 {
        self.spacing_m
    }

    /// Map coordinates of node (0, 0), m.
    pub fn origin_m(&self) -> (f64, f64) {
        (self.e0_m, self.n0_m)
    }

    /// Map extent `(e_min, e_max, n_min, n_max)`, m.
    pub fn bounds_m(&self) -> (f64, f64, f64, f64) {
        let s = self.spacing_m;
        (
            self.e0_m,
            self.e0_m + s * (self.nx - 1) as f64,
            self.n0_m,
            self.n0_m + s * (self.ny - 1) as f64,
        )
    }

    /// Upper bound of the gradient magnitude (m/m) anywhere on the surface.
    pub fn max_gradient(&self) -> f64 {
        self.max_gradient
    }

    /// Lowest and highest sample, m.
    pub fn elevation_range_m(&self) -> (f64, f64) {
        (self.min_m, self.max_m)
    }

    /// The samples, row by row in n.
    pub fn samples(&self) -> &[f64] {
        &self.h_m
    }

    /// Sample at node `(i, j)`.
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.h_m[j * self.nx + i]
    }

    /// Bilinear elevation and gradient at `(e, n)`, with the edge rule outside.
    #[inline]
    pub fn sample(&self, e_m: f64, n_m: f64) -> Sample {
        let (i, fx, inside_e) = axis(e_m, self.e0_m, self.spacing_m, self.nx);
        let (j, fy, inside_n) = axis(n_m, self.n0_m, self.spacing_m, self.ny);
        let k = j * self.nx + i;
        let h00 = self.h_m[k];
        let h10 = self.h_m[k + 1];
        let h01 = self.h_m[k + self.nx];
        let h11 = self.h_m[k + self.nx + 1];
        let a = h00 + (h10 - h00) * fx;
        let b = h01 + (h11 - h01) * fx;
        let h = a + (b - a) * fy;
        let dh_de = if inside_e {
            ((h10 - h00) * (1.0 - fy) + (h11 - h01) * fy) / self.spacing_m
        } else {
            0.0
        };
        let dh_dn = if inside_n {
            (b - a) / self.spacing_m
        } else {
            0.0
        };
        Sample {
            h_m: h,
            dh_de,
            dh_dn,
        }
    }

    /// Adds `f(e, n)` to every node within the map box `[e_lo, e_hi] x [n_lo, n_hi]`
    /// (used by builders to stamp features); bounds are refreshed by [`Self::finish`].
    pub(crate) fn add_in_box(
        &mut self,
        e_lo: f64,
        e_hi: f64,
        n_lo: f64,
        n_hi: f64,
        mut f: impl FnMut(f64, f64) -> f64,
    ) {
        let s = self.spacing_m;
        let lo = |x: f64, x0: f64| ((x - x0) / s).ceil().max(0.0) as usize;
        let hi = |x: f64, x0: f64, n: usize| (((x - x0) / s).floor()).min((n - 1) as f64);
        let (i0, j0) = (lo(e_lo, self.e0_m), lo(n_lo, self.n0_m));
        let (i1, j1) = (hi(e_hi, self.e0_m, self.nx), hi(n_hi, self.n0_m, self.ny));
        if i1 < 0.0 || j1 < 0.0 {
            return;
        }
        let (i1, j1) = (i1 as usize, j1 as usize);
        for j in j0..=j1 {
            let n = self.n0_m + s * j as f64;
            for i in i0..=i1 {
                let e = self.e0_m + s * i as f64;
                self.h_m[j * self.nx + i] += f(e, n);
            }
        }
    }

    /// Recomputes bounds after builders changed samples; `false` if one is not finite.
    pub(crate) fn finish(&mut self) -> bool {
        if !self.h_m.iter().all(|h| h.is_finite()) {
            return false;
        }
        self.refresh_bounds();
        true
    }
}

/// Cell index, fraction within the cell and whether `x` lies inside the axis' span.
#[inline]
fn axis(x: f64, x0: f64, s: f64, n: usize) -> (usize, f64, bool) {
    let u = (x - x0) / s;
    let last = (n - 1) as f64;
    if u >= 0.0 && u <= last {
        let i = (u.floor() as usize).min(n - 2);
        (i, u - i as f64, true)
    } else if u > last {
        (n - 2, 1.0, false)
    } else {
        // Below the first node, or NaN (which the caller never passes).
        (0, 0.0, false)
    }
}
