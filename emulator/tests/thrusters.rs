//! Attitude thrusters at device level (#33 item 2), against the closed forms of
//! `plant/thrusters.rs`: a couple pair's torque is `r x F`, a pulse's impulse is
//! `F (T + d_close - d_open)` at any plant tick, below the minimum on-time nothing fires,
//! propellant is impulse / (Isp g0), a held command does not fire again, and zero
//! on-times coast. The inertia is held constant (wet = dry) so that `I dw` is exactly
//! the angular impulse; the bounds are round-off, not tuned.

use nalgebra::Vector3;
use oils_emulator::config::ScenarioConfig;
use oils_emulator::devices::Devices;
use oils_emulator::plant::thrusters::ThrusterBank;
use oils_emulator::plant::{ActuatorCommand, Plant, PlantStatus};
use oils_emulator::propulsion::ideal::IdealPropulsion;
use oils_shared::{PacketHeader, THRUSTER_COUNT};

const G0_M_S2: f64 = 9.80665;
const MS: u64 = 1_000_000;
/// Flight-software cycle of these runs.
const CYCLE_NS: u64 = 20 * MS;
/// Thrust of one thruster (sourced: 8 x 58 N).
const F_N: f64 = 58.0;
/// Timing of these runs (distinct delays, so a sign error in either shows).
const OPEN_S: f64 = 0.005;
const CLOSE_S: f64 = 0.003;
const TAU_S: f64 = 0.004;
const MIN_ON_S: f64 = 0.010;

/// High above the ground, constant inertia, the timing above.
fn config() -> ScenarioConfig {
    let mut cfg = ScenarioConfig::default();
    cfg.initial.altitude_m = 20_000.0;
    cfg.nav_noise.enabled = false;
    cfg.lander.inertia_dry_kg_m2 = cfg.lander.inertia_wet_kg_m2;
    cfg.lander.rcs_open_delay_s = OPEN_S;
    cfg.lander.rcs_close_delay_s = CLOSE_S;
    cfg.lander.rcs_time_constant_s = TAU_S;
    cfg.lander.rcs_min_on_time_s = MIN_ON_S;
    cfg
}

fn plant(cfg: &ScenarioConfig) -> Plant {
    Plant::new(cfg, Box::new(IdealPropulsion::new(&cfg.propulsion))).unwrap()
}

/// Thruster mode, `on` on-times (thruster, ns), for the cycle starting at `cycle_start_ns`.
fn pulse(on: &[(usize, u64)], cycle_start_ns: i64) -> ActuatorCommand {
    let mut c = ActuatorCommand {
        use_thrusters: true,
        cycle_start_ns,
        ..Default::default()
    };
    for &(i, t) in on {
        c.thruster_on_time_ns[i] = t;
    }
    c
}

/// `cycles` flight-software cycles at plant tick `dt_ns`, the command of cycle `k` from
/// `cmd(k)` held over its cycle (as the scheduler does).
fn fly(p: &mut Plant, dt_ns: u64, cycles: u64, cmd: impl Fn(u64) -> ActuatorCommand) {
    for k in 0..cycles {
        let c = cmd(k);
        for _ in 0..CYCLE_NS / dt_ns {
            assert_eq!(p.step(&c, dt_ns), PlantStatus::Flying);
        }
    }
}

/// One pulse of `on` in cycle 0, then zero on-times: 300 ms, long past the tail.
fn one_pulse(cfg: &ScenarioConfig, dt_ns: u64, on: &[(usize, u64)]) -> Plant {
    let mut p = plant(cfg);
    fly(&mut p, dt_ns, 15, |k| {
        let start = (k * CYCLE_NS) as i64;
        pulse(if k == 0 { on } else { &[] }, start)
    });
    p
}

/// `r_i x d_i` summed over `thrusters`, from the configuration's arrays (independent of
/// the bank).
fn couple_per_newton(cfg: &ScenarioConfig, thrusters: &[usize]) -> Vector3<f64> {
    thrusters
        .iter()
        .map(|&i| {
            Vector3::from(cfg.lander.rcs_positions_body_m[i])
                .cross(&Vector3::from(cfg.lander.rcs_directions_body[i]))
        })
        .sum()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}

#[test]
fn default_layout_gives_six_pure_couples_of_r_cross_f() {
    let cfg = ScenarioConfig::default();
    let arm_xy = 2.0; // 2 x the 1 m offset of the pods
    let arm_z = 2.0 * std::f64::consts::SQRT_2; // 2 x the pods' 1.414 m radius
    for (pair, axis, arm) in [
        ([0, 2], Vector3::x(), arm_xy),
        ([4, 6], -Vector3::x(), arm_xy),
        ([4, 2], Vector3::y(), arm_xy),
        ([0, 6], -Vector3::y(), arm_xy),
        ([1, 5], Vector3::z(), arm_z),
        ([3, 7], -Vector3::z(), arm_z),
    ] {
        let net: Vector3<f64> = pair
            .iter()
            .map(|&i| Vector3::from(cfg.lander.rcs_directions_body[i]))
            .sum();
        assert!(net.norm() < 1e-15, "pair {pair:?} nets {net}");
        let c = couple_per_newton(&cfg, &pair);
        assert!((c - axis * arm).norm() < 1e-15, "pair {pair:?}: {c}");
    }
    // With the thrust following the valve (tau = 0), a step inside the open window
    // gives the pair's torque r x F exactly.
    let mut lander = cfg.lander.clone();
    lander.rcs_time_constant_s = 0.0;
    let mut bank = ThrusterBank::from_config(&lander);
    let mut on = [0; THRUSTER_COUNT];
    on[0] = 16 * MS;
    on[2] = 16 * MS;
    bank.command(&on, 0);
    let before_open = bank.step(0, 5 * MS);
    assert_eq!(before_open.torque_body_nm, Vector3::zeros());
    let open = bank.step(5 * MS as i64, 10 * MS);
    println!(
        "+x pair, valve open: torque {:?} N m, force {:?} N",
        open.torque_body_nm, open.force_body_n
    );
    assert!((open.torque_body_nm - Vector3::new(2.0 * F_N, 0.0, 0.0)).norm() < 1e-12);
    assert!(open.force_body_n.norm() < 1e-12);
}

#[test]
fn one_couple_pulse_turns_the_vehicle_by_the_closed_form_impulse_at_any_tick() {
    let cfg = config();
    let on_ns = 14 * MS;
    let impulse_n_s = F_N * (on_ns as f64 * 1e-9 + CLOSE_S - OPEN_S);
    let want = couple_per_newton(&cfg, &[0, 2]) * impulse_n_s;
    let inertia = Vector3::from(cfg.lander.inertia_wet_kg_m2);
    let mut rates = Vec::new();
    for dt_ns in [MS, 10 * MS] {
        let p = one_pulse(&cfg, dt_ns, &[(0, on_ns), (2, on_ns)]);
        let h = p.state().rate_body_rad_s.component_mul(&inertia);
        println!(
            "dt {} ms: angular impulse {:.15e} N m s, closed form {:.15e}, rel err {:.1e}",
            dt_ns / MS,
            h.x,
            want.x,
            rel(h.x, want.x)
        );
        assert!(rel(h.x, want.x) < 1e-12);
        assert!(h.y.abs() < 1e-15 && h.z.abs() < 1e-15, "{h}");
        assert!(!p.thrusters().active());
        rates.push(p.state().rate_body_rad_s.x);
    }
    assert!(rel(rates[0], rates[1]) < 1e-13, "{rates:?}");
    // A pure couple: the centre of mass moves as if coasting.
    let coast = one_pulse(&cfg, MS, &[]);
    let p = one_pulse(&cfg, MS, &[(0, on_ns), (2, on_ns)]);
    let dv = (p.state().vel_mci_m_s - coast.state().vel_mci_m_s).norm();
    assert!(dv < 1e-12, "{dv}");
}

#[test]
fn propellant_used_is_the_impulse_over_isp_g0() {
    let cfg = config();
    let on_ns = 18 * MS;
    let p = one_pulse(&cfg, 10 * MS, &[(1, on_ns), (5, on_ns)]);
    let impulse_n_s = 2.0 * F_N * (on_ns as f64 * 1e-9 + CLOSE_S - OPEN_S);
    let want_kg = impulse_n_s / (cfg.lander.rcs_isp_s * G0_M_S2);
    println!(
        "propellant {:.15e} kg, closed form {want_kg:.15e}",
        p.rcs_propellant_used_kg()
    );
    assert!(rel(p.rcs_propellant_used_kg(), want_kg) < 1e-12);
    assert!(rel(p.propellant_used_kg(), want_kg) < 1e-9);
    // About z this time: (1, 5) is the +z couple.
    let h_z = p.state().rate_body_rad_s.z * cfg.lander.inertia_wet_kg_m2[2];
    assert!(rel(h_z, couple_per_newton(&cfg, &[1, 5]).z * impulse_n_s / 2.0) < 1e-12);
}

#[test]
fn below_the_minimum_on_time_nothing_fires_at_it_the_minimum_impulse_bit() {
    let cfg = config();
    let coast = one_pulse(&cfg, MS, &[]);
    let short = one_pulse(&cfg, MS, &[(0, 9_999_999), (2, 9_999_999)]);
    assert_eq!(short.state(), coast.state(), "a short pulse is not fired");
    assert_eq!(short.rcs_propellant_used_kg(), 0.0);
    let min_ns = (MIN_ON_S * 1e9) as u64;
    let p = one_pulse(&cfg, MS, &[(0, min_ns), (2, min_ns)]);
    let mib = F_N * (MIN_ON_S + CLOSE_S - OPEN_S);
    assert_eq!(
        ThrusterBank::from_config(&cfg.lander).minimum_impulse_bit_n_s(),
        mib
    );
    let h_x = p.state().rate_body_rad_s.x * cfg.lander.inertia_wet_kg_m2[0];
    println!("minimum impulse bit {mib} N s per thruster; pair gives {h_x:.15e} N m s");
    assert!(rel(h_x, 2.0 * mib) < 1e-12, "1 m arm x two thrusters' bits");
}

#[test]
fn a_command_held_over_a_missed_cycle_does_not_fire_again() {
    let cfg = config();
    let on = [(4, 12 * MS), (6, 12 * MS)];
    // Cycle 1 missed: the scheduler holds cycle 0's command, cycle start and all.
    let mut held = plant(&cfg);
    fly(&mut held, MS, 15, |k| match k {
        0 | 1 => pulse(&on, 0),
        _ => pulse(&[], (k * CYCLE_NS) as i64),
    });
    // The same on-times issued again for cycle 1 do fire twice.
    let mut twice = plant(&cfg);
    fly(&mut twice, MS, 15, |k| match k {
        0 | 1 => pulse(&on, (k * CYCLE_NS) as i64),
        _ => pulse(&[], (k * CYCLE_NS) as i64),
    });
    let once = F_N * (0.012 + CLOSE_S - OPEN_S) * couple_per_newton(&cfg, &[4, 6]).x;
    let i_x = cfg.lander.inertia_wet_kg_m2[0];
    let held_h = held.state().rate_body_rad_s.x * i_x;
    let twice_h = twice.state().rate_body_rad_s.x * i_x;
    println!("held: {held_h:.15e} N m s, re-issued: {twice_h:.15e}, one pulse: {once:.15e}");
    assert!(rel(held_h, once) < 1e-12);
    assert!(rel(twice_h, 2.0 * once) < 1e-12);
}

#[test]
fn thruster_mode_with_zero_on_times_coasts_bit_for_bit() {
    let cfg = ScenarioConfig::default();
    let mut ideal = plant(&cfg);
    let mut thrusters = plant(&cfg);
    for k in 0..500u64 {
        let start = (k * CYCLE_NS) as i64;
        for _ in 0..2 {
            ideal.step(&ActuatorCommand::default(), 10 * MS);
            thrusters.step(&pulse(&[], start), 10 * MS);
        }
    }
    assert_eq!(ideal.state(), thrusters.state());
    assert_eq!(thrusters.rcs_propellant_used_kg(), 0.0);
    let h = PacketHeader::new(1, 0, 0);
    assert_eq!(
        Devices::new(&cfg, 1).telemetry(&ideal, h).accel_body_m_s2,
        Devices::new(&cfg, 1)
            .telemetry(&thrusters, h)
            .accel_body_m_s2
    );
}

#[test]
fn one_thruster_through_the_centre_of_mass_pushes_by_its_impulse_over_mass() {
    let mut cfg = config();
    cfg.lander.rcs_positions_body_m[1] = [0.0; 3];
    let dt_ns = MS;
    let on_ns = 16 * MS;
    let coast = one_pulse(&cfg, dt_ns, &[]);
    let m0 = coast.state().mass_kg;
    let p = one_pulse(&cfg, dt_ns, &[(1, on_ns)]);
    assert_eq!(p.state().rate_body_rad_s, Vector3::zeros());
    let impulse_n_s = F_N * (on_ns as f64 * 1e-9 + CLOSE_S - OPEN_S);
    let d_body = Vector3::from(cfg.lander.rcs_directions_body[1]);
    let want = p.state().q_mci_from_body * d_body * (impulse_n_s / m0);
    let dv = p.state().vel_mci_m_s - coast.state().vel_mci_m_s;
    println!("dv {dv:?} m/s, closed form {want:?}");
    // The mass falls by ~2e-7 of itself over the pulse; gravity differs by ~1e-12.
    assert!((dv - want).norm() < 1e-6 * want.norm());

    // The specific force the IMU sees at a step's end: the thrust there, F x(t) / m,
    // with x(t) = 1 - exp(-(t - t_o) / tau) while the valve is open.
    let mut q = plant(&cfg);
    let c = pulse(&[(1, on_ns)], 0);
    for _ in 0..12 {
        q.step(&c, dt_ns);
    }
    let x = 1.0 - (-(0.012 - OPEN_S) / TAU_S).exp();
    let want_accel = d_body * (F_N * x / q.state().mass_kg);
    let accel = Vector3::from(
        Devices::new(&cfg, 1)
            .telemetry(&q, PacketHeader::new(1, 0, 0))
            .accel_body_m_s2,
    );
    assert!((accel - want_accel).norm() < 1e-12 * want_accel.norm());
}

#[test]
fn a_switch_back_to_ideal_torque_lets_the_pulse_finish() {
    let cfg = config();
    let on_ns = 20 * MS;
    let mut p = plant(&cfg);
    // The valve closes at 23 ms and the tail runs on into ideal-torque cycles.
    fly(&mut p, MS, 15, |k| {
        if k == 0 {
            pulse(&[(0, on_ns), (2, on_ns)], 0)
        } else {
            ActuatorCommand::default()
        }
    });
    let want = F_N * (0.020 + CLOSE_S - OPEN_S) * 2.0;
    let h_x = p.state().rate_body_rad_s.x * cfg.lander.inertia_wet_kg_m2[0];
    assert!(rel(h_x, want) < 1e-12, "{h_x} vs {want}");
    assert!(!p.thrusters().active());
}
