//! Imaging devices (protocol v4): a frame device renders a whole image at its own rate
//! into a buffer the link hands it, and the frame travels on its own service, announced
//! by the next telemetry (`docs/protocol.md`, "Frames").
//!
//! * [`FrameSource`]: one imaging device (the test card here; the navigation camera and
//!   the flash lidar implement it too). A source renders into `&mut [u8]` and never
//!   allocates, so the same renderer writes into an iceoryx2 loan (zero-copy across
//!   processes) or the in-process link's buffer.
//! * [`FrameSink`]: where frames go, implemented by every emulator link: a writable
//!   buffer for the device's next frame, then its publication with its announcement.
//! * [`FrameRack`]: the devices on board, built before tick 0: after each plant step it
//!   asks each due device to render, hashes the frame (XXH3-64, so the run digest covers
//!   its bytes through the telemetry) and publishes it; at the next telemetry it hands the
//!   announcements over ([`FrameRack::announce_into`]).
//!
//! A frame's time of validity is mid-exposure: a device whose exposure ends at the end of
//! step `k` (its period's end, [`super::due`]) is stamped `end - exposure / 2`.

use super::camera::{ShadowMap, ShadowMapConfig};
use super::frame_faults::{FrameFault, FrameFaultState, FrameMode};
use super::imaging::{CameraDevice, LidarDevice};
use super::SensorTruth;
use crate::config::ConfigError;
use crate::link::ExchangeError;
use crate::plant::ground::Ground;
use nalgebra::Vector3;
use oils_shared::link::FrameSpec;
use oils_shared::{frame_device_name, frame_hash, FrameAnnouncement, SensorFrame, FRAMES_MAX};

/// What a source says of the frame it rendered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FrameMeta {
    /// `FRAME_FLAG_*` bits (saturated, outage, frozen).
    pub flags: u32,
}

/// One imaging device. Implementations are built before tick 0 with every buffer they
/// need; [`FrameSource::render`] must not allocate, lock, log or read a clock, and must
/// write every byte of `out` (the link's buffer may hold an earlier frame).
pub trait FrameSource: Send {
    /// `FRAME_DEVICE_*`.
    fn device(&self) -> u32;
    /// `FRAME_FORMAT_*`.
    fn format(&self) -> u32;
    /// Pixels per row.
    fn width(&self) -> u32;
    /// Rows.
    fn height(&self) -> u32;
    /// Length of a frame in bytes (`width * height * bytes per pixel`).
    fn frame_bytes(&self) -> usize {
        let bpp = oils_shared::frame_format_bytes_per_pixel(self.format()).unwrap_or(0);
        self.width() as usize * self.height() as usize * bpp
    }
    /// Frame period, ns (a whole multiple of the plant step, at least the flight-software
    /// cycle: checked before tick 0).
    fn period_ns(&self) -> i64;
    /// Exposure (integration) time, ns (at most the period).
    fn exposure_ns(&self) -> u64;
    /// The largest value a 16-bit pixel reaches (a 12-bit camera's 4095), where a
    /// blinding fault's glare clips.
    fn full_scale_dn(&self) -> u16 {
        u16::MAX
    }
    /// The end of the exposure that falls in the step `(t - dt, t]`, if one does.
    fn due(&self, t_ns: i64, dt_ns: u64) -> Option<i64> {
        super::due(t_ns, dt_ns, self.period_ns())
    }
    /// Renders frame `seq`, whose exposure ends at `truth.t_ns`, into `out` (exactly
    /// [`FrameSource::frame_bytes`] long).
    fn render(&mut self, truth: &SensorTruth<'_>, seq: u64, out: &mut [u8]) -> FrameMeta;
    /// One line for `oils run --print-config`.
    fn summary(&self) -> String {
        format!(
            "{:<16} {:>8.3} Hz  period {} ms  {} x {}  {} bytes a frame",
            frame_device_name(self.device()).unwrap_or("frame-device"),
            1e9 / self.period_ns().max(1) as f64,
            self.period_ns() as f64 * 1e-6,
            self.width(),
            self.height(),
            self.frame_bytes()
        )
    }
}

/// Where frames go: every emulator link is one ([`crate::link::Link`]).
pub trait FrameSink {
    /// A writable buffer of `bytes` for `device`'s next frame, held until
    /// [`FrameSink::publish_frame`]: on iceoryx2 a loan of the frame service's shared
    /// memory, in process a buffer allocated before tick 0. No allocation.
    fn frame_buffer(&mut self, device: u32, bytes: usize) -> Result<&mut [u8], ExchangeError>;
    /// Publishes the frame last handed out for `ann.device`, with `ann` as its header.
    fn publish_frame(&mut self, ann: &FrameAnnouncement) -> Result<(), ExchangeError>;
}

/// The imaging devices on board and the frames published since the last telemetry.
pub struct FrameRack {
    /// In device order (the order of the announcements).
    sources: Vec<Box<dyn FrameSource>>,
    /// Next frame counter per source.
    seq: Vec<u64>,
    /// The faults active on each source.
    faults: Vec<FrameFaultState>,
    /// Each source's last good frame and its flags (what a frozen readout repeats),
    /// allocated when the source is added; blank until its first frame.
    last: Vec<(Vec<u8>, u32)>,
    pending: [FrameAnnouncement; FRAMES_MAX],
    pending_count: usize,
    /// Announcements that did not fit a telemetry (never with periods at least a cycle).
    dropped: u64,
}

impl std::fmt::Debug for FrameRack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FrameRack")
            .field("specs", &self.specs())
            .field("seq", &self.seq)
            .field("pending_count", &self.pending_count)
            .finish()
    }
}

impl Default for FrameRack {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameRack {
    /// No devices.
    pub fn new() -> Self {
        Self {
            sources: Vec::with_capacity(FRAMES_MAX),
            seq: Vec::with_capacity(FRAMES_MAX),
            faults: Vec::with_capacity(FRAMES_MAX),
            last: Vec::with_capacity(FRAMES_MAX),
            pending: [FrameAnnouncement::default(); FRAMES_MAX],
            pending_count: 0,
            dropped: 0,
        }
    }

    /// The enabled frame devices of `cfg` for a run with `seed`, looking at `ground`
    /// under the sun in unit direction `sun_dir_mcmf` (Moon-fixed); `None` when there
    /// are none (the telemetry's `frame_count` then stays 0); `moon_radius_m` for the
    /// devices' power-on height. With the camera on, its
    /// shadow map for that ground and sun is built here, before tick 0 (about 0.5 s),
    /// or taken from an earlier run of this process on the same terrain and sun (a
    /// campaign's cases share one: [`ShadowMap::shared`]).
    pub fn from_config(
        cfg: &super::SensorsConfig,
        seed: u64,
        ground: &Ground,
        sun_dir_mcmf: Vector3<f64>,
        moon_radius_m: f64,
    ) -> Result<Option<Self>, ConfigError> {
        let mut rack = Self::new();
        if cfg.test_card.enabled {
            rack.push(Box::new(super::test_card::TestCard::new(&cfg.test_card)?))?;
        }
        if cfg.camera.enabled {
            let shadow = ShadowMap::shared(ground, &sun_dir_mcmf, &ShadowMapConfig::default())
                .map_err(|e| ConfigError {
                    field: "sensors.camera",
                    value: e.to_string(),
                    why: "a shadow map for the scenario's terrain and sun",
                })?;
            rack.push(Box::new(CameraDevice::new(
                &cfg.camera,
                seed,
                sun_dir_mcmf,
                Some(shadow),
                moon_radius_m,
            )?))?;
        }
        if cfg.lidar.enabled {
            rack.push(Box::new(LidarDevice::new(&cfg.lidar, seed, moon_radius_m)?))?;
        }
        Ok((!rack.sources.is_empty()).then_some(rack))
    }

    /// Adds a device (before tick 0). Refused: a second device with the same id, an id
    /// without a name, more than [`FRAMES_MAX`] devices, or a frame longer than `u32`.
    pub fn push(&mut self, source: Box<dyn FrameSource>) -> Result<(), ConfigError> {
        let device = source.device();
        let refuse = |why: &'static str| ConfigError {
            field: "sensors",
            value: format!("frame device {device}"),
            why,
        };
        if frame_device_name(device).is_none() {
            return Err(refuse("a FRAME_DEVICE_* id"));
        }
        if self.sources.iter().any(|s| s.device() == device) {
            return Err(refuse("one source per frame device"));
        }
        if self.sources.len() >= FRAMES_MAX {
            return Err(refuse("at most FRAMES_MAX frame devices"));
        }
        if source.frame_bytes() == 0 || u32::try_from(source.frame_bytes()).is_err() {
            return Err(refuse("a frame of 1 byte to 4 GiB"));
        }
        let at = self
            .sources
            .iter()
            .position(|s| s.device() > device)
            .unwrap_or(self.sources.len());
        self.last.insert(at, (vec![0; source.frame_bytes()], 0));
        self.sources.insert(at, source);
        self.seq.insert(at, 0);
        self.faults.insert(at, FrameFaultState::default());
        Ok(())
    }

    /// Whether a device `device` (`FRAME_DEVICE_*`) is on board.
    pub fn has_device(&self, device: u32) -> bool {
        self.sources.iter().any(|s| s.device() == device)
    }

    /// A fault on `device` fired (`active`) or cleared; nothing for a device not on
    /// board (a run configuration refuses such a fault before tick 0). No allocation.
    pub fn set_fault(&mut self, device: u32, fault: FrameFault, active: bool) {
        if let Some(i) = self.sources.iter().position(|s| s.device() == device) {
            self.faults[i].set(fault, active);
        }
    }

    /// The frame services the devices need (for the link, before tick 0).
    pub fn specs(&self) -> Vec<FrameSpec> {
        self.sources
            .iter()
            .map(|s| FrameSpec {
                device: s.device(),
                max_bytes: s.frame_bytes(),
            })
            .collect()
    }

    /// After a plant step: every device whose exposure ended in it renders into `sink`'s
    /// buffer, is hashed and published, and its announcement waits for the next
    /// telemetry. A step of zero length (time stopped at touchdown) renders nothing. No
    /// allocation.
    pub fn after_plant_step<S: FrameSink + ?Sized>(
        &mut self,
        truth: &SensorTruth<'_>,
        sink: &mut S,
    ) -> Result<(), ExchangeError> {
        if truth.dt_ns == 0 {
            return Ok(());
        }
        for (i, source) in self.sources.iter_mut().enumerate() {
            let Some(end_ns) = source.due(truth.t_ns, truth.dt_ns) else {
                continue;
            };
            let faults = self.faults[i];
            let mode = faults.mode();
            if mode == FrameMode::Skip {
                continue;
            }
            let seq = &mut self.seq[i];
            let device = source.device();
            let bytes = source.frame_bytes();
            let buf = sink.frame_buffer(device, bytes)?;
            let (last, last_flags) = &mut self.last[i];
            let meta = match mode {
                FrameMode::Repeat => {
                    buf.copy_from_slice(last);
                    FrameMeta { flags: *last_flags }
                }
                FrameMode::Blank => {
                    buf.fill(0);
                    FrameMeta {
                        flags: oils_shared::FRAME_FLAG_OUTAGE,
                    }
                }
                _ => {
                    let mut meta = source.render(truth, *seq, buf);
                    let (format, w, h) = (source.format(), source.width(), source.height());
                    if faults.degrade(format, w, h, source.full_scale_dn(), buf) {
                        meta.flags |= oils_shared::FRAME_FLAG_SATURATED;
                    }
                    last.copy_from_slice(buf);
                    *last_flags = meta.flags;
                    meta
                }
            };
            let hash = frame_hash(buf);
            let exposure_ns = source.exposure_ns();
            let ann = FrameAnnouncement {
                device,
                format: source.format(),
                width: source.width(),
                height: source.height(),
                seq: *seq,
                t_ns: end_ns - (exposure_ns / 2) as i64,
                exposure_ns,
                bytes: bytes as u32,
                flags: meta.flags,
                hash,
            };
            sink.publish_frame(&ann)?;
            *seq += 1;
            if self.pending_count < FRAMES_MAX {
                self.pending[self.pending_count] = ann;
                self.pending_count += 1;
            } else {
                self.dropped += 1;
            }
        }
        Ok(())
    }

    /// Moves the frames published since the last call into `frame` (`frame_count`,
    /// `frames`; the rest zeroed).
    pub fn announce_into(&mut self, frame: &mut SensorFrame) {
        let n = self.pending_count;
        frame.frames[..n].copy_from_slice(&self.pending[..n]);
        for slot in &mut frame.frames[n..] {
            *slot = FrameAnnouncement::default();
        }
        frame.frame_count = n as u32;
        self.pending_count = 0;
    }

    /// Frames published so far per device, in device order: `(device, count)`.
    pub fn published(&self) -> impl Iterator<Item = (u32, u64)> + '_ {
        self.sources
            .iter()
            .zip(&self.seq)
            .map(|(s, n)| (s.device(), *n))
    }

    /// Announcements lost for want of room in a telemetry.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// One line per device, for `oils run --print-config`.
    pub fn summary(&self) -> String {
        let mut out = String::new();
        for s in &self.sources {
            out.push_str(&s.summary());
            out.push('\n');
        }
        out
    }
}
