//! The frames of the rotating Moon.
//!
//! * `mci`, Moon-centred inertial: the frame the equations of motion are integrated in.
//!   Its axes coincide with the Moon-fixed axes at `t = 0`.
//! * `mcmf`, Moon-centred Moon-fixed: `+Z` the north pole, `+X` through latitude 0,
//!   longitude 0. It turns about `+Z` at `omega` (the sidereal rate), so
//!   `p_mcmf = Rz(-omega t) p_mci`, and a point fixed on the surface moves at
//!   `omega x r` in `mci`.
//! * `site` (East-North-Up at the landing site, Moon-fixed): origin on the reference
//!   sphere below the site, `+Z` up (radial), `+Y` north, `+X` east. Telemetry stays in
//!   `mci` (what an inertial navigation system integrates); the log and the report add
//!   `mcmf` and `site` values.

use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// The Moon's rotation: turns `mci` into `mcmf` at a given time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoonRotation {
    /// Rotation rate about `+Z`, rad/s.
    pub rate_rad_s: f64,
}

impl MoonRotation {
    /// The angular velocity vector, `mci` (equal in `mcmf`), rad/s.
    pub fn omega_mci(&self) -> Vector3<f64> {
        Vector3::new(0.0, 0.0, self.rate_rad_s)
    }

    /// The rotation taking `mci` vectors to `mcmf` at `t_s`.
    pub fn mcmf_from_mci(&self, t_s: f64) -> Rotation3<f64> {
        Rotation3::from_axis_angle(&Vector3::z_axis(), -self.rate_rad_s * t_s)
    }

    /// Velocity of `pos_mci_m` relative to the Moon-fixed frame, in `mci` axes:
    /// `v - omega x r` (the surface-relative velocity the touchdown limits are about).
    pub fn surface_relative_mci(
        &self,
        pos_mci_m: &Vector3<f64>,
        vel_mci_m_s: &Vector3<f64>,
    ) -> Vector3<f64> {
        vel_mci_m_s - self.omega_mci().cross(pos_mci_m)
    }
}

/// The site frame (East-North-Up at the landing site, Moon-fixed) is the terrain's.
pub use crate::world::terrain::SiteFrame;

/// The orientation whose axes are the given orthonormal columns (a right-handed set).
pub fn quaternion_from_axes(
    x: &Vector3<f64>,
    y: &Vector3<f64>,
    z: &Vector3<f64>,
) -> UnitQuaternion<f64> {
    UnitQuaternion::from_rotation_matrix(&Rotation3::from_matrix_unchecked(Matrix3::from_columns(
        &[*x, *y, *z],
    )))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_speed_is_omega_r_cos_latitude() {
        let rot = MoonRotation {
            rate_rad_s: 2.6617e-6,
        };
        let r = 1_737_400.0;
        for lat in [0.0_f64, 30.0, -69.373, 80.0] {
            let site = SiteFrame::from_deg(lat, 32.319, r);
            let p = site.up_mcmf() * r;
            // A point fixed on the surface, seen from mci: velocity omega x r.
            let v_fixed = rot.omega_mci().cross(&p);
            let expect = 2.6617e-6 * r * lat.to_radians().cos();
            assert!((v_fixed.norm() - expect).abs() < 1e-12, "lat {lat}");
            // It points east.
            assert!((v_fixed.normalize().dot(&site.axes_mcmf()[0]) - 1.0).abs() < 1e-12);
            // And it is at rest relative to the surface.
            assert!(rot.surface_relative_mci(&p, &v_fixed).norm() < 1e-12);
        }
        // 4.62 m/s at the equator, 1.63 m/s at the Chandrayaan-3 site (reference table).
        let eq = 2.6617e-6 * r;
        assert!((eq - 4.62).abs() < 0.01);
        assert!((eq * 69.373_f64.to_radians().cos() - 1.63).abs() < 0.01);
    }

    #[test]
    fn mcmf_turns_the_other_way_from_the_moon() {
        let rot = MoonRotation { rate_rad_s: 1e-3 };
        // After a quarter turn the mci +Y axis is where mcmf's +X was... seen from the
        // Moon a fixed inertial point drifts west.
        let t = std::f64::consts::FRAC_PI_2 / 1e-3;
        let p = rot.mcmf_from_mci(t) * Vector3::y();
        assert!((p - Vector3::x()).norm() < 1e-12);
    }

    #[test]
    fn approach_azimuth_is_clockwise_from_north() {
        let site = SiteFrame::from_deg(-69.373, 32.319, 1_737_400.0);
        let [east, north, up] = site.axes_mcmf();
        assert!((east.cross(&north) - up).norm() < 1e-15);
        // Azimuth 90 is east, 180 south.
        assert!((site.track_mcmf(90.0) - east).norm() < 1e-15);
        assert!((site.track_mcmf(180.0) + north).norm() < 1e-15);
    }
}
