//! Map coordinates `(e, n)` of the terrain grid: the azimuthal equidistant projection
//! about the site on the reference sphere (distance and azimuth from the site kept
//! exactly; cross-range scale `theta / sin(theta)`, 1 + 5.5e-6 at 10 km on the Moon).
//! An infinite radius means a flat world: `(e, n) = (x, y)` and up is `+z` everywhere.

use nalgebra::Vector3;

/// Below this angle from the site (rad) the series forms replace `sin(theta)/theta`
/// and its derivative, which cancel catastrophically there.
const SERIES_THETA: f64 = 1e-2;

/// The projection between the site frame and map coordinates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapProjection {
    /// Reference sphere radius, m; `f64::INFINITY` for a flat world.
    pub radius_m: f64,
}

/// A site-frame point split into map coordinates and radial height above the sphere.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MapPoint {
    /// Map east, m.
    pub e_m: f64,
    /// Map north, m.
    pub n_m: f64,
    /// Radial height above the reference sphere (flat world: `z`), m.
    pub height_m: f64,
}

impl MapProjection {
    /// True for the flat world (infinite radius).
    pub fn is_flat(&self) -> bool {
        self.radius_m.is_infinite()
    }

    /// Map coordinates and radial height of `p_site`.
    pub fn map_of_site(&self, p: &Vector3<f64>) -> MapPoint {
        if self.is_flat() {
            return MapPoint {
                e_m: p.x,
                n_m: p.y,
                height_m: p.z,
            };
        }
        let r0 = self.radius_m;
        let cz = p.z + r0;
        let hor = p.x.hypot(p.y);
        let r = (hor * hor + cz * cz).sqrt();
        // r - R without cancelling two large numbers.
        let height_m = (p.x * p.x + p.y * p.y + p.z * (p.z + 2.0 * r0)) / (r + r0);
        if hor == 0.0 {
            return MapPoint {
                e_m: 0.0,
                n_m: 0.0,
                height_m,
            };
        }
        let s = r0 * hor.atan2(cz);
        MapPoint {
            e_m: s * p.x / hor,
            n_m: s * p.y / hor,
            height_m,
        }
    }

    /// The radial unit vector (local up) over map point `(e, n)`, site frame.
    pub fn up(&self, e_m: f64, n_m: f64) -> Vector3<f64> {
        if self.is_flat() {
            return Vector3::z();
        }
        let (f, _) = self.f_and_g(e_m, n_m);
        let theta = e_m.hypot(n_m) / self.radius_m;
        Vector3::new(f * e_m, f * n_m, theta.cos())
    }

    /// The site-frame point at map `(e, n)` and radial height `height_m`.
    pub fn site_of_map(&self, e_m: f64, n_m: f64, height_m: f64) -> Vector3<f64> {
        if self.is_flat() {
            return Vector3::new(e_m, n_m, height_m);
        }
        let u = self.up(e_m, n_m);
        let rho = self.radius_m + height_m;
        Vector3::new(rho * u.x, rho * u.y, rho * u.z - self.radius_m)
    }

    /// Partial derivatives of [`Self::up`] with respect to `e` and `n` (1/m).
    pub fn up_derivatives(&self, e_m: f64, n_m: f64) -> (Vector3<f64>, Vector3<f64>) {
        if self.is_flat() {
            return (Vector3::zeros(), Vector3::zeros());
        }
        let (f, g) = self.f_and_g(e_m, n_m);
        // u = (f e, f n, cos(s/R)), f = sin(s/R)/s, df/ds = g s, d cos/ds = -f s / R.
        let k = -f / self.radius_m;
        let du_de = Vector3::new(f + g * e_m * e_m, g * e_m * n_m, k * e_m);
        let du_dn = Vector3::new(g * e_m * n_m, f + g * n_m * n_m, k * n_m);
        (du_de, du_dn)
    }

    /// [`Self::up`] and [`Self::up_derivatives`] together, bit for bit the same, with
    /// one `hypot` where the two calls take three (a camera shades a million nodes).
    pub fn up_with_derivatives(
        &self,
        e_m: f64,
        n_m: f64,
    ) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
        if self.is_flat() {
            return (Vector3::z(), Vector3::zeros(), Vector3::zeros());
        }
        let s = e_m.hypot(n_m);
        let (f, g) = self.f_and_g_at(s);
        let u = Vector3::new(f * e_m, f * n_m, (s / self.radius_m).cos());
        let k = -f / self.radius_m;
        let du_de = Vector3::new(f + g * e_m * e_m, g * e_m * n_m, k * e_m);
        let du_dn = Vector3::new(g * e_m * n_m, f + g * n_m * n_m, k * n_m);
        (u, du_de, du_dn)
    }

    /// `f = sin(theta)/s` and `g = f'(s)/s` at map distance `s = hypot(e, n)`.
    fn f_and_g(&self, e_m: f64, n_m: f64) -> (f64, f64) {
        self.f_and_g_at(e_m.hypot(n_m))
    }

    /// [`Self::f_and_g`] at map distance `s`.
    fn f_and_g_at(&self, s: f64) -> (f64, f64) {
        let r0 = self.radius_m;
        let th = s / r0;
        if th < SERIES_THETA {
            let t2 = th * th;
            let f = (1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0))) / r0;
            let g = (-1.0 / 3.0 + t2 / 30.0 - t2 * t2 / 840.0) / (r0 * r0 * r0);
            (f, g)
        } else {
            let (sn, cs) = th.sin_cos();
            (sn / s, (th * cs - sn) / (r0 * r0 * r0 * th * th * th))
        }
    }
}
