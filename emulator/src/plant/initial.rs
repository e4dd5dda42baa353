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

    let mut state = RigidBodyState {
        pos_mci_m,
        vel_mci_m_s,
        q_mci_from_body: UnitQuaternion::from_rotation_matrix(&rot),
        rate_body_rad_s: Vector3::zeros(),
        mass_kg: cfg.wet_mass_kg(),
    };
    disperse(cfg, &mut state);
    state
}

/// The dispersions of the start (all zero by default: the nominal state is left bit
/// for bit as it is, so default runs keep their digests).
fn disperse(cfg: &ScenarioConfig, state: &mut RigidBodyState) {
    let init = &cfg.initial;
    if init.crossrange_speed_m_s != 0.0 {
        state.vel_mci_m_s += Vector3::z() * init.crossrange_speed_m_s;
    }
    if init.attitude_error_deg != [0.0; 3] {
        let [x, y, z] = init.attitude_error_deg.map(f64::to_radians);
        let error = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x)
            * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y)
            * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z);
        state.q_mci_from_body *= error;
    }
    if init.body_rate_rad_s != [0.0; 3] {
        state.rate_body_rad_s = Vector3::from(init.body_rate_rad_s);
    }
    if init.downrange_m != 0.0 || init.crossrange_m != 0.0 {
        // Moving the start over a sphere is a rotation of the whole state: across the
        // track (X towards +Z, about -Y), then along it (X towards +Y, about +Z).
        let radius_m = cfg.moon.radius_m;
        let across =
            UnitQuaternion::from_axis_angle(&Vector3::y_axis(), -init.crossrange_m / radius_m);
        let along =
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), init.downrange_m / radius_m);
        let shift = along * across;
        state.pos_mci_m = shift * state.pos_mci_m;
        state.vel_mci_m_s = shift * state.vel_mci_m_s;
        state.q_mci_from_body = shift * state.q_mci_from_body;
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

    #[test]
    fn downrange_and_crossrange_move_the_start_over_the_surface() {
        let nominal = initial_state(&ScenarioConfig::default());
        let mut cfg = ScenarioConfig::default();
        cfg.initial.downrange_m = 1000.0;
        cfg.initial.crossrange_m = -500.0;
        let s = initial_state(&cfg);
        let r = cfg.moon.radius_m;
        // Same altitude and speed; moved by the arcs asked for.
        assert!((s.pos_mci_m.norm() - nominal.pos_mci_m.norm()).abs() < 1e-6);
        assert!((s.vel_mci_m_s.norm() - nominal.vel_mci_m_s.norm()).abs() < 1e-9);
        let u = s.pos_mci_m.normalize();
        assert!((r * u.y.atan2(u.x) - 1000.0).abs() < 0.01);
        assert!((r * u.z.asin() + 500.0).abs() < 0.01);
        // Still flying along the track, the thrust axis moved with the state.
        let z_nominal = nominal.thrust_axis_mci();
        assert!(
            (s.thrust_axis_mci().dot(&s.pos_mci_m.normalize())
                - z_nominal.dot(&nominal.pos_mci_m.normalize()))
            .abs()
                < 1e-12
        );
    }

    #[test]
    fn attitude_error_and_rates_are_applied() {
        let nominal = initial_state(&ScenarioConfig::default());
        let mut cfg = ScenarioConfig::default();
        cfg.initial.attitude_error_deg = [0.0, 2.0, 0.0];
        cfg.initial.body_rate_rad_s = [0.01, 0.0, -0.02];
        let s = initial_state(&cfg);
        let angle = s.thrust_axis_mci().angle(&nominal.thrust_axis_mci());
        assert!((angle.to_degrees() - 2.0).abs() < 1e-9);
        assert_eq!(s.rate_body_rad_s, Vector3::new(0.01, 0.0, -0.02));
    }

    #[test]
    fn zero_dispersions_leave_the_state_bit_for_bit() {
        let a = initial_state(&ScenarioConfig::default());
        let mut cfg = ScenarioConfig::default();
        cfg.initial.downrange_m = 0.0;
        let b = initial_state(&cfg);
        assert_eq!(a.pos_mci_m, b.pos_mci_m);
        assert_eq!(a.q_mci_from_body, b.q_mci_from_body);
    }
}
