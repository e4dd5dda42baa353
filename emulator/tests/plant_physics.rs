//! Physics checks of the plant against closed forms and invariants. Each bound is set by
//! the integrator's truncation and round-off error, not tuned to the output.

use nalgebra::{UnitQuaternion, Vector3};
use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus, TouchdownState};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_shared::{PacketHeader, TLM_FLAG_NAV_NOISE};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const G0_M_S2: f64 = 9.80665;

fn plant(cfg: &ScenarioConfig) -> Plant {
    Plant::new(cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap()
}

fn coast() -> ActuatorCommand {
    ActuatorCommand::default()
}

fn full_thrust() -> ActuatorCommand {
    ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [800.0; 4],
            on: [true; 4],
        },
        torque_cmd_body_nm: [0.0; 3],
        ..Default::default()
    }
}

/// A circular orbit `altitude_m` above the footpads' reach (the Moon held still: the
/// closed forms are inertial, and the start speeds are relative to the surface).
fn circular_orbit(altitude_m: f64) -> ScenarioConfig {
    let mut cfg = ScenarioConfig::default();
    cfg.moon.rotation_rate_rad_s = 0.0;
    cfg.initial.altitude_m = altitude_m;
    let r = cfg.moon.radius_m + cfg.lander.leg_height_m() + altitude_m;
    cfg.initial.horizontal_speed_m_s = (cfg.moon.mu_m3_s2 / r).sqrt();
    cfg.initial.vertical_speed_m_s = 0.0;
    cfg
}

fn energy_per_kg(p: &Plant, mu: f64) -> f64 {
    let s = p.state();
    0.5 * s.vel_mci_m_s.norm_squared() - mu / s.pos_mci_m.norm()
}

#[test]
fn circular_orbit_conserves_energy_and_angular_momentum_over_ten_orbits() {
    let cfg = circular_orbit(30_000.0);
    let mu = cfg.moon.mu_m3_s2;
    let mut p = plant(&cfg);
    let r0 = p.state().pos_mci_m.norm();
    let period_s = 2.0 * std::f64::consts::PI * (r0.powi(3) / mu).sqrt();
    let e0 = energy_per_kg(&p, mu);
    let h0 = p.state().pos_mci_m.cross(&p.state().vel_mci_m_s);
    let dt_ns = 1_000_000_000;
    let steps = (10.0 * period_s) as usize;
    for _ in 0..steps {
        assert_eq!(p.step(&coast(), dt_ns), PlantStatus::Flying);
    }
    let e1 = energy_per_kg(&p, mu);
    let h1 = p.state().pos_mci_m.cross(&p.state().vel_mci_m_s);
    assert!(
        ((e1 - e0) / e0).abs() < 1e-10,
        "energy drift {}",
        (e1 - e0) / e0
    );
    assert!((h1 - h0).norm() / h0.norm() < 1e-10, "h drift");
    // Still circular: radius within a millimetre.
    assert!((p.state().pos_mci_m.norm() - r0).abs() < 1e-3);
    // Coasting burns nothing.
    assert_eq!(p.propellant_used_kg(), 0.0);
}

#[test]
fn rk4_global_error_falls_sixteenfold_when_dt_halves() {
    let cfg = circular_orbit(30_000.0);
    let mu = cfg.moon.mu_m3_s2;
    let duration_s = 3_000.0;
    let error_m = |dt_s: f64| {
        let mut p = plant(&cfg);
        let r0 = p.state().pos_mci_m;
        let v0 = p.state().vel_mci_m_s;
        let n = (duration_s / dt_s).round() as usize;
        for _ in 0..n {
            p.step(&coast(), (dt_s * 1e9) as u64);
        }
        // Closed form: uniform rotation in the orbit plane.
        let omega = (mu / r0.norm().powi(3)).sqrt();
        let (s, c) = (omega * duration_s).sin_cos();
        let exact = r0 * c + v0 / omega * s;
        (p.state().pos_mci_m - exact).norm()
    };
    let (e60, e30, e15) = (error_m(60.0), error_m(30.0), error_m(15.0));
    eprintln!("RK4 position error after {duration_s} s: {e60} m, {e30} m, {e15} m");
    for (coarse, fine) in [(e60, e30), (e30, e15)] {
        let ratio = coarse / fine;
        assert!(
            (14.0..18.5).contains(&ratio),
            "ratio {ratio} ({coarse} m / {fine} m)"
        );
    }
}

/// Time for a radial fall from rest at `r0` to reach `r` (cycloid closed form).
fn radial_fall_time_s(mu: f64, r0: f64, r: f64) -> f64 {
    let eta = 2.0 * ((r0 - r) / r0).sqrt().asin();
    (r0.powi(3) / (8.0 * mu)).sqrt() * (eta + eta.sin())
}

fn vertical_drop(altitude_m: f64, pitch_deg: f64) -> ScenarioConfig {
    let mut cfg = ScenarioConfig::default();
    // Inertial closed forms: the Moon held still (the turning Moon has its own tests).
    cfg.moon.rotation_rate_rad_s = 0.0;
    cfg.initial.altitude_m = altitude_m;
    cfg.initial.horizontal_speed_m_s = 0.0;
    cfg.initial.vertical_speed_m_s = 0.0;
    cfg.initial.thrust_pitch_deg = pitch_deg;
    cfg
}

#[test]
fn radial_free_fall_matches_kepler_closed_form() {
    let cfg = vertical_drop(30_000.0, 90.0);
    let mu = cfg.moon.mu_m3_s2;
    let mut p = plant(&cfg);
    let r0 = p.state().pos_mci_m.norm();
    let u0 = p.state().pos_mci_m / r0;
    let dt_ns = 10_000_000;
    for _ in 0..6_000 {
        p.step(&coast(), dt_ns);
    }
    assert_eq!(p.time_ns(), 60_000_000_000);
    let t_s = 60.0;
    let r = p.state().pos_mci_m.norm();
    let t_closed = radial_fall_time_s(mu, r0, r);
    // Energy: v = sqrt(2 mu (1/r - 1/r0)).
    let v_closed = (2.0 * mu * (1.0 / r - 1.0 / r0)).sqrt();
    assert!((t_closed - t_s).abs() < 1e-8, "t {t_closed} vs {t_s}");
    assert!((p.state().vel_mci_m_s.norm() - v_closed).abs() < 1e-8);
    // Still purely radial: along the start direction, no velocity across it.
    let s = p.state();
    let across_m = (s.pos_mci_m - u0 * s.pos_mci_m.dot(&u0)).norm();
    // Round-off only: the start direction has no zero components, so each of the
    // 6000 steps rounds a 1.7e6 m vector (~1e-16 relative each); 1e-12 of r0 bounds it.
    assert!(across_m < 1e-12 * r0, "{across_m}");
    assert!((s.vel_mci_m_s - u0 * s.vel_mci_m_s.dot(&u0)).norm() < 1e-12 * v_closed.max(1.0));
}

#[test]
fn rocket_equation_holds_for_a_constant_burn() {
    // Gravity made negligible; thrust against the velocity for 100 s.
    let mut cfg = ScenarioConfig::default();
    cfg.moon.mu_m3_s2 = 1.0;
    cfg.initial.horizontal_speed_m_s = 5_000.0;
    cfg.initial.thrust_pitch_deg = 0.0;
    let mut p = plant(&cfg);
    let (m0, v0) = (p.state().mass_kg, p.state().vel_mci_m_s);
    for _ in 0..10_000 {
        p.step(&full_thrust(), 10_000_000);
    }
    let (m1, v1) = (p.state().mass_kg, p.state().vel_mci_m_s);
    let dv = (v1 - v0).norm();
    let expected = cfg.propulsion.isp_s * G0_M_S2 * (m0 / m1).ln();
    assert!(m1 < m0 - 100.0, "burned {}", m0 - m1);
    assert!(
        ((dv - expected) / expected).abs() < 1e-9,
        "{dv} vs {expected}"
    );
    // The mass matches the propulsion model's account.
    let ejected = p.propulsion_output().ejected_kg();
    assert!((p.propellant_used_kg() - ejected).abs() < 1e-9);
    // Symmetric engines: no rotation.
    assert!(p.state().rate_body_rad_s.norm() < 1e-12);
}

#[test]
fn constant_torque_spins_up_as_t_over_i() {
    let cfg = vertical_drop(30_000.0, 90.0);
    let mut p = plant(&cfg);
    let torque_nm = 20.0;
    let cmd = ActuatorCommand {
        torque_cmd_body_nm: [torque_nm, 0.0, 0.0],
        ..Default::default()
    };
    let duration_s = 10.0;
    for _ in 0..1_000 {
        p.step(&cmd, 10_000_000);
    }
    // The thrusters burn propellant, so I_x falls linearly: I(t) = I0 - c t and
    // omega = (T / c) ln(I0 / I(t)).
    let lander = &cfg.lander;
    let flow_kg_s = torque_nm / lander.rcs_moment_arm_m[0] / (lander.rcs_isp_s * G0_M_S2);
    let di_dm =
        (lander.inertia_wet_kg_m2[0] - lander.inertia_dry_kg_m2[0]) / cfg.propulsion.propellant_kg;
    let c = di_dm * flow_kg_s;
    let i0 = lander.inertia_wet_kg_m2[0];
    let expected = torque_nm / c * (i0 / (i0 - c * duration_s)).ln();
    let w = p.state().rate_body_rad_s;
    assert!(
        ((w.x - expected) / expected).abs() < 1e-9,
        "{} vs {expected}",
        w.x
    );
    assert!((w.x - torque_nm / i0 * duration_s).abs() / w.x < 1e-3);
    assert!(w.y.abs() < 1e-15 && w.z.abs() < 1e-15);
    let rcs = p.rcs_propellant_used_kg();
    assert!((rcs - flow_kg_s * duration_s).abs() < 1e-12);
    // The attitude advanced by the integral of omega (about body x).
    let angle = p.state().q_mci_from_body.angle_to(&initial_attitude(&cfg));
    let expected_angle = 0.5 * torque_nm / i0 * duration_s * duration_s;
    assert!((angle - expected_angle).abs() / expected_angle < 1e-3);
}

fn initial_attitude(cfg: &ScenarioConfig) -> UnitQuaternion<f64> {
    plant(cfg).state().q_mci_from_body
}

#[test]
fn torque_saturates_at_rcs_limit() {
    let cfg = vertical_drop(30_000.0, 90.0);
    let mut p = plant(&cfg);
    let cmd = ActuatorCommand {
        torque_cmd_body_nm: [0.0, 0.0, -1e6],
        ..Default::default()
    };
    p.step(&cmd, 10_000_000);
    let max = cfg.lander.rcs_max_torque_nm()[2];
    let expected = -max / cfg.lander.inertia_wet_kg_m2[2] * 0.01;
    let wz = p.state().rate_body_rad_s.z;
    assert!(
        (wz - expected).abs() / expected.abs() < 1e-5,
        "{wz} vs {expected}"
    );
}

#[test]
fn torque_free_tumble_conserves_angular_momentum_and_energy() {
    let mut cfg = vertical_drop(300_000.0, 90.0);
    // Fixed, strongly asymmetric inertia: the tumble is not a simple spin.
    cfg.lander.inertia_wet_kg_m2 = [1000.0, 1500.0, 2200.0];
    cfg.lander.inertia_dry_kg_m2 = cfg.lander.inertia_wet_kg_m2;
    let inertia = Vector3::from(cfg.lander.inertia_wet_kg_m2);
    let mut p = plant(&cfg);
    let spin_up = ActuatorCommand {
        torque_cmd_body_nm: [60.0, 20.0, 40.0],
        ..Default::default()
    };
    for _ in 0..300 {
        p.step(&spin_up, 10_000_000);
    }
    let momentum = |p: &Plant| {
        let s = p.state();
        s.q_mci_from_body * inertia.component_mul(&s.rate_body_rad_s)
    };
    let energy = |p: &Plant| {
        let w = p.state().rate_body_rad_s;
        0.5 * w.dot(&inertia.component_mul(&w))
    };
    let (l0, e0) = (momentum(&p), energy(&p));
    let w0 = p.state().rate_body_rad_s;
    for _ in 0..60_000 {
        p.step(&coast(), 10_000_000);
        let q = p.state().q_mci_from_body.quaternion();
        assert!((q.norm() - 1.0).abs() < 1e-12);
    }
    assert!((momentum(&p) - l0).norm() / l0.norm() < 1e-9);
    assert!(((energy(&p) - e0) / e0).abs() < 1e-9);
    // It really tumbled: the body rate vector moved.
    assert!((p.state().rate_body_rad_s - w0).norm() > 0.01 * w0.norm());
}

#[test]
fn mass_never_rises_and_matches_the_account_under_random_commands() {
    let mut cfg = circular_orbit(50_000.0);
    cfg.propulsion.propellant_kg = 5.0; // run the tanks dry on the way
    let dry = cfg.lander.dry_mass_kg;
    let mut p = plant(&cfg);
    let mut rng = ChaCha8Rng::seed_from_u64(42);
    let mut last_mass = p.state().mass_kg;
    for _ in 0..20_000 {
        let mut cmd = ActuatorCommand::default();
        for e in 0..4 {
            cmd.engines.thrust_cmd_n[e] = rng.gen_range(0.0..=800.0);
            cmd.engines.on[e] = rng.gen_bool(0.7);
        }
        for a in 0..3 {
            cmd.torque_cmd_body_nm[a] = rng.gen_range(-200.0..=200.0);
        }
        p.step(&cmd, 10_000_000);
        let m = p.state().mass_kg;
        assert!(m <= last_mass, "mass rose {last_mass} -> {m}");
        assert!(m >= dry);
        let account = p.propulsion_output().ejected_kg() + p.rcs_propellant_used_kg();
        assert!((p.propellant_used_kg() - account.min(5.0)).abs() < 1e-9);
        last_mass = m;
    }
    assert!(
        (last_mass - dry).abs() < 1e-9,
        "tanks not empty: {last_mass}"
    );
}

fn drop_until_contact(cfg: &ScenarioConfig) -> (Plant, TouchdownState) {
    let mut p = plant(cfg);
    for _ in 0..100_000 {
        if let PlantStatus::Touchdown(td) = p.step(&coast(), 10_000_000) {
            return (p, td);
        }
    }
    panic!("no touchdown");
}

#[test]
fn touchdown_is_found_at_the_exact_contact_instant() {
    let cfg = vertical_drop(10.0, 90.0);
    let mu = cfg.moon.mu_m3_s2;
    let r0 = cfg.moon.radius_m + cfg.lander.leg_height_m() + 10.0;
    // Upright, the footpads sit 1.8 m off the axis: on the sphere they touch when
    // (r - 1.2)^2 + 1.8^2 = R^2, 0.93 um higher than a footpad on the axis would.
    let pad = cfg.lander.footpad_positions_body_m[0];
    let off_axis_m = pad[0].hypot(pad[1]);
    let r_contact = cfg.lander.leg_height_m()
        + (cfg.moon.radius_m * cfg.moon.radius_m - off_axis_m * off_axis_m).sqrt();
    let (p, td) = drop_until_contact(&cfg);
    let t_exact = radial_fall_time_s(mu, r0, r_contact);
    let v_exact = (2.0 * mu * (1.0 / r_contact - 1.0 / r0)).sqrt();
    assert!((td.t_s - t_exact).abs() < 1e-7, "{} vs {t_exact}", td.t_s);
    assert!((td.vertical_speed_mps - v_exact).abs() < 1e-7);
    assert!(td.horizontal_speed_mps < 1e-9 && td.tilt_deg < 1e-6);
    assert!(p.altitude_m().abs() < 1e-6);
    // 5.7 m/s is a crash, not a landing.
    assert!(!td.landed);
    // The state is frozen at contact from then on.
    let mut p = p;
    let before = *p.state();
    assert_eq!(
        p.step(&full_thrust(), 10_000_000),
        PlantStatus::Touchdown(td)
    );
    assert_eq!(*p.state(), before);
}

#[test]
fn gentle_contact_is_a_landing_and_a_tilted_contact_rights_itself() {
    let (_, td) = drop_until_contact(&vertical_drop(1.0, 90.0));
    assert!(td.vertical_speed_mps < 2.0 && td.landed, "{td:?}");
    // 15 deg tilted at first contact: the low footpad (0, on +x) touches first and
    // crushes its strut most; the legs right the vehicle on flat ground (the tilt
    // judged is the one at rest). The struts keep what they crushed, so it rests on
    // that pad and its two neighbours, the fourth in the air like a table's short
    // leg, tilted by the crush difference over the triangle's height, 1.8 m, less the
    // elastic part's give under the two neighbours, which carry nearly all the weight
    // (the centre of mass sits a few centimetres off their line).
    let cfg = vertical_drop(1.0, 75.0);
    let (p, tilted) = drop_until_contact(&cfg);
    assert!((tilted.contact_tilt_deg - 15.0).abs() < 1e-9, "{tilted:?}");
    assert!(tilted.landed, "{tilted:?}");
    let c = tilted.leg_crush_m;
    assert!(c[0] > c[1] && c[0] > c[2] && c[0] > c[3], "{tilted:?}");
    assert_eq!(p.footpads_in_contact(), 3, "{tilted:?}");
    let weight_n = p.state().mass_kg * cfg.moon.mu_m3_s2 / p.state().pos_mci_m.norm_squared();
    let give_m = 0.5 * weight_n / cfg.lander.leg_stiffness_n_m;
    let expect_deg = (c[0] - 0.5 * (c[1] + c[3]) - give_m)
        .atan2(1.8)
        .to_degrees();
    assert!(
        (tilted.tilt_deg - expect_deg).abs() < 0.01,
        "{tilted:?}: expected {expect_deg} deg"
    );
}

#[test]
fn telemetry_reports_specific_force_altitude_and_valves() {
    let cfg = vertical_drop(1_000.0, 90.0);
    let mut p = plant(&cfg);
    let mut cmd = full_thrust();
    cmd.engines.on[3] = false;
    for _ in 0..500 {
        p.step(&cmd, 10_000_000);
    }
    let tlm = Devices::new(&cfg, 1).telemetry(&p, PacketHeader::new(9, 500, p.time_ns()));
    assert_eq!(tlm.header.step, 500);
    assert_eq!(tlm.header.flags & TLM_FLAG_NAV_NOISE, 0);
    let thrust: f64 = p.propulsion_output().thrust_n.iter().sum();
    assert!((tlm.accel_body_m_s2[2] - thrust / p.state().mass_kg).abs() < 1e-12);
    assert!((thrust - 2400.0).abs() < 1e-6);
    assert_eq!(tlm.accel_body_m_s2[0], 0.0);
    assert!((tlm.altitude_m - p.altitude_m()).abs() < 1e-12);
    assert_eq!(tlm.mass_estimate_kg, p.state().mass_kg);
    let valves: Vec<u32> = tlm
        .propulsion
        .engines
        .iter()
        .map(|e| e.valve_open)
        .collect();
    assert_eq!(valves, [1, 1, 1, 0]);
    let q = tlm.nav.q_mci_from_body;
    assert!(((q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]) - 1.0).abs() < 1e-12);
}

#[test]
fn nav_noise_is_flagged_seeded_and_reproducible() {
    let mut cfg = vertical_drop(1_000.0, 90.0);
    cfg.nav_noise.enabled = true;
    let run = |seed: u64| {
        let mut p = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap();
        p.step(&full_thrust(), 10_000_000);
        Devices::new(&cfg, seed).telemetry(&p, PacketHeader::new(1, 1, p.time_ns()))
    };
    let (a, b, c) = (run(3), run(3), run(4));
    assert_eq!(a, b);
    assert_ne!(a.nav.pos_mci_m, c.nav.pos_mci_m);
    assert_ne!(a.header.flags & TLM_FLAG_NAV_NOISE, 0);
    let truth = plant(&cfg).state().pos_mci_m;
    let err = (Vector3::from(a.nav.pos_mci_m) - truth).norm();
    assert!(err > 0.0 && err < 10.0 * cfg.nav_noise.position_m, "{err}");
}

#[test]
fn bad_configuration_is_refused() {
    let mut cfg = ScenarioConfig::default();
    cfg.moon.radius_m = -1.0;
    let r = Plant::new(&cfg, Box::new(IdealPropulsion::new(&cfg.propulsion)));
    assert_eq!(r.err().map(|e| e.field), Some("moon.radius_m"));
}

/// The specific force the accelerometer reads after one full-thrust step.
fn specific_force_after_one_step(cfg: &ScenarioConfig) -> Vector3<f64> {
    let mut p = plant(cfg);
    assert_eq!(p.step(&full_thrust(), 10_000_000), PlantStatus::Flying);
    Vector3::from(
        Devices::new(cfg, 1)
            .telemetry(&p, PacketHeader::default())
            .accel_body_m_s2,
    )
}

#[test]
fn engine_thrust_scale_scales_the_delivered_force() {
    let nominal = specific_force_after_one_step(&ScenarioConfig::default());
    let mut cfg = ScenarioConfig::default();
    cfg.lander.engine_thrust_scale = [0.9; 4];
    let scaled = specific_force_after_one_step(&cfg);
    // Same propellant flow, so the same mass: the force ratio is the scale.
    assert!(
        (scaled.z / nominal.z - 0.9).abs() < 1e-12,
        "{scaled} vs {nominal}"
    );
}

#[test]
fn misaligned_engines_push_sideways_by_the_tangent_of_the_angle() {
    let mut cfg = ScenarioConfig::default();
    cfg.lander.engine_misalignment_deg = [[2.0, 0.0]; 4];
    let f = specific_force_after_one_step(&cfg);
    // Thrust axis rotated 2 deg about body X: (0, -sin, cos).
    assert!((f.y / f.z + 2f64.to_radians().tan()).abs() < 1e-12, "{f}");
    assert_eq!(f.x, 0.0);
    let nominal = specific_force_after_one_step(&ScenarioConfig::default());
    assert!((f.norm() - nominal.z).abs() < 1e-9 * nominal.z);
}

#[test]
fn a_centre_of_mass_offset_gives_the_engines_a_moment_arm() {
    let pitch_rate = |offset_x_m: f64| {
        let mut cfg = ScenarioConfig::default();
        cfg.lander.com_offset_body_m = [offset_x_m, 0.0, 0.0];
        let mut p = plant(&cfg);
        assert_eq!(p.step(&full_thrust(), 10_000_000), PlantStatus::Flying);
        p.state().rate_body_rad_s
    };
    assert_eq!(pitch_rate(0.0), Vector3::zeros());
    let small = pitch_rate(0.01);
    let large = pitch_rate(0.02);
    // Equal thrusts through arms shifted by -x: a torque +4 F x about body +Y.
    assert!(small.y > 0.0);
    assert!(small.x.abs() < 1e-15 && small.z.abs() < 1e-12);
    // Linear in the offset (one short step: the rate is torque / I * dt).
    assert!((large.y / small.y - 2.0).abs() < 1e-6, "{small} {large}");
}

/// Issue #24: a hifi model whose state became non-finite rolled the step back and then
/// froze its outputs, and the run went on to COMPLETED. A propulsion failure is now
/// named by the plant, and the scheduler aborts on it.
#[test]
fn a_failed_propulsion_model_is_named_by_the_plant() {
    use oils_emulator::propulsion::{Propulsion, PropulsionOutput};
    #[derive(Debug)]
    struct FailsAfter(u32, IdealPropulsion);
    impl Propulsion for FailsAfter {
        fn name(&self) -> &'static str {
            "fails"
        }
        fn step(&mut self, cmd: &EngineCommand, dt_ns: u64) -> PropulsionOutput {
            self.0 = self.0.saturating_sub(1);
            self.1.step(cmd, dt_ns)
        }
        fn output(&self) -> PropulsionOutput {
            self.1.output()
        }
        fn failure(&self) -> Option<&'static str> {
            (self.0 == 0).then_some("test propulsion state")
        }
    }
    let cfg = ScenarioConfig::default();
    let prop = FailsAfter(3, IdealPropulsion::new(&cfg.propulsion));
    let mut plant = Plant::new(&cfg, Box::new(prop)).unwrap();
    let cmd = ActuatorCommand::default();
    for _ in 0..2 {
        plant.step(&cmd, 10_000_000);
        assert_eq!(plant.propulsion_failure(), None);
    }
    plant.step(&cmd, 10_000_000);
    assert_eq!(plant.propulsion_failure(), Some("test propulsion state"));
    assert_eq!(plant.first_non_finite(), None, "the state itself is finite");
}
