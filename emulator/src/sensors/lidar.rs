//! The flash lidar: a range image, one exact ray cast per pixel on the same ground as
//! the altimeters (`docs/sensors.md`, "Flash lidar").
//!
//! ```text
//! pixel (i, j):  d = R_mcmf<-lidar  ray(i + 0.5, j + 0.5)       (pinhole, no distortion)
//! range = Ground::ray_cast_mcmf(origin, d, max_range)
//! out   = range + sigma n     if min_range <= range <= max_range and incidence <= max
//!       = 0.0                 otherwise (no return)
//! ```
//!
//! Output: `width * height` little-endian f32 metres, row-major, top row first. One
//! normal is drawn per pixel whether or not it returns, from a ChaCha8 stream set to
//! the frame's index, so the noise does not depend on the scene or on earlier frames.

use super::camera::{
    mounted_pose, ms_to_ns, optics, truth_is_finite, FrameError, FrameMeta, Pinhole,
};
use super::{device_rng, gauss, SensorTruth};
use crate::config::ConfigError;
use crate::sensors::LidarConfig;
use nalgebra::{Matrix3, Vector3};

/// The flash lidar, built once before tick 0.
#[derive(Debug, Clone)]
pub struct Lidar {
    pinhole: Pinhole,
    body_from_lidar: Matrix3<f64>,
    lever_body: Vector3<f64>,
    period_ns: i64,
    range_noise_m: f64,
    min_range_m: f64,
    max_range_m: f64,
    max_incidence_deg: f64,
    noise: bool,
    seed: u64,
}

impl Lidar {
    /// The lidar of `cfg` (validated here) for a run with `seed`.
    pub fn new(cfg: &LidarConfig, seed: u64) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            pinhole: Pinhole::new(cfg.width_px, cfg.height_px, cfg.fov_deg, 0.0, 0.0),
            body_from_lidar: optics::body_from_camera(cfg.boresight_body, cfg.image_right_body),
            lever_body: Vector3::from(cfg.position_body_m),
            period_ns: ms_to_ns(cfg.period_ms).max(1),
            range_noise_m: cfg.range_noise_m,
            min_range_m: cfg.min_range_m,
            max_range_m: cfg.max_range_m,
            max_incidence_deg: cfg.max_incidence_deg,
            noise: cfg.noise,
            seed,
        })
    }

    /// Bytes of one frame: `width * height` little-endian f32.
    pub fn frame_bytes(&self) -> usize {
        self.pinhole.width as usize * self.pinhole.height as usize * 4
    }

    /// Whether a frame falls at `t_ns`.
    pub fn due(&self, t_ns: i64) -> bool {
        t_ns.rem_euclid(self.period_ns) == 0
    }

    /// Frame period, ns.
    pub fn period_ns(&self) -> i64 {
        self.period_ns
    }

    /// The intrinsics (no distortion).
    pub fn pinhole(&self) -> &Pinhole {
        &self.pinhole
    }

    /// The unit `mcmf` direction of pixel `(i, j)` and the receiver's `mcmf` position at
    /// the truth's instant (for tests that intersect by hand).
    pub fn pixel_ray_mcmf(
        &self,
        truth: &SensorTruth<'_>,
        i: u32,
        j: u32,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let pose = mounted_pose(truth, &self.lever_body, &self.body_from_lidar, 0.0);
        (
            pose.origin_mcmf,
            pose.mcmf_from_sensor * self.pinhole.pixel_ray(i, j),
        )
    }

    /// Renders the range image at `truth.t_ns` into `out` (exactly
    /// [`Self::frame_bytes`]). Allocates nothing.
    pub fn render(
        &mut self,
        truth: &SensorTruth<'_>,
        out: &mut [u8],
    ) -> Result<FrameMeta, FrameError> {
        let want = self.frame_bytes();
        if out.len() != want {
            return Err(FrameError::BufferSize {
                got: out.len(),
                want,
            });
        }
        if !truth_is_finite(truth) {
            return Err(FrameError::NonFinite);
        }
        let pose = mounted_pose(truth, &self.lever_body, &self.body_from_lidar, 0.0);
        let sequence = truth.t_ns.div_euclid(self.period_ns).max(0) as u64;
        let mut rng = device_rng(self.seed, "lidar");
        rng.set_word_pos((sequence as u128) << 32);
        let (w, h) = (self.pinhole.width, self.pinhole.height);
        let mut empty = 0u32;
        for j in 0..h {
            for i in 0..w {
                let d = pose.mcmf_from_sensor * self.pinhole.pixel_ray(i, j);
                let n = gauss(&mut rng);
                let range = truth
                    .ground
                    .ray_cast_mcmf(&pose.origin_mcmf, &d, self.max_range_m)
                    .filter(|hit| {
                        hit.range_m >= self.min_range_m
                            && hit.incidence_deg <= self.max_incidence_deg
                    })
                    .map(|hit| {
                        let noise = if self.noise {
                            self.range_noise_m * n
                        } else {
                            0.0
                        };
                        (hit.range_m + noise).max(0.0) as f32
                    });
                let value = range.unwrap_or(0.0);
                empty += (value == 0.0) as u32;
                let k = (j * w + i) as usize * 4;
                out[k..k + 4].copy_from_slice(&value.to_le_bytes());
            }
        }
        Ok(FrameMeta {
            t_ns: truth.t_ns,
            sequence,
            exposure_ns: 0,
            width: w,
            height: h,
            bits: 32,
            saturated_pixels: 0,
            empty_pixels: empty,
        })
    }
}
