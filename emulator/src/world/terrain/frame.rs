//! The site frame: Moon-fixed (`mcmf`) Cartesian axes East-North-Up at the landing site,
//! origin on the reference sphere under the site. Pure rotations and one translation.

use nalgebra::{Matrix3, Vector3};

/// East-North-Up axes at a site on a sphere of `radius_m`, fixed to the Moon.
///
/// `site_from_mcmf` and `mcmf_from_site` map points; the `*_dir` functions rotate
/// directions (velocities, beam axes, normals) without the translation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SiteFrame {
    /// Planetocentric latitude of the site, rad.
    pub lat_rad: f64,
    /// East longitude of the site, rad.
    pub lon_rad: f64,
    /// Reference sphere radius, m (the Moon's 1 737 400 m).
    pub radius_m: f64,
}

impl SiteFrame {
    /// A site at `lat_deg`, `lon_deg` on a sphere of `radius_m`.
    pub fn from_deg(lat_deg: f64, lon_deg: f64, radius_m: f64) -> Self {
        Self {
            lat_rad: lat_deg.to_radians(),
            lon_rad: lon_deg.to_radians(),
            radius_m,
        }
    }

    /// Rows are the site's East, North and Up unit vectors in `mcmf`: the rotation that
    /// takes an `mcmf` direction into the site frame.
    pub fn rot_site_from_mcmf(&self) -> Matrix3<f64> {
        let (sl, cl) = self.lat_rad.sin_cos();
        let (so, co) = self.lon_rad.sin_cos();
        Matrix3::new(
            -so,
            co,
            0.0, // east
            -sl * co,
            -sl * so,
            cl, // north
            cl * co,
            cl * so,
            sl, // up
        )
    }

    /// The site (on the reference sphere) in `mcmf`, m.
    pub fn origin_mcmf(&self) -> Vector3<f64> {
        let (sl, cl) = self.lat_rad.sin_cos();
        let (so, co) = self.lon_rad.sin_cos();
        self.radius_m * Vector3::new(cl * co, cl * so, sl)
    }

    /// Unit East, North and Up at the site, `mcmf` (the rows of
    /// [`Self::rot_site_from_mcmf`]).
    pub fn axes_mcmf(&self) -> [Vector3<f64>; 3] {
        let r = self.rot_site_from_mcmf();
        [0, 1, 2].map(|i| r.row(i).transpose())
    }

    /// Unit radial (up) at the site, `mcmf`.
    pub fn up_mcmf(&self) -> Vector3<f64> {
        self.axes_mcmf()[2]
    }

    /// Unit direction of travel over the site for an approach azimuth (degrees
    /// clockwise from north), `mcmf`.
    pub fn track_mcmf(&self, azimuth_deg: f64) -> Vector3<f64> {
        let [east, north, _] = self.axes_mcmf();
        let (s, c) = azimuth_deg.to_radians().sin_cos();
        north * c + east * s
    }

    /// A point in `mcmf` (m) expressed in the site frame (m).
    pub fn site_from_mcmf(&self, p_mcmf: &Vector3<f64>) -> Vector3<f64> {
        self.rot_site_from_mcmf() * (p_mcmf - self.origin_mcmf())
    }

    /// A point in the site frame (m) expressed in `mcmf` (m).
    pub fn mcmf_from_site(&self, p_site: &Vector3<f64>) -> Vector3<f64> {
        self.rot_site_from_mcmf().transpose() * p_site + self.origin_mcmf()
    }

    /// A direction in `mcmf` rotated into the site frame.
    pub fn site_dir_from_mcmf(&self, d_mcmf: &Vector3<f64>) -> Vector3<f64> {
        self.rot_site_from_mcmf() * d_mcmf
    }

    /// A direction in the site frame rotated into `mcmf`.
    pub fn mcmf_dir_from_site(&self, d_site: &Vector3<f64>) -> Vector3<f64> {
        self.rot_site_from_mcmf().transpose() * d_site
    }

    /// Latitude and east longitude (rad) of the radial direction through `p_site`.
    pub fn lat_lon_of_site(&self, p_site: &Vector3<f64>) -> (f64, f64) {
        let p = self.mcmf_from_site(p_site);
        let lat = p.z.atan2(p.x.hypot(p.y));
        let lon = p.y.atan2(p.x);
        (lat, lon)
    }

    /// The site-frame point on the reference sphere at latitude, east longitude (rad).
    pub fn site_of_lat_lon(&self, lat_rad: f64, lon_rad: f64) -> Vector3<f64> {
        let (sl, cl) = lat_rad.sin_cos();
        let (so, co) = lon_rad.sin_cos();
        let p = self.radius_m * Vector3::new(cl * co, cl * so, sl);
        self.site_from_mcmf(&p)
    }
}
