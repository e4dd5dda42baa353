//! [`Terrain`]: the reference sphere plus a DEM, and the point queries on it (elevation,
//! normal, slope, height of a point above the ground). Every query is allocation-free.

use super::grid::{Grid, Sample};
use super::map::MapProjection;
use super::pyramid::MaxPyramid;
use nalgebra::Vector3;

/// The Moon's surface about a site: a sphere of `radius_m` (or a flat world) plus
/// elevations `h(e, n)` from a grid (none: `h = 0`), and optionally a finer detail tile
/// about the site that replaces the grid inside its bounds ([`super::detail`]: it holds
/// base plus detail and meets the base at its edge). Immutable once built; share it
/// across runs with `Arc<Terrain>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Terrain {
    pub(super) map: MapProjection,
    pub(super) grid: Option<Grid>,
    /// The detail tile, if any: inside its bounds the surface is its grid.
    pub(super) detail: Option<DetailTile>,
    /// Bound on |d(height above ground)/d(range)| along any unit ray: the ray-march
    /// step `height / lipschitz` cannot cross the surface.
    pub(super) lipschitz: f64,
    /// Maximum heights over the grid's tiles, for ray casts to skip open air.
    pub(super) pyramid: Option<MaxPyramid>,
}

/// Bound on the map distance moved per metre of 3D displacement. Curvature factors (map
/// scale theta/sin(theta) and R/(R + h_min), each within 1e-4 of 1 for DEMs of tens of km
/// and depths of km) are covered by 1 %.
pub(super) fn map_scale(map: &MapProjection) -> f64 {
    if map.is_flat() {
        1.0
    } else {
        1.01
    }
}

/// The detail tile: its grid (total heights), the grid's pyramid and its map bounds.
#[derive(Debug, Clone, PartialEq)]
pub(super) struct DetailTile {
    pub(super) grid: Grid,
    pub(super) pyramid: Option<MaxPyramid>,
    /// `(e_min, e_max, n_min, n_max)`, m.
    pub(super) bounds: (f64, f64, f64, f64),
}

impl DetailTile {
    #[inline]
    pub(super) fn contains(&self, e_m: f64, n_m: f64) -> bool {
        let b = self.bounds;
        e_m >= b.0 && e_m <= b.1 && n_m >= b.2 && n_m <= b.3
    }

    /// Chebyshev map distance from `(e, n)` to the tile (0 inside).
    #[inline]
    pub(super) fn distance_m(&self, e_m: f64, n_m: f64) -> f64 {
        let b = self.bounds;
        let de = (b.0 - e_m).max(e_m - b.1).max(0.0);
        let dn = (b.2 - n_m).max(n_m - b.3).max(0.0);
        de.max(dn)
    }
}

impl Terrain {
    /// A terrain from an optional grid on a sphere of `radius_m` (`f64::INFINITY`: flat).
    /// `None` if the radius is not positive (or NaN).
    pub fn new(grid: Option<Grid>, radius_m: f64) -> Option<Self> {
        Self::with_detail(grid, None, radius_m)
    }

    /// A terrain from an optional base grid and an optional detail tile (a grid of total
    /// heights that replaces the base inside its bounds, as [`super::detail::build_tile`]
    /// makes it). `None` if the radius is not positive (or NaN).
    pub fn with_detail(grid: Option<Grid>, detail: Option<Grid>, radius_m: f64) -> Option<Self> {
        if radius_m.is_nan() || radius_m <= 0.0 {
            return None;
        }
        let map = MapProjection { radius_m };
        // The surface is piecewise the base or the tile, continuous at the seam: the
        // larger gradient bound holds for both.
        let slope = grid
            .as_ref()
            .map_or(0.0, Grid::max_gradient)
            .max(detail.as_ref().map_or(0.0, Grid::max_gradient));
        let curvature = map_scale(&map);
        let lipschitz = (1.0 + slope * slope).sqrt() * curvature;
        let pyramid = grid.as_ref().map(MaxPyramid::new);
        let detail = detail.map(|g| DetailTile {
            pyramid: Some(MaxPyramid::new(&g)),
            bounds: g.bounds_m(),
            grid: g,
        });
        Some(Self {
            map,
            grid,
            detail,
            lipschitz,
            pyramid,
        })
    }

    /// The detail tile's grid of total heights, if any.
    pub fn detail_grid(&self) -> Option<&Grid> {
        self.detail.as_ref().map(|d| &d.grid)
    }

    /// Highest elevation anywhere on the surface, m (0 for the bare sphere).
    pub fn max_elevation_m(&self) -> f64 {
        let base = self.grid.as_ref().map_or(0.0, |g| g.elevation_range_m().1);
        let tile = self
            .detail
            .as_ref()
            .map_or(f64::NEG_INFINITY, |d| d.grid.elevation_range_m().1);
        base.max(tile)
    }

    /// Drops the ray-march pyramids (tests compare against the plain march).
    #[doc(hidden)]
    pub fn without_pyramids(mut self) -> Self {
        self.pyramid = None;
        if let Some(d) = &mut self.detail {
            d.pyramid = None;
        }
        self
    }

    /// The smooth sphere (`h = 0`) of `radius_m`.
    pub fn smooth(radius_m: f64) -> Option<Self> {
        Self::new(None, radius_m)
    }

    /// The map projection between the site frame and `(e, n)`.
    pub fn map(&self) -> &MapProjection {
        &self.map
    }

    /// The elevation grid, if any.
    pub fn grid(&self) -> Option<&Grid> {
        self.grid.as_ref()
    }

    /// Bound on the surface's map gradient magnitude (m/m).
    pub fn max_gradient(&self) -> f64 {
        self.grid
            .as_ref()
            .map_or(0.0, Grid::max_gradient)
            .max(self.detail.as_ref().map_or(0.0, |d| d.grid.max_gradient()))
    }

    #[inline]
    pub(crate) fn sample(&self, e_m: f64, n_m: f64) -> Sample {
        if let Some(d) = &self.detail {
            if d.contains(e_m, n_m) {
                return d.grid.sample(e_m, n_m);
            }
        }
        match &self.grid {
            Some(g) => g.sample(e_m, n_m),
            None => Sample {
                h_m: 0.0,
                dh_de: 0.0,
                dh_dn: 0.0,
            },
        }
    }

    /// Elevation above the reference sphere at map `(e, n)`, m (bilinear; outside the
    /// grid the nearest edge value).
    #[inline]
    pub fn elevation_m(&self, e_m: f64, n_m: f64) -> f64 {
        self.sample(e_m, n_m).h_m
    }

    /// Unit outward normal of the surface at map `(e, n)`, site frame.
    pub fn normal_site(&self, e_m: f64, n_m: f64) -> Vector3<f64> {
        let s = self.sample(e_m, n_m);
        self.normal_from_sample(e_m, n_m, &s)
    }

    /// [`Self::normal_site`] from the sample already taken at map `(e, n)`.
    pub(crate) fn normal_from_sample(&self, e_m: f64, n_m: f64, s: &Sample) -> Vector3<f64> {
        if self.map.is_flat() {
            return Vector3::new(-s.dh_de, -s.dh_dn, 1.0).normalize();
        }
        // Surface S(e, n) = (R + h) u(e, n); its normal is dS/de x dS/dn.
        let (u, du_de, du_dn) = self.map.up_with_derivatives(e_m, n_m);
        let rho = self.map.radius_m + s.h_m;
        let ds_de = u * s.dh_de + du_de * rho;
        let ds_dn = u * s.dh_dn + du_dn * rho;
        ds_de.cross(&ds_dn).normalize()
    }

    /// Slope at map `(e, n)`: the angle between the normal and local up, degrees.
    pub fn slope_deg(&self, e_m: f64, n_m: f64) -> f64 {
        let nrm = self.normal_site(e_m, n_m);
        let up = self.map.up(e_m, n_m);
        // atan2 of the cross and dot products stays accurate for small slopes.
        nrm.cross(&up).norm().atan2(nrm.dot(&up)).to_degrees()
    }

    /// Radial height of `p_site` above the terrain, m (negative below it): the radial
    /// distance from the Moon's centre minus `R + h(e, n)` at the point's map coordinates.
    /// Flat world: `z - h(x, y)`. What a footpad contact uses.
    #[inline]
    pub fn height_above_surface_m(&self, p_site: &Vector3<f64>) -> f64 {
        let m = self.map.map_of_site(p_site);
        m.height_m - self.elevation_m(m.e_m, m.n_m)
    }

    /// Map coordinates `(e, n)` of `p_site` (its radial projection onto the sphere).
    pub fn map_of_site(&self, p_site: &Vector3<f64>) -> (f64, f64) {
        let m = self.map.map_of_site(p_site);
        (m.e_m, m.n_m)
    }

    /// The site-frame point on the terrain at map `(e, n)`.
    pub fn surface_point_site(&self, e_m: f64, n_m: f64) -> Vector3<f64> {
        self.map.site_of_map(e_m, n_m, self.elevation_m(e_m, n_m))
    }
}
