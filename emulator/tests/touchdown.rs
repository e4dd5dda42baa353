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
    // At 0.06 m/s the legs never reach the crush load.
    assert_eq!(td.leg_crush_m, [0.0; 4], "{td:?}");
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
    let (p, td, _) = fly_to_the_end(&cfg);
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
    // The struts crush D - F_crush / k, D = m v^2 / 2 / (n F_crush - m g) (see
    // `a_drop_crushes_the_struts_by_the_energy_it_brings_and_does_not_rebound`): 0.128 m.
    let m = p.state().mass_kg;
    let v = td.vertical_speed_mps;
    let l = &cfg.lander;
    let travel_m = 0.5 * m * v * v / (4.0 * l.leg_crush_load_n - m * g);
    let crush_m = travel_m - l.leg_crush_load_n / l.leg_stiffness_n_m;
    for c in td.leg_crush_m {
        assert!(
            (c - crush_m).abs() < 5e-4,
            "{td:?}: closed form {crush_m} m"
        );
    }
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
    // 0.9 m up. Falling back, the far pad meets the ground fast and crushes its strut
    // most; the crushed struts keep their length, so it rests tilted off the ground by
    // no more than the legs can tilt it.
    let mut cfg = drop(0.9, 0.0);
    cfg.initial.thrust_pitch_deg = 50.0;
    let (_, td, _) = fly_to_the_end(&cfg);
    assert!((td.contact_tilt_deg - 40.0).abs() < 1e-6, "{td:?}");
    let legs_tilt_deg = cfg.landing_limits().legs_tilt_deg;
    assert!(td.landed && td.tilt_deg <= legs_tilt_deg, "{td:?}");
    assert!(td.leg_crush_m.iter().all(|&c| c > 0.0), "{td:?}");
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
    // 20 deg: tan 20 = 0.36 < mu = 0.6, the pads stick; the slope breaks the limit
    // derived from the legs (11.38 deg).
    let (_, td, _) = fly_to_the_end(&on_slope(20.0));
    assert!((td.slope_deg - 20.0).abs() < 0.05, "{td:?}");
    assert_eq!(td.reason, Some(CrashReason::Slope), "{td:?}");
    assert!(td.slide_m < 0.5, "held, not slid: {td:?}");
    // 8 deg: within every limit, it lands, tilted by the slope and by what the struts
    // crushed unequally (the downhill ones more).
    let cfg = on_slope(8.0);
    let (_, td, _) = fly_to_the_end(&cfg);
    let legs_tilt_deg = cfg.landing_limits().legs_tilt_deg;
    assert!(
        td.landed && td.tilt_deg >= 8.0 - 0.5 && td.tilt_deg <= 8.0 + legs_tilt_deg,
        "{td:?}"
    );
}

/// Speed of the centre of mass over the ground, m/s.
fn ground_speed_m_s(p: &Plant, cfg: &ScenarioConfig) -> f64 {
    let rot = MoonRotation {
        rate_rad_s: cfg.moon.rotation_rate_rad_s,
    };
    rot.surface_relative_mci(&p.state().pos_mci_m, &p.state().vel_mci_m_s)
        .norm()
}

#[test]
fn a_drop_on_a_slope_steeper_than_the_friction_angle_slides() {
    // 40 deg: tan 40 = 0.84 > mu = 0.6, it cannot come to rest (and 40 deg is inside
    // the 46.7 deg stability angle, so it slides rather than falls over at once).
    let cfg = on_slope(40.0);
    let mut p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let timeout_ns = (cfg.touchdown.settle_timeout_s * 1e9) as i64;
    // The slide's last 9.5 s, well after the vehicle fell onto the slope.
    let before_ns = timeout_ns - 9_000_000_000;
    let mut before = None;
    let td = loop {
        let status = p.step(&ActuatorCommand::default(), 10_000_000);
        if let PlantStatus::Touchdown(td) = status {
            break td;
        }
        if p.time_ns() == before_ns {
            before = Some((
                ground_speed_m_s(&p, &cfg),
                mcmf_position(&p, &cfg),
                p.legs().slide_m(),
            ));
        }
        assert!(p.time_ns() < 100_000_000_000, "the landing never ended");
    };
    let (v_before, p_before, slide_before_m) = before.expect("slid that long");
    assert!(!td.landed, "{td:?}");
    // Slid, and the report says how far and how fast.
    assert_eq!(td.reason, Some(CrashReason::Slid), "{td:?}");
    assert!(
        td.end_t_s - td.t_s >= cfg.touchdown.settle_timeout_s,
        "{td:?}"
    );
    // Sliding down at a = g (sin 40 - mu cos 40) = 0.297 m/s^2 (Coulomb friction on
    // four pads sliding together).
    let g = cfg.moon.mu_m3_s2 / p.state().pos_mci_m.norm_squared();
    let (sin, cos) = 40f64.to_radians().sin_cos();
    let a = g * (sin - cfg.lander.footpad_friction * cos);
    let v_end = ground_speed_m_s(&p, &cfg);
    let span_s = (p.time_ns() - before_ns) as f64 * 1e-9;
    let a_measured = (v_end - v_before) / span_s;
    assert!(
        (a_measured - a).abs() < 0.005 * a,
        "{a_measured} m/s^2 vs {a} m/s^2"
    );
    // The slide's speed is the pads' at the end (they sped up all along); over the
    // span the pads slid as far as the centre of mass went, v t + a t^2 / 2.
    assert!(
        (td.slide_speed_m_s - v_end).abs() < 0.01 * v_end,
        "{td:?} vs {v_end} m/s"
    );
    let moved_m = (mcmf_position(&p, &cfg) - p_before).norm();
    let slid_m = td.slide_m - slide_before_m;
    let closed_m = v_before * span_s + 0.5 * a * span_s * span_s;
    assert!(
        (slid_m - moved_m).abs() < 0.01 && (slid_m - closed_m).abs() < 0.005 * closed_m,
        "slid {slid_m} m, moved {moved_m} m, closed form {closed_m} m"
    );
    assert!(td.slide_m > 50.0, "{td:?}");
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

/// Distance of the centre of mass from the Moon's centre, metres.
fn radius_m(p: &Plant) -> f64 {
    p.state().pos_mci_m.norm()
}

/// The struts absorb the drop: from first contact every leg pushes at the crush load
/// (the damper alone would push harder), so the energy balance
/// `n F_crush D = m v^2 / 2 + m g D` gives the centre of mass's travel
/// `D = m v^2 / 2 / (n F_crush - m g)`; the
/// struts crush `D - F_crush / k` (the elastic part takes the rest) and keep it. Then
/// the elastic part unloads to the weight, `(F_crush - m g / n) / k`, and nothing throws
/// the vehicle back up: no footpad leaves the ground, no overshoot above the rest.
#[test]
fn a_drop_crushes_the_struts_by_the_energy_it_brings_and_does_not_rebound() {
    let cfg = drop(0.001, -1.9);
    let lander = &cfg.lander;
    let mut p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
    let mut lowest_r_m = f64::INFINITY;
    let mut highest_after_lowest_m = f64::NEG_INFINITY;
    let mut all_down = false;
    let td = loop {
        let status = p.step(&ActuatorCommand::default(), 10_000_000);
        let r = radius_m(&p);
        if p.truth().contact {
            if r < lowest_r_m {
                lowest_r_m = r;
                highest_after_lowest_m = f64::NEG_INFINITY;
            } else {
                highest_after_lowest_m = highest_after_lowest_m.max(r);
            }
            if p.footpads_in_contact() == 4 {
                all_down = true;
            } else {
                assert!(!all_down, "a footpad left the ground at {} ns", p.time_ns());
            }
        }
        if let PlantStatus::Touchdown(td) = status {
            break td;
        }
        assert!(p.time_ns() < 100_000_000_000, "the landing never ended");
    };
    assert!(td.landed && all_down, "{td:?}");
    let m = p.state().mass_kg;
    let g = cfg.moon.mu_m3_s2 / (radius_m(&p) * radius_m(&p));
    let v = td.vertical_speed_mps;
    let n_f = 4.0 * lander.leg_crush_load_n;
    let travel_m = 0.5 * m * v * v / (n_f - m * g);
    // On the sphere the off-axis footpads touch when (r - h)^2 + 1.8^2 = R^2.
    let pad = lander.footpad_positions_body_m[0];
    let r_contact_m = lander.leg_height_m()
        + (cfg.moon.radius_m * cfg.moon.radius_m - pad[0] * pad[0] - pad[1] * pad[1]).sqrt();
    let measured_m = r_contact_m - lowest_r_m;
    // 1750 kg at 1.90 m/s onto 4 x 6 kN: 0.149 m (measured 0.2 mm more, the lowest
    // point sampled at the 10 ms step).
    assert!(
        (measured_m - travel_m).abs() < 5e-4,
        "travel {measured_m} m, closed form {travel_m} m"
    );
    let spring_m = lander.leg_crush_load_n / lander.leg_stiffness_n_m;
    for c in td.leg_crush_m {
        assert!(
            (c - (travel_m - spring_m)).abs() < 1e-3,
            "crushed {:?}, closed form {}",
            td.leg_crush_m,
            travel_m - spring_m
        );
    }
    // The energy went into the struts: n F_crush c = m v^2 / 2 + m g D less the elastic
    // part's share, n F_crush (F_crush / k).
    let absorbed_j = lander.leg_crush_load_n * td.leg_crush_m.iter().sum::<f64>();
    let brought_j = 0.5 * m * v * v + m * g * travel_m - n_f * spring_m;
    assert!(
        (absorbed_j - brought_j).abs() < 0.01 * brought_j,
        "{absorbed_j} J absorbed of {brought_j} J"
    );
    // The elastic part unloads from the crush load to the weight and stops there.
    let end_m = radius_m(&p);
    let unload_m = (lander.leg_crush_load_n - m * g / 4.0) / lander.leg_stiffness_n_m;
    assert!(
        ((end_m - lowest_r_m) - unload_m).abs() < 1e-4,
        "rose {} m, elastic unloading {unload_m} m",
        end_m - lowest_r_m
    );
    assert!(
        highest_after_lowest_m - end_m < 1e-5,
        "rebound {} m above the rest",
        highest_after_lowest_m - end_m
    );
}

/// One rule for slope and tilt: a vehicle that comes to rest on a plane below the
/// derived slope limit is within the derived tilt limit (the legs tilt it off the
/// plane by at most `legs_tilt_deg`), whatever its contact speed; above the limit it
/// is judged on the slope. Issue #57: an 11.4 deg slope failed on tilt (limits 12 and
/// 10 deg); the derived slope limit is 11.38 deg, so it now fails on the slope.
#[test]
fn below_the_derived_slope_limit_a_landing_never_fails_on_tilt() {
    let limits = ScenarioConfig::default().landing_limits();
    assert!((limits.slope_deg - 11.377).abs() < 1e-3, "{limits:?}");
    for slope_deg in [3.0, 6.0, 9.0, limits.slope_deg - 0.05] {
        for vertical_m_s in [0.0, -1.8] {
            let mut cfg = on_slope(slope_deg);
            cfg.initial.vertical_speed_m_s = vertical_m_s;
            let (_, td, _) = fly_to_the_end(&cfg);
            assert!(td.landed, "{slope_deg} deg at {vertical_m_s} m/s: {td:?}");
            assert!(
                td.tilt_deg <= slope_deg + limits.legs_tilt_deg + 1e-3,
                "{slope_deg} deg at {vertical_m_s} m/s: {td:?}"
            );
            assert_eq!(td.tilt_limit_deg, limits.tilt_deg);
            assert_eq!(td.slope_limit_deg, limits.slope_deg);
        }
    }
    let (_, td, _) = fly_to_the_end(&on_slope(11.4));
    assert_eq!(td.reason, Some(CrashReason::Slope), "{td:?}");
    assert!(td.tilt_deg < limits.tilt_deg, "{td:?}");
}
