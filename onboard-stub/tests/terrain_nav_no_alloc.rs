//! Terrain navigation and hazard detection allocate nothing in flight: a camera frame
//! taken in and matched against the map (acquisition, then tracking), and a lidar frame
//! turned into a hazard map and a choice, under a counting allocator.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use oils_onboard_stub::gnc::hazard::{HazardConfig, HazardDetection};
use oils_onboard_stub::gnc::nav_filter::{NavFilter, NavFilterConfig};
use oils_onboard_stub::gnc::terrain_map::{MapFrame, MapLevel, TerrainMap};
use oils_onboard_stub::gnc::terrain_nav::{CameraModel, TerrainNav, TerrainNavConfig};
use oils_shared::{
    FrameAnnouncement, Telemetry, FRAME_DEVICE_CAMERA, FRAME_DEVICE_LIDAR, FRAME_FORMAT_F32_LE_M,
    FRAME_FORMAT_U16_LE,
};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

struct Counting;
static ALLOCS: AtomicU64 = AtomicU64::new(0);
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCS.fetch_add(1, Ordering::Relaxed);
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}
#[global_allocator]
static GLOBAL: Counting = Counting;

const R_M: f64 = 1_737_400.0;
const H_M: f64 = 300.0;
const HOVER_M: f64 = 100.0;

/// Value noise on a 10 m lattice.
fn texture(e: f64, n: f64) -> f64 {
    let hash = |i: i64, j: i64| {
        let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        x ^= x >> 29;
        x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x ^= x >> 32;
        (x >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let (x, y) = (e / 10.0, n / 10.0);
    let (i, j) = (x.floor(), y.floor());
    let (fx, fy) = (x - i, y - j);
    let (i, j) = (i as i64, j as i64);
    let top = hash(i, j) * (1.0 - fx) + hash(i + 1, j) * fx;
    let bot = hash(i, j + 1) * (1.0 - fx) + hash(i + 1, j + 1) * fx;
    top * (1.0 - fy) + bot * fy
}

fn camera() -> CameraModel {
    CameraModel {
        width_px: 128,
        height_px: 128,
        k1: 0.0,
        k2: 0.0,
        ..CameraModel::default()
    }
}

fn map() -> TerrainMap {
    let levels = [4.0, 8.0]
        .iter()
        .map(|&s| {
            let n = 256u32;
            let half = 0.5 * (n as f64 - 1.0) * s;
            let mut iof = Vec::new();
            for i in 0..n {
                for j in 0..n {
                    iof.push(
                        (0.1 + 0.04 * texture(-half + j as f64 * s, -half + i as f64 * s)) as f32,
                    );
                }
            }
            MapLevel {
                spacing_m: s,
                e0_m: -half,
                n0_m: -half,
                width: n,
                height: n,
                iof,
                height_m: vec![0.0; (n * n) as usize],
            }
        })
        .collect();
    TerrainMap {
        frame: MapFrame::new(-69.373, 32.319, R_M),
        sun_azimuth_deg: 90.0,
        sun_elevation_deg: 30.0,
        camera: camera(),
        levels,
    }
}

#[test]
fn matching_frames_and_mapping_hazards_allocate_nothing() {
    let m = map();
    let f = m.frame;
    let [e, n, u] = f.axes_mcmf();
    let q = UnitQuaternion::from_matrix(&Matrix3::from_columns(&[e, n, u]));
    // The camera's frame from the true pose, through its own pinhole.
    let cam = camera();
    let c = f.mcmf_of_map(0.0, 0.0, H_M) + q * Vector3::from(cam.position_body_m);
    let rot = q.to_rotation_matrix().matrix() * cam.body_from_camera();
    let fpx = cam.f_px();
    let mut px = Vec::new();
    for v in 0..128 {
        for uu in 0..128 {
            let d = (rot
                * Vector3::new(
                    (uu as f64 + 0.5 - 64.0) / fpx,
                    (v as f64 + 0.5 - 64.0) / fpx,
                    1.0,
                ))
            .normalize();
            let b = c.dot(&d);
            let t = -b - (b * b - c.norm_squared() + R_M * R_M).sqrt();
            let (ee, nn, _) = f.map_of_mcmf(&(c + d * t));
            px.extend_from_slice(
                &((1000.0 + 400.0 * texture(ee, nn)).round() as u16).to_le_bytes(),
            );
        }
    }
    let ann = FrameAnnouncement {
        device: FRAME_DEVICE_CAMERA,
        format: FRAME_FORMAT_U16_LE,
        width: 128,
        height: 128,
        bytes: px.len() as u32,
        ..Default::default()
    };
    // A flat ground 100 m below for the lidar (the hover; its pixels' ranges to the
    // sphere), seen by a filter of its own there.
    let lidar = HazardConfig {
        enabled: true,
        ..HazardConfig::default()
    }
    .lidar;
    let lidar_origin = f.mcmf_of_map(0.0, 0.0, HOVER_M) + q * Vector3::from(lidar.position_body_m);
    let lz = Vector3::from(lidar.boresight_body).normalize();
    let lr = Vector3::from(lidar.image_right_body);
    let lx = (lr - lz * lz.dot(&lr)).normalize();
    let lrot = q.to_rotation_matrix().matrix() * Matrix3::from_columns(&[lx, lz.cross(&lx), lz]);
    let lf = 64.0 / (10.0f64.to_radians()).tan();
    let mut ranges = Vec::new();
    for v in 0..128 {
        for uu in 0..128 {
            let d = (lrot
                * Vector3::new(
                    (uu as f64 + 0.5 - 64.0) / lf,
                    (v as f64 + 0.5 - 64.0) / lf,
                    1.0,
                ))
            .normalize();
            let b = lidar_origin.dot(&d);
            let t = -b - (b * b - lidar_origin.norm_squared() + R_M * R_M).sqrt();
            ranges.extend_from_slice(&(t as f32).to_le_bytes());
        }
    }
    let lann = FrameAnnouncement {
        device: FRAME_DEVICE_LIDAR,
        format: FRAME_FORMAT_F32_LE_M,
        width: 128,
        height: 128,
        bytes: ranges.len() as u32,
        ..Default::default()
    };

    // Built before flight (allocates).
    let mut tlm = Telemetry::default();
    tlm.nav.pos_mci_m = (f.mcmf_of_map(0.0, 0.0, H_M) + e * 12.0 - n * 7.0).into();
    tlm.nav.q_mci_from_body = [q.w, q.i, q.j, q.k];
    let mut nf = NavFilter::new(NavFilterConfig {
        init_sigma_pos_m: 30.0,
        ..NavFilterConfig::default()
    });
    nf.step(&tlm);
    let mut tn = TerrainNav::new(TerrainNavConfig {
        camera: cam,
        map: Some(Arc::new(m)),
        acquisition_radius_m: 0.0,
        ..TerrainNavConfig::default()
    });
    let mut hz = HazardDetection::new(HazardConfig {
        enabled: true,
        ..HazardConfig::default()
    });
    let mut hover = Telemetry::default();
    hover.nav.pos_mci_m = f.mcmf_of_map(0.0, 0.0, HOVER_M).into();
    hover.nav.q_mci_from_body = [q.w, q.i, q.j, q.k];
    let mut hover_nf = NavFilter::new(NavFilterConfig::default());
    hover_nf.step(&hover);
    let aim = f.mcmf_of_map(0.0, 0.0, 0.0);

    let before = ALLOCS.load(Ordering::Relaxed);
    for _ in 0..3 {
        tn.frame(&ann, &px);
        tn.process(&mut nf, 0.0, 0);
    }
    hz.arm();
    hz.frame(&lann, &ranges);
    let choice = hz.assess(&hover_nf, |_| aim);
    let after = ALLOCS.load(Ordering::Relaxed);
    assert_eq!(
        tn.accepted(),
        2,
        "acquired and tracked: {:?}",
        tn.rejected()
    );
    let choice = choice.expect("a flat ground is mapped");
    assert!(
        choice.safe && choice.slope_deg < 1.0 && choice.roughness_m < 0.05,
        "{choice:?}"
    );
    assert_eq!(after - before, 0, "allocations in flight");
}
