//! The lander as a rigid body of varying mass in the Moon's central gravity field:
//! state, mass properties and the equations of motion (no integrator here).
//!
//! ```text
//! dr/dt = v
//! dv/dt = -mu r / |r|^3 + R(q) F_body / m(t)
//! dq/dt = 1/2 q (x) [0, w]
//! dw/dt = I(m)^-1 (tau_body - w x I(m) w)
//! ```
//! `m(t)` falls linearly over a step by the propellant ejected in it; `I(m)` is
//! interpolated between the wet and dry inertia by the propellant fraction. The
//! `dI/dt w` term is left out: the exhaust carries its own angular momentum away (the
//! usual jet-damping simplification for a slow burn on a compact vehicle).

use crate::config::LanderConfig;
use nalgebra::{Quaternion, SVector, UnitQuaternion, Vector3};

/// Length of the integrated state vector: position 3, velocity 3, quaternion 4, rate 3.
pub const STATE_LEN: usize = 13;
/// The integrated state as one vector, for the integrator.
pub type StateVector = SVector<f64, STATE_LEN>;

/// Rigid-body state of the lander.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RigidBodyState {
    /// Centre-of-mass position, Moon-centred inertial, metres.
    pub pos_mci_m: Vector3<f64>,
    /// Centre-of-mass velocity, Moon-centred inertial, m/s.
    pub vel_mci_m_s: Vector3<f64>,
    /// Attitude: rotates body vectors into `mci`.
    pub q_mci_from_body: UnitQuaternion<f64>,
    /// Angular rate relative to `mci`, body axes, rad/s.
    pub rate_body_rad_s: Vector3<f64>,
    /// Vehicle mass, kilograms.
    pub mass_kg: f64,
}

impl RigidBodyState {
    /// Packs position, velocity, quaternion `[w, x, y, z]` and rate.
    pub fn to_vector(&self) -> StateVector {
        let q = self.q_mci_from_body.quaternion();
        let mut x = StateVector::zeros();
        x.fixed_rows_mut::<3>(0).copy_from(&self.pos_mci_m);
        x.fixed_rows_mut::<3>(3).copy_from(&self.vel_mci_m_s);
        x[6] = q.w;
        x[7] = q.i;
        x[8] = q.j;
        x[9] = q.k;
        x.fixed_rows_mut::<3>(10).copy_from(&self.rate_body_rad_s);
        x
    }

    /// Unpacks a state vector, renormalising the quaternion.
    pub fn from_vector(x: &StateVector, mass_kg: f64) -> Self {
        Self {
            pos_mci_m: x.fixed_rows::<3>(0).into_owned(),
            vel_mci_m_s: x.fixed_rows::<3>(3).into_owned(),
            q_mci_from_body: UnitQuaternion::from_quaternion(Quaternion::new(
                x[6], x[7], x[8], x[9],
            )),
            rate_body_rad_s: x.fixed_rows::<3>(10).into_owned(),
            mass_kg,
        }
    }

    /// Body +Z (the thrust axis) in `mci`.
    pub fn thrust_axis_mci(&self) -> Vector3<f64> {
        self.q_mci_from_body * Vector3::z()
    }
}

/// Mass properties: the inertia follows the propellant fraction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassModel {
    /// Mass with empty main tanks, kilograms.
    pub dry_mass_kg: f64,
    /// Propellant at descent start, kilograms.
    pub propellant_kg: f64,
    /// Principal inertia with full tanks, kg m^2.
    pub inertia_wet_kg_m2: Vector3<f64>,
    /// Principal inertia with empty tanks, kg m^2.
    pub inertia_dry_kg_m2: Vector3<f64>,
}

impl MassModel {
    /// From the lander configuration and the loaded propellant.
    pub fn new(lander: &LanderConfig, propellant_kg: f64) -> Self {
        Self {
            dry_mass_kg: lander.dry_mass_kg,
            propellant_kg,
            inertia_wet_kg_m2: Vector3::from(lander.inertia_wet_kg_m2),
            inertia_dry_kg_m2: Vector3::from(lander.inertia_dry_kg_m2),
        }
    }

    /// Principal inertia at a vehicle mass, linear in the propellant fraction (clamped
    /// to [0, 1] so an empty or overfull tank never extrapolates).
    pub fn inertia_kg_m2(&self, mass_kg: f64) -> Vector3<f64> {
        let frac = if self.propellant_kg > 0.0 {
            ((mass_kg - self.dry_mass_kg) / self.propellant_kg).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.inertia_dry_kg_m2 + (self.inertia_wet_kg_m2 - self.inertia_dry_kg_m2) * frac
    }
}

/// Loads held over one step: body force and torque, and the mass-flow schedule.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeldLoads {
    /// Non-gravitational force on the centre of mass, body axes, newtons.
    pub force_body_n: Vector3<f64>,
    /// Torque about the centre of mass, body axes, N m.
    pub torque_body_nm: Vector3<f64>,
    /// Mass at the start of the step, kilograms.
    pub mass_start_kg: f64,
    /// Mass flow out of the vehicle over the step, kg/s (>= 0).
    pub mass_flow_kg_s: f64,
}

/// The equations of motion.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dynamics {
    /// Moon's gravitational parameter, m^3/s^2.
    pub mu_m3_s2: f64,
    /// Mass properties.
    pub mass: MassModel,
}

impl Dynamics {
    /// Time derivative of the state `t_s` seconds into a step with `loads` held.
    pub fn derivative(&self, loads: &HeldLoads, t_s: f64, x: &StateVector) -> StateVector {
        let r = x.fixed_rows::<3>(0).into_owned();
        let v = x.fixed_rows::<3>(3).into_owned();
        let q = Quaternion::new(x[6], x[7], x[8], x[9]);
        let w = x.fixed_rows::<3>(10).into_owned();
        let mass_kg = loads.mass_start_kg - loads.mass_flow_kg_s * t_s;

        let r_norm = r.norm();
        let gravity = -r * (self.mu_m3_s2 / (r_norm * r_norm * r_norm));
        // The stage quaternion is not exactly unit; rotate with the normalised one so
        // RK4's intermediate norm drift does not scale the thrust.
        let q_unit = UnitQuaternion::from_quaternion(q);
        let accel = gravity + q_unit * loads.force_body_n / mass_kg;

        let q_dot = q * Quaternion::new(0.0, w.x, w.y, w.z) * 0.5;

        let inertia = self.mass.inertia_kg_m2(mass_kg);
        let h = inertia.component_mul(&w);
        let w_dot = (loads.torque_body_nm - w.cross(&h)).component_div(&inertia);

        let mut dx = StateVector::zeros();
        dx.fixed_rows_mut::<3>(0).copy_from(&v);
        dx.fixed_rows_mut::<3>(3).copy_from(&accel);
        dx[6] = q_dot.w;
        dx[7] = q_dot.i;
        dx[8] = q_dot.j;
        dx[9] = q_dot.k;
        dx.fixed_rows_mut::<3>(10).copy_from(&w_dot);
        dx
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inertia_interpolates_and_clamps() {
        let m = MassModel::new(&LanderConfig::default(), 1000.0);
        assert_eq!(m.inertia_kg_m2(1750.0), m.inertia_wet_kg_m2);
        assert_eq!(m.inertia_kg_m2(750.0), m.inertia_dry_kg_m2);
        assert_eq!(m.inertia_kg_m2(9999.0), m.inertia_wet_kg_m2);
        assert_eq!(m.inertia_kg_m2(0.0), m.inertia_dry_kg_m2);
        let half = m.inertia_kg_m2(1250.0);
        assert!((half.x - 950.0).abs() < 1e-9 && (half.z - 850.0).abs() < 1e-9);
    }

    #[test]
    fn vector_round_trip() {
        let s = RigidBodyState {
            pos_mci_m: Vector3::new(1.0, 2.0, 3.0),
            vel_mci_m_s: Vector3::new(4.0, 5.0, 6.0),
            q_mci_from_body: UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3),
            rate_body_rad_s: Vector3::new(7.0, 8.0, 9.0),
            mass_kg: 10.0,
        };
        let back = RigidBodyState::from_vector(&s.to_vector(), 10.0);
        assert!((back.q_mci_from_body.angle_to(&s.q_mci_from_body)) < 1e-12);
        assert_eq!(back.pos_mci_m, s.pos_mci_m);
        assert_eq!(back.rate_body_rad_s, s.rate_body_rad_s);
    }
}
