//! The sensor models against closed forms (`docs/sensors.md`, "Tests"): IMU increments
//! on closed-form motions, bias and scale factor, Allan deviations of the simulated
//! noise, altimeter ranges on a tilted plane and over a crater, velocimeter projections,
//! one test per fault kind, timing and frame capacity. Fixed seeds throughout.

use nalgebra::{UnitQuaternion, Vector3};
use oils_emulator::config::ScenarioConfig;
use oils_emulator::faults::{FaultAction, FaultPlan, FaultSpec};
use oils_emulator::plant::frames::quaternion_from_axes;
use oils_emulator::plant::ground::Ground;
use oils_emulator::plant::{ActuatorCommand, Plant};
use oils_emulator::propulsion::{ideal::IdealPropulsion, EngineCommand};
use oils_emulator::sensors::{
    DeviceFault, ImuConfig, SensorSuite, SensorTarget, SensorTruth, SensorsConfig,
};
use oils_emulator::world::terrain::synthetic::crater_profile_m;
use oils_emulator::world::terrain::{Grid, SiteFrame, SyntheticSpec, Terrain};
use oils_shared::{
    AltimeterSample, ImuSample, SensorFrame, VelocimeterSample, SAMPLE_FLAG_INHIBITED,
    SAMPLE_FLAG_NO_LOCK, SAMPLE_FLAG_SATURATED,
};
use std::sync::Arc;

type V3 = Vector3<f64>;
type Uq = UnitQuaternion<f64>;

const R_M: f64 = 1_737_400.0;

/// The truth at one instant, from a closed-form motion.
#[derive(Clone, Copy)]
struct Kin {
    pos: V3,
    vel: V3,
    q: Uq,
    rate: V3,
    /// Specific force, body axes.
    f_body: V3,
}

fn arr4(q: &Uq) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Only the devices named, every other off.
fn only(imu: bool, st: bool, laser: bool, rf: bool, velo: bool) -> SensorsConfig {
    let mut c = SensorsConfig::default();
    c.imu.enabled = imu;
    c.star_tracker.enabled = st;
    c.laser_altimeter.enabled = laser;
    c.rf_altimeter.enabled = rf;
    c.velocimeter.enabled = velo;
    c
}

/// An IMU without any error but its quanta.
fn ideal_imu(gyro_quantum: f64, accel_quantum: f64) -> ImuConfig {
    ImuConfig {
        latency_ms: 0.0,
        gyro_bias_sigma_deg_h: 0.0,
        gyro_bias_instability_deg_h: 0.0,
        gyro_arw_deg_rt_h: 0.0,
        gyro_scale_factor_sigma_ppm: 0.0,
        gyro_misalignment_sigma_mrad: 0.0,
        gyro_quantum_rad: gyro_quantum,
        accel_bias_sigma_ug: 0.0,
        accel_bias_instability_ug: 0.0,
        accel_vrw_ug_rt_hz: 0.0,
        accel_scale_factor_sigma_ppm: 0.0,
        accel_misalignment_sigma_mrad: 0.0,
        accel_quantum_m_s: accel_quantum,
        ..ImuConfig::default()
    }
}

/// Steps the suite `steps` times by `dt_ns` along `motion(t_s)`, the frame filled after
/// every step; `each` sees every frame.
#[allow(clippy::too_many_arguments)]
fn drive(
    suite: &mut SensorSuite,
    ground: &Ground,
    moon_rate: f64,
    dt_ns: u64,
    steps: u64,
    motion: impl Fn(f64) -> Kin,
    mut before_step: impl FnMut(u64, &mut SensorSuite),
    mut each: impl FnMut(&SensorFrame),
) {
    let mut frame = SensorFrame::default();
    for k in 1..=steps {
        before_step(k, suite);
        let t_ns = (k * dt_ns) as i64;
        let t_s = t_ns as f64 * 1e-9;
        let dt_s = dt_ns as f64 * 1e-9;
        let start = motion(t_s - dt_s);
        let end = motion(t_s);
        let mid = motion(t_s - 0.5 * dt_s);
        let truth = SensorTruth {
            t_ns,
            dt_ns,
            pos_mci_m: end.pos.into(),
            vel_mci_m_s: end.vel.into(),
            q_start_mci_from_body: arr4(&start.q),
            q_mci_from_body: arr4(&end.q),
            rate_body_rad_s: end.rate.into(),
            specific_force_body_m_s2: mid.f_body.into(),
            moon_rotation_rate_rad_s: moon_rate,
            ground,
        };
        suite.after_plant_step(&truth);
        suite.fill_frame(t_ns, &mut frame);
        each(&frame);
    }
}

fn imu_samples(
    cfg: &SensorsConfig,
    seed: u64,
    dt_ns: u64,
    steps: u64,
    motion: impl Fn(f64) -> Kin,
) -> Vec<ImuSample> {
    let mut suite = SensorSuite::new(cfg, seed).unwrap();
    let ground = Ground::Sphere { radius_m: R_M };
    let mut out = Vec::new();
    drive(
        &mut suite,
        &ground,
        0.0,
        dt_ns,
        steps,
        motion,
        |_, _| {},
        |f| out.extend_from_slice(&f.imu[..f.imu_count as usize]),
    );
    out
}

fn at_rest(_t: f64) -> Kin {
    Kin {
        pos: V3::new(R_M + 1000.0, 0.0, 0.0),
        vel: V3::zeros(),
        q: Uq::identity(),
        rate: V3::zeros(),
        f_body: V3::zeros(),
    }
}

#[test]
fn imu_increments_integrate_a_constant_rotation_within_the_quantum() {
    let w = V3::new(0.1, -0.2, 0.3);
    let q0 = Uq::from_euler_angles(0.3, -0.2, 1.0);
    let q_of = |t: f64| q0 * Uq::from_scaled_axis(w * t);
    let quantum = 1e-6;
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(quantum, 1e-5);
    let samples = imu_samples(&cfg, 1, 1_000_000, 10_000, |t| Kin {
        q: q_of(t),
        rate: w,
        ..at_rest(t)
    });
    assert_eq!(samples.len(), 2000, "200 Hz for 10 s");
    let mut sum = V3::zeros();
    let mut q = q0;
    for s in &samples {
        let d = V3::from(s.delta_theta_body_rad);
        assert!((d - w * 0.005).amax() <= quantum, "{d:?}");
        assert_eq!(s.valid, 1);
        sum += d;
        q *= Uq::from_scaled_axis(d);
    }
    // The residual is carried: the sum strays from the truth by less than one quantum.
    let err = (sum - w * 10.0).amax();
    assert!(err <= quantum, "sum error {err:e} rad");
    let att_err = (q.inverse() * q_of(10.0)).angle();
    println!("constant rotation: sum error {err:.2e} rad, attitude error {att_err:.2e} rad");
    assert!(att_err < 2.0 * quantum, "attitude error {att_err:e} rad");
}

#[test]
fn imu_increments_integrate_a_constant_acceleration_within_the_quantum() {
    let f = V3::new(0.5, -1.0, 3.0);
    let quantum = 1e-5;
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(1e-6, quantum);
    let samples = imu_samples(&cfg, 2, 1_000_000, 10_000, |t| Kin {
        f_body: f,
        ..at_rest(t)
    });
    let sum: V3 = samples.iter().map(|s| V3::from(s.delta_v_body_m_s)).sum();
    let err = (sum - f * 10.0).amax();
    println!("constant acceleration: delta-v sum error {err:.2e} m/s");
    assert!(err <= quantum, "sum error {err:e} m/s");
}

#[test]
fn imu_delta_v_integrates_an_inertial_acceleration_while_turning() {
    // A body turning at a constant rate under a constant inertial specific force: the
    // delta-v of each period, rotated by the attitude at the period's start, sums to
    // the inertial velocity change.
    let w = V3::new(0.2, 0.05, -0.4);
    let q0 = Uq::from_euler_angles(-0.4, 0.2, 0.1);
    let f_i = V3::new(1.0, 2.0, -0.5);
    let q_of = |t: f64| q0 * Uq::from_scaled_axis(w * t);
    let quantum = 1e-6;
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(1e-7, quantum);
    let samples = imu_samples(&cfg, 3, 1_000_000, 10_000, |t| Kin {
        q: q_of(t),
        rate: w,
        f_body: q_of(t).inverse() * f_i,
        ..at_rest(t)
    });
    let mut dv_i = V3::zeros();
    for (k, s) in samples.iter().enumerate() {
        let q_start = q_of(k as f64 * 0.005);
        dv_i += q_start * V3::from(s.delta_v_body_m_s);
    }
    let err = (dv_i - f_i * 10.0).norm();
    println!("turning, inertial force: velocity error {err:.2e} m/s after 10 s");
    assert!(err < 50.0 * quantum, "velocity error {err:e} m/s");
}

#[test]
fn imu_bias_and_scale_factor_appear_as_configured() {
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(0.0, 0.0);
    cfg.imu.gyro_bias_deg_h = [1.0, -2.0, 3.0];
    cfg.imu.gyro_scale_factor_ppm = [100.0, 200.0, -300.0];
    cfg.imu.accel_bias_ug = [50.0, -100.0, 150.0];
    cfg.imu.accel_scale_factor_ppm = [-50.0, 400.0, 250.0];
    let w = V3::new(0.02, -0.03, 0.05);
    // Rotation about a fixed axis with the body force along that axis: both constant
    // in body axes, and the force unchanged by the turn within a period.
    let f = w * 30.0;
    let samples = imu_samples(&cfg, 4, 5_000_000, 200, |t| Kin {
        q: Uq::from_scaled_axis(w * t),
        rate: w,
        f_body: f,
        ..at_rest(t)
    });
    let n = samples.len() as f64;
    let mean_w = samples
        .iter()
        .map(|s| V3::from(s.delta_theta_body_rad))
        .sum::<V3>()
        / (n * 0.005);
    let mean_f = samples
        .iter()
        .map(|s| V3::from(s.delta_v_body_m_s))
        .sum::<V3>()
        / (n * 0.005);
    let deg_h = std::f64::consts::PI / 180.0 / 3600.0;
    let ug = 9.80665e-6;
    for i in 0..3 {
        let want_w = w[i] * (1.0 + cfg.imu.gyro_scale_factor_ppm[i] * 1e-6)
            + cfg.imu.gyro_bias_deg_h[i] * deg_h;
        let want_f =
            f[i] * (1.0 + cfg.imu.accel_scale_factor_ppm[i] * 1e-6) + cfg.imu.accel_bias_ug[i] * ug;
        assert!(
            (mean_w[i] - want_w).abs() < 1e-12,
            "gyro {i}: {} vs {want_w}",
            mean_w[i]
        );
        assert!(
            (mean_f[i] - want_f).abs() < 1e-11,
            "accel {i}: {} vs {want_f}",
            mean_f[i]
        );
    }
}

#[test]
fn imu_saturation_is_flagged_and_clamped() {
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(0.0, 0.0);
    cfg.imu.gyro_range_deg_s = 10.0;
    let w = V3::new(0.0, 0.0, 0.5); // 28.6 deg/s
    let samples = imu_samples(&cfg, 5, 5_000_000, 10, |t| Kin {
        q: Uq::from_scaled_axis(w * t),
        rate: w,
        ..at_rest(t)
    });
    for s in &samples {
        assert_ne!(s.flags & SAMPLE_FLAG_SATURATED, 0);
        assert!((s.delta_theta_body_rad[2] - 10f64.to_radians() * 0.005).abs() < 1e-15);
    }
}

/// Overlapping Allan deviation of rate samples at period `t0`, for cluster sizes `ms`.
fn overlapping_adev(increments: &[f64], t0: f64, ms: &[usize]) -> Vec<(f64, f64)> {
    let mut theta = Vec::with_capacity(increments.len() + 1);
    theta.push(0.0);
    let mut acc = 0.0;
    for d in increments {
        acc += d;
        theta.push(acc);
    }
    let n = increments.len();
    ms.iter()
        .map(|&m| {
            let tau = m as f64 * t0;
            let terms = n + 1 - 2 * m;
            let sum: f64 = (0..terms)
                .map(|j| {
                    let d = theta[j + 2 * m] - 2.0 * theta[j + m] + theta[j];
                    d * d
                })
                .sum();
            (tau, (sum / (2.0 * tau * tau * terms as f64)).sqrt())
        })
        .collect()
}

/// Allan deviation of a first-order Gauss-Markov rate of stationary sigma `s`,
/// correlation time `tc`.
fn gm_adev(s: f64, tc: f64, tau: f64) -> f64 {
    let x = tau / tc;
    s * ((2.0 * x - 3.0 + 4.0 * (-x).exp() - (-2.0 * x).exp()) / (x * x)).sqrt()
}

/// Runs the IMU at rest and returns the gyro-x and accel-z increments.
fn rest_record(cfg: &SensorsConfig, seconds: u64) -> (Vec<f64>, Vec<f64>) {
    let samples = imu_samples(cfg, 11, 5_000_000, seconds * 200, at_rest);
    (
        samples.iter().map(|s| s.delta_theta_body_rad[0]).collect(),
        samples.iter().map(|s| s.delta_v_body_m_s[2]).collect(),
    )
}

#[test]
fn allan_deviation_of_white_noise_is_the_configured_random_walk() {
    // Navigation grade (the defaults): ARW 0.005 deg/sqrt(h), VRW 30 ug/sqrt(Hz); no
    // bias instability or quantisation, so sigma(tau) sqrt(tau) = N at every tau.
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ImuConfig {
        gyro_arw_deg_rt_h: 0.005,
        accel_vrw_ug_rt_hz: 30.0,
        ..ideal_imu(0.0, 0.0)
    };
    let (g, a) = rest_record(&cfg, 3600);
    let n_g = 0.005f64.to_radians() / 60.0;
    let n_a = 30.0 * 9.80665e-6;
    let ms = [1, 10, 100, 1000, 2000];
    let mut worst: f64 = 0.0;
    for (name, x, n) in [("gyro", &g, n_g), ("accel", &a, n_a)] {
        for (tau, adev) in overlapping_adev(x, 0.005, &ms) {
            let ratio = adev / (n / tau.sqrt());
            println!("{name} white: tau {tau:>6} s  adev/expected {ratio:.4}");
            worst = worst.max((ratio - 1.0).abs());
        }
    }
    // One hour: at tau = 10 s the overlapping estimate has ~540 degrees of freedom,
    // a 1-sigma spread of ~3 %; the tolerance is 8 %.
    assert!(worst < 0.08, "worst ratio error {worst:.3}");
}

#[test]
fn allan_deviation_of_the_bias_shows_the_configured_instability() {
    // Bias instability only (B = 0.01 deg/h and 10 ug), its Gauss-Markov correlation
    // shortened to 10 s so two hours show the whole curve: the peak must sit at the
    // flicker floor 0.664 B, the curve on the Gauss-Markov closed form.
    let tc = 10.0;
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ImuConfig {
        gyro_bias_instability_deg_h: 0.01,
        gyro_bias_correlation_s: tc,
        accel_bias_instability_ug: 10.0,
        accel_bias_correlation_s: tc,
        ..ideal_imu(0.0, 0.0)
    };
    let (g, a) = rest_record(&cfg, 7200);
    let b_g = 0.01f64.to_radians() / 3600.0;
    let b_a = 10.0 * 9.80665e-6;
    let ms = [200, 600, 1000, 2000, 3780, 6000, 10_000, 20_000];
    for (name, x, b) in [("gyro", &g, b_g), ("accel", &a, b_a)] {
        let sigma = b * 0.664_282 / 0.617_364;
        let curve = overlapping_adev(x, 0.005, &ms);
        let mut peak: f64 = 0.0;
        for &(tau, adev) in &curve {
            let ratio = adev / gm_adev(sigma, tc, tau);
            println!("{name} GM: tau {tau:>6} s  adev/closed-form {ratio:.4}");
            assert!(
                (ratio - 1.0).abs() < 0.15,
                "{name} tau {tau}: ratio {ratio:.3}"
            );
            peak = peak.max(adev);
        }
        let floor = peak / (0.664_282 * b);
        println!("{name} GM: peak / (0.664 B) = {floor:.4}");
        assert!((floor - 1.0).abs() < 0.10, "{name}: peak ratio {floor:.3}");
    }
}

/// A flat world (the tangent plane at the site, optionally with a grid on it).
fn flat_ground(grid: Option<Grid>) -> (Ground, SiteFrame) {
    let site = SiteFrame::from_deg(0.0, 0.0, R_M);
    let terrain = Terrain::new(grid, f64::INFINITY).unwrap();
    (Ground::from_terrain(Arc::new(terrain), site), site)
}

/// Body axes tilted by `theta` about the site's north: body +Z from up towards east.
fn tilted(site: &SiteFrame, theta: f64) -> Uq {
    let [east, north, up] = site.axes_mcmf();
    let z = up * theta.cos() + east * theta.sin();
    let x = north.cross(&z);
    quaternion_from_axes(&x, &north, &z)
}

fn altimeter_samples(
    cfg: &SensorsConfig,
    ground: &Ground,
    steps: u64,
    motion: impl Fn(f64) -> Kin,
    faults: impl FnMut(u64, &mut SensorSuite),
) -> (
    Vec<AltimeterSample>,
    Vec<AltimeterSample>,
    Vec<VelocimeterSample>,
) {
    let mut suite = SensorSuite::new(cfg, 21).unwrap();
    let (mut la, mut rf, mut v) = (Vec::new(), Vec::new(), Vec::new());
    drive(
        &mut suite,
        ground,
        0.0,
        10_000_000,
        steps,
        motion,
        faults,
        |f| {
            la.extend_from_slice(&f.laser_altimeter[..f.laser_altimeter_count as usize]);
            rf.extend_from_slice(&f.rf_altimeter[..f.rf_altimeter_count as usize]);
            v.extend_from_slice(&f.velocimeter[..f.velocimeter_count as usize]);
        },
    );
    (la, rf, v)
}

fn quiet_laser(cfg: &mut SensorsConfig) {
    let l = &mut cfg.laser_altimeter;
    l.noise_frac = 0.0;
    l.noise_m = 0.0;
    l.latency_ms = 0.0;
    l.position_body_m = [0.0; 3];
}

#[test]
fn laser_range_over_a_tilted_plane_is_h_over_cos_theta_and_locks_off_at_grazing() {
    let (ground, site) = flat_ground(None);
    let h = 1500.0;
    let mut cfg = only(false, false, true, false, false);
    quiet_laser(&mut cfg);
    cfg.laser_altimeter.max_incidence_deg = 60.0;
    let mut worst: f64 = 0.0;
    for theta_deg in [0.0, 10.0, 25.0, 45.0, 59.0, 61.0, 75.0] {
        let theta = f64::to_radians(theta_deg);
        let (la, _, _) = altimeter_samples(
            &cfg,
            &ground,
            10,
            |_| Kin {
                pos: site.mcmf_from_site(&V3::new(0.0, 0.0, h)),
                q: tilted(&site, theta),
                ..at_rest(0.0)
            },
            |_, _| {},
        );
        assert_eq!(la.len(), 1);
        let s = la[0];
        if theta_deg < 60.0 {
            assert_eq!(s.valid, 1, "{theta_deg} deg");
            let err = (s.range_m - h / theta.cos()).abs();
            worst = worst.max(err);
        } else {
            assert_eq!(
                (s.valid, s.flags, s.range_m),
                (0, SAMPLE_FLAG_NO_LOCK, 0.0),
                "{theta_deg} deg"
            );
        }
    }
    println!("tilted plane: worst |range - h/cos(theta)| = {worst:.2e} m");
    assert!(worst < 1e-5, "{worst:e}");
}

#[test]
fn laser_range_over_a_crater_follows_its_profile() {
    // One fresh 100 m crater (Pike shape) at the site on a 0.5 m grid; the beam points
    // straight down from 200 m as the vehicle crosses it east to west.
    let spec = SyntheticSpec::default();
    let half = 200.0;
    let spacing = 0.5;
    let side = (2.0 * half / spacing) as usize + 1;
    let mut h = Vec::with_capacity(side * side);
    for j in 0..side {
        for i in 0..side {
            let (e, n) = (-half + spacing * i as f64, -half + spacing * j as f64);
            h.push(crater_profile_m(&spec, 100.0, e.hypot(n)));
        }
    }
    let grid = Grid::new(side, side, -half, -half, spacing, h).unwrap();
    let (ground, site) = flat_ground(Some(grid));
    let mut cfg = only(false, false, true, true, false);
    quiet_laser(&mut cfg);
    cfg.laser_altimeter.period_ms = 10.0;
    cfg.laser_altimeter.max_incidence_deg = 90.0;
    let r = &mut cfg.rf_altimeter;
    r.noise_frac = 0.0;
    r.noise_m = 0.0;
    r.latency_ms = 0.0;
    r.period_ms = 10.0;
    r.position_body_m = [0.0; 3];
    r.max_incidence_deg = 90.0;
    let height = 200.0;
    let speed = 10.0; // m/s westward from e = 150
    let e_of = |t: f64| 150.0 - speed * t;
    let (la, rf, _) = altimeter_samples(
        &cfg,
        &ground,
        3000,
        |t| Kin {
            pos: site.mcmf_from_site(&V3::new(e_of(t), 0.0, height)),
            q: tilted(&site, 0.0),
            ..at_rest(t)
        },
        |_, _| {},
    );
    assert_eq!(la.len(), 3000);
    let mut worst: f64 = 0.0;
    let mut deepest: f64 = 0.0;
    for s in &la {
        let e = e_of(s.t_ns as f64 * 1e-9);
        let want = height - crater_profile_m(&spec, 100.0, e.abs());
        worst = worst.max((s.range_m - want).abs());
        deepest = deepest.max(s.range_m);
    }
    println!("crater: worst |range - profile| = {worst:.2e} m, deepest range {deepest:.2} m");
    // Bilinear interpolation of the parabolic bowl: s^2 h''/8 = 5e-4 m.
    assert!(worst < 2e-3, "{worst:e}");
    assert!(
        (deepest - (height + 0.16 * 100.0)).abs() < 0.01,
        "floor {deepest}"
    );
    // The RF cone returns the nearest surface: never farther than the centre ray.
    for (l, r) in la.iter().zip(&rf) {
        assert!(
            r.range_m <= l.range_m + 1e-6,
            "{} > {}",
            r.range_m,
            l.range_m
        );
    }
    // Over the rim the cone sees the rim before the centre does.
    assert!(la.iter().zip(&rf).any(|(l, r)| r.range_m < l.range_m - 1.0));
}

#[test]
fn velocimeter_reads_the_projections_of_the_velocity_relative_to_the_turning_ground() {
    let (ground, site) = flat_ground(None);
    let omega_moon = 2.6617e-6;
    let mut cfg = only(false, false, false, false, true);
    let v = &mut cfg.velocimeter;
    v.velocity_noise_m_s = 0.0;
    v.range_noise_frac = 0.0;
    v.range_noise_m = 0.0;
    v.latency_ms = 0.0;
    v.position_body_m = [0.3, -0.2, -0.8];
    let lever = V3::from(v.position_body_m);
    let beams = v.beams_body.map(|b| V3::from(b).normalize());
    let q = tilted(&site, 0.2) * Uq::from_euler_angles(0.05, -0.1, 0.7);
    let rate = V3::new(0.01, -0.02, 0.03);
    let t_s = 0.1;
    // Moon-fixed position at t; mci = Rz(+omega t) mcmf.
    let to_mci = nalgebra::Rotation3::from_axis_angle(&V3::z_axis(), omega_moon * t_s);
    let pos = to_mci * site.mcmf_from_site(&V3::new(20.0, -30.0, 800.0));
    let vel = V3::new(-12.0, 35.0, 4.0);
    let mut suite = SensorSuite::new(&cfg, 5).unwrap();
    let mut got = None;
    drive(
        &mut suite,
        &ground,
        omega_moon,
        100_000_000,
        1,
        |_| Kin {
            pos,
            vel,
            q,
            rate,
            f_body: V3::zeros(),
        },
        |_, _| {},
        |f| {
            if f.velocimeter_count > 0 {
                got = Some(f.velocimeter[0]);
            }
        },
    );
    let s = got.expect("one sample at 10 Hz");
    let origin = pos + q * lever;
    let v_head = vel + q * rate.cross(&lever);
    let v_rel = v_head - V3::new(0.0, 0.0, omega_moon).cross(&origin);
    let up_mci = to_mci * site.up_mcmf();
    let height = (to_mci.inverse() * origin - site.origin_mcmf()).dot(&site.up_mcmf());
    for (b, beam) in beams.iter().enumerate() {
        let u = q * beam;
        let want_v = v_rel.dot(&u);
        let want_r = height / -u.dot(&up_mci);
        assert_eq!(s.valid[b], 1);
        println!(
            "beam {b}: los {:.9} vs {want_v:.9} m/s, range {:.6} vs {want_r:.6} m",
            s.los_velocity_m_s[b], s.range_m[b]
        );
        assert!((s.los_velocity_m_s[b] - want_v).abs() < 1e-9);
        assert!((s.range_m[b] - want_r).abs() < 1e-5);
    }
    // The Moon's turning matters: ~4.6 m/s at the equator.
    assert!((vel - v_rel).norm() > 4.0);
}

/// One laser altimeter over a plane, 100 samples at 10 Hz, with faults set by
/// `faults(step, suite)`; returns the samples.
fn laser_with_faults(faults: impl FnMut(u64, &mut SensorSuite)) -> Vec<AltimeterSample> {
    let (ground, site) = flat_ground(None);
    let mut cfg = only(false, false, true, false, false);
    cfg.laser_altimeter.latency_ms = 0.0;
    cfg.laser_altimeter.position_body_m = [0.0; 3];
    // Descending at 10 m/s from 1000 m: each sample differs.
    altimeter_samples(
        &cfg,
        &ground,
        1000,
        |t| Kin {
            pos: site.mcmf_from_site(&V3::new(0.0, 0.0, 1000.0 - 10.0 * t)),
            q: tilted(&site, 0.0),
            ..at_rest(t)
        },
        faults,
    )
    .0
}

/// `fault` set before step 301 and cleared before step 601: the samples of
/// t in (3 s, 6 s] see it.
fn windowed(target: SensorTarget, fault: DeviceFault) -> impl FnMut(u64, &mut SensorSuite) {
    move |k, suite| {
        if k == 301 {
            suite.set_fault(target, fault, true);
        }
        if k == 601 {
            suite.set_fault(target, fault, false);
        }
    }
}

fn in_window(s: &AltimeterSample) -> bool {
    s.t_ns > 3_000_000_000 && s.t_ns <= 6_000_000_000
}

#[test]
fn fault_bias_adds_its_value_while_active() {
    let clean = laser_with_faults(|_, _| {});
    let t = SensorTarget::LaserAltimeter;
    let biased = laser_with_faults(windowed(t, DeviceFault::Bias { value: 50.0 }));
    for (c, b) in clean.iter().zip(&biased) {
        let want = if in_window(c) { 50.0 } else { 0.0 };
        assert!((b.range_m - c.range_m - want).abs() < 1e-9, "t {}", c.t_ns);
    }
}

#[test]
fn fault_noise_scales_the_devices_own_noise() {
    let clean = laser_with_faults(|_, _| {});
    let t = SensorTarget::LaserAltimeter;
    let noisy = laser_with_faults(windowed(t, DeviceFault::Noise { factor: 10.0 }));
    for (c, n) in clean.iter().zip(&noisy) {
        let truth = 1000.0 - 10.0 * c.t_ns as f64 * 1e-9;
        let k = if in_window(c) { 10.0 } else { 1.0 };
        assert!(
            ((n.range_m - truth) - k * (c.range_m - truth)).abs() < 1e-6,
            "t {}",
            c.t_ns
        );
    }
}

#[test]
fn fault_dropout_withholds_samples_while_active() {
    let t = SensorTarget::LaserAltimeter;
    let s = laser_with_faults(windowed(t, DeviceFault::Dropout));
    assert_eq!(s.len(), 100 - 30);
    assert!(s.iter().all(|s| !in_window(s)));
}

#[test]
fn fault_frozen_repeats_the_last_sample_before_it() {
    let t = SensorTarget::LaserAltimeter;
    let s = laser_with_faults(windowed(t, DeviceFault::Frozen));
    let before = s.iter().rfind(|s| s.t_ns <= 3_000_000_000).unwrap().range_m;
    for x in s.iter().filter(|s| in_window(s)) {
        assert_eq!((x.range_m, x.valid), (before, 1));
    }
    assert!(
        s.last().unwrap().range_m < before - 30.0,
        "moves again once cleared"
    );
}

#[test]
fn fault_spike_hits_one_sample_only() {
    let clean = laser_with_faults(|_, _| {});
    let t = SensorTarget::LaserAltimeter;
    let spiked = laser_with_faults(windowed(t, DeviceFault::Spike { value: -300.0 }));
    let diffs: Vec<f64> = clean
        .iter()
        .zip(&spiked)
        .map(|(c, s)| s.range_m - c.range_m)
        .collect();
    assert_eq!(diffs.iter().filter(|d| d.abs() > 1e-9).count(), 1);
    let k = diffs.iter().position(|d| d.abs() > 1e-9).unwrap();
    assert!((diffs[k] + 300.0).abs() < 1e-9);
    assert_eq!(
        clean[k].t_ns, 3_100_000_000,
        "the first sample after it fired"
    );
}

#[test]
fn fault_inhibited_marks_samples_invalid() {
    let t = SensorTarget::LaserAltimeter;
    let s = laser_with_faults(windowed(t, DeviceFault::Inhibited));
    assert_eq!(s.len(), 100);
    for x in &s {
        if in_window(x) {
            assert_eq!(
                (x.valid, x.flags, x.range_m),
                (0, SAMPLE_FLAG_INHIBITED, 0.0)
            );
        } else {
            assert_eq!(x.valid, 1);
        }
    }
}

#[test]
fn imu_faults_act_on_their_half() {
    let mut cfg = only(true, false, false, false, false);
    cfg.imu = ideal_imu(0.0, 0.0);
    let mut suite = SensorSuite::new(&cfg, 9).unwrap();
    let ground = Ground::Sphere { radius_m: R_M };
    let mut got = Vec::new();
    drive(
        &mut suite,
        &ground,
        0.0,
        5_000_000,
        40,
        |t| Kin {
            f_body: V3::new(0.0, 0.0, 2.0),
            ..at_rest(t)
        },
        |k, s| {
            if k == 11 {
                s.set_fault(
                    SensorTarget::ImuGyro,
                    DeviceFault::Bias { value: 1e-3 },
                    true,
                );
            }
            if k == 21 {
                s.set_fault(SensorTarget::ImuAccel, DeviceFault::Frozen, true);
            }
            if k == 31 {
                s.set_fault(SensorTarget::Imu, DeviceFault::Inhibited, true);
            }
        },
        |f| got.extend_from_slice(&f.imu[..f.imu_count as usize]),
    );
    assert_eq!(got.len(), 40);
    assert_eq!(got[5].delta_theta_body_rad, [0.0; 3]);
    assert!((got[15].delta_theta_body_rad[1] - 5e-6).abs() < 1e-18);
    assert!((got[15].delta_v_body_m_s[2] - 0.01).abs() < 1e-12);
    assert_eq!(got[25].delta_v_body_m_s, got[19].delta_v_body_m_s);
    assert_eq!((got[35].valid, got[35].flags), (0, SAMPLE_FLAG_INHIBITED));
}

#[test]
fn device_faults_parse_compile_and_reach_the_suite() {
    for (s, target, fault) in [
        (
            "sensor-inhibit:laser-altimeter@t=0",
            SensorTarget::LaserAltimeter,
            DeviceFault::Inhibited,
        ),
        (
            "sensor-bias:imu-gyro,value=0.001@t=1",
            SensorTarget::ImuGyro,
            DeviceFault::Bias { value: 0.001 },
        ),
        (
            "sensor-noise:rf-altimeter,factor=5@alt=3000",
            SensorTarget::RfAltimeter,
            DeviceFault::Noise { factor: 5.0 },
        ),
        (
            "sensor-dropout:imu@random,p=0.5,window=10..20,for=1",
            SensorTarget::Imu,
            DeviceFault::Dropout,
        ),
        (
            "sensor-frozen:velocimeter@t=3",
            SensorTarget::Velocimeter,
            DeviceFault::Frozen,
        ),
        (
            "sensor-spike:star-tracker,value=200@t=2",
            SensorTarget::StarTracker,
            DeviceFault::Spike { value: 200.0 },
        ),
    ] {
        let spec: FaultSpec = s.parse().unwrap_or_else(|e| panic!("{s}: {e}"));
        assert_eq!(spec.to_string(), s);
        assert_eq!(
            FaultAction::of(&spec),
            Some(FaultAction::Device(target, fault)),
            "{s}"
        );
    }
    for (s, needle) in [
        ("sensor-bias:imu,value=1@t=1", "imu-gyro"),
        ("sensor-spike:altitude_m,value=1@t=1", "acts on a device"),
        ("sensor-inhibit:altitude_m@t=1", "acts on a device"),
        (
            "sensor-noise:rf-altimeter,sigma=1@t=1",
            "unknown parameter `sigma` (takes: factor)",
        ),
        ("sensor-noise:rf-altimeter,factor=0@t=1", "out of its range"),
        ("sensor-bias:warp-drive,value=1@t=1", "laser-altimeter"),
        ("sensor-spike:velocimeter@t=1", "needs value"),
    ] {
        let e = s.parse::<FaultSpec>().unwrap_err();
        assert!(e.contains(needle), "{s}: {e}");
    }
    // The telemetry-field form is unchanged.
    let f: FaultSpec = "sensor-noise:altitude_m,sigma=2@t=1".parse().unwrap();
    assert!(matches!(FaultAction::of(&f), Some(FaultAction::Sensor(..))));

    // Through the plan: fires at t = 3 s, clears 2 s later.
    let spec: FaultSpec = "sensor-inhibit:laser-altimeter@t=3,for=2".parse().unwrap();
    let mut plan = FaultPlan::compile(&[spec], 1).unwrap();
    assert!(plan.device_fault(0).is_some());
    let (ground, site) = flat_ground(None);
    let mut cfg = only(false, false, true, false, false);
    cfg.laser_altimeter.latency_ms = 0.0;
    let mut suite = SensorSuite::new(&cfg, 1).unwrap();
    let mut got = Vec::new();
    drive(
        &mut suite,
        &ground,
        0.0,
        10_000_000,
        1000,
        |_| Kin {
            pos: site.mcmf_from_site(&V3::new(0.0, 0.0, 500.0)),
            q: tilted(&site, 0.0),
            ..at_rest(0.0)
        },
        |k, s| {
            let (fired, cleared) = plan.advance(k, (k * 10_000_000) as i64, 500.0);
            plan.apply_device_faults(fired, cleared, s);
        },
        |f| got.extend_from_slice(&f.laser_altimeter[..f.laser_altimeter_count as usize]),
    );
    let inhibited = got
        .iter()
        .filter(|s| s.flags == SAMPLE_FLAG_INHIBITED)
        .count();
    assert_eq!(inhibited, 20, "2 s at 10 Hz");
}

#[test]
fn star_tracker_noise_and_outages() {
    let mut cfg = only(false, true, false, false, false);
    cfg.star_tracker.latency_ms = 0.0;
    cfg.star_tracker.boresight_body = [0.0, 0.0, 1.0];
    cfg.star_tracker.outage_start_s = vec![100.0];
    cfg.star_tracker.outage_duration_s = vec![50.0];
    let q = Uq::from_euler_angles(0.1, 0.2, 0.3);
    let mut suite = SensorSuite::new(&cfg, 3).unwrap();
    let ground = Ground::Sphere { radius_m: R_M };
    let mut got = Vec::new();
    drive(
        &mut suite,
        &ground,
        0.0,
        100_000_000,
        4000,
        |t| Kin { q, ..at_rest(t) },
        |_, _| {},
        |f| got.extend_from_slice(&f.star_tracker[..f.star_tracker_count as usize]),
    );
    assert_eq!(got.len(), 2000);
    let (mut sx, mut sz, mut n) = (0.0, 0.0, 0.0);
    for s in &got {
        let t = s.t_ns as f64 * 1e-9;
        if (100.0..150.0).contains(&t) {
            assert_eq!(s.valid, 0);
            continue;
        }
        let e = (q.inverse() * oils_emulator::sensors::quat_of(&s.q_mci_from_body)).scaled_axis();
        sx += e.x * e.x;
        sz += e.z * e.z;
        n += 1.0;
    }
    let arcsec = std::f64::consts::PI / 648_000.0;
    let (cross, about) = ((sx / n).sqrt() / arcsec, (sz / n).sqrt() / arcsec);
    println!("star tracker: cross-boresight {cross:.2} arcsec (5), about boresight {about:.2} arcsec (30)");
    assert!((cross / 5.0 - 1.0).abs() < 0.06 && (about / 30.0 - 1.0).abs() < 0.06);
}

#[test]
fn samples_arrive_after_their_latency_and_overflow_is_counted() {
    let mut cfg = only(true, false, true, false, false);
    cfg.imu.latency_ms = 2.0;
    cfg.laser_altimeter.latency_ms = 30.0;
    let ground = Ground::Sphere { radius_m: R_M };
    // Frames every 50 ms: 10 IMU samples due, 8 fit.
    let mut suite = SensorSuite::new(&cfg, 1).unwrap();
    let mut frame = SensorFrame::default();
    let mut seen = Vec::new();
    for k in 1..=500u64 {
        let t_ns = k as i64 * 1_000_000;
        let truth = SensorTruth {
            t_ns,
            dt_ns: 1_000_000,
            pos_mci_m: [R_M + 1000.0, 0.0, 0.0],
            vel_mci_m_s: [0.0; 3],
            q_start_mci_from_body: [1.0, 0.0, 0.0, 0.0],
            q_mci_from_body: [1.0, 0.0, 0.0, 0.0],
            rate_body_rad_s: [0.0; 3],
            specific_force_body_m_s2: [0.0; 3],
            moon_rotation_rate_rad_s: 0.0,
            ground: &ground,
        };
        suite.after_plant_step(&truth);
        if k % 50 == 0 {
            suite.fill_frame(t_ns, &mut frame);
            for s in &frame.imu[..frame.imu_count as usize] {
                assert!(s.t_ns + 2_000_000 <= t_ns);
                seen.push(s.t_ns);
            }
            for s in &frame.laser_altimeter[..frame.laser_altimeter_count as usize] {
                assert!(s.t_ns + 30_000_000 <= t_ns);
            }
            assert_eq!(frame.imu_count, 8);
            assert!(
                frame.imu[..8].windows(2).all(|w| w[0].t_ns < w[1].t_ns),
                "oldest first"
            );
        }
    }
    // 100 IMU samples in 0.5 s, the two newest due in each of 10 frames do not fit
    // (the first frame has 9 due: the one at 50 ms is 2 ms short of delivery).
    let d = suite.dropped();
    println!("dropped: {d:?}");
    assert_eq!(d.imu as usize + seen.len() + 1, 100);
    assert_eq!(d.laser_altimeter, 0);
}

#[test]
fn rate_checks_name_the_device() {
    let cfg = SensorsConfig::default();
    cfg.check_rates(1_000_000, 10_000_000).unwrap();
    cfg.check_rates(5_000_000, 40_000_000).unwrap();
    let e = cfg.check_rates(10_000_000, 10_000_000).unwrap_err();
    assert_eq!(e.field, "sensors.imu.period_ms");
    assert!(e.to_string().contains("whole multiple"), "{e}");
    let e = cfg.check_rates(5_000_000, 100_000_000).unwrap_err();
    assert_eq!(e.field, "sensors.imu.period_ms");
    assert!(e.to_string().contains("frame holds 8"), "{e}");
    let mut c = SensorsConfig::default();
    c.imu.enabled = false;
    let e = c.check_rates(10_000_000, 1_000_000_000).unwrap_err();
    assert_eq!(e.field, "sensors.star_tracker.period_ms");
    let mut c = SensorsConfig::default();
    c.rf_altimeter.period_ms = 0.0;
    assert_eq!(
        c.validate().unwrap_err().field,
        "sensors.rf_altimeter.period_ms"
    );
    c = SensorsConfig::default();
    c.star_tracker.outage_start_s = vec![1.0];
    assert_eq!(
        c.validate().unwrap_err().field,
        "sensors.star_tracker.outage_duration_s"
    );
    assert!(SensorsConfig::default().summary().contains("imu"));
}

#[test]
fn scenario_table_parses_and_refuses_bad_arrays_by_name() {
    let c: ScenarioConfig = toml::from_str(
        "[sensors.laser_altimeter]\nperiod_ms = 50.0\nbeam_body = [0.0, 0.1, -1.0]\n[sensors.imu]\nenabled = false\n",
    )
    .unwrap();
    assert_eq!(c.sensors.laser_altimeter.period_ms, 50.0);
    assert_eq!(
        c.sensors.laser_altimeter.noise_m, 0.5,
        "other fields keep defaults"
    );
    assert!(!c.sensors.imu.enabled);
    c.validate().unwrap();
    let e = toml::from_str::<ScenarioConfig>(
        "[sensors.velocimeter]\nbeams_body = [[0.0, 0.0, -1.0], [0.0, 0.0, -1.0]]\n",
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("`sensors.velocimeter.beams_body` has 2 elements, expected 3"),
        "{e}"
    );
    assert!(toml::from_str::<ScenarioConfig>("[sensors.imu]\nwarp = 1\n").is_err());
}

#[test]
fn each_device_draws_from_its_own_stream() {
    // The IMU's samples do not change when the other devices are switched off.
    let run = |cfg: &SensorsConfig| imu_samples(cfg, 77, 5_000_000, 400, at_rest);
    let all = run(&SensorsConfig::default());
    let alone = run(&only(true, false, false, false, false));
    assert_eq!(all, alone);
    assert_ne!(
        all,
        imu_samples(&SensorsConfig::default(), 78, 5_000_000, 400, at_rest)
    );
}

#[test]
fn the_plants_truth_senses_free_fall_as_zero_and_thrust_as_thrust_over_mass() {
    let scenario = ScenarioConfig::default();
    let mut plant = Plant::new(
        &scenario,
        Box::new(IdealPropulsion::new(&scenario.propulsion)),
    )
    .unwrap();
    let mut cfg = only(true, false, true, true, true);
    cfg.imu = ideal_imu(0.0, 0.0);
    let mut suite = SensorSuite::new(&cfg, 1).unwrap();
    let mut frame = SensorFrame::default();
    let off = ActuatorCommand::default();
    let mut worst_free: f64 = 0.0;
    for k in 1..=1000i64 {
        plant.step(&off, 1_000_000);
        suite.after_plant_step(&plant.sensor_truth());
        suite.fill_frame(k * 1_000_000, &mut frame);
        for s in &frame.imu[..frame.imu_count as usize] {
            worst_free = worst_free.max(V3::from(s.delta_v_body_m_s).amax());
        }
    }
    println!("free fall: largest delta-v component {worst_free:.2e} m/s per 5 ms");
    assert!(worst_free < 1e-9);
    // 30 km up: the altimeters are beyond their range, no lock.
    assert_eq!(frame.laser_altimeter_count + frame.rf_altimeter_count, 0);
    let on = ActuatorCommand {
        engines: EngineCommand {
            thrust_cmd_n: [800.0; 4],
            on: [true; 4],
        },
        ..Default::default()
    };
    let mut last = None;
    for k in 1001..=3000i64 {
        plant.step(&on, 1_000_000);
        suite.after_plant_step(&plant.sensor_truth());
        suite.fill_frame(k * 1_000_000, &mut frame);
        if frame.imu_count > 0 {
            last = Some(frame.imu[frame.imu_count as usize - 1]);
        }
    }
    let s = last.unwrap();
    let thrust: f64 = plant.propulsion_output().thrust_n.iter().sum();
    let want = thrust / plant.state().mass_kg * 0.005;
    println!(
        "thrusting: delta-v z {:.6e} vs thrust/mass T {want:.6e} m/s",
        s.delta_v_body_m_s[2]
    );
    assert!((s.delta_v_body_m_s[2] / want - 1.0).abs() < 1e-3);
    assert!(s.delta_v_body_m_s[0].abs() < 1e-9 && s.delta_v_body_m_s[1].abs() < 1e-9);
}
