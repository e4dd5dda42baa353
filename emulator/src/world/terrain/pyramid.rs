//! A maximum-height pyramid over a DEM: the highest elevation in every tile of
//! `2^l x 2^l` cells, level by level, so a ray high above a region crosses it in one step
//! instead of marching it metre by metre (the "maximum mipmap" of heightfield ray tracing:
//! Tevs, Ihrke and Seidel, "Maximum mipmaps for fast, accurate, and scalable dynamic
//! height field rendering", I3D 2008).
//!
//! Level 0 holds each grid cell's largest node (the bilinear patch never rises above its
//! corners); level `l + 1` the largest of its four children. Values are `f32` rounded up,
//! so a bound never falls below the `f64` surface; each level also keeps the bound over
//! every tile's 3 x 3 neighbourhood, which is what a query reads. Two `f32` a tile over
//! every level: 4/3 of the grid's own memory. Hand-written: the heightfield crates on
//! crates.io build meshes for rendering engines, not conservative bounds over a geodetic
//! DEM.

use super::grid::Grid;

/// Conservative maximum heights over square tiles of the grid's cells.
#[derive(Debug, Clone, PartialEq)]
pub struct MaxPyramid {
    /// Level `l`: `(tiles along e, tiles along n, maxima row by row in n)`.
    levels: Vec<Level>,
    e0_m: f64,
    n0_m: f64,
    spacing_m: f64,
    /// Cells along e and n (nodes minus one).
    cells: (usize, usize),
}

#[derive(Debug, Clone, PartialEq)]
struct Level {
    nx: usize,
    ny: usize,
    /// The bound over each tile.
    max_m: Vec<f32>,
    /// The bound over each tile and the eight around it (those inside): what a query
    /// reads, one load a level.
    around_m: Vec<f32>,
}

impl Level {
    fn new(nx: usize, ny: usize, max_m: Vec<f32>) -> Self {
        // The 3 x 3 maximum as two 3-wide passes, along e then along n.
        let wide = |v: &[f32], k: usize, stride: usize, i: usize, n: usize| {
            let mut m = v[k];
            if i > 0 {
                m = m.max(v[k - stride]);
            }
            if i + 1 < n {
                m = m.max(v[k + stride]);
            }
            m
        };
        let along_e: Vec<f32> = (0..nx * ny)
            .map(|k| wide(&max_m, k, 1, k % nx, nx))
            .collect();
        let around_m = (0..nx * ny)
            .map(|k| wide(&along_e, k, nx, k / nx, ny))
            .collect();
        Self {
            nx,
            ny,
            max_m,
            around_m,
        }
    }

    #[inline]
    fn at(&self, i: usize, j: usize) -> f32 {
        self.max_m[j * self.nx + i]
    }
}

/// An `f64` as the smallest `f32` not below it.
fn f32_at_least(x: f64) -> f32 {
    let y = x as f32;
    if (y as f64) < x {
        y.next_up()
    } else {
        y
    }
}

impl MaxPyramid {
    /// Builds every level, up to a single tile.
    pub fn new(grid: &Grid) -> Self {
        let (cx, cy) = (grid.nx() - 1, grid.ny() - 1);
        let mut base = Vec::with_capacity(cx * cy);
        for j in 0..cy {
            for i in 0..cx {
                let m = grid
                    .at(i, j)
                    .max(grid.at(i + 1, j))
                    .max(grid.at(i, j + 1))
                    .max(grid.at(i + 1, j + 1));
                base.push(f32_at_least(m));
            }
        }
        let mut levels = vec![Level::new(cx, cy, base)];
        while let Some(prev) = levels.last().filter(|l| l.nx > 1 || l.ny > 1) {
            let (nx, ny) = (prev.nx.div_ceil(2), prev.ny.div_ceil(2));
            let mut max_m = Vec::with_capacity(nx * ny);
            for j in 0..ny {
                for i in 0..nx {
                    let mut m = f32::NEG_INFINITY;
                    for (di, dj) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                        let (ci, cj) = (2 * i + di, 2 * j + dj);
                        if ci < prev.nx && cj < prev.ny {
                            m = m.max(prev.at(ci, cj));
                        }
                    }
                    max_m.push(m);
                }
            }
            levels.push(Level::new(nx, ny, max_m));
        }
        let (e0_m, n0_m) = grid.origin_m();
        Self {
            levels,
            e0_m,
            n0_m,
            spacing_m: grid.spacing_m(),
            cells: (cx, cy),
        }
    }

    /// Number of levels (the last is one tile).
    pub fn depth(&self) -> usize {
        self.levels.len()
    }

    /// The longest safe advance of a ray now at map `(e, n)` and radial height
    /// `height_m`: a range `s` over which it cannot reach the surface, given that it
    /// descends at most 1 m per metre of range and moves at most `map_scale` metres on the
    /// map per metre. Each level `l` bounds the surface within Chebyshev distance
    /// `2^l * spacing` of the point (its tile and the eight around it) and gives
    /// `min(gap to that bound, reach)`; the best level wins. 0 when none gives an advance.
    ///
    /// Points outside the grid take the nearest edge's heights (the grid's edge rule);
    /// clamping to the grid never increases a distance, so the tile of the clamped point
    /// and its neighbours bound them too.
    ///
    /// `start_level` is where the search begins (the level the previous step of the same
    /// ray chose, `usize::MAX` for the top): it climbs while the reach limits the advance
    /// and descends while the gap does and a finer level could still do better, so the
    /// answer is the same from any start. Returns the advance and the level that gave it.
    pub fn safe_advance_m(
        &self,
        e_m: f64,
        n_m: f64,
        height_m: f64,
        map_scale: f64,
        start_level: usize,
    ) -> (f64, usize) {
        let u = ((e_m - self.e0_m) / self.spacing_m).clamp(0.0, self.cells.0 as f64 - 0.5);
        let v = ((n_m - self.n0_m) / self.spacing_m).clamp(0.0, self.cells.1 as f64 - 0.5);
        if !(u.is_finite() && v.is_finite() && height_m.is_finite()) {
            return (0.0, 0);
        }
        let (ci, cj) = (u as usize, v as usize);
        let top = self.levels.len() - 1;
        // Level l: min(gap, reach), gap = height - bound(l), reach = 2^l spacing / scale.
        let advance = |l: usize| {
            let level = &self.levels[l];
            let highest = level.around_m[(cj >> l) * level.nx + (ci >> l)] as f64;
            let gap = height_m - highest;
            let reach = self.spacing_m * (1u64 << l) as f64 / map_scale;
            (gap.min(reach), gap, reach)
        };
        let mut l = start_level.min(top);
        let (mut best, gap, reach) = advance(l);
        let mut best_level = l;
        if gap >= reach {
            // Reach-limited: coarser tiles reach further while the gap allows.
            while l < top {
                l += 1;
                let (s, gap, reach) = advance(l);
                if s > best {
                    best = s;
                    best_level = l;
                }
                if gap <= reach {
                    break;
                }
            }
        } else {
            // Gap-limited: finer tiles may have a lower bound, while their reach exceeds
            // the best so far.
            while l > 0 {
                l -= 1;
                let (s, _, reach) = advance(l);
                if s > best {
                    best = s;
                    best_level = l;
                }
                if reach <= best {
                    break;
                }
            }
        }
        (best.max(0.0), best_level)
    }
}

/// The largest value over tile `(i, j)` and its eight neighbours (those inside).
#[cfg(test)]
fn neighbourhood_max(level: &Level, i: usize, j: usize) -> f32 {
    let (i0, i1) = (i.saturating_sub(1), (i + 1).min(level.nx - 1));
    let (j0, j1) = (j.saturating_sub(1), (j + 1).min(level.ny - 1));
    let mut m = f32::NEG_INFINITY;
    for jj in j0..=j1 {
        let row = &level.max_m[jj * level.nx..(jj + 1) * level.nx];
        for v in &row[i0..=i1] {
            m = m.max(*v);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> Grid {
        let (nx, ny) = (37, 23);
        let h = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k % nx) as f64, (k / nx) as f64);
                30.0 * (0.31 * i).sin() * (0.17 * j).cos() + 0.5 * i
            })
            .collect();
        Grid::new(nx, ny, -100.0, 50.0, 2.5, h).unwrap()
    }

    #[test]
    fn every_level_bounds_the_nodes_it_covers() {
        let g = grid();
        let p = MaxPyramid::new(&g);
        assert_eq!(p.levels.last().map(|l| (l.nx, l.ny)), Some((1, 1)));
        for (l, level) in p.levels.iter().enumerate() {
            let side = 1usize << l;
            for tj in 0..level.ny {
                for ti in 0..level.nx {
                    let mut m = f64::NEG_INFINITY;
                    for j in tj * side..=((tj + 1) * side).min(g.ny() - 1) {
                        for i in ti * side..=((ti + 1) * side).min(g.nx() - 1) {
                            m = m.max(g.at(i, j));
                        }
                    }
                    let b = level.at(ti, tj) as f64;
                    let around = level.around_m[tj * level.nx + ti];
                    assert_eq!(around, neighbourhood_max(level, ti, tj));
                    assert!(b >= m, "level {l} tile ({ti}, {tj}): {b} < {m}");
                    assert!(
                        b - m <= m.abs() * 1e-6 + 1e-6,
                        "bound {b} loose against {m}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_safe_advance_never_reaches_a_higher_point() {
        let g = grid();
        let p = MaxPyramid::new(&g);
        let (e0, e1, n0, n1) = g.bounds_m();
        let mut checked = 0;
        for k in 0..2000 {
            let x = k as f64;
            // Points inside and beyond the grid, at heights from just above to far above.
            let e = e0 - 20.0 + (e1 - e0 + 40.0) * (0.5 + 0.5 * (0.713 * x).sin());
            let n = n0 - 20.0 + (n1 - n0 + 40.0) * (0.5 + 0.5 * (0.377 * x).cos());
            let h = g.sample(e, n).h_m + 200.0 * (0.5 + 0.5 * (1.3 * x).sin()).powi(3);
            let (s, _) = p.safe_advance_m(e, n, h, 1.0, (k % 13) as usize);
            // The same answer from the top and from the finest level.
            assert_eq!(p.safe_advance_m(e, n, h, 1.0, usize::MAX).0, s);
            assert_eq!(p.safe_advance_m(e, n, h, 1.0, 0).0, s);
            if s <= 0.0 {
                continue;
            }
            checked += 1;
            // Every node within the reach on the map lies below the lowest the ray can be.
            for j in 0..g.ny() {
                for i in 0..g.nx() {
                    let (ne, nn) = (e0 + 2.5 * i as f64, n0 + 2.5 * j as f64);
                    let (ce, cn) = (e.clamp(e0, e1), n.clamp(n0, n1));
                    if (ne - ce).abs().max((nn - cn).abs()) <= s {
                        assert!(g.at(i, j) < h - s + 1e-9, "node above the advance");
                    }
                }
            }
        }
        assert!(checked > 1000, "only {checked} points had an advance");
    }
}
