//! Touchdown on four legs over the turning Moon: drops with the engines off, judged
//! against closed forms and the configured limits.

use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::frames::MoonRotation;
use oils_emulator::plant::{ActuatorCommand, CrashReason, Plant, PlantStatus, TouchdownState};
use oils_emulator::propulsion::ideal::IdealPropulsion;

/// An upright vehicle at rest relative to the surface, `altitude_m` above it, falling
/// at `vertical_speed_m_s` (negative down), over the default site on the turning Moon.
fn drop(altitude_m: f64, vertical_speed_m_s: f64) -> ScenarioConfig {
    let mut cfg = ScenarioConfig::default();
    cfg.initial.range_to_site_m = 0.0;
    cfg.initial.altitude_m = altitude_m;
    cfg.initial.horizontal_speed_m_s = 0.0;
    cfg.initial.vertical_speed_m_s = vertical_speed_m_s;
    cfg.initial.thrust_pitch_deg = 90.0;
    cfg
}

fn fly_to_the_end(cfg: &ScenarioConfig) -> (Plant, TouchdownState, u64) {
    let mut p = Plant::new(cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    for step in 1..200_000 {
        if let PlantStatus::Touchdown(td) = p.step(&ActuatorCommand::default(), 10_000_000) {
            return (p, td, step);
        }
    }
    panic!("the landing never ended");
}

/// Moon-fixed position of the vehicle's centre of mass now.
fn mcmf_position(p: &Plant, cfg: &ScenarioConfig) -> nalgebra::Vector3<f64> {
    let rot = MoonRotation {
        rate_rad_s: cfg.moon.rotation_rate_rad_s,
    };
    rot.mcmf_from_mci(p.time_ns() as f64 * 1e-9) * p.state().pos_mci_m
}

#[test]
fn a_lander_at_rest_on_the_surface_stays_at_rest_in_the_moon_fixed_frame() {
    let cfg = drop(0.001, 0.0);
    let start = {
        let p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
        mcmf_position(&p, &cfg)
    };
    // Inertially it moves at omega R cos(lat) = 1.63 m/s with the ground.
    let rot = MoonRotation {
        rate_rad_s: cfg.moon.rotation_rate_rad_s,
    };
    let p0 = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let inertial_speed = p0.state().vel_mci_m_s.norm();
    let expect = cfg.moon.rotation_rate_rad_s
        * p0.state().pos_mci_m.norm()
        * cfg.site.latitude_deg.to_radians().cos();
    assert!(
        (inertial_speed - expect).abs() < 1e-9,
        "{inertial_speed} vs {expect}"
    );

    let (p, td, _) = fly_to_the_end(&cfg);
    assert!(td.landed, "{td:?}");
    assert_eq!(td.reason, None);
    // It came to rest within the hold time of touching: settled, not slid.
    assert!(td.end_t_s - td.t_s < 5.0, "{td:?}");
    let end = mcmf_position(&p, &cfg);
    let moved = end - start;
    let up = start.normalize();
    let horizontal_m = (moved - up * moved.dot(&up)).norm();
    // Sinks by the static deflection (weight / 4 legs / stiffness: ~1.7 mm) plus the
    // 1 mm drop, and does not move along the ground.
    let weight_n = p.state().mass_kg * cfg.moon.mu_m3_s2 / start.norm_squared();
    let deflection_m = weight_n / 4.0 / cfg.lander.leg_stiffness_n_m;
    assert!(
        horizontal_m < 1e-4,
        "moved {horizontal_m} m along the ground"
    );
    assert!(
        (moved.dot(&up) + 0.001 + deflection_m).abs() < 2e-4,
        "sank {} m, expected {}",
        -moved.dot(&up),
        0.001 + deflection_m
    );
    let v_rel = rot.surface_relative_mci(&p.state().pos_mci_m, &p.state().vel_mci_m_s);
    assert!(v_rel.norm() < cfg.touchdown.rest_speed_m_s, "{v_rel}");
}

#[test]
fn a_drop_on_flat_ground_comes_to_rest_upright() {
    let cfg = drop(1.0, 0.0);
    let (_, td, _) = fly_to_the_end(&cfg);
    // Free fall from 1 m at lunar gravity: sqrt(2 g h) = 1.80 m/s.
    let g = cfg.moon.mu_m3_s2 / (cfg.moon.radius_m * cfg.moon.radius_m);
    assert!(
        (td.vertical_speed_mps - (2.0 * g * 1.0).sqrt()).abs() < 1e-3,
        "{td:?}"
    );
    // At rest over the turning ground at the start, it falls on a straight inertial
    // line while the ground turns under it: the Coriolis drift, about omega v t =
    // 2.7e-6 x 1.8 x 1.1 = 5e-6 m/s.
    assert!(td.horizontal_speed_mps < 2e-5, "{td:?}");
    assert!(
        td.landed && td.tilt_deg < 0.01 && td.slope_deg < 1e-5,
        "{td:?}"
    );
    assert!(td.end_t_s > td.t_s);
}

#[test]
fn a_drop_at_3_m_s_breaks_the_speed_limit() {
    let cfg = drop(0.01, -3.0);
    let (_, td, _) = fly_to_the_end(&cfg);
    assert!((td.vertical_speed_mps - 3.0).abs() < 0.01, "{td:?}");
    assert!(!td.landed);
    assert_eq!(td.reason, Some(CrashReason::VerticalSpeed));
}

#[test]
fn sliding_along_the_ground_breaks_the_horizontal_limit() {
    let mut cfg = drop(0.5, 0.0);
    cfg.initial.horizontal_speed_m_s = 0.8;
    let (_, td, _) = fly_to_the_end(&cfg);
    assert!((td.horizontal_speed_mps - 0.8).abs() < 0.01, "{td:?}");
    assert_eq!(td.reason, Some(CrashReason::HorizontalSpeed));
}

#[test]
fn a_lander_tilted_past_its_footprint_falls_over() {
    // 50 deg: beyond the static stability angle atan(1.273 / 1.2) = 46.7 deg. The
    // low footpad hangs 1.2 cos 50 + 1.8 sin 50 = 2.15 m below the centre of mass, 0.95 m
    // below the footpad plane's reference: start 1 m up.
    let mut cfg = drop(1.0, 0.0);
    cfg.initial.thrust_pitch_deg = 40.0;
    let (_, td, _) = fly_to_the_end(&cfg);
    assert!((td.contact_tilt_deg - 50.0).abs() < 1e-6, "{td:?}");
    assert_eq!(td.reason, Some(CrashReason::TipOver), "{td:?}");
    assert!(td.tilt_deg > 46.7);
}

#[test]
fn a_lander_tilted_inside_its_footprint_rights_itself() {
    // 40 deg: inside the stability angle, it falls back onto all four pads. The low
    // footpad hangs 1.2 cos 40 + 1.8 sin 40 = 2.08 m below the centre of mass: start
    // 0.9 m up.
    let mut cfg = drop(0.9, 0.0);
    cfg.initial.thrust_pitch_deg = 50.0;
    let (_, td, _) = fly_to_the_end(&cfg);
    assert!((td.contact_tilt_deg - 40.0).abs() < 1e-6, "{td:?}");
    assert!(td.landed && td.tilt_deg < 0.5, "{td:?}");
}

/// A plane of `slope_deg` about the site (a synthetic surface with no craters).
fn on_slope(slope_deg: f64) -> ScenarioConfig {
    use oils_emulator::world::terrain::{SyntheticSpec, TerrainSpec};
    // Upright, the uphill footpad (1.8 m off the axis) is 1.8 tan(slope) higher than
    // the ground below the centre: start 0.2 m above that.
    let mut cfg = drop(1.8 * slope_deg.to_radians().tan() + 0.2, 0.0);
    cfg.terrain = TerrainSpec::Synthetic(SyntheticSpec {
        crater_density: 0.0,
        regional_slope_deg: slope_deg,
        extent_m: 200.0,
        spacing_m: 1.0,
        ..Default::default()
    });
    cfg
}

#[test]
fn a_drop_on_a_slope_within_the_friction_angle_holds_and_is_judged_on_the_slope() {
    // 20 deg: tan 20 = 0.36 < mu = 0.6, the pads stick; the slope breaks the 12 deg limit.
    let (_, td, _) = fly_to_the_end(&on_slope(20.0));
    assert!((td.slope_deg - 20.0).abs() < 0.05, "{td:?}");
    assert_eq!(td.reason, Some(CrashReason::Slope), "{td:?}");
    // 8 deg: within every limit, it lands (tilted by the slope, under 10 deg).
    let (_, td, _) = fly_to_the_end(&on_slope(8.0));
    assert!(td.landed && (td.tilt_deg - 8.0).abs() < 0.5, "{td:?}");
}

#[test]
fn a_drop_on_a_slope_steeper_than_the_friction_angle_slides() {
    // 40 deg: tan 40 = 0.84 > mu = 0.6, it cannot come to rest (and 40 deg is inside
    // the 46.7 deg stability angle, so it slides rather than falls over at once).
    let cfg = on_slope(40.0);
    let (p, td, _) = fly_to_the_end(&cfg);
    assert!(!td.landed, "{td:?}");
    // Still sliding when the settling time ran out (the slope is the first reason).
    assert_eq!(td.reason, Some(CrashReason::Slope), "{td:?}");
    assert!(
        td.end_t_s - td.t_s >= cfg.touchdown.settle_timeout_s,
        "{td:?}"
    );
    // Sliding down at g (sin 40 - mu cos 40) = 0.30 m/s^2 at most: far from rest.
    let rot = MoonRotation {
        rate_rad_s: cfg.moon.rotation_rate_rad_s,
    };
    let v = rot.surface_relative_mci(&p.state().pos_mci_m, &p.state().vel_mci_m_s);
    assert!(v.norm() > 1.0, "{v}");
}

/// `truth.contact` says the footpads have touched: it is set at the first contact (the
/// touchdown's `t_s`), not when the landing is judged a second or more later.
#[test]
fn truth_contact_is_set_from_the_first_footpad_contact() {
    let cfg = drop(0.05, -0.5);
    let mut p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut first_contact_s = None;
    let td = loop {
        let status = p.step(&ActuatorCommand::default(), 10_000_000);
        let t_s = p.time_ns() as f64 * 1e-9;
        if p.truth().contact && first_contact_s.is_none() {
            first_contact_s = Some(t_s);
        }
        if let PlantStatus::Touchdown(td) = status {
            break td;
        }
        assert!(t_s < 100.0, "the landing never ended");
    };
    let first = first_contact_s.expect("truth.contact never set");
    // Set on the step that holds the contact instant, well before the judgement.
    assert!(
        first >= td.t_s && first < td.t_s + 0.0100001,
        "{first} vs contact at {}",
        td.t_s
    );
    let judged_s = p.time_ns() as f64 * 1e-9;
    assert!(
        judged_s > first + 0.1,
        "judged at {judged_s} s, first contact {first} s, td {td:?}"
    );
}

/// The ideal navigation's specific force feels the legs: at rest on the ground it reads
/// the ground's push, `g` up the body Z axis (1.62 m/s^2), as the IMU does, not 0.
#[test]
fn ideal_navigation_feels_the_legs_at_rest() {
    let cfg = drop(0.05, -0.5);
    let mut p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    loop {
        let status = p.step(&ActuatorCommand::default(), 10_000_000);
        if let PlantStatus::Touchdown(td) = status {
            assert!(td.landed, "{td:?}");
            break;
        }
        assert!(p.time_ns() < 100_000_000_000, "the landing never ended");
    }
    let tlm = Devices::new(&cfg, 1).telemetry(&p, Default::default());
    let g = cfg.moon.mu_m3_s2 / p.state().pos_mci_m.norm_squared();
    let a = tlm.accel_body_m_s2;
    assert!((a[2] - g).abs() < 0.02 * g, "at rest: {a:?}, g = {g}");
    assert!(a[0].abs() < 0.02 * g && a[1].abs() < 0.02 * g, "{a:?}");
}
