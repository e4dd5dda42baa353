//! Attitude control: point body +Z (the thrust axis) along the thrust direction guidance
//! asks for; yaw is left free and only damped.
//!
//! The pointing error is the shortest rotation taking body +Z onto the demanded
//! direction, as a body rotation vector `e` (no z component). A rate-limited PD law:
//! `w_ref = (wn / 2 zeta) e` (norm limited to `max_rate`), then
//! `tau = I 2 zeta wn (w_ref - w) + w x I w`: a second-order loop of natural frequency
//! `wn` and damping `zeta` for small errors, a constant-rate slew for large ones.

use super::navigation::NavSolution;
use super::GncConfig;
use nalgebra::Vector3;

/// The attitude controller (stateless apart from its gains).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeController {
    natural_freq_rad_s: f64,
    damping: f64,
    max_rate_rad_s: f64,
}

impl AttitudeController {
    /// Gains from the configuration.
    pub fn new(cfg: &GncConfig) -> Self {
        Self {
            natural_freq_rad_s: cfg.attitude_natural_freq_rad_s,
            damping: cfg.attitude_damping,
            max_rate_rad_s: cfg.attitude_max_rate_rad_s,
        }
    }

    /// Pointing error of body +Z from `desired_dir_mci` as a body rotation vector, rad.
    pub fn pointing_error_body(nav: &NavSolution, desired_dir_mci: &Vector3<f64>) -> Vector3<f64> {
        let want_body = nav
            .q_mci_from_body
            .inverse_transform_vector(desired_dir_mci);
        let norm = want_body.norm();
        if norm < 1e-12 {
            return Vector3::zeros();
        }
        let want = want_body / norm;
        let axis = Vector3::z().cross(&want);
        let sin = axis.norm();
        let cos = want.z;
        if sin < 1e-12 {
            // Aligned, or exactly opposite: turn about body x.
            return if cos > 0.0 {
                Vector3::zeros()
            } else {
                Vector3::new(std::f64::consts::PI, 0.0, 0.0)
            };
        }
        axis * (sin.atan2(cos) / sin)
    }

    /// Torque demand, body axes, N m, for principal inertia `inertia_kg_m2`.
    pub fn torque_body_nm(
        &self,
        nav: &NavSolution,
        desired_dir_mci: &Vector3<f64>,
        inertia_kg_m2: &Vector3<f64>,
    ) -> Vector3<f64> {
        let err = Self::pointing_error_body(nav, desired_dir_mci);
        let mut rate_ref = err * (self.natural_freq_rad_s / (2.0 * self.damping));
        let n = rate_ref.norm();
        if n > self.max_rate_rad_s {
            rate_ref *= self.max_rate_rad_s / n;
        }
        let w = nav.rate_body_rad_s;
        let gain = 2.0 * self.damping * self.natural_freq_rad_s;
        let h = inertia_kg_m2.component_mul(&w);
        inertia_kg_m2.component_mul(&((rate_ref - w) * gain)) + w.cross(&h)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn nav_with(q: UnitQuaternion<f64>, w: Vector3<f64>) -> NavSolution {
        NavSolution {
            t_s: 0.0,
            pos_mci_m: Vector3::x() * 1.8e6,
            vel_mci_m_s: Vector3::zeros(),
            q_mci_from_body: q,
            rate_body_rad_s: w,
            specific_force_body_m_s2: Vector3::zeros(),
            altitude_m: 1.0,
            mass_kg: 1000.0,
            up_mci: Vector3::x(),
            gravity_m_s2: 1.6,
            omega_moon_mci: Vector3::zeros(),
        }
    }

    #[test]
    fn error_is_the_rotation_vector_towards_the_target() {
        let nav = nav_with(UnitQuaternion::identity(), Vector3::zeros());
        // Target tilted 0.2 rad from +Z towards +X: rotate about +Y by +0.2.
        let dir = Vector3::new(0.2f64.sin(), 0.0, 0.2f64.cos());
        let e = AttitudeController::pointing_error_body(&nav, &dir);
        assert!((e - Vector3::new(0.0, 0.2, 0.0)).norm() < 1e-12, "{e}");
    }

    /// Closed loop on a rigid body: a 10 deg step settles with little overshoot.
    #[test]
    fn small_step_settles_like_a_second_order_loop() {
        let cfg = GncConfig::default();
        let ctl = AttitudeController::new(&cfg);
        let inertia = Vector3::new(1000.0, 1000.0, 900.0);
        let mut q = UnitQuaternion::identity();
        let mut w = Vector3::zeros();
        let target = Vector3::new(10f64.to_radians().sin(), 0.0, 10f64.to_radians().cos());
        let dt = 0.01;
        let mut max_overshoot: f64 = 0.0;
        for k in 0..2000 {
            let nav = nav_with(q, w);
            let tau = ctl.torque_body_nm(&nav, &target, &inertia);
            w += tau.component_div(&inertia) * dt;
            q *= UnitQuaternion::from_scaled_axis(w * dt);
            let e = AttitudeController::pointing_error_body(&nav_with(q, w), &target);
            if k > 300 {
                max_overshoot = max_overshoot.max(-e.y);
            }
        }
        let e = AttitudeController::pointing_error_body(&nav_with(q, w), &target);
        assert!(e.norm() < 1e-4, "residual {e}");
        assert!(max_overshoot < 0.02 * 10f64.to_radians(), "{max_overshoot}");
        assert!(w.norm() < 1e-4);
    }
}
