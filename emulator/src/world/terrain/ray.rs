//! Ray casts on the terrain (for altimeter and velocimeter beams), allocation-free.
//!
//! March: the height above ground `g(t)` along a unit ray changes by at most
//! `L = sqrt(1 + s_max^2)` per metre of range (`s_max` the grid's gradient bound), so a
//! step of `g / L` cannot cross the surface (sphere tracing). Over a DEM a step may also
//! be as long as the maximum-height pyramid allows ([`super::pyramid`]): a ray well above
//! the highest point of the tiles around it crosses them in one step, so a ray from
//! kilometres up takes a few dozen steps instead of thousands. Both steps are safe, so
//! the longer is taken; the crossing's bracket is then the same kind as without the
//! pyramid and the refined range agrees to the tolerance. Steps never shrink below
//! `spacing / 8`, so a ray grazing a crest by less than about `L * spacing / 16` may pass
//! it; a crossing is then bracketed and refined by the Illinois variant of regula falsi
//! to 1e-6 m in range.

use super::map::MapPoint;
use super::surface::{map_scale, Terrain};
use nalgebra::Vector3;

/// Range tolerance of the refined intersection, m.
pub const RANGE_TOL_M: f64 = 1e-6;
/// Smallest march step as a fraction of the grid spacing.
const MIN_STEP_FRACTION: f64 = 0.125;
/// Smallest march step without a grid (the smooth sphere, where `g / L` converges), m.
const MIN_STEP_SMOOTH_M: f64 = 1e-3;
/// Iteration caps: march steps and refinement steps (each far above what rays need).
const MAX_MARCH: usize = 1 << 20;
const MAX_REFINE: usize = 200;

/// Where a ray meets the terrain.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Distance from the ray's origin along its unit direction, m.
    pub range_m: f64,
    /// The hit point, site frame, m.
    pub point_site: Vector3<f64>,
    /// Unit surface normal at the hit, site frame.
    pub normal_site: Vector3<f64>,
    /// Angle between the reversed beam and the normal, degrees (0: head-on).
    pub incidence_deg: f64,
}

impl Terrain {
    /// The first point where the ray `origin + t dir` (t in `[0, max_range_m]`) meets
    /// the terrain. `dir` need not be unit length. `None` if it misses within range, or
    /// if an input is not finite or `dir` is zero. An origin at or below the ground hits
    /// at range 0.
    pub fn ray_cast(
        &self,
        origin_site: &Vector3<f64>,
        dir_site: &Vector3<f64>,
        max_range_m: f64,
    ) -> Option<Hit> {
        let norm = dir_site.norm();
        let finite = origin_site.iter().all(|x| x.is_finite()) && norm.is_finite();
        if !finite || norm == 0.0 || max_range_m.is_nan() || max_range_m < 0.0 {
            return None;
        }
        let d = dir_site / norm;
        let g = |t: f64| self.height_above_surface_m(&(origin_site + d * t));
        let min_step = self
            .grid
            .as_ref()
            .map_or(MIN_STEP_SMOOTH_M, |gr| gr.spacing_m() * MIN_STEP_FRACTION);

        // The march carries the map point of `t0`: its height above ground and, over a
        // DEM, the pyramid's bound both come from it.
        let at = |t: f64| self.map.map_of_site(&(origin_site + d * t));
        let above = |m: &MapPoint| m.height_m - self.elevation_m(m.e_m, m.n_m);
        let mut t0 = 0.0;
        let mut m0 = at(0.0);
        let mut g0 = above(&m0);
        if g0 <= 0.0 {
            return Some(self.hit(origin_site, &d, 0.0));
        }
        let scale = map_scale(&self.map);
        let mut level = usize::MAX;
        let mut tile_level = usize::MAX;
        for _ in 0..MAX_MARCH {
            if t0 >= max_range_m {
                return None;
            }
            let mut step = (g0 / self.lipschitz).max(self.min_step_near(&m0, min_step));
            if let Some(advance) = self.pyramid_advance_m(&m0, scale, &mut level, &mut tile_level) {
                step = step.max(advance);
            }
            let t1 = (t0 + step).min(max_range_m);
            let m1 = at(t1);
            let g1 = above(&m1);
            if g1 <= 0.0 {
                let t = refine(&g, t0, g0, t1, g1);
                return Some(self.hit(origin_site, &d, t));
            }
            t0 = t1;
            m0 = m1;
            g0 = g1;
        }
        None
    }

    /// The march's smallest step at `m`: within a base step of the detail tile, the
    /// tile's (if finer); the base's elsewhere.
    #[inline]
    fn min_step_near(&self, m: &MapPoint, base_min_step: f64) -> f64 {
        match &self.detail {
            Some(d) if d.distance_m(m.e_m, m.n_m) <= base_min_step => {
                base_min_step.min(d.grid.spacing_m() * MIN_STEP_FRACTION)
            }
            _ => base_min_step,
        }
    }

    /// The longest safe advance the pyramids give at `m` (`None` without pyramids).
    /// Without a tile, the base pyramid's. With one: the base's bound (or, on the bare
    /// sphere, the height itself) covers the base; an advance that reaches no closer than
    /// the tile's Chebyshev distance cannot meet it, and beyond that the tile's own
    /// pyramid bounds it, so the advance is `min(base, max(free, tile))`.
    #[inline]
    fn pyramid_advance_m(
        &self,
        m: &MapPoint,
        scale: f64,
        level: &mut usize,
        tile_level: &mut usize,
    ) -> Option<f64> {
        let base = match &self.pyramid {
            Some(p) => {
                let (advance, best) = p.safe_advance_m(m.e_m, m.n_m, m.height_m, scale, *level);
                *level = best;
                Some(advance)
            }
            None => None,
        };
        let Some(tile) = &self.detail else {
            return base;
        };
        let tile_pyramid = tile.pyramid.as_ref()?;
        let base = match base {
            Some(b) => b,
            // The bare sphere under the tile: h = 0 outside it.
            None if self.grid.is_none() => m.height_m.max(0.0),
            None => return None,
        };
        let free = tile.distance_m(m.e_m, m.n_m) / scale;
        if base <= free {
            return Some(base);
        }
        let (inside, best) =
            tile_pyramid.safe_advance_m(m.e_m, m.n_m, m.height_m, scale, *tile_level);
        *tile_level = best;
        Some(base.min(free.max(inside)))
    }

    fn hit(&self, origin: &Vector3<f64>, d: &Vector3<f64>, t: f64) -> Hit {
        let p = origin + d * t;
        let (e, n) = self.map_of_site(&p);
        let normal = self.normal_site(e, n);
        let cos_inc = (-d.dot(&normal)).clamp(-1.0, 1.0);
        Hit {
            range_m: t,
            point_site: p,
            normal_site: normal,
            incidence_deg: cos_inc.acos().to_degrees(),
        }
    }
}

/// Illinois regula falsi on a bracket with `g(a) > 0 >= g(b)`: the crossing's range.
fn refine(g: &impl Fn(f64) -> f64, mut a: f64, mut ga: f64, mut b: f64, mut gb: f64) -> f64 {
    let mut side = 0i8;
    for _ in 0..MAX_REFINE {
        if b - a <= RANGE_TOL_M || gb == 0.0 {
            break;
        }
        let mut c = (a * gb - b * ga) / (gb - ga);
        if !(c > a && c < b) {
            c = 0.5 * (a + b);
        }
        let gc = g(c);
        if gc.abs() < 1e-12 {
            return c;
        }
        if gc > 0.0 {
            a = c;
            ga = gc;
            if side == 1 {
                gb *= 0.5;
            }
            side = 1;
        } else {
            b = c;
            gb = gc;
            if side == -1 {
                ga *= 0.5;
            }
            side = -1;
        }
    }
    // The ground side of the bracket: the returned point is never above the surface by
    // more than the tolerance.
    b
}

#[cfg(test)]
mod tests {
    use super::super::{build, SiteFrame, SyntheticSpec, TerrainSpec};
    use super::*;

    /// The pyramid changes how far the march jumps in the open, never where it brackets a
    /// crossing: every ray hits (or misses) as it does without it, at the same range to
    /// the refinement's tolerance, from 20 m to 6 km over the default cratered surface.
    #[test]
    fn pyramid_casts_agree_with_the_plain_march() {
        let site = SiteFrame::from_deg(-69.373, 32.319, 1_737_400.0);
        let with = build(&TerrainSpec::Synthetic(SyntheticSpec::default()), &site).unwrap();
        let mut without = with.clone();
        without.pyramid = None;
        let (mut hits, mut misses) = (0, 0);
        for k in 0..3000 {
            let x = k as f64;
            let e = 3000.0 * (0.713 * x).sin();
            let n = 3000.0 * (0.377 * x).cos();
            let up = 20.0 + 6000.0 * (0.5 + 0.5 * (1.3 * x).sin()).powi(3);
            let origin = with.map().site_of_map(e, n, with.elevation_m(e, n) + up);
            // Off-nadir up to 70 deg, any azimuth.
            let (off, az) = (70f64.to_radians() * (0.5 + 0.5 * (2.1 * x).sin()), 0.9 * x);
            let dir = Vector3::new(off.sin() * az.cos(), off.sin() * az.sin(), -off.cos());
            let a = with.ray_cast(&origin, &dir, 20_000.0);
            let b = without.ray_cast(&origin, &dir, 20_000.0);
            match (a, b) {
                (Some(a), Some(b)) => {
                    hits += 1;
                    assert!(
                        (a.range_m - b.range_m).abs() <= 2.0 * RANGE_TOL_M,
                        "ray {k}: {} against {}",
                        a.range_m,
                        b.range_m
                    );
                }
                (None, None) => misses += 1,
                (a, b) => panic!("ray {k}: {a:?} against {b:?}"),
            }
        }
        assert!(hits > 2900, "{hits} hits, {misses} misses");
    }
}
