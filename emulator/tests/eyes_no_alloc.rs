//! Rendering a camera frame (fast and exact renderers, motion blur, the shadow map) and
//! a lidar frame allocates nothing once the devices are built: a counting global
//! allocator in its own test binary proves it.

mod common;
mod eyes_common;

use eyes_common::{site, sun_mcmf, R_M};
use oils_emulator::plant::ground::Ground;
use oils_emulator::sensors::camera::{
    looking_along, still_truth, Renderer, ShadowMap, ShadowMapConfig,
};
use oils_emulator::sensors::{Camera, CameraConfig, Lidar, LidarConfig, SensorTruth};
use oils_emulator::world::terrain::{SyntheticSpec, TerrainSpec};
use std::sync::Arc;

#[global_allocator]
static GLOBAL: common::CountingAlloc = common::CountingAlloc;

#[test]
fn frames_do_not_allocate() {
    let spec = TerrainSpec::Synthetic(SyntheticSpec {
        extent_m: 1000.0,
        ..SyntheticSpec::default()
    });
    let ground = Ground::new(&spec, -69.373, 32.319, R_M).unwrap();
    let sun = sun_mcmf(10.0, 80.0);
    let map = Arc::new(
        ShadowMap::build(
            &ground,
            &sun,
            &ShadowMapConfig {
                spacings_m: vec![0.5, 2.0],
                nodes: 256,
            },
        )
        .unwrap(),
    );
    let s = site();
    let [east, _, up] = s.axes_mcmf();
    let q = looking_along(&-up, &east);
    let mut cam = Camera::new(
        &CameraConfig {
            enabled: true,
            width_px: 96,
            height_px: 64,
            blur_samples: 3,
            ..CameraConfig::default()
        },
        5,
    )
    .unwrap();
    cam.set_shadow_map(Some(map));
    let mut lidar = Lidar::new(
        &LidarConfig {
            enabled: true,
            width_px: 32,
            height_px: 32,
            ..LidarConfig::default()
        },
        5,
    )
    .unwrap();
    let mut frame = vec![0u8; cam.frame_bytes()];
    let mut range = vec![0u8; lidar.frame_bytes()];
    let truths: Vec<SensorTruth<'_>> = [400.0, 120.0, 30.0]
        .iter()
        .enumerate()
        .map(|(k, h)| {
            let p = s.mcmf_from_site(&nalgebra::Vector3::new(10.0 * k as f64, 0.0, *h));
            SensorTruth {
                vel_mci_m_s: [3.0, -1.0, -2.0],
                rate_body_rad_s: [0.01, 0.02, -0.01],
                ..still_truth(&ground, &p, &q, k as i64 * 200_000_000)
            }
        })
        .collect();
    let before = common::allocations();
    for renderer in [Renderer::Fast, Renderer::Exact] {
        cam.set_renderer(renderer);
        for truth in &truths {
            cam.render(truth, &sun, &mut frame).unwrap();
            lidar.render(truth, &mut range).unwrap();
        }
    }
    let after = common::allocations();
    assert_eq!(
        after - before,
        0,
        "frames allocated {} times",
        after - before
    );
}
