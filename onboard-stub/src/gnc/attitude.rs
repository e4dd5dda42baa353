//! Attitude control: point body +Z (the thrust axis) along the thrust direction guidance
//! asks for; yaw is left free and only damped.
//!
//! The pointing error is the shortest rotation taking body +Z onto the demanded
//! direction, as a body rotation vector `e` (no z component). A rate-limited PD law:
//! `w_ref = (wn / 2 zeta) e` (norm limited to `max_rate`), then
//! `tau = I 2 zeta wn (w_ref - w) + w x I w`: a second-order loop of natural frequency
//! `wn` and damping `zeta` for small errors, a constant-rate slew for large ones.
//! Plus an integral of the error while it is small and steady (below `integral_band`,
//! turning slower than 0.01 rad/s: a slew does not wind it up):
//! `tau_i += I wn^2 e dt / T_i`, clamped per axis to the thrusters' torque limit. It learns a steady disturbance torque (a weak engine, a
//! centre-of-mass offset) that a PD law only balances with a steady pointing error: a
//! few degrees, as much as the final descent's whole tilt allowance.

use super::navigation::NavSolution;
use super::GncConfig;
use nalgebra::Vector3;

/// The integral runs only while the body turns slower than this (a steady error, not a
/// slew passing through the band), rad/s.
const INTEGRAL_MAX_RATE_RAD_S: f64 = 0.01;

/// The attitude controller: gains, and the integral of the small pointing errors.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AttitudeController {
    natural_freq_rad_s: f64,
    damping: f64,
    max_rate_rad_s: f64,
    integral_time_s: f64,
    integral_band_rad: f64,
    integral_limit_nm: Vector3<f64>,
    /// The learned disturbance-cancelling torque, body axes, N m (z stays zero).
    integral_body_nm: Vector3<f64>,
}

impl AttitudeController {
    /// Gains from the configuration.
    pub fn new(cfg: &GncConfig) -> Self {
        Self {
            natural_freq_rad_s: cfg.attitude_natural_freq_rad_s,
            damping: cfg.attitude_damping,
            max_rate_rad_s: cfg.attitude_max_rate_rad_s,
            integral_time_s: cfg.attitude_integral_time_s,
            integral_band_rad: cfg.attitude_integral_band_deg.to_radians(),
            integral_limit_nm: Vector3::from(cfg.rcs_max_torque_nm),
            integral_body_nm: Vector3::zeros(),
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

    /// Torque demand, body axes, N m, for principal inertia `inertia_kg_m2`; `dt_s`
    /// since the last call (integrates the error).
    pub fn torque_body_nm(
        &mut self,
        nav: &NavSolution,
        desired_dir_mci: &Vector3<f64>,
        inertia_kg_m2: &Vector3<f64>,
        dt_s: f64,
    ) -> Vector3<f64> {
        let err = Self::pointing_error_body(nav, desired_dir_mci);
        self.torque_for_error_body_nm(nav, &err, inertia_kg_m2, dt_s)
    }

    /// [`AttitudeController::torque_body_nm`] for a pointing error already worked out
    /// ([`AttitudeController::pointing_error_body`]): the GNC reports the error too, and
    /// needs it once a cycle.
    pub fn torque_for_error_body_nm(
        &mut self,
        nav: &NavSolution,
        err: &Vector3<f64>,
        inertia_kg_m2: &Vector3<f64>,
        dt_s: f64,
    ) -> Vector3<f64> {
        let err = *err;
        let settled = err.norm() < self.integral_band_rad
            && nav.rate_body_rad_s.xy().norm() < INTEGRAL_MAX_RATE_RAD_S;
        if self.integral_time_s > 0.0 && settled {
            let wn2 = self.natural_freq_rad_s * self.natural_freq_rad_s;
            self.integral_body_nm +=
                inertia_kg_m2.component_mul(&err) * (wn2 * dt_s / self.integral_time_s);
            self.integral_body_nm = self
                .integral_body_nm
                .zip_map(&self.integral_limit_nm, |t, max| t.clamp(-max, max));
            self.integral_body_nm.z = 0.0;
        }
        let mut rate_ref = err * (self.natural_freq_rad_s / (2.0 * self.damping));
        let n = rate_ref.norm();
        if n > self.max_rate_rad_s {
            rate_ref *= self.max_rate_rad_s / n;
        }
        let w = nav.rate_body_rad_s;
        let gain = 2.0 * self.damping * self.natural_freq_rad_s;
        let h = inertia_kg_m2.component_mul(&w);
        inertia_kg_m2.component_mul(&((rate_ref - w) * gain)) + w.cross(&h) + self.integral_body_nm
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
        let mut ctl = AttitudeController::new(&cfg);
        let inertia = Vector3::new(1000.0, 1000.0, 900.0);
        let mut q = UnitQuaternion::identity();
        let mut w = Vector3::zeros();
        let target = Vector3::new(10f64.to_radians().sin(), 0.0, 10f64.to_radians().cos());
        let dt = 0.01;
        let mut max_overshoot: f64 = 0.0;
        for k in 0..6000 {
            let nav = nav_with(q, w);
            let tau = ctl.torque_body_nm(&nav, &target, &inertia, dt);
            w += tau.component_div(&inertia) * dt;
            q *= UnitQuaternion::from_scaled_axis(w * dt);
            let e = AttitudeController::pointing_error_body(&nav_with(q, w), &target);
            if k > 300 {
                max_overshoot = max_overshoot.max(-e.y);
            }
        }
        let e = AttitudeController::pointing_error_body(&nav_with(q, w), &target);
        assert!(e.norm() < 1e-4, "residual {}", e.norm());
        assert!(max_overshoot < 0.02 * 10f64.to_radians(), "{max_overshoot}");
        assert!(w.norm() < 1e-4);
    }

    /// A steady disturbance torque: the PD law alone holds it with a steady error of
    /// `tau / (I wn^2)`; with the integral the error goes to zero.
    #[test]
    fn a_steady_disturbance_torque_leaves_no_steady_pointing_error() {
        let cfg = GncConfig::default();
        let inertia = Vector3::new(1000.0, 1000.0, 900.0);
        let disturbance = Vector3::new(0.0, 40.0, 0.0);
        let target = Vector3::z();
        let settle = |mut ctl: AttitudeController| {
            let (mut q, mut w) = (UnitQuaternion::identity(), Vector3::zeros());
            let dt = 0.01;
            for _ in 0..12_000 {
                let tau = ctl.torque_body_nm(&nav_with(q, w), &target, &inertia, dt);
                w += (tau + disturbance).component_div(&inertia) * dt;
                q *= UnitQuaternion::from_scaled_axis(w * dt);
            }
            AttitudeController::pointing_error_body(&nav_with(q, w), &target).norm()
        };
        let pd_only = settle(AttitudeController::new(&GncConfig {
            attitude_integral_time_s: 0.0,
            ..cfg.clone()
        }));
        // PD: e = 40 / (1000 * 1) = 0.04 rad.
        assert!((pd_only - 0.04).abs() < 1e-3, "{pd_only}");
        let with_integral = settle(AttitudeController::new(&cfg));
        assert!(with_integral < 1e-4, "{with_integral}");
    }
}
