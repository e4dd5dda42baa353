//! Device-level sensor models: IMU, star tracker, laser and RF altimeters, laser Doppler
//! velocimeter, each at its own period with its own latency, seeded error model and a
//! validity flag per sample, computed from the plant's truth (`docs/sensors.md`).
//!
//! Two calls drive the suite, both pure (no I/O, no clock) and allocation-free once
//! built:
//! * [`SensorSuite::after_plant_step`] after every plant step, with its
//!   [`SensorTruth`] (`Plant::sensor_truth`): the IMU accumulates its increments from
//!   every step; a device whose period ends at the step's end takes a sample, stamped
//!   with that time of validity and queued for delivery `latency` later;
//! * [`SensorSuite::fill_frame`] at each flight-software cycle: every queued sample
//!   delivered by then goes into the protocol frame, oldest first, up to its capacity;
//!   what does not fit is dropped and counted ([`SensorSuite::dropped`]).
//!
//! Random numbers: one ChaCha8 stream per device, seeded from the run seed and switched
//! to a stream id derived from the device's name ([`stream_id`]), so adding a device or
//! enabling one never shifts another's draws. Each sample draws a fixed count whatever
//! the faults do, so a fault never shifts the later noise either.
//!
//! Faults ([`DeviceFault`], on a [`SensorTarget`]) act inside the devices: a bias, a
//! noise scale, a dropout (no samples), a frozen output, a one-sample spike, an
//! inhibited device (samples invalid, flagged).

pub mod camera;
pub mod config;
mod devices;
pub mod frame_faults;
pub mod frame_source;
pub mod imaging;
mod imu;
pub mod lidar;
pub mod test_card;

pub use camera::{Camera, FrameError};
pub use config::{
    CameraConfig, ImuConfig, LaserAltimeterConfig, LidarConfig, RfAltimeterConfig, SensorsConfig,
    StarTrackerConfig, TestCardConfig, VelocimeterConfig,
};
pub use frame_faults::FrameFault;
pub use frame_source::{FrameMeta, FrameRack, FrameSink, FrameSource};
pub use lidar::Lidar;

use crate::config::ConfigError;
use crate::plant::ground::{Ground, GroundHit};
use devices::{Altimeter, StarTracker, Velocimeter};
use imu::Imu;
use nalgebra::{Rotation3, UnitQuaternion, Vector3};
use oils_shared::SensorFrame;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::VecDeque;

/// The truth after one plant step, as the sensors need it ([`crate::plant::Plant::sensor_truth`]).
#[derive(Debug, Clone, Copy)]
pub struct SensorTruth<'a> {
    /// End of the step, ns since the start of the run.
    pub t_ns: i64,
    /// Length of the step, ns (0: time did not advance, nothing is sampled).
    pub dt_ns: u64,
    /// Centre-of-mass position at the end of the step, `mci`, m.
    pub pos_mci_m: [f64; 3],
    /// Velocity at the end of the step, `mci`, m/s.
    pub vel_mci_m_s: [f64; 3],
    /// Attitude at the start of the step, `[w, x, y, z]`, body to `mci`.
    pub q_start_mci_from_body: [f64; 4],
    /// Attitude at the end of the step.
    pub q_mci_from_body: [f64; 4],
    /// Body rate at the end of the step, body axes, rad/s.
    pub rate_body_rad_s: [f64; 3],
    /// Mean specific force (non-gravitational acceleration) over the step, in the body
    /// axes of the step's middle, m/s^2.
    pub specific_force_body_m_s2: [f64; 3],
    /// The Moon's rotation rate about `mci` +Z, rad/s (`mcmf = Rz(-omega t) mci`).
    pub moon_rotation_rate_rad_s: f64,
    /// The ground the beams are cast on, Moon-fixed.
    pub ground: &'a Ground,
}

impl SensorTruth<'_> {
    fn q_end(&self) -> UnitQuaternion<f64> {
        quat(&self.q_mci_from_body)
    }

    /// The rotation taking `mci` vectors into `mcmf` at the end of the step.
    fn mcmf_from_mci(&self) -> Rotation3<f64> {
        Rotation3::from_axis_angle(
            &Vector3::z_axis(),
            -self.moon_rotation_rate_rad_s * self.t_ns as f64 * 1e-9,
        )
    }

    /// Casts a body-fixed beam from `lever_body` (from the centre of mass) along
    /// `dir_body` onto the ground.
    fn cast(
        &self,
        lever_body: &Vector3<f64>,
        dir_body: &Vector3<f64>,
        max_range_m: f64,
    ) -> Option<GroundHit> {
        let q = self.q_end();
        let to_mcmf = self.mcmf_from_mci();
        let origin = to_mcmf * (Vector3::from(self.pos_mci_m) + q * lever_body);
        let dir = to_mcmf * (q * dir_body);
        self.ground.ray_cast_mcmf(&origin, &dir, max_range_m)
    }
}

/// A `[w, x, y, z]` quaternion as a unit quaternion (normalised).
pub fn quat_of(q: &[f64; 4]) -> UnitQuaternion<f64> {
    quat(q)
}

pub(crate) fn quat(q: &[f64; 4]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(q[0], q[1], q[2], q[3]))
}

/// A device on board.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Device {
    /// Inertial measurement unit.
    Imu,
    /// Star tracker.
    StarTracker,
    /// Laser altimeter.
    LaserAltimeter,
    /// RF (Ka-band) altimeter.
    RfAltimeter,
    /// Laser Doppler velocimeter.
    Velocimeter,
}

impl Device {
    /// Every device, in frame order.
    pub const ALL: [Device; 5] = [
        Device::Imu,
        Device::StarTracker,
        Device::LaserAltimeter,
        Device::RfAltimeter,
        Device::Velocimeter,
    ];

    /// The device's name (fault targets, log columns use it with `_`).
    pub fn name(self) -> &'static str {
        match self {
            Device::Imu => "imu",
            Device::StarTracker => "star-tracker",
            Device::LaserAltimeter => "laser-altimeter",
            Device::RfAltimeter => "rf-altimeter",
            Device::Velocimeter => "velocimeter",
        }
    }
}

/// FNV-1a of `"sensors/" + name`: the ChaCha stream id of a device's random numbers.
pub const fn stream_id(name: &str) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let prefix = b"sensors/";
    let mut i = 0;
    while i < prefix.len() {
        hash ^= prefix[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    let bytes = name.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

/// The random stream of device `name` for run `seed`.
pub(crate) fn device_rng(seed: u64, name: &str) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(stream_id(name));
    rng
}

/// What a sensor fault acts on: a device, or one half of the IMU.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorTarget {
    /// The whole IMU (dropout, frozen, inhibited act on both halves).
    Imu,
    /// The IMU's gyros (bias and spike in rad/s).
    ImuGyro,
    /// The IMU's accelerometers (bias and spike in m/s^2).
    ImuAccel,
    /// The star tracker (bias and spike in arcsec about its first cross-boresight axis).
    StarTracker,
    /// The laser altimeter (bias and spike in m).
    LaserAltimeter,
    /// The RF altimeter (bias and spike in m).
    RfAltimeter,
    /// The velocimeter (bias and spike in m/s on each beam's line-of-sight velocity).
    Velocimeter,
}

impl SensorTarget {
    /// Every target name, as the fault syntax writes it.
    pub const NAMES: [&'static str; 7] = [
        "imu",
        "imu-gyro",
        "imu-accel",
        "star-tracker",
        "laser-altimeter",
        "rf-altimeter",
        "velocimeter",
    ];

    /// The target of a name in [`Self::NAMES`].
    pub fn from_name(name: &str) -> Option<Self> {
        Some(match name {
            "imu" => SensorTarget::Imu,
            "imu-gyro" => SensorTarget::ImuGyro,
            "imu-accel" => SensorTarget::ImuAccel,
            "star-tracker" => SensorTarget::StarTracker,
            "laser-altimeter" => SensorTarget::LaserAltimeter,
            "rf-altimeter" => SensorTarget::RfAltimeter,
            "velocimeter" => SensorTarget::Velocimeter,
            _ => return None,
        })
    }

    /// The device the target belongs to.
    pub fn device(self) -> Device {
        match self {
            SensorTarget::Imu | SensorTarget::ImuGyro | SensorTarget::ImuAccel => Device::Imu,
            SensorTarget::StarTracker => Device::StarTracker,
            SensorTarget::LaserAltimeter => Device::LaserAltimeter,
            SensorTarget::RfAltimeter => Device::RfAltimeter,
            SensorTarget::Velocimeter => Device::Velocimeter,
        }
    }
}

/// A fault inside a device.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DeviceFault {
    /// A constant added to the output (units per [`SensorTarget`]).
    Bias {
        /// The added value.
        value: f64,
    },
    /// The device's white noise scaled.
    Noise {
        /// Scale of every noise sigma (> 0).
        factor: f64,
    },
    /// No samples at all while active.
    Dropout,
    /// The output sticks at the last sample before the fault (valid, new timestamps).
    Frozen,
    /// The first sample after the fault fires carries an outlier of `value` (units per
    /// [`SensorTarget`]; the IMU's is a rate held for one period).
    Spike {
        /// The outlier.
        value: f64,
    },
    /// The device is inhibited: its samples arrive invalid, flagged inhibited.
    Inhibited,
}

/// Faults acting on one device (or one IMU half). Counts, so overlapping faults of one
/// kind clear one at a time.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct FaultState {
    pub bias: f64,
    pub noise: f64,
    pub dropout: u32,
    pub frozen: u32,
    pub inhibited: u32,
    pub spike: f64,
}

impl Default for FaultState {
    fn default() -> Self {
        Self {
            bias: 0.0,
            noise: 1.0,
            dropout: 0,
            frozen: 0,
            inhibited: 0,
            spike: 0.0,
        }
    }
}

impl FaultState {
    fn set(&mut self, fault: DeviceFault, active: bool) {
        let count = |n: &mut u32| {
            *n = if active {
                n.saturating_add(1)
            } else {
                n.saturating_sub(1)
            }
        };
        match fault {
            DeviceFault::Bias { value } => self.bias += if active { value } else { -value },
            DeviceFault::Noise { factor } => {
                if factor > 0.0 && factor.is_finite() {
                    self.noise = if active {
                        self.noise * factor
                    } else {
                        self.noise / factor
                    };
                }
            }
            DeviceFault::Dropout => count(&mut self.dropout),
            DeviceFault::Frozen => count(&mut self.frozen),
            DeviceFault::Inhibited => count(&mut self.inhibited),
            DeviceFault::Spike { value } => {
                if active {
                    self.spike += value;
                }
            }
        }
    }

    /// The pending spike, once.
    pub fn take_spike(&mut self) -> f64 {
        std::mem::take(&mut self.spike)
    }
}

/// Samples waiting for their delivery time: a ring of fixed capacity (allocated when
/// built); a full ring drops its oldest sample.
#[derive(Debug, Clone)]
pub(crate) struct Queue<T> {
    ring: VecDeque<(i64, T)>,
    capacity: usize,
    pub dropped: u64,
}

impl<T: Copy + Default> Queue<T> {
    /// A queue for a device of `period_ns`, `latency_ns` whose frame holds `frame`.
    pub fn new(period_ns: i64, latency_ns: i64, frame: usize) -> Self {
        let capacity = (latency_ns / period_ns.max(1)) as usize + 2 * frame + 2;
        Self {
            ring: VecDeque::with_capacity(capacity),
            capacity,
            dropped: 0,
        }
    }

    pub fn push(&mut self, deliver_ns: i64, sample: T) {
        if self.ring.len() >= self.capacity {
            self.ring.pop_front();
            self.dropped += 1;
        }
        self.ring.push_back((deliver_ns, sample));
    }

    /// Moves the samples delivered by `t_ns` into `out`, oldest first; drops and
    /// counts what does not fit; zeroes the rest of `out`. Returns the count written.
    fn drain(&mut self, t_ns: i64, out: &mut [T]) -> u32 {
        let mut n = 0;
        while let Some(&(deliver_ns, sample)) = self.ring.front() {
            if deliver_ns > t_ns {
                break;
            }
            self.ring.pop_front();
            if n < out.len() {
                out[n] = sample;
                n += 1;
            } else {
                self.dropped += 1;
            }
        }
        for slot in &mut out[n..] {
            *slot = T::default();
        }
        n as u32
    }
}

/// The time of validity of a device of `period_ns` if one falls in the step `(t - dt,
/// t]` (on step ends when the period is a whole multiple of the step).
pub(crate) fn due(t_ns: i64, dt_ns: u64, period_ns: i64) -> Option<i64> {
    let tv = t_ns.div_euclid(period_ns) * period_ns;
    (dt_ns > 0 && tv > t_ns - dt_ns as i64).then_some(tv)
}

/// Samples lost per device: dropped from a full frame or a full queue.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
pub struct DroppedSamples {
    /// IMU samples.
    pub imu: u64,
    /// Star-tracker samples.
    pub star_tracker: u64,
    /// Laser altimeter samples.
    pub laser_altimeter: u64,
    /// RF altimeter samples.
    pub rf_altimeter: u64,
    /// Velocimeter samples.
    pub velocimeter: u64,
}

/// Every device on board, built once before tick 0.
#[derive(Debug, Clone)]
pub struct SensorSuite {
    imu: Option<Imu>,
    star_tracker: Option<StarTracker>,
    laser_altimeter: Option<Altimeter>,
    rf_altimeter: Option<Altimeter>,
    velocimeter: Option<Velocimeter>,
    summary: String,
}

impl SensorSuite {
    /// The enabled devices of `cfg` (validated here) for a run with `seed`.
    pub fn new(cfg: &SensorsConfig, seed: u64) -> Result<Self, ConfigError> {
        cfg.validate()?;
        Ok(Self {
            imu: cfg.imu.enabled.then(|| Imu::new(&cfg.imu, seed)),
            star_tracker: cfg
                .star_tracker
                .enabled
                .then(|| StarTracker::new(&cfg.star_tracker, seed)),
            laser_altimeter: cfg
                .laser_altimeter
                .enabled
                .then(|| Altimeter::laser(&cfg.laser_altimeter, seed)),
            rf_altimeter: cfg
                .rf_altimeter
                .enabled
                .then(|| Altimeter::rf(&cfg.rf_altimeter, seed)),
            velocimeter: cfg
                .velocimeter
                .enabled
                .then(|| Velocimeter::new(&cfg.velocimeter, seed)),
            summary: cfg.summary(),
        })
    }

    /// Feeds the truth after one plant step: the IMU integrates it; each device whose
    /// period ends in the step samples it. A step of zero length is ignored.
    pub fn after_plant_step(&mut self, truth: &SensorTruth<'_>) {
        if truth.dt_ns == 0 {
            return;
        }
        if let Some(d) = self.imu.as_mut() {
            d.step(truth);
        }
        if let Some(d) = self.star_tracker.as_mut() {
            d.step(truth);
        }
        if let Some(d) = self.laser_altimeter.as_mut() {
            d.step(truth);
        }
        if let Some(d) = self.rf_altimeter.as_mut() {
            d.step(truth);
        }
        if let Some(d) = self.velocimeter.as_mut() {
            d.step(truth);
        }
    }

    /// Fills `frame` with every sample delivered by `t_ns` (time of validity plus
    /// latency) and not yet handed over, oldest first per device, up to each array's
    /// capacity; the rest of each array is zeroed and what did not fit is counted in
    /// [`Self::dropped`]. A disabled device's count is 0. The frame announcements
    /// (`frame_count`, `frames`) are the [`FrameRack`]'s, untouched here.
    pub fn fill_frame(&mut self, t_ns: i64, frame: &mut SensorFrame) {
        frame.imu_count = match self.imu.as_mut() {
            Some(d) => d.queue.drain(t_ns, &mut frame.imu),
            None => Queue::<oils_shared::ImuSample>::clear(&mut frame.imu),
        };
        frame.star_tracker_count = match self.star_tracker.as_mut() {
            Some(d) => d.queue.drain(t_ns, &mut frame.star_tracker),
            None => Queue::clear(&mut frame.star_tracker),
        };
        frame.laser_altimeter_count = match self.laser_altimeter.as_mut() {
            Some(d) => d.queue.drain(t_ns, &mut frame.laser_altimeter),
            None => Queue::clear(&mut frame.laser_altimeter),
        };
        frame.rf_altimeter_count = match self.rf_altimeter.as_mut() {
            Some(d) => d.queue.drain(t_ns, &mut frame.rf_altimeter),
            None => Queue::clear(&mut frame.rf_altimeter),
        };
        frame.velocimeter_count = match self.velocimeter.as_mut() {
            Some(d) => d.queue.drain(t_ns, &mut frame.velocimeter),
            None => Queue::clear(&mut frame.velocimeter),
        };
    }

    /// Starts (`active`) or clears a fault on a device; a fault on a disabled device
    /// does nothing.
    pub fn set_fault(&mut self, target: SensorTarget, fault: DeviceFault, active: bool) {
        match target {
            SensorTarget::Imu | SensorTarget::ImuGyro | SensorTarget::ImuAccel => {
                if let Some(d) = self.imu.as_mut() {
                    d.set_fault(target, fault, active);
                }
            }
            SensorTarget::StarTracker => {
                if let Some(d) = self.star_tracker.as_mut() {
                    d.faults.set(fault, active);
                }
            }
            SensorTarget::LaserAltimeter => {
                if let Some(d) = self.laser_altimeter.as_mut() {
                    d.faults.set(fault, active);
                }
            }
            SensorTarget::RfAltimeter => {
                if let Some(d) = self.rf_altimeter.as_mut() {
                    d.faults.set(fault, active);
                }
            }
            SensorTarget::Velocimeter => {
                if let Some(d) = self.velocimeter.as_mut() {
                    d.faults.set(fault, active);
                }
            }
        }
    }

    /// Samples lost so far per device (a full frame or queue), for the report.
    pub fn dropped(&self) -> DroppedSamples {
        DroppedSamples {
            imu: self.imu.as_ref().map_or(0, |d| d.queue.dropped),
            star_tracker: self.star_tracker.as_ref().map_or(0, |d| d.queue.dropped),
            laser_altimeter: self.laser_altimeter.as_ref().map_or(0, |d| d.queue.dropped),
            rf_altimeter: self.rf_altimeter.as_ref().map_or(0, |d| d.queue.dropped),
            velocimeter: self.velocimeter.as_ref().map_or(0, |d| d.queue.dropped),
        }
    }

    /// Whether `device` is on.
    pub fn is_enabled(&self, device: Device) -> bool {
        match device {
            Device::Imu => self.imu.is_some(),
            Device::StarTracker => self.star_tracker.is_some(),
            Device::LaserAltimeter => self.laser_altimeter.is_some(),
            Device::RfAltimeter => self.rf_altimeter.is_some(),
            Device::Velocimeter => self.velocimeter.is_some(),
        }
    }

    /// The sensor set and rates, one line per device ([`SensorsConfig::summary`]).
    pub fn config_summary(&self) -> &str {
        &self.summary
    }
}

impl<T: Copy + Default> Queue<T> {
    fn clear(out: &mut [T]) -> u32 {
        for slot in out {
            *slot = T::default();
        }
        0
    }
}

/// A standard normal draw.
pub(crate) fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    use rand::Rng;
    rng.sample(rand_distr::StandardNormal)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn streams_differ_per_device_and_from_the_other_streams() {
        let ids = Device::ALL.map(|d| stream_id(d.name()));
        for (i, a) in ids.iter().enumerate() {
            for b in &ids[i + 1..] {
                assert_ne!(a, b);
            }
            assert_ne!(*a, crate::devices::nav_noise::NAV_NOISE_STREAM);
        }
    }

    #[test]
    fn a_sample_falls_due_on_the_step_that_ends_its_period() {
        let ms = 1_000_000;
        assert_eq!(due(5 * ms, ms as u64, 5 * ms), Some(5 * ms));
        assert_eq!(due(6 * ms, ms as u64, 5 * ms), None);
        assert_eq!(due(4 * ms, ms as u64, 5 * ms), None);
        // A step longer than the period (refused by check_rates) stamps the last end.
        assert_eq!(due(10 * ms, 10 * ms as u64, 5 * ms), Some(10 * ms));
        assert_eq!(due(5 * ms, 0, 5 * ms), None);
    }
}
