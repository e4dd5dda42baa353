//! The navigation camera: a global-shutter pinhole with radial distortion looking at the
//! terrain, rendered from the truth (`docs/sensors.md`, "Navigation camera").
//!
//! Modules: [`optics`] (projection, distortion, mounting), [`photometry`] (McEwen's
//! lunar-Lambert I/F), [`detector`] (electrons, noise, ADC), [`shadow`] (cast shadows
//! for one sun, built once), [`render`] (the exact ray-cast renderer, the test oracle,
//! and the fast rasterising one).
//!
//! A frame is a pure function of (ground, pose, sun, seed, time): no wall clock, no
//! allocation once built (the buffers are sized in [`Camera::new`]), one ChaCha8 stream
//! per device whose position is set from the frame's index, so frame `k`'s noise does
//! not depend on which frames were rendered before it.

pub mod detector;
pub mod optics;
pub mod ortho;
pub mod photometry;
pub mod render;
pub mod shadow;

pub use detector::Detector;
pub use optics::Pinhole;
pub use render::Renderer;
pub use shadow::{ShadowMap, ShadowMapConfig, ShadowMapError};

use super::{device_rng, quat, SensorTruth};
use crate::config::ConfigError;
use crate::sensors::CameraConfig;
use nalgebra::{Matrix3, Rotation3, UnitQuaternion, Vector3};
use render::{Pose, Scratch};
use std::sync::Arc;

/// Angular radius of the sun seen from the Moon, rad (0.2666 deg at 1 au: the solar
/// radius 695 700 km, IAU 2015 Resolution B3, over 1 au).
pub const SUN_ANGULAR_RADIUS_RAD: f64 = 695_700.0 / 149_597_870.7;

/// What a frame is: written alongside its bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameMeta {
    /// Time of validity (the middle of the exposure), ns since the start of the run.
    pub t_ns: i64,
    /// Frame index: `t_ns / period` (the noise stream's position).
    pub sequence: u64,
    /// Exposure, ns (0 for the lidar).
    pub exposure_ns: u64,
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// Bits per pixel value (camera: ADC bits in a u16; lidar: 32, an f32).
    pub bits: u32,
    /// Camera: pixels at full well (the sun in view, glints); lidar: 0.
    pub saturated_pixels: u32,
    /// Camera: pixels that saw no surface (sky); lidar: pixels without a return.
    pub empty_pixels: u32,
}

/// What the renderer did for the last frame ([`Camera::last_stats`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RenderStats {
    /// Lattice nodes shaded (fast renderer).
    pub nodes: usize,
    /// Pixels no triangle covered, cast exactly (fast renderer).
    pub fallback_pixels: u32,
    /// Pixels that saw the sky.
    pub sky_pixels: u32,
}

/// Why a frame was not rendered.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum FrameError {
    /// The output buffer is not the frame's size.
    #[error("frame buffer holds {got} bytes, the frame is {want}")]
    BufferSize {
        /// Bytes given.
        got: usize,
        /// Bytes of a frame.
        want: usize,
    },
    /// A truth value or the sun direction is not finite (or the sun is zero).
    #[error("non-finite truth or sun direction")]
    NonFinite,
}

/// Where a body-mounted sensor is and how it looks, at one instant.
pub(crate) fn mounted_pose(
    truth: &SensorTruth<'_>,
    lever_body: &Vector3<f64>,
    body_from_sensor: &Matrix3<f64>,
    dt_s: f64,
) -> Pose {
    let q: UnitQuaternion<f64> = quat(&truth.q_mci_from_body);
    let w = Vector3::from(truth.rate_body_rad_s);
    let q = q * UnitQuaternion::from_scaled_axis(w * dt_s);
    let pos = Vector3::from(truth.pos_mci_m) + Vector3::from(truth.vel_mci_m_s) * dt_s;
    let t_s = truth.t_ns as f64 * 1e-9 + dt_s;
    let to_mcmf =
        Rotation3::from_axis_angle(&Vector3::z_axis(), -truth.moon_rotation_rate_rad_s * t_s);
    let rot = to_mcmf * q.to_rotation_matrix();
    Pose {
        origin_mcmf: to_mcmf * (pos + q * lever_body),
        mcmf_from_sensor: rot.matrix() * body_from_sensor,
    }
}

pub(crate) fn truth_is_finite(truth: &SensorTruth<'_>) -> bool {
    truth.pos_mci_m.iter().all(|x| x.is_finite())
        && truth.vel_mci_m_s.iter().all(|x| x.is_finite())
        && truth.q_mci_from_body.iter().all(|x| x.is_finite())
        && truth.rate_body_rad_s.iter().all(|x| x.is_finite())
        && truth.moon_rotation_rate_rad_s.is_finite()
        && truth.q_mci_from_body.iter().any(|x| *x != 0.0)
}

/// The navigation camera, built once before tick 0.
#[derive(Debug, Clone)]
pub struct Camera {
    pinhole: Pinhole,
    detector: Detector,
    body_from_cam: Matrix3<f64>,
    lever_body: Vector3<f64>,
    period_ns: i64,
    exposure_ns: u64,
    blur_samples: u32,
    albedo: f64,
    floor_iof: f64,
    shadow_tolerance_cos: f64,
    seed: u64,
    renderer: Renderer,
    shadow: Option<Arc<ShadowMap>>,
    /// I/F per pixel of the frame (the blurred mean), row-major.
    iof: Vec<f32>,
    scratch: Scratch,
}

impl Camera {
    /// The camera of `cfg` (validated here) for a run with `seed`: allocates every
    /// buffer a frame needs.
    pub fn new(cfg: &CameraConfig, seed: u64) -> Result<Self, ConfigError> {
        cfg.validate()?;
        let pinhole = Pinhole::new(cfg.width_px, cfg.height_px, cfg.fov_deg, cfg.k1, cfg.k2);
        let n = cfg.width_px as usize * cfg.height_px as usize;
        Ok(Self {
            pinhole,
            detector: Detector::new(cfg),
            body_from_cam: optics::body_from_camera(cfg.boresight_body, cfg.image_right_body),
            lever_body: Vector3::from(cfg.position_body_m),
            period_ns: ms_to_ns(cfg.period_ms).max(1),
            exposure_ns: ms_to_ns(cfg.exposure_ms).max(1) as u64,
            blur_samples: cfg.blur_samples.max(1),
            albedo: cfg.normal_albedo,
            floor_iof: cfg.shadow_floor_iof,
            shadow_tolerance_cos: cfg.shadow_map_tolerance_deg.to_radians().cos(),
            seed,
            renderer: Renderer::Fast,
            shadow: None,
            iof: vec![0.0; n],
            scratch: Scratch::new(n, (n as f64).sqrt() as usize * 8 + 64),
        })
    }

    /// Bytes of one frame: `width * height` little-endian u16, row-major, top row first.
    pub fn frame_bytes(&self) -> usize {
        self.iof.len() * 2
    }

    /// Whether a frame's time of validity falls at `t_ns` (integer multiples of the
    /// period).
    pub fn due(&self, t_ns: i64) -> bool {
        t_ns.rem_euclid(self.period_ns) == 0
    }

    /// Frame period, ns.
    pub fn period_ns(&self) -> i64 {
        self.period_ns
    }

    /// The intrinsics.
    pub fn pinhole(&self) -> &Pinhole {
        &self.pinhole
    }

    /// The sensor chain.
    pub fn detector(&self) -> &Detector {
        &self.detector
    }

    /// Chooses the renderer ([`Renderer::Fast`] by default; [`Renderer::Exact`] casts
    /// two rays a pixel: the oracle the fast one is tested against).
    pub fn set_renderer(&mut self, renderer: Renderer) {
        self.renderer = renderer;
    }

    /// Shares a shadow map built for the run's ground and sun. Without one (or when the
    /// frame's sun is further from the map's than the tolerance, or the map is for
    /// another ground), every lit point casts an exact shadow ray: right, but slow.
    pub fn set_shadow_map(&mut self, map: Option<Arc<ShadowMap>>) {
        self.shadow = map;
    }

    /// The image point `(u, v)` (pixels; pixel `(i, j)` spans `[i, i+1) x [j, j+1)`) of a
    /// Moon-fixed point seen at the truth's instant, `None` behind the camera. For tests
    /// and for the flight software's ground truth.
    pub fn project_mcmf(
        &self,
        truth: &SensorTruth<'_>,
        p_mcmf: &Vector3<f64>,
    ) -> Option<(f64, f64)> {
        let pose = mounted_pose(truth, &self.lever_body, &self.body_from_cam, 0.0);
        let p_cam = pose.mcmf_from_sensor.transpose() * (p_mcmf - pose.origin_mcmf);
        self.pinhole.project(&p_cam)
    }

    /// What the last frame's renderer did: lattice nodes shaded and pixels that fell
    /// back to an exact ray (the fast renderer), sky pixels.
    pub fn last_stats(&self) -> RenderStats {
        RenderStats {
            nodes: self.scratch.nodes,
            fallback_pixels: self.scratch.fallback_pixels,
            sky_pixels: self.scratch.sky_pixels,
        }
    }

    /// The frame's I/F image from the last [`Self::render`] (the sun's pixels
    /// infinite), row-major: what the detector read.
    pub fn last_iof(&self) -> &[f32] {
        &self.iof
    }

    /// Renders the frame whose time of validity (mid-exposure) is `truth.t_ns` into
    /// `out` (exactly [`Self::frame_bytes`]: little-endian u16, row-major, top row first),
    /// with the sun in unit direction `sun_dir_mcmf` (towards the sun, Moon-fixed). With
    /// `blur_samples > 1` the mean of that many poses across the exposure, moved by the
    /// truth's velocity and body rate. Allocates nothing.
    pub fn render(
        &mut self,
        truth: &SensorTruth<'_>,
        sun_dir_mcmf: &Vector3<f64>,
        out: &mut [u8],
    ) -> Result<FrameMeta, FrameError> {
        let want = self.frame_bytes();
        if out.len() != want {
            return Err(FrameError::BufferSize {
                got: out.len(),
                want,
            });
        }
        let sun_norm = sun_dir_mcmf.norm();
        if !truth_is_finite(truth) || !sun_norm.is_finite() || sun_norm == 0.0 {
            return Err(FrameError::NonFinite);
        }
        let sun = sun_dir_mcmf / sun_norm;
        let shadow = self.shadow.as_deref().filter(|m| {
            m.is_for(truth.ground) && m.sun_dir_mcmf().dot(&sun) >= self.shadow_tolerance_cos
        });
        let params = render::Shading {
            albedo: self.albedo,
            floor_iof: self.floor_iof,
            sun_mcmf: sun,
            shadow,
        };
        let n = self.blur_samples;
        let exposure_s = self.exposure_ns as f64 * 1e-9;
        for k in 0..n {
            let dt_s = if n == 1 {
                0.0
            } else {
                exposure_s * ((k as f64 + 0.5) / n as f64 - 0.5)
            };
            let pose = mounted_pose(truth, &self.lever_body, &self.body_from_cam, dt_s);
            let into_mean = n > 1;
            render::render_pose(
                self.renderer,
                truth.ground,
                &self.pinhole,
                &pose,
                &params,
                &mut self.scratch,
                &mut self.iof,
                into_mean.then_some((k, n)),
            );
        }
        Ok(self.read_out(truth.t_ns, out))
    }

    /// The detector's pass: electrons, noise, ADC, into `out`.
    fn read_out(&mut self, t_ns: i64, out: &mut [u8]) -> FrameMeta {
        let sequence = t_ns.div_euclid(self.period_ns).max(0) as u64;
        let mut rng = device_rng(self.seed, "camera");
        // 2^36 words per frame: a 1024^2 frame draws about 2^21 normals of a few words.
        rng.set_word_pos((sequence as u128) << 36);
        let det = self.detector;
        let mut saturated = 0u32;
        for (iof, px) in self.iof.iter().zip(out.chunks_exact_mut(2)) {
            let electrons = if iof.is_infinite() {
                det.full_well_e
            } else {
                *iof as f64 * det.electrons_per_iof
            };
            let (dn, sat) = det.read(electrons, &mut rng);
            saturated += sat as u32;
            px.copy_from_slice(&dn.to_le_bytes());
        }
        FrameMeta {
            t_ns,
            sequence,
            exposure_ns: self.exposure_ns,
            width: self.pinhole.width,
            height: self.pinhole.height,
            bits: 16 - det.max_dn.leading_zeros(),
            saturated_pixels: saturated,
            empty_pixels: self.scratch.sky_pixels,
        }
    }
}

/// Milliseconds to whole nanoseconds.
pub(crate) fn ms_to_ns(ms: f64) -> i64 {
    (ms * 1e6).round() as i64
}

/// A truth at rest at one pose, the Moon not turning (`mci = mcmf`): for benches,
/// examples and tests that place a sensor by hand.
pub fn still_truth<'a>(
    ground: &'a crate::plant::ground::Ground,
    pos_mcmf_m: &Vector3<f64>,
    q_mcmf_from_body: &UnitQuaternion<f64>,
    t_ns: i64,
) -> SensorTruth<'a> {
    let q = [
        q_mcmf_from_body.w,
        q_mcmf_from_body.i,
        q_mcmf_from_body.j,
        q_mcmf_from_body.k,
    ];
    SensorTruth {
        t_ns,
        dt_ns: 1_000_000,
        pos_mci_m: (*pos_mcmf_m).into(),
        vel_mci_m_s: [0.0; 3],
        q_start_mci_from_body: q,
        q_mci_from_body: q,
        rate_body_rad_s: [0.0; 3],
        specific_force_body_m_s2: [0.0; 3],
        moon_rotation_rate_rad_s: 0.0,
        ground,
    }
}

/// The body attitude whose `-Z` (the default camera's boresight) points along the unit
/// `look_mcmf`, with body `+Y` as near `along_mcmf` as it can be: body to `mcmf`.
pub fn looking_along(look_mcmf: &Vector3<f64>, along_mcmf: &Vector3<f64>) -> UnitQuaternion<f64> {
    let z = -look_mcmf.normalize();
    let y = (along_mcmf - z * z.dot(along_mcmf)).normalize();
    let x = y.cross(&z);
    crate::plant::frames::quaternion_from_axes(&x, &y, &z)
}
