//! The state at descent start, from [`crate::config::InitialStateConfig`].
//!
//! The lander starts above the `mci` +X axis and flies horizontally along +Y (so the
//! orbit plane is X-Y and the orbit normal +Z). Its thrust axis (body +Z) points against
//! the horizontal velocity, pitched up (towards the local vertical) by `thrust_pitch_deg`;
//! body +Y is the pitch axis, along `mci` +Z.

use super::rigid_body::RigidBodyState;
use crate::config::ScenarioConfig;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};

/// Initial rigid-body state for a validated configuration.
pub fn initial_state(cfg: &ScenarioConfig) -> RigidBodyState {
    let init = &cfg.initial;
    let radius_m = cfg.moon.radius_m + cfg.lander.leg_height_m + init.altitude_m;
    let up = Vector3::x();
    let along_track = Vector3::y();
    let pos_mci_m = up * radius_m;
    let vel_mci_m_s = along_track * init.horizontal_speed_m_s + up * init.vertical_speed_m_s;

    // Retrograde horizontal: against the horizontal velocity (against +Y when at rest).
    let retro = if init.horizontal_speed_m_s < 0.0 {
        along_track
    } else {
        -along_track
    };
    let pitch_rad = init.thrust_pitch_deg.to_radians();
    let z_body = retro * pitch_rad.cos() + up * pitch_rad.sin();
    // Pitch axis normal to the plane of the thrust axis and the local vertical.
    let y_body = up.cross(&retro).normalize();
    let x_body = y_body.cross(&z_body);
    let rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x_body, y_body, z_body]));

    RigidBodyState {
        pos_mci_m,
        vel_mci_m_s,
        q_mci_from_body: UnitQuaternion::from_rotation_matrix(&rot),
        rate_body_rad_s: Vector3::zeros(),
        mass_kg: cfg.wet_mass_kg(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thrust_axis_is_retrograde_pitched_up() {
        let mut cfg = ScenarioConfig::default();
        cfg.initial.thrust_pitch_deg = 30.0;
        let s = initial_state(&cfg);
        let z = s.thrust_axis_mci();
        let up = s.pos_mci_m.normalize();
        let horiz_vel = s.vel_mci_m_s - up * s.vel_mci_m_s.dot(&up);
        // 30 deg above the horizontal, horizontal part against the velocity.
        assert!((z.dot(&up) - 0.5).abs() < 1e-12);
        assert!(z.dot(&horiz_vel) < 0.0);
        let alt = s.pos_mci_m.norm() - cfg.moon.radius_m - cfg.lander.leg_height_m;
        assert!((alt - cfg.initial.altitude_m).abs() < 1e-6);
        // A proper rotation (det +1): x = y cross z.
        let r = s.q_mci_from_body.to_rotation_matrix();
        assert!((r.matrix().determinant() - 1.0).abs() < 1e-12);
    }
}
