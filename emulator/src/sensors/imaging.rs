//! The navigation camera and the flash lidar as frame devices ([`FrameSource`]): what
//! the frame rack asks of a device (its id, format, size, period), turned into the
//! renderers' calls, with the sun of the scenario and the time of validity the protocol
//! states (mid-exposure).
//!
//! The rack calls a device at the end of the plant step in which its exposure ends; the
//! renderers take the truth at the frame's time of validity. The adapter moves the
//! truth back by half the exposure (position along the velocity, attitude along the
//! step's rotation): with the camera's 0.3 ms exposure that is 0.5 m at 1.7 km/s, which
//! a pixel of 0.5 mrad at 1 km would show.

use super::camera::{Camera, FrameMeta as CameraMeta, ShadowMap};
use super::frame_source::{FrameMeta, FrameSource};
use super::lidar::Lidar;
use super::{quat, CameraConfig, LidarConfig, SensorTruth};
use crate::config::ConfigError;
use nalgebra::{UnitQuaternion, Vector3};
use oils_shared::{
    FRAME_DEVICE_CAMERA, FRAME_DEVICE_LIDAR, FRAME_FLAG_OUTAGE, FRAME_FLAG_SATURATED,
    FRAME_FORMAT_F32_LE_M, FRAME_FORMAT_U16_LE,
};
use std::sync::Arc;

/// The truth `back_ns` before `truth.t_ns`, within its step: position moved back along
/// the velocity, attitude interpolated between the step's start and end.
fn truth_before<'a>(truth: &SensorTruth<'a>, back_ns: u64) -> SensorTruth<'a> {
    if back_ns == 0 || truth.dt_ns == 0 {
        return *truth;
    }
    let back_s = back_ns as f64 * 1e-9;
    let mut t = *truth;
    t.t_ns = truth.t_ns - back_ns as i64;
    for (p, v) in t.pos_mci_m.iter_mut().zip(truth.vel_mci_m_s) {
        *p -= v * back_s;
    }
    let along = 1.0 - (back_ns as f64 / truth.dt_ns as f64).min(1.0);
    let q0 = quat(&truth.q_start_mci_from_body);
    let q1 = quat(&truth.q_mci_from_body);
    let q: UnitQuaternion<f64> =
        q0 * UnitQuaternion::from_scaled_axis((q0.inverse() * q1).scaled_axis() * along);
    t.q_mci_from_body = [q.w, q.i, q.j, q.k];
    t
}

/// What a failed render leaves: a blank frame, flagged as an outage (every byte written,
/// as the rack requires).
fn outage(out: &mut [u8]) -> FrameMeta {
    out.fill(0);
    FrameMeta {
        flags: FRAME_FLAG_OUTAGE,
    }
}

fn flags_of(meta: &CameraMeta) -> u32 {
    if meta.saturated_pixels > 0 {
        FRAME_FLAG_SATURATED
    } else {
        0
    }
}

/// Whether a device powered below `on_below_m` (height above the sphere of
/// `radius_m`) is on at `truth`.
fn powered(truth: &SensorTruth<'_>, radius_m: f64, on_below_m: f64) -> bool {
    Vector3::from(truth.pos_mci_m).norm() - radius_m < on_below_m
}

/// The navigation camera on board, with the scenario's sun.
pub struct CameraDevice {
    camera: Camera,
    radius_m: f64,
    on_below_m: f64,
    sun_dir_mcmf: Vector3<f64>,
    width: u32,
    height: u32,
    exposure_ns: u64,
    full_scale_dn: u16,
}

impl CameraDevice {
    /// The camera of `cfg` for a run with `seed`, under the sun in unit direction
    /// `sun_dir_mcmf` (Moon-fixed, towards the sun), with the shadow map built for that
    /// sun and the run's terrain (none: exact shadow rays, slow).
    /// `radius_m`: the Moon's reference radius (for the power-on height).
    pub fn new(
        cfg: &CameraConfig,
        seed: u64,
        sun_dir_mcmf: Vector3<f64>,
        shadow: Option<Arc<ShadowMap>>,
        radius_m: f64,
    ) -> Result<Self, ConfigError> {
        let mut camera = Camera::new(cfg, seed)?;
        camera.set_shadow_map(shadow);
        Ok(Self {
            camera,
            radius_m,
            on_below_m: cfg.on_below_altitude_m,
            sun_dir_mcmf,
            width: cfg.width_px,
            height: cfg.height_px,
            exposure_ns: super::config::ms_to_ns(cfg.exposure_ms).max(1) as u64,
            full_scale_dn: ((1u32 << cfg.bits.clamp(1, 16)) - 1) as u16,
        })
    }
}

impl FrameSource for CameraDevice {
    fn device(&self) -> u32 {
        FRAME_DEVICE_CAMERA
    }
    fn format(&self) -> u32 {
        FRAME_FORMAT_U16_LE
    }
    fn width(&self) -> u32 {
        self.width
    }
    fn height(&self) -> u32 {
        self.height
    }
    fn period_ns(&self) -> i64 {
        self.camera.period_ns()
    }
    fn exposure_ns(&self) -> u64 {
        self.exposure_ns
    }
    fn full_scale_dn(&self) -> u16 {
        self.full_scale_dn
    }
    fn render(&mut self, truth: &SensorTruth<'_>, _seq: u64, out: &mut [u8]) -> FrameMeta {
        if !powered(truth, self.radius_m, self.on_below_m) {
            return outage(out);
        }
        let mid = truth_before(truth, self.exposure_ns / 2);
        match self.camera.render(&mid, &self.sun_dir_mcmf, out) {
            Ok(meta) => FrameMeta {
                flags: flags_of(&meta),
            },
            Err(_) => outage(out),
        }
    }
}

/// The flash lidar on board (a flash: its exposure is the pulse, taken as instantaneous).
pub struct LidarDevice {
    lidar: Lidar,
    radius_m: f64,
    on_below_m: f64,
    width: u32,
    height: u32,
}

impl LidarDevice {
    /// The lidar of `cfg` for a run with `seed`; `radius_m` as the camera's.
    pub fn new(cfg: &LidarConfig, seed: u64, radius_m: f64) -> Result<Self, ConfigError> {
        Ok(Self {
            lidar: Lidar::new(cfg, seed)?,
            radius_m,
            on_below_m: cfg.on_below_altitude_m,
            width: cfg.width_px,
            height: cfg.height_px,
        })
    }
}

impl FrameSource for LidarDevice {
    fn device(&self) -> u32 {
        FRAME_DEVICE_LIDAR
    }
    fn format(&self) -> u32 {
        FRAME_FORMAT_F32_LE_M
    }
    fn width(&self) -> u32 {
        self.width
    }
    fn height(&self) -> u32 {
        self.height
    }
    fn period_ns(&self) -> i64 {
        self.lidar.period_ns()
    }
    fn exposure_ns(&self) -> u64 {
        0
    }
    fn render(&mut self, truth: &SensorTruth<'_>, _seq: u64, out: &mut [u8]) -> FrameMeta {
        if !powered(truth, self.radius_m, self.on_below_m) {
            return outage(out);
        }
        match self.lidar.render(truth, out) {
            Ok(_) => FrameMeta { flags: 0 },
            Err(_) => outage(out),
        }
    }
}
