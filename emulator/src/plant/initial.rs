//! The state at descent start, from [`crate::config::InitialStateConfig`] and the site.
//!
//! The start lies `range_to_site_m` of surface arc before the site, back along the
//! great circle that crosses the site at `site.approach_azimuth_deg`; it flies along
//! that circle towards the site. Speeds are relative to the Moon-fixed surface; the
//! inertial velocity adds `omega x r`. The thrust axis (body +Z) points against the
//! horizontal velocity, pitched up (towards the local vertical) by `thrust_pitch_deg`;
//! body +Y is the pitch axis, along the orbit normal `up x track`.
//! At `t = 0` the inertial axes coincide with the Moon-fixed ones.

use super::frames::{quaternion_from_axes, MoonRotation, SiteFrame};
use super::rigid_body::RigidBodyState;
use crate::config::ScenarioConfig;
use nalgebra::{Unit, UnitQuaternion, Vector3};

/// Where the start is, relative to the site: unit radial `up`, unit `track` (direction
/// of travel towards the site) and the orbit normal `up x track`, all `mcmf` (= `mci`
/// at `t = 0`).
#[derive(Debug, Clone, Copy)]
pub struct StartGeometry {
    /// Radial unit vector at the start.
    pub up: Vector3<f64>,
    /// Direction of travel at the start, horizontal.
    pub track: Vector3<f64>,
    /// Orbit normal.
    pub normal: Vector3<f64>,
}

/// The nominal start point: `range_to_site_m` back along the approach circle.
pub fn start_geometry(cfg: &ScenarioConfig) -> StartGeometry {
    let site = SiteFrame::from_deg(
        cfg.site.latitude_deg,
        cfg.site.longitude_deg,
        cfg.moon.radius_m,
    );
    let track_site = site.track_mcmf(cfg.site.approach_azimuth_deg);
    let arc_rad = cfg.initial.range_to_site_m / cfg.moon.radius_m;
    let (s, c) = arc_rad.sin_cos();
    StartGeometry {
        up: site.up_mcmf() * c - track_site * s,
        track: site.up_mcmf() * s + track_site * c,
        normal: site.up_mcmf().cross(&track_site),
    }
}

/// Initial rigid-body state for a validated configuration.
pub fn initial_state(cfg: &ScenarioConfig) -> RigidBodyState {
    let init = &cfg.initial;
    let geo = start_geometry(cfg);
    let radius_m = cfg.moon.radius_m + cfg.lander.leg_height_m() + init.altitude_m;
    let (up, along_track) = (geo.up, geo.track);
    let pos_mci_m = up * radius_m;
    // Surface-relative velocity; the Moon's rotation is added at the end.
    let vel_rel_m_s = along_track * init.horizontal_speed_m_s + up * init.vertical_speed_m_s;

    // Retrograde horizontal: against the horizontal velocity (against the track when
    // at rest).
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

    let mut state = RigidBodyState {
        pos_mci_m,
        vel_mci_m_s: vel_rel_m_s,
        q_mci_from_body: quaternion_from_axes(&x_body, &y_body, &z_body),
        rate_body_rad_s: Vector3::zeros(),
        mass_kg: cfg.wet_mass_kg(),
    };
    disperse(cfg, &geo, &mut state);
    let rotation = MoonRotation {
        rate_rad_s: cfg.moon.rotation_rate_rad_s,
    };
    state.vel_mci_m_s += rotation.omega_mci().cross(&state.pos_mci_m);
    state
}

/// The dispersions of the start (all zero by default: the nominal state is left bit
/// for bit as it is). Velocities here are still surface-relative.
fn disperse(cfg: &ScenarioConfig, geo: &StartGeometry, state: &mut RigidBodyState) {
    let init = &cfg.initial;
    if init.crossrange_speed_m_s != 0.0 {
        state.vel_mci_m_s += geo.normal * init.crossrange_speed_m_s;
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
        // track (up towards the orbit normal, about -track), then along it (up
        // towards the track, about the orbit normal).
        let radius_m = cfg.moon.radius_m;
        let across = UnitQuaternion::from_axis_angle(
            &Unit::new_normalize(geo.track),
            -init.crossrange_m / radius_m,
        );
        let along = UnitQuaternion::from_axis_angle(
            &Unit::new_normalize(geo.normal),
            init.downrange_m / radius_m,
        );
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
        let alt = s.pos_mci_m.norm() - cfg.moon.radius_m - cfg.lander.leg_height_m();
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
        let geo = start_geometry(&cfg);
        let rot = MoonRotation {
            rate_rad_s: cfg.moon.rotation_rate_rad_s,
        };
        let rel = |st: &RigidBodyState| rot.surface_relative_mci(&st.pos_mci_m, &st.vel_mci_m_s);
        // Same altitude and surface-relative speed; moved by the arcs asked for.
        assert!((s.pos_mci_m.norm() - nominal.pos_mci_m.norm()).abs() < 1e-6);
        assert!((rel(&s).norm() - rel(&nominal).norm()).abs() < 1e-9);
        let u = s.pos_mci_m.normalize();
        assert!((r * u.dot(&geo.track).atan2(u.dot(&geo.up)) - 1000.0).abs() < 0.01);
        assert!((r * u.dot(&geo.normal).asin() + 500.0).abs() < 0.01);
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
    fn the_start_is_range_to_site_back_along_the_approach() {
        let mut cfg = ScenarioConfig::default();
        cfg.initial.range_to_site_m = 500_000.0;
        let s = initial_state(&cfg);
        let site = SiteFrame::from_deg(cfg.site.latitude_deg, cfg.site.longitude_deg, 1.0);
        let u = s.pos_mci_m.normalize();
        // The arc to the site is the range; the velocity relative to the surface points
        // at it along the great circle of the approach azimuth (southbound: latitude
        // of the start is higher by the arc).
        assert!((u.angle(&site.up_mcmf()) * cfg.moon.radius_m - 500_000.0).abs() < 1e-3);
        let start_lat = u.z.asin().to_degrees();
        let arc_deg = (500_000.0 / cfg.moon.radius_m).to_degrees();
        assert!((start_lat - (cfg.site.latitude_deg + arc_deg)).abs() < 1e-9);
        let rot = MoonRotation {
            rate_rad_s: cfg.moon.rotation_rate_rad_s,
        };
        let v = rot.surface_relative_mci(&s.pos_mci_m, &s.vel_mci_m_s);
        assert!((v.norm() - cfg.initial.horizontal_speed_m_s).abs() < 1e-9);
        let to_site = site.up_mcmf() - u * u.dot(&site.up_mcmf());
        assert!(v.normalize().angle(&to_site.normalize()) < 1e-9);
        // Inertially it also carries the surface's own motion.
        let dv = s.vel_mci_m_s - v;
        let expect = cfg.moon.rotation_rate_rad_s * s.pos_mci_m.xy().norm();
        assert!((dv.norm() - expect).abs() < 1e-9);
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
