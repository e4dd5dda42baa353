//! The flight software keeps its own copies of what it assumes about the world and the
//! vehicle (it must not read the emulator's code or configuration). These tests hold
//! each copy to the emulator's original, so a change on one side fails here:
//! * the onboard map's projection (`MapFrame`) against the terrain's (`MapProjection`
//!   in the site frame);
//! * the terrain navigation's pinhole (`CameraModel`) against the camera's (`Pinhole`);
//! * the defaults of the GNC's camera and lidar models against the emulator's device
//!   defaults.

use nalgebra::Vector3;
use oils_emulator::sensors::camera::optics::Pinhole;
use oils_emulator::sensors::config::{CameraConfig, LidarConfig};
use oils_emulator::world::terrain::{MapProjection, SiteFrame};
use oils_onboard_stub::gnc::hazard::LidarModel;
use oils_onboard_stub::gnc::terrain_map::MapFrame;
use oils_onboard_stub::gnc::terrain_nav::CameraModel;

#[test]
fn the_onboard_map_projection_is_the_terrains() {
    let (lat, lon, r) = (-69.373, 32.319, 1_737_400.0);
    let site = SiteFrame::from_deg(lat, lon, r);
    let terrain = MapProjection { radius_m: r };
    let onboard = MapFrame::new(lat, lon, r);
    for (e, n, h) in [
        (0.0, 0.0, 0.0),
        (120.0, -340.0, 12.5),
        (-8000.0, 5000.0, -40.0),
        (30000.0, 1.0, 3.0),
    ] {
        let p_emulator = site.mcmf_from_site(&terrain.site_of_map(e, n, h));
        let p_onboard = onboard.mcmf_of_map(e, n, h);
        assert!(
            (p_emulator - p_onboard).norm() < 1e-6,
            "({e}, {n}, {h}): {p_emulator} vs {p_onboard}"
        );
        let (e2, n2, h2) = onboard.map_of_mcmf(&p_emulator);
        assert!((e2 - e).abs() < 1e-6 && (n2 - n).abs() < 1e-6 && (h2 - h).abs() < 1e-6);
    }
}

#[test]
fn the_terrain_navigations_pinhole_is_the_cameras() {
    let cam = CameraConfig::default();
    let model = CameraModel::default();
    let pinhole = Pinhole::new(cam.width_px, cam.height_px, cam.fov_deg, cam.k1, cam.k2);
    for d in [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.2, -0.1, 1.0),
        Vector3::new(-0.35, 0.3, 1.0),
        Vector3::new(0.0, 0.0, -1.0),
    ] {
        let a = pinhole.project(&d);
        let b = model.project(model.f_px(), &d);
        match (a, b) {
            (Some((u1, v1)), Some((u2, v2))) => {
                assert!(
                    (u1 - u2).abs() < 1e-9 && (v1 - v2).abs() < 1e-9,
                    "{d}: ({u1}, {v1}) vs ({u2}, {v2})"
                )
            }
            (None, None) => {}
            other => panic!("{d}: {other:?}"),
        }
    }
}

#[test]
fn the_gncs_device_models_default_to_the_emulators_devices() {
    let (cam, model) = (CameraConfig::default(), CameraModel::default());
    assert_eq!(
        (cam.width_px, cam.height_px),
        (model.width_px, model.height_px)
    );
    assert_eq!(
        (cam.fov_deg, cam.k1, cam.k2),
        (model.fov_deg, model.k1, model.k2)
    );
    assert_eq!(cam.boresight_body, model.boresight_body);
    assert_eq!(cam.image_right_body, model.image_right_body);
    assert_eq!(cam.position_body_m, model.position_body_m);
    assert_eq!((1u32 << cam.bits) - 1, u32::from(model.full_scale_dn));
    let (lidar, lmodel) = (LidarConfig::default(), LidarModel::default());
    assert_eq!(
        (lidar.width_px, lidar.height_px, lidar.fov_deg),
        (lmodel.width_px, lmodel.height_px, lmodel.fov_deg)
    );
    assert_eq!(lidar.boresight_body, lmodel.boresight_body);
    assert_eq!(lidar.image_right_body, lmodel.image_right_body);
    assert_eq!(lidar.position_body_m, lmodel.position_body_m);
}
