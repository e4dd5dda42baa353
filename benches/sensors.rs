//! Cost of one sample per sensor (`docs/sensors.md`, "Cost"): each device alone in a
//! suite, stepped at its own period so every `after_plant_step` takes one sample (and
//! `fill_frame` hands it over), 2 km above the default synthetic surface about the
//! Chandrayaan-3 site with the beams tilted 15 deg; plus the IMU's accumulation of one
//! plant step between samples.
//!
//! `cargo bench --bench sensors -- --warm-up-time 1 --measurement-time 3`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{UnitQuaternion, Vector3};
use oils_emulator::plant::ground::Ground;
use oils_emulator::sensors::{SensorSuite, SensorTruth, SensorsConfig};
use oils_emulator::world::terrain::{SiteFrame, SyntheticSpec, TerrainSpec};
use oils_shared::SensorFrame;
use std::hint::black_box;

const R_M: f64 = 1_737_400.0;

fn only(name: &str) -> SensorsConfig {
    let mut c = SensorsConfig::default();
    c.imu.enabled = name == "imu";
    c.star_tracker.enabled = name == "star_tracker";
    c.laser_altimeter.enabled = name == "laser_altimeter";
    c.rf_altimeter.enabled = name == "rf_altimeter";
    c.velocimeter.enabled = name == "velocimeter";
    for p in [
        &mut c.imu.latency_ms,
        &mut c.star_tracker.latency_ms,
        &mut c.laser_altimeter.latency_ms,
        &mut c.rf_altimeter.latency_ms,
        &mut c.velocimeter.latency_ms,
    ] {
        *p = 0.0;
    }
    c
}

fn period_ns(c: &SensorsConfig, name: &str) -> u64 {
    let ms = match name {
        "imu" => c.imu.period_ms,
        "star_tracker" => c.star_tracker.period_ms,
        "laser_altimeter" => c.laser_altimeter.period_ms,
        "rf_altimeter" => c.rf_altimeter.period_ms,
        _ => c.velocimeter.period_ms,
    };
    (ms * 1e6).round() as u64
}

fn samples(c: &mut Criterion) {
    let (lat, lon) = (-69.373, 32.319);
    let site = SiteFrame::from_deg(lat, lon, R_M);
    let spec = TerrainSpec::Synthetic(SyntheticSpec::default());
    let ground = Ground::new(&spec, lat, lon, R_M).expect("default synthetic builds");
    let [east, north, up] = site.axes_mcmf();
    let tilt = 15f64.to_radians();
    let z = up * tilt.cos() + east * tilt.sin();
    let q = oils_emulator::plant::frames::quaternion_from_axes(&north.cross(&z), &north, &z);
    let w = Vector3::new(0.01, -0.02, 0.005);
    for name in [
        "imu",
        "star_tracker",
        "laser_altimeter",
        "rf_altimeter",
        "velocimeter",
    ] {
        let cfg = only(name);
        let dt_ns = period_ns(&cfg, name);
        let mut suite = SensorSuite::new(&cfg, 1).unwrap();
        let mut frame = SensorFrame::default();
        let mut k = 0i64;
        c.bench_function(&format!("sensors/{name}_sample"), |b| {
            b.iter(|| {
                k += 1;
                let x = k as f64;
                let p = site.mcmf_from_site(&Vector3::new(
                    1500.0 * (0.37 * x).sin(),
                    1500.0 * (0.61 * x).cos(),
                    2000.0,
                ));
                let q0 = q * UnitQuaternion::from_scaled_axis(w * (x * 1e-3));
                let q1 = q0 * UnitQuaternion::from_scaled_axis(w * (dt_ns as f64 * 1e-9));
                let truth = SensorTruth {
                    t_ns: k * dt_ns as i64,
                    dt_ns,
                    pos_mci_m: p.into(),
                    vel_mci_m_s: [10.0, -20.0, 5.0],
                    q_start_mci_from_body: [q0.w, q0.i, q0.j, q0.k],
                    q_mci_from_body: [q1.w, q1.i, q1.j, q1.k],
                    rate_body_rad_s: w.into(),
                    specific_force_body_m_s2: [0.1, -0.2, 3.0],
                    moon_rotation_rate_rad_s: 0.0,
                    ground: &ground,
                };
                suite.after_plant_step(black_box(&truth));
                suite.fill_frame(k * dt_ns as i64, &mut frame);
                black_box(&frame);
            })
        });
    }

    // The IMU between samples: one 1 ms plant step accumulated (no sample taken).
    let cfg = only("imu");
    let mut suite = SensorSuite::new(&cfg, 1).unwrap();
    let mut k = 0i64;
    c.bench_function("sensors/imu_accumulate_step", |b| {
        b.iter(|| {
            // Steps at 1, 2, 3, 4 ms of each 5 ms period only: never a sample.
            k += 1;
            if k % 5 == 0 {
                k += 1;
            }
            let truth = SensorTruth {
                t_ns: k * 1_000_000,
                dt_ns: 1_000_000,
                pos_mci_m: [R_M + 2000.0, 0.0, 0.0],
                vel_mci_m_s: [10.0, -20.0, 5.0],
                q_start_mci_from_body: [1.0, 0.0, 0.0, 0.0],
                q_mci_from_body: [1.0, 1e-4, 0.0, 0.0],
                rate_body_rad_s: w.into(),
                specific_force_body_m_s2: [0.1, -0.2, 3.0],
                moon_rotation_rate_rad_s: 0.0,
                ground: &ground,
            };
            suite.after_plant_step(black_box(&truth));
        })
    });
}

criterion_group!(benches, samples);
criterion_main!(benches);
