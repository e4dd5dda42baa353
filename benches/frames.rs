//! Cost of one frame (`docs/sensors.md`, "Cost of a frame"): the navigation camera at
//! 1024 x 1024 with the fast renderer and the shadow map over the default synthetic
//! surface, at 5 km, 1 km, 100 m and 10 m above it, the boresight 15 deg off nadir,
//! the sun 12 deg high; the flash lidar (128 x 128) at 500 m; building the shadow map.
//!
//! `cargo bench --bench frames -- --warm-up-time 1 --measurement-time 5`

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use oils_emulator::plant::ground::Ground;
use oils_emulator::sensors::camera::{looking_along, still_truth, ShadowMap, ShadowMapConfig};
use oils_emulator::sensors::{Camera, CameraConfig, Lidar, LidarConfig};
use oils_emulator::world::terrain::{SiteFrame, SyntheticSpec, TerrainSpec};
use std::hint::black_box;
use std::sync::Arc;

const R_M: f64 = 1_737_400.0;

fn frames(c: &mut Criterion) {
    let (lat, lon) = (-69.373, 32.319);
    let site = SiteFrame::from_deg(lat, lon, R_M);
    let spec = TerrainSpec::Synthetic(SyntheticSpec::default());
    let ground = Ground::new(&spec, lat, lon, R_M).expect("default synthetic builds");
    let Ground::Terrain { terrain, .. } = &ground else {
        unreachable!()
    };
    let [east, north, up] = site.axes_mcmf();
    let (el, az) = (12f64.to_radians(), 100f64.to_radians());
    let sun = site.mcmf_dir_from_site(&Vector3::new(
        el.cos() * az.sin(),
        el.cos() * az.cos(),
        el.sin(),
    ));
    let tilt = 15f64.to_radians();
    let look = -up * tilt.cos() + north * tilt.sin();
    let q = looking_along(&look, &east);

    let mut g = c.benchmark_group("frames");
    g.sample_size(10);
    g.bench_function("shadow_map_build", |b| {
        b.iter(|| black_box(ShadowMap::build(&ground, &sun, &ShadowMapConfig::default()).unwrap()))
    });
    let map = Arc::new(ShadowMap::build(&ground, &sun, &ShadowMapConfig::default()).unwrap());
    let mut cam = Camera::new(
        &CameraConfig {
            enabled: true,
            ..CameraConfig::default()
        },
        1,
    )
    .unwrap();
    cam.set_shadow_map(Some(map));
    let mut out = vec![0u8; cam.frame_bytes()];
    for (name, h) in [
        ("5km", 5000.0),
        ("1km", 1000.0),
        ("100m", 100.0),
        ("10m", 10.0),
    ] {
        let (e, n) = (-h * tilt.tan(), 0.0);
        let p = site.mcmf_from_site(&terrain.map().site_of_map(
            e,
            n,
            terrain.elevation_m(e, n) + h,
        ));
        let truth = still_truth(&ground, &p, &q, 0);
        g.bench_function(format!("camera_1024_{name}"), |b| {
            b.iter(|| black_box(cam.render(black_box(&truth), &sun, &mut out).unwrap()))
        });
    }
    let mut lidar = Lidar::new(
        &LidarConfig {
            enabled: true,
            ..LidarConfig::default()
        },
        1,
    )
    .unwrap();
    let mut lout = vec![0u8; lidar.frame_bytes()];
    let p = site.mcmf_from_site(&terrain.map().site_of_map(
        0.0,
        0.0,
        terrain.elevation_m(0.0, 0.0) + 500.0,
    ));
    let truth = still_truth(&ground, &p, &q, 0);
    g.bench_function("lidar_128_500m", |b| {
        b.iter(|| black_box(lidar.render(black_box(&truth), &mut lout).unwrap()))
    });
    g.finish();
}

criterion_group!(benches, frames);
criterion_main!(benches);
