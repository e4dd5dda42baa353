//! A run as an MCAP file that opens in Foxglove: the same records as the OILSLOG3 log
//! ([`oils_emulator::recorder`]), one message per record on each per-step channel, stamped with
//! simulated time (`log_time` = `publish_time` = `t_ns`).
//!
//! Channels (JSON messages, JSON-schema schemas). The five per-step messages and their
//! schemas come from the core's table of record fields ([`crate::log_json`]):
//!
//! | topic | schema | per record |
//! |---|---|---|
//! | `/oils/telemetry` | `oils.Telemetry` | Telemetry(k) as published (navigation is noisy) |
//! | `/oils/command` | `oils.Command` | Command(k) as received, and what the plant applied |
//! | `/oils/truth` | `oils.TrueState` | the true state at t_k, with derived speeds and tilt |
//! | `/oils/propulsion` | `oils.Propulsion` | the propulsion model's outputs and internals |
//! | `/oils/timing` | `oils.StepTiming` | per-step timing (see [`step_timing`]) |
//! | `/tf` | `foxglove.FrameTransforms` | `moon` -> `site` (turning with the Moon) and `moon` -> `lander` |
//! | `/oils/pose` | `foxglove.PoseInFrame` | the lander in the `site` frame (3D trail, ground track) |
//! | `/oils/events` | `foxglove.Log` | only when something happens: start, deadline miss, rejected values, touchdown, end of run (fault events: [`Event`]) |
//! | `/oils/scene` | `foxglove.SceneUpdate` | once, at the first record: the Moon and a lander model |
//!
//! Frames: `moon` is the plant's `mci` (Moon-centred inertial); `site` is the
//! scenario's landing site, an east-north-up frame fixed on the turning Moon (its
//! transform from `moon` changes with time); `lander` is the body frame (+Z the thrust
//! axis).
//!
//! Why JSON and not protobuf: Foxglove reads both; JSON needs no code generation and no
//! protobuf crate, every message is readable as text in Foxglove's raw-message panel and
//! in any tool, the schemas are plain JSON (the per-step ones made from the field table,
//! Foxglove's in this file), and `serde_json` writes every
//! f64 as its shortest round-trip form, so nothing is rounded. Protobuf would be smaller
//! before compression and faster to encode; the measured cost of JSON is in the README
//! ("Log formats"), and it is paid on the writer thread, not the stepping thread.
//! Non-finite values (the `NaN` of a propulsion state a model does not have) are written
//! as `null` and read back as `NaN`.
//!
//! The file is chunked (1 MiB uncompressed), zstd-compressed, CRC-checked per chunk and
//! indexed, with the run's header (its whole configuration) as the metadata record
//! `oils`. Chunk boundaries depend on the content only, so the same run gives the same
//! bytes. [`read_mcap`] turns such a file back into a [`Log`].

use crate::log_json;
use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions, Writer};
use nalgebra::{UnitQuaternion, Vector3};
use oils_emulator::log_fields::{Derived, Sample, Site, Topic, MESSAGE_FORMAT};
use oils_emulator::recorder::{
    Log, LogFormat, Record, RecordSink, Recorder, RecorderError, SinkOpener, REC_COMMAND_RECEIVED,
    REC_DEADLINE_MISS, REC_END_OF_RUN, REC_REJECTED_VALUES,
};
use serde::Serialize;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Seek, Write};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// First bytes of every MCAP file.
pub const MCAP_MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Name of the metadata record holding the run's header.
pub const METADATA_NAME: &str = "oils";
/// Uncompressed chunk size, bytes (the crate's default; 4 MiB saved only 0.5 %).
const CHUNK_SIZE: u64 = 1 << 20;
/// zstd level of the chunks.
const ZSTD_LEVEL: u32 = 1;

/// Topics, as written.
pub mod topic {
    /// Telemetry(k) as published.
    pub const TELEMETRY: &str = "/oils/telemetry";
    /// Command(k) as received and as applied.
    pub const COMMAND: &str = "/oils/command";
    /// The true state.
    pub const TRUTH: &str = "/oils/truth";
    /// Propulsion outputs and internals.
    pub const PROPULSION: &str = "/oils/propulsion";
    /// Per-step timing.
    pub const TIMING: &str = "/oils/timing";
    /// The devices' samples and the thruster command.
    pub const DEVICES: &str = "/oils/devices";
    /// Frame transforms.
    pub const TF: &str = "/tf";
    /// The lander's pose in the site frame.
    pub const POSE: &str = "/oils/pose";
    /// Events (foxglove.Log).
    pub const EVENTS: &str = "/oils/events";
    /// The 3D scene (once).
    pub const SCENE: &str = "/oils/scene";
    /// The channels with exactly one message per record.
    pub const PER_STEP: [&str; 8] = [
        TELEMETRY, COMMAND, TRUTH, PROPULSION, TIMING, DEVICES, TF, POSE,
    ];
}

/// The field table's topics and their channels, in channel-id order.
const PER_STEP_TOPICS: [(Topic, &str); 6] = [
    (Topic::Telemetry, topic::TELEMETRY),
    (Topic::Command, topic::COMMAND),
    (Topic::Truth, topic::TRUTH),
    (Topic::Propulsion, topic::PROPULSION),
    (Topic::Timing, topic::TIMING),
    (Topic::Devices, topic::DEVICES),
];

/// MCAP log errors.
#[derive(Debug, Error)]
pub enum McapLogError {
    /// The file could not be created, written or read.
    #[error("{path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// The MCAP library refused (a damaged file: bad CRC, truncated chunk, ...).
    #[error("{path}: {source}")]
    Mcap {
        /// The file.
        path: PathBuf,
        /// What the library said.
        source: mcap::McapError,
    },
    /// The file could not be opened for a run's log (locked by another run, ...).
    #[error(transparent)]
    Open(#[from] RecorderError),
    /// The file is MCAP but not an oils run (a channel or the header is missing or bad).
    #[error("{path} is not an oils MCAP log ({why})")]
    NotOils {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
}

impl From<McapLogError> for RecorderError {
    fn from(e: McapLogError) -> Self {
        match e {
            McapLogError::Io { path, source } => RecorderError::Io { path, source },
            // A write that failed (a full disk) is an I/O error, not a damaged file.
            McapLogError::Mcap {
                path,
                source: mcap::McapError::Io(source),
            } => RecorderError::Io { path, source },
            McapLogError::Mcap { path, source } => RecorderError::NotALog {
                path,
                why: format!("damaged MCAP: {source}"),
            },
            McapLogError::NotOils { path, why } => RecorderError::NotALog { path, why },
            McapLogError::Open(e) => e,
        }
    }
}

// ---------------------------------------------------------------------------------------
// Messages. The five per-step messages come from the core's field table
// (`crate::log_json`); the Foxglove messages below are this file's own.

/// An f64 that serialises as a JSON number, or `null` when not finite.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
struct F(f64);

impl Serialize for F {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        // serde_json writes non-finite floats as null.
        s.serialize_f64(self.0)
    }
}

/// A u64 that JavaScript cannot hold exactly (run id): hex text.
fn hex(v: u64) -> String {
    format!("{v:016x}")
}

/// Per-step timing, nanoseconds; `None` where a step has no such figure (no command
/// received; wake error outside realtime; transport in process). The `/oils/timing`
/// message holds these.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct StepTiming {
    /// Step index.
    pub step: u64,
    /// Simulated time, seconds.
    pub t_s: f64,
    /// The flight software's own step time, from the command.
    pub stub_compute_ns: Option<u64>,
    /// Telemetry(k) published until Command(k) received.
    pub round_trip_ns: Option<u64>,
    /// Step start minus scheduled start (realtime).
    pub wake_error_ns: Option<i64>,
    /// Round trip minus stub compute.
    pub transport_ns: Option<u64>,
}

/// The timing of one record (wall-clock measurements the scheduler took at that step).
pub fn step_timing(r: &Record) -> StepTiming {
    let received = r.flags & REC_COMMAND_RECEIVED != 0;
    StepTiming {
        step: r.telemetry.header.step,
        t_s: r.telemetry.header.t_ns as f64 * 1e-9,
        stub_compute_ns: received.then_some(r.command.stub_compute_ns),
        round_trip_ns: r.timing.round_trip_ns,
        wake_error_ns: r.timing.wake_error_ns,
        transport_ns: r.timing.transport_ns,
    }
}

#[derive(Serialize)]
struct Time {
    sec: u64,
    nsec: u32,
}

impl Time {
    fn of(t_ns: u64) -> Self {
        Self {
            sec: t_ns / 1_000_000_000,
            nsec: (t_ns % 1_000_000_000) as u32,
        }
    }
}

#[derive(Serialize)]
struct Vec3 {
    x: F,
    y: F,
    z: F,
}

#[derive(Serialize)]
struct Quat {
    x: F,
    y: F,
    z: F,
    w: F,
}

fn vec3(v: &Vector3<f64>) -> Vec3 {
    Vec3 {
        x: F(v.x),
        y: F(v.y),
        z: F(v.z),
    }
}

/// `[w, x, y, z]` to Foxglove's `{x, y, z, w}`.
fn quat(q: &[f64; 4]) -> Quat {
    Quat {
        x: F(q[1]),
        y: F(q[2]),
        z: F(q[3]),
        w: F(q[0]),
    }
}

#[derive(Serialize)]
struct FrameTransform<'a> {
    timestamp: Time,
    parent_frame_id: &'a str,
    child_frame_id: &'a str,
    translation: Vec3,
    rotation: Quat,
}

#[derive(Serialize)]
struct FrameTransforms<'a> {
    transforms: [FrameTransform<'a>; 2],
}

#[derive(Serialize)]
struct Pose {
    position: Vec3,
    orientation: Quat,
}

#[derive(Serialize)]
struct PoseInFrame<'a> {
    timestamp: Time,
    frame_id: &'a str,
    pose: Pose,
}

/// What happened, as a `foxglove.Log` message on `/oils/events`.
#[derive(Debug, Clone, PartialEq)]
pub struct Event {
    /// Short kind: `start`, `deadline_miss`, `rejected_values`, `touchdown`,
    /// `end_of_run`; fault injection adds `fault` (its detail names the fault).
    pub kind: &'static str,
    /// Foxglove level: 2 info, 3 warning, 4 error.
    pub level: u8,
    /// The sentence shown in Foxglove's log panel.
    pub message: String,
}

#[derive(Serialize)]
struct LogMsg<'a> {
    timestamp: Time,
    level: u8,
    message: &'a str,
    name: &'a str,
    file: &'a str,
    line: u32,
}

// ---------------------------------------------------------------------------------------
// Schemas.

/// JSON schema of a number that may be `null` (non-finite).
const NUM: &str = r#"{"type":["number","null"]}"#;

/// An object schema: every field required unless `optional` names it, no other field
/// allowed (so the schema-validation test catches a field added to a message and not
/// to its schema, or the other way round).
fn obj_with(title: &str, fields: &[(&str, String)], optional: &[&str]) -> String {
    let props: Vec<String> = fields
        .iter()
        .map(|(name, schema)| format!(r#""{name}":{schema}"#))
        .collect();
    let required: Vec<String> = fields
        .iter()
        .filter(|(name, _)| !optional.contains(name))
        .map(|(name, _)| format!(r#""{name}""#))
        .collect();
    format!(
        r#"{{"title":"{title}","type":"object","properties":{{{}}},"required":[{}],"additionalProperties":false}}"#,
        props.join(","),
        required.join(",")
    )
}

fn obj(title: &str, fields: &[(&str, String)]) -> String {
    obj_with(title, fields, &[])
}

fn num() -> String {
    NUM.to_string()
}

fn int() -> String {
    r#"{"type":"integer"}"#.to_string()
}

fn boolean() -> String {
    r#"{"type":"boolean"}"#.to_string()
}

fn string() -> String {
    r#"{"type":"string"}"#.to_string()
}

fn time_schema() -> String {
    obj("time", &[("sec", int()), ("nsec", int())])
}

fn vec3_schema() -> String {
    obj(
        "foxglove.Vector3",
        &[("x", num()), ("y", num()), ("z", num())],
    )
}

fn quat_schema() -> String {
    obj(
        "foxglove.Quaternion",
        &[("x", num()), ("y", num()), ("z", num()), ("w", num())],
    )
}

fn list(item: String) -> String {
    format!(r#"{{"type":"array","items":{item}}}"#)
}

/// `(topic, schema name, schema JSON)` of every channel, in channel-id order: the six
/// per-step messages of the field table, then Foxglove's.
fn channels() -> Vec<(&'static str, &'static str, String)> {
    let mut out: Vec<(&'static str, &'static str, String)> = PER_STEP_TOPICS
        .iter()
        .map(|&(t, name)| {
            (
                name,
                log_json::schema_name(t),
                log_json::schema(t).to_string(),
            )
        })
        .collect();
    let transform = obj(
        "foxglove.FrameTransform",
        &[
            ("timestamp", time_schema()),
            ("parent_frame_id", string()),
            ("child_frame_id", string()),
            ("translation", vec3_schema()),
            ("rotation", quat_schema()),
        ],
    );
    let transforms = obj(
        "foxglove.FrameTransforms",
        &[("transforms", list(transform))],
    );
    let pose = obj(
        "foxglove.PoseInFrame",
        &[
            ("timestamp", time_schema()),
            ("frame_id", string()),
            (
                "pose",
                obj(
                    "foxglove.Pose",
                    &[("position", vec3_schema()), ("orientation", quat_schema())],
                ),
            ),
        ],
    );
    let log = obj(
        "foxglove.Log",
        &[
            ("timestamp", time_schema()),
            ("level", int()),
            ("message", string()),
            ("name", string()),
            ("file", string()),
            ("line", int()),
        ],
    );
    // The scene is written once; its schema names the fields used (Foxglove reads
    // missing fields as defaults).
    let color = obj(
        "foxglove.Color",
        &[("r", num()), ("g", num()), ("b", num()), ("a", num())],
    );
    let prim = |title: &str| {
        obj(
            title,
            &[
                (
                    "pose",
                    obj(
                        "foxglove.Pose",
                        &[("position", vec3_schema()), ("orientation", quat_schema())],
                    ),
                ),
                ("size", vec3_schema()),
                ("color", color.clone()),
            ],
        )
    };
    // Each entity has the primitives it uses.
    let entity = obj_with(
        "foxglove.SceneEntity",
        &[
            ("timestamp", time_schema()),
            ("frame_id", string()),
            ("id", string()),
            ("frame_locked", boolean()),
            ("spheres", list(prim("foxglove.SpherePrimitive"))),
            ("cubes", list(prim("foxglove.CubePrimitive"))),
            ("cylinders", list(prim("foxglove.CylinderPrimitive"))),
        ],
        &["spheres", "cubes", "cylinders"],
    );
    let scene = obj(
        "foxglove.SceneUpdate",
        &[
            ("deletions", list(obj("foxglove.SceneEntityDeletion", &[]))),
            ("entities", list(entity)),
        ],
    );
    out.extend([
        (topic::TF, "foxglove.FrameTransforms", transforms),
        (topic::POSE, "foxglove.PoseInFrame", pose),
        (topic::EVENTS, "foxglove.Log", log),
        (topic::SCENE, "foxglove.SceneUpdate", scene),
    ]);
    out
}

// ---------------------------------------------------------------------------------------
// Writing.

/// Turns records into MCAP messages on a writer; keeps what spans records (channel ids,
/// the site frame, sequence numbers, the previous contact state).
struct Encoder {
    ids: Vec<u16>,
    seq: Vec<u32>,
    site: Site,
    /// The first record was written (the scene and the start event with it).
    started: bool,
    contact: bool,
    buf: Vec<u8>,
    written: u64,
    /// The image schema's id, once a frame was written.
    image_schema: Option<u16>,
    /// Per frame device: its channel id.
    image_channels: Vec<(u32, u16)>,
    /// Frames written.
    frames: u64,
}

const CH_TF: usize = 6;
const CH_POSE: usize = 7;
const CH_EVENTS: usize = 8;
const CH_SCENE: usize = 9;

impl Encoder {
    fn new<W: Write + Seek>(
        w: &mut Writer<W>,
        header_json: &str,
        site: Site,
    ) -> mcap::McapResult<Self> {
        let mut metadata = BTreeMap::new();
        metadata.insert("header_json".to_string(), header_json.to_string());
        metadata.insert("format".to_string(), format!("oils-mcap-{MESSAGE_FORMAT}"));
        w.write_metadata(&Metadata {
            name: METADATA_NAME.to_string(),
            metadata,
        })?;
        let mut ids = Vec::new();
        for (topic, name, schema) in channels() {
            let schema_id = w.add_schema(name, "jsonschema", schema.as_bytes())?;
            ids.push(w.add_channel(schema_id, topic, "json", &BTreeMap::new())?);
        }
        let n = ids.len();
        Ok(Self {
            ids,
            seq: vec![0; n],
            site,
            started: false,
            contact: false,
            buf: Vec::with_capacity(4096),
            written: 0,
            image_schema: None,
            image_channels: Vec::new(),
            frames: 0,
        })
    }

    /// Writes frame `ann` as a `foxglove.RawImage` on its device's image channel (added
    /// with the schema at the device's first frame).
    fn frame<W: Write + Seek>(
        &mut self,
        w: &mut Writer<W>,
        ann: &oils_shared::FrameAnnouncement,
        pixels: &[u8],
        camera_bits: u32,
    ) -> Result<(), FrameWriteError> {
        let schema = match self.image_schema {
            Some(id) => id,
            None => {
                let id = w.add_schema(
                    crate::mcap_frames::SCHEMA_NAME,
                    "protobuf",
                    &crate::mcap_frames::schema(),
                )?;
                self.image_schema = Some(id);
                id
            }
        };
        let slot = match self.image_channels.iter().position(|c| c.0 == ann.device) {
            Some(i) => i,
            None => {
                let id = w.add_channel(
                    schema,
                    &crate::mcap_frames::topic(ann.device),
                    "protobuf",
                    &BTreeMap::new(),
                )?;
                self.image_channels.push((ann.device, id));
                self.image_channels.len() - 1
            }
        };
        crate::mcap_frames::encode(ann, pixels, camera_bits, &mut self.buf)?;
        let t_ns = ann.t_ns.max(0) as u64;
        // The message's sequence is the frame's counter (a dropout shows as a gap).
        let header = MessageHeader {
            channel_id: self.image_channels[slot].1,
            sequence: ann.seq as u32,
            log_time: t_ns,
            publish_time: t_ns,
        };
        w.write_to_known_channel(&header, &self.buf)?;
        self.frames += 1;
        Ok(())
    }

    fn put<W: Write + Seek, T: Serialize>(
        &mut self,
        w: &mut Writer<W>,
        ch: usize,
        t_ns: u64,
        msg: &T,
    ) -> mcap::McapResult<()> {
        self.buf.clear();
        // Serialising plain structs to a Vec cannot fail.
        serde_json::to_writer(&mut self.buf, msg).expect("JSON of a plain struct");
        let header = MessageHeader {
            channel_id: self.ids[ch],
            sequence: self.seq[ch],
            log_time: t_ns,
            publish_time: t_ns,
        };
        self.seq[ch] = self.seq[ch].wrapping_add(1);
        w.write_to_known_channel(&header, &self.buf)
    }

    fn event<W: Write + Seek>(
        &mut self,
        w: &mut Writer<W>,
        t_ns: u64,
        e: &Event,
    ) -> mcap::McapResult<()> {
        let msg = LogMsg {
            timestamp: Time::of(t_ns),
            level: e.level,
            message: &e.message,
            name: e.kind,
            file: "",
            line: 0,
        };
        self.put(w, CH_EVENTS, t_ns, &msg)
    }

    fn write<W: Write + Seek>(&mut self, w: &mut Writer<W>, r: &Record) -> mcap::McapResult<()> {
        let tlm = &r.telemetry;
        let t_ns = tlm.header.t_ns.max(0) as u64;
        let step = tlm.header.step;
        let truth = &r.truth;
        let first = !self.started;
        self.started = true;
        let site = self.site;
        let t_s = tlm.header.t_ns as f64 * 1e-9;
        if first {
            self.scene(w, t_ns)?;
            let e = Event {
                kind: "start",
                level: 2,
                message: format!(
                    "run {} starts at step {step}, altitude {:.1} m",
                    hex(tlm.header.run_id),
                    truth.altitude_m
                ),
            };
            self.event(w, t_ns, &e)?;
        }

        let derived = Derived::of(truth, t_s, &site);
        let sample = Sample {
            record: r,
            derived: &derived,
        };
        for (ch, (t, _)) in PER_STEP_TOPICS.iter().enumerate() {
            self.put(w, ch, t_ns, &log_json::message(*t, &sample))?;
        }
        let pos = Vector3::from(truth.pos_mci_m);
        let pos_site = Vector3::from(derived.pos_site_m);
        let (vertical, horizontal, tilt) = (
            derived.vertical_speed_m_s,
            derived.horizontal_speed_m_s,
            derived.tilt_deg,
        );

        let q_mci_from_site = site.q_mci_from_site(t_s);
        let q_site_from_body = q_mci_from_site.inverse()
            * UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(
                truth.q_mci_from_body[0],
                truth.q_mci_from_body[1],
                truth.q_mci_from_body[2],
                truth.q_mci_from_body[3],
            ));
        let qs = q_mci_from_site.quaternion();
        let tf = FrameTransforms {
            transforms: [
                FrameTransform {
                    timestamp: Time::of(t_ns),
                    parent_frame_id: "moon",
                    child_frame_id: "site",
                    translation: vec3(&site.origin_mci_m(t_s)),
                    rotation: quat(&[qs.w, qs.i, qs.j, qs.k]),
                },
                FrameTransform {
                    timestamp: Time::of(t_ns),
                    parent_frame_id: "moon",
                    child_frame_id: "lander",
                    translation: vec3(&pos),
                    rotation: quat(&truth.q_mci_from_body),
                },
            ],
        };
        self.put(w, CH_TF, t_ns, &tf)?;
        let qb = q_site_from_body.quaternion();
        let pose = PoseInFrame {
            timestamp: Time::of(t_ns),
            frame_id: "site",
            pose: Pose {
                position: vec3(&pos_site),
                orientation: quat(&[qb.w, qb.i, qb.j, qb.k]),
            },
        };
        self.put(w, CH_POSE, t_ns, &pose)?;

        for e in events(r, self.contact, vertical, horizontal, tilt) {
            self.event(w, t_ns, &e)?;
        }
        self.contact = truth.contact;
        self.written += 1;
        Ok(())
    }

    /// The Moon and a lander model (a 2 m box on four engine bells), written once.
    fn scene<W: Write + Seek>(&mut self, w: &mut Writer<W>, t_ns: u64) -> mcap::McapResult<()> {
        let d = 2.0 * 1_737_400.0;
        let bells: Vec<serde_json::Value> = [[0.6, 0.6], [-0.6, 0.6], [-0.6, -0.6], [0.6, -0.6]]
            .iter()
            .map(|[x, y]| {
                serde_json::json!({
                    "pose": {"position": {"x": x, "y": y, "z": 0.2},
                             "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
                    "size": {"x": 0.4, "y": 0.4, "z": 0.4},
                    "color": {"r": 0.3, "g": 0.3, "b": 0.35, "a": 1.0}
                })
            })
            .collect();
        let scene = serde_json::json!({
            "deletions": [],
            "entities": [
                {
                    "timestamp": {"sec": t_ns / 1_000_000_000, "nsec": t_ns % 1_000_000_000},
                    "frame_id": "moon", "id": "moon", "frame_locked": true,
                    "spheres": [{
                        "pose": {"position": {"x": 0, "y": 0, "z": 0},
                                 "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
                        "size": {"x": d, "y": d, "z": d},
                        "color": {"r": 0.55, "g": 0.55, "b": 0.55, "a": 1.0}
                    }]
                },
                {
                    "timestamp": {"sec": t_ns / 1_000_000_000, "nsec": t_ns % 1_000_000_000},
                    "frame_id": "lander", "id": "lander", "frame_locked": true,
                    "cubes": [{
                        "pose": {"position": {"x": 0, "y": 0, "z": 1.2},
                                 "orientation": {"x": 0, "y": 0, "z": 0, "w": 1}},
                        "size": {"x": 2.0, "y": 2.0, "z": 1.6},
                        "color": {"r": 0.85, "g": 0.65, "b": 0.2, "a": 1.0}
                    }],
                    "cylinders": bells
                }
            ]
        });
        self.put(w, CH_SCENE, t_ns, &scene)
    }
}

/// The events one record gives. `was_in_contact`: the previous record's contact.
fn events(
    r: &Record,
    was_in_contact: bool,
    vertical_m_s: f64,
    horizontal_m_s: f64,
    tilt_deg: f64,
) -> Vec<Event> {
    let step = r.telemetry.header.step;
    let t_s = r.telemetry.header.t_ns as f64 * 1e-9;
    let mut out = Vec::new();
    if r.flags & REC_DEADLINE_MISS != 0 {
        out.push(Event {
            kind: "deadline_miss",
            level: 3,
            message: format!(
                "step {step} (t = {t_s:.2} s): deadline miss, miss policy applied (thrust {:?} N)",
                r.applied.engines.thrust_cmd_n
            ),
        });
    }
    if r.flags & REC_REJECTED_VALUES != 0 {
        out.push(Event {
            kind: "rejected_values",
            level: 3,
            message: format!(
                "step {step} (t = {t_s:.2} s): command values rejected: sent thrust {:?} N, on {:?}, torque {:?} N m; applied thrust {:?} N, on {:?}, torque {:?} N m",
                r.command.thrust_cmd_n,
                r.command.engine_on,
                r.command.torque_cmd_body_nm,
                r.applied.engines.thrust_cmd_n,
                r.applied.engines.on,
                r.applied.torque_cmd_body_nm
            ),
        });
    }
    if r.flags
        & (oils_emulator::recorder::REC_FAULT_FIRED | oils_emulator::recorder::REC_FAULT_CLEARED)
        != 0
    {
        // Which faults: bit i of faults_active is the i-th of the configuration's faults.
        out.push(Event {
            kind: "fault",
            level: 3,
            message: format!(
                "step {step} (t = {t_s:.2} s): fault {}; active faults now {:#x} (bit i: the i-th of config.faults)",
                if r.flags & oils_emulator::recorder::REC_FAULT_FIRED != 0 { "fired" } else { "cleared" },
                r.faults_active
            ),
        });
    }
    if r.truth.contact && !was_in_contact {
        out.push(Event {
            kind: "touchdown",
            level: 2,
            message: format!(
                "step {step} (t = {t_s:.2} s): touchdown, vertical {vertical_m_s:.2} m/s, horizontal {horizontal_m_s:.2} m/s, tilt {tilt_deg:.2} deg"
            ),
        });
    }
    if r.flags & REC_END_OF_RUN != 0 {
        out.push(Event {
            kind: "end_of_run",
            level: 2,
            message: format!(
                "step {step} (t = {t_s:.2} s): end of run, altitude {:.2} m, mass {:.1} kg",
                r.truth.altitude_m, r.truth.mass_kg
            ),
        });
    }
    out
}

fn write_options() -> WriteOptions {
    WriteOptions::new()
        .compression(Some(Compression::Zstd))
        // Level 1: on a whole descent it gave a smaller file than the default level 3
        // (79.9 against 89.3 MB: the JSON floats' digits are what is left to squeeze)
        // for less time; 6 was 4x slower for 86 MB.
        .compression_level(ZSTD_LEVEL)
        .chunk_size(Some(CHUNK_SIZE))
        // Compress on the writer thread itself: no extra threads on a shared machine,
        // and one deterministic compressor.
        .compression_threads(0)
        // Each chunk built whole in memory and handed to the file in one go (no seeking
        // back to patch a header), straight to the OS (no buffer in between): after a
        // kill -9 or a full disk the file holds every finished chunk, whole, and a
        // reader recovers them (`read_mcap`).
        .disable_seeking(true)
        .profile("")
}

/// What writing an MCAP log gave.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct McapStats {
    /// Records written.
    pub records: u64,
    /// File size, bytes.
    pub bytes: u64,
}

/// Why a frame was not written.
#[derive(Debug, thiserror::Error)]
enum FrameWriteError {
    #[error(transparent)]
    Mcap(#[from] mcap::McapError),
    #[error(transparent)]
    Image(#[from] crate::mcap_frames::FrameImageError),
}

/// Writes a log (read from an OILSLOG3 file) as MCAP.
pub fn export_mcap(log: &Log, path: &Path) -> Result<McapStats, McapLogError> {
    let mut sink = McapSink::create(path, &log.header_json)?;
    for r in &log.records {
        sink.write_record(r)?;
    }
    sink.close()?;
    let bytes = std::fs::metadata(path)
        .map_err(|source| McapLogError::Io {
            path: path.to_path_buf(),
            source,
        })?
        .len();
    Ok(McapStats {
        records: sink.enc.written,
        bytes,
    })
}

/// The MCAP log as the recorder's writer: `oils run --log-format mcap`.
pub struct McapSink {
    writer: Option<Writer<File>>,
    enc: Encoder,
    path: PathBuf,
}

impl McapSink {
    /// Creates the file and writes the header (metadata, schemas, channels).
    pub fn create(path: &Path, header_json: &str) -> Result<Self, McapLogError> {
        let file = oils_emulator::recorder::create_locked(path)?;
        let mcap_err = |source| McapLogError::Mcap {
            path: path.to_path_buf(),
            source,
        };
        let mut writer = write_options().create(file).map_err(mcap_err)?;
        let site = Site::of_log_header(header_json).map_err(|why| McapLogError::NotOils {
            path: path.to_path_buf(),
            why,
        })?;
        let enc = Encoder::new(&mut writer, header_json, site).map_err(mcap_err)?;
        Ok(Self {
            writer: Some(writer),
            enc,
            path: path.to_path_buf(),
        })
    }

    fn mcap_err(&self, source: mcap::McapError) -> McapLogError {
        McapLogError::Mcap {
            path: self.path.clone(),
            source,
        }
    }

    /// Writes one record's messages.
    pub fn write_record(&mut self, r: &Record) -> Result<(), McapLogError> {
        let Some(w) = self.writer.as_mut() else {
            return Err(McapLogError::NotOils {
                path: self.path.clone(),
                why: "written after it was closed".into(),
            });
        };
        self.enc.write(w, r).map_err(|e| self.mcap_err(e))
    }

    /// Writes one frame as a `foxglove.RawImage` ([`crate::mcap_frames`]); a camera's
    /// DN of `camera_bits` shifted to 16 bits.
    pub fn write_frame(
        &mut self,
        ann: &oils_shared::FrameAnnouncement,
        pixels: &[u8],
        camera_bits: u32,
    ) -> Result<(), McapLogError> {
        let Some(w) = self.writer.as_mut() else {
            return Err(McapLogError::NotOils {
                path: self.path.clone(),
                why: "written after it was closed".into(),
            });
        };
        self.enc
            .frame(w, ann, pixels, camera_bits)
            .map_err(|e| match e {
                FrameWriteError::Mcap(source) => McapLogError::Mcap {
                    path: self.path.clone(),
                    source,
                },
                FrameWriteError::Image(e) => McapLogError::NotOils {
                    path: self.path.clone(),
                    why: e.to_string(),
                },
            })
    }

    /// Records and frames written so far.
    pub fn written(&self) -> (u64, u64) {
        (self.enc.written, self.enc.frames)
    }

    /// Writes the summary (index, statistics), flushes and syncs.
    pub fn close(&mut self) -> Result<(), McapLogError> {
        let Some(mut w) = self.writer.take() else {
            return Ok(());
        };
        w.finish().map_err(|e| self.mcap_err(e))?;
        let io = |source| McapLogError::Io {
            path: self.path.clone(),
            source,
        };
        let mut out = w.into_inner();
        out.flush().map_err(io)?;
        out.sync_all().map_err(io)
    }

    /// A recorder (writer thread, bounded channel) writing MCAP to `path`.
    pub fn recorder(path: &Path, header_json: &str) -> Result<Recorder, RecorderError> {
        let sink = Self::create(path, header_json)?;
        Recorder::with_sink(path, Box::new(sink))
    }
}

/// Hands the run core an MCAP writer for `log.format = "mcap"` ([`Extras::sinks`]).
///
/// [`Extras::sinks`]: oils_emulator::session::Extras::sinks
#[derive(Debug, Clone, Copy, Default)]
pub struct McapOpener;

impl SinkOpener for McapOpener {
    fn writes(&self, format: LogFormat) -> bool {
        format == LogFormat::Mcap
    }

    fn open(
        &self,
        _format: LogFormat,
        path: &Path,
        header_json: &str,
    ) -> Result<Box<dyn RecordSink>, RecorderError> {
        Ok(Box::new(McapSink::create(path, header_json)?))
    }
}

impl RecordSink for McapSink {
    fn write(&mut self, rec: &Record) -> Result<(), RecorderError> {
        Ok(self.write_record(rec)?)
    }

    /// Nothing: a chunk is written, whole and straight to the OS, when it is full, so
    /// chunk boundaries (and the file's bytes) do not depend on how fast the writer kept
    /// up. A crash loses at most the chunk being filled (1 MiB of JSON, about 3 s of
    /// simulated time at 10 ms).
    fn caught_up(&mut self) -> Result<(), RecorderError> {
        Ok(())
    }

    fn finish(&mut self) -> Result<(), RecorderError> {
        Ok(self.close()?)
    }
}

// ---------------------------------------------------------------------------------------
// Reading.

/// The longest record the readers accept, inside a chunk or not: the file's own length,
/// or 16 MiB for a small file (an oils message is a few kilobytes).
fn record_length_limit(file_len: usize) -> usize {
    file_len.max(16 << 20)
}

/// One message of an MCAP file.
#[derive(Debug)]
struct McapMessage {
    topic: std::sync::Arc<str>,
    sequence: u32,
    log_time: u64,
    data: Vec<u8>,
}

/// What the oils readers take from an MCAP file.
#[derive(Debug)]
enum McapItem {
    Message(McapMessage),
    Metadata(mcap::records::Metadata),
}

/// The messages (with chunks read) or the metadata records (chunks skipped) of an MCAP
/// file, in file order, chunk CRCs checked; other records are skipped unparsed.
///
/// Not `mcap::MessageStream` or `mcap::read::LinearReader`: in mcap 0.26 the first reads
/// chunk contents with no bound on a record's declared length, so a damaged length makes
/// it try to allocate exabytes and abort the process, and both parse every record, and a
/// short attachment record panics. Both found by the `mcap` fuzz target
/// (`docs/fuzzing.md`). This drives the same crate's sans-io reader with a bound on record
/// lengths ([`record_length_limit`]) and parses only channels, messages and metadata.
struct McapReader<'a> {
    rest: &'a [u8],
    reader: mcap::sans_io::LinearReader,
    topics: BTreeMap<u16, std::sync::Arc<str>>,
    /// The file ended inside a record (a run killed, a full disk): iteration stopped
    /// after the last whole record.
    truncated: bool,
}

impl<'a> McapReader<'a> {
    /// Messages, from inside the chunks.
    fn messages(bytes: &'a [u8]) -> Self {
        Self::new(bytes, false)
    }

    /// Metadata records, without decompressing a chunk.
    fn metadata(bytes: &'a [u8]) -> Self {
        Self::new(bytes, true)
    }

    fn new(bytes: &'a [u8], skip_chunks: bool) -> Self {
        let options = mcap::sans_io::LinearReaderOptions::default()
            .with_record_length_limit(record_length_limit(bytes.len()))
            .with_validate_chunk_crcs(true)
            .with_emit_chunks(skip_chunks);
        Self {
            rest: bytes,
            reader: mcap::sans_io::LinearReader::new_with_options(options),
            topics: BTreeMap::new(),
            truncated: false,
        }
    }
}

impl Iterator for McapReader<'_> {
    type Item = Result<McapItem, mcap::McapError>;

    fn next(&mut self) -> Option<Self::Item> {
        use mcap::records::{op, Record as R};
        use mcap::sans_io::LinearReadEvent as E;
        while let Some(event) = self.reader.next_event() {
            let (opcode, data) = match event {
                Ok(E::ReadRequest(_)) if self.rest.is_empty() => {
                    self.truncated = true;
                    return None;
                }
                Ok(E::ReadRequest(need)) => {
                    let n = need.min(self.rest.len());
                    self.reader.insert(n).copy_from_slice(&self.rest[..n]);
                    self.reader.notify_read(n);
                    self.rest = &self.rest[n..];
                    continue;
                }
                Ok(E::Record { opcode, data }) => (opcode, data),
                Err(e) => return Some(Err(e)),
            };
            if ![op::CHANNEL, op::MESSAGE, op::METADATA].contains(&opcode) {
                continue;
            }
            match mcap::parse_record(opcode, data) {
                Ok(R::Channel(c)) => {
                    self.topics.insert(c.id, c.topic.as_str().into());
                }
                Ok(R::Message { header, data }) => {
                    let Some(topic) = self.topics.get(&header.channel_id) else {
                        return Some(Err(mcap::McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        )));
                    };
                    return Some(Ok(McapItem::Message(McapMessage {
                        topic: topic.clone(),
                        sequence: header.sequence,
                        log_time: header.log_time,
                        data: data.into_owned(),
                    })));
                }
                Ok(R::Metadata(m)) => return Some(Ok(McapItem::Metadata(m))),
                Ok(_) => {}
                Err(e) => return Some(Err(e)),
            }
        }
        None
    }
}

/// The messages of an MCAP file (see [`McapReader`]).
#[cfg(test)]
fn mcap_messages(bytes: &[u8]) -> impl Iterator<Item = Result<McapMessage, mcap::McapError>> + '_ {
    McapReader::messages(bytes).filter_map(|item| match item {
        Ok(McapItem::Message(m)) => Some(Ok(m)),
        Ok(McapItem::Metadata(_)) => None,
        Err(e) => Some(Err(e)),
    })
}

/// Is this file an MCAP file (by its magic)?
pub fn is_mcap(path: &Path) -> bool {
    use std::io::Read;
    let mut magic = [0u8; 8];
    File::open(path)
        .and_then(|mut f| f.read_exact(&mut magic))
        .map(|_| &magic == MCAP_MAGIC)
        .unwrap_or(false)
}

/// Reads an oils MCAP log back into a [`Log`]: telemetry, command, applied command and
/// true state per record (derived fields are not read). Chunk CRCs are checked; a
/// damaged file is an error naming the file.
pub fn read_mcap(path: &Path) -> Result<Log, McapLogError> {
    let bytes = std::fs::read(path).map_err(|source| McapLogError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    parse_mcap(path, &bytes)
}

/// [`read_mcap`] of bytes already read (`path` names them in errors); the fuzz target
/// `mcap` feeds it arbitrary bytes.
pub fn parse_mcap(path: &Path, bytes: &[u8]) -> Result<Log, McapLogError> {
    let mcap_err = |source| McapLogError::Mcap {
        path: path.to_path_buf(),
        source,
    };
    let not = |why: String| McapLogError::NotOils {
        path: path.to_path_buf(),
        why,
    };
    let mut header_json = None;
    let mut format = 1;
    for item in McapReader::metadata(bytes) {
        if let McapItem::Metadata(m) = item.map_err(mcap_err)? {
            if m.name == METADATA_NAME {
                header_json = m.metadata.get("header_json").cloned();
                format = m
                    .metadata
                    .get("format")
                    .and_then(|f| f.strip_prefix("oils-mcap-"))
                    .and_then(|n| n.parse().ok())
                    .unwrap_or(1);
            }
        }
    }
    let header_json = header_json.ok_or_else(|| not("no `oils` metadata record".into()))?;
    if format > MESSAGE_FORMAT {
        return Err(not(format!(
            "message format oils-mcap-{format} is newer than this program's ({MESSAGE_FORMAT})"
        )));
    }
    let mut records: Vec<Record> = Vec::new();
    // Per record, the per-step messages read (a record cut off by a truncation lacks some).
    let mut parts: Vec<usize> = Vec::new();
    let mut index: BTreeMap<u64, usize> = BTreeMap::new();
    // Every per-step channel has one message per record: its sequence number is the
    // record's position.
    let mut slot = |seq: u64, records: &mut Vec<Record>| -> usize {
        *index.entry(seq).or_insert_with(|| {
            records.push(Record::default());
            records.len() - 1
        })
    };
    let mut reader = McapReader::messages(bytes);
    let messages = reader.by_ref().filter_map(|item| match item {
        Ok(McapItem::Message(m)) => Some(Ok(m)),
        Ok(McapItem::Metadata(_)) => None,
        Err(e) => Some(Err(e)),
    });
    for msg in messages {
        let msg = msg.map_err(mcap_err)?;
        let Some(&(t, _)) = PER_STEP_TOPICS
            .iter()
            .find(|(_, name)| **name == *msg.topic)
        else {
            continue;
        };
        let i = slot(u64::from(msg.sequence), &mut records);
        parts.resize(records.len(), 0);
        parts[i] += 1;
        log_json::read_message(t, &msg.data, format, &mut records[i])
            .map_err(|e| not(format!("{} at t = {} ns: {e}", msg.topic, msg.log_time)))?;
    }
    let truncated = reader.truncated;
    let mut warnings = Vec::new();
    if truncated {
        // Only whole records: every per-step message of a record read.
        let whole = parts
            .iter()
            .position(|n| *n < PER_STEP_TOPICS.len())
            .unwrap_or(records.len());
        records.truncate(whole);
        warnings.push(format!(
            "the MCAP file ends inside a record (the run was killed, or the disk filled): {whole} whole records recovered from its complete chunks"
        ));
    }
    let mut log = Log {
        header_json,
        records,
        warnings,
        ..Log::default()
    };
    log.check_end(!truncated);
    Ok(log)
}

/// Per-step timing from an MCAP log's `/oils/timing` channel (in record order).
pub fn read_mcap_timing(path: &Path) -> Result<Vec<StepTiming>, McapLogError> {
    Ok(read_mcap(path)?.records.iter().map(step_timing).collect())
}

/// Reads a run log in either format: OILSLOG6 or MCAP (by the file's magic).
pub fn read_any(path: &Path) -> Result<Log, RecorderError> {
    if is_mcap(path) {
        Ok(read_mcap(path)?)
    } else {
        oils_emulator::recorder::read_log(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use oils_emulator::propulsion::PropulsionInternals;
    use oils_shared::PacketHeader;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("oils-mcap-{}-{name}", std::process::id()))
    }

    fn record(k: u64) -> Record {
        let mut r = Record {
            flags: REC_COMMAND_RECEIVED,
            ..Default::default()
        };
        r.telemetry.header = PacketHeader::new(0xdead_beef_0123_4567, k, k as i64 * 10_000_000);
        r.telemetry.altitude_m = 1000.0 - k as f64 * 0.1;
        r.command.header = r.telemetry.header;
        r.command.thrust_cmd_n = [400.0 + k as f64 / 3.0, 0.1, 800.0, 1e-300];
        r.command.stub_compute_ns = 1234 + k;
        r.applied.engines.thrust_cmd_n = r.command.thrust_cmd_n;
        r.truth.pos_mci_m = [1_737_400.0 + 1000.0, k as f64, 0.0];
        r.truth.q_mci_from_body = [1.0, 0.0, 0.0, 0.0];
        r.truth.altitude_m = 1000.0;
        r.truth.internals = PropulsionInternals::NONE;
        r.truth.propulsion.thrust_n = [1.0 / 3.0, 2.0 / 3.0, 0.1 + 0.2, 123.456e-7];
        r
    }

    #[test]
    fn records_survive_mcap_and_nan_comes_back_as_nan() {
        let path = temp("rt.mcap");
        let mut records: Vec<Record> = (0..500).map(record).collect();
        records[10].flags |= REC_REJECTED_VALUES;
        records[499].flags = REC_END_OF_RUN;
        let log = Log {
            header_json: oils_emulator::session::log_header(
                &oils_emulator::run_config::RunConfig::default(),
                0xdeadbeef01234567,
            ),
            records,
            ..Log::default()
        };
        let stats = export_mcap(&log, &path).unwrap();
        assert_eq!(stats.records, 500);
        assert!(is_mcap(&path));
        let back = read_mcap(&path).unwrap();
        assert_eq!(back.header_json, log.header_json);
        assert_eq!(back.records.len(), 500);
        for (a, b) in log.records.iter().zip(&back.records) {
            assert_eq!(a.telemetry, b.telemetry);
            assert_eq!(a.command, b.command);
            assert_eq!(a.flags, b.flags);
            assert_eq!(a.applied, b.applied);
            assert_eq!(a.truth.propulsion, b.truth.propulsion);
            assert!(b.truth.internals.regulator_outlet_pa.is_nan());
        }
        let timing = read_mcap_timing(&path).unwrap();
        assert_eq!(timing.len(), 500);
        assert_eq!(timing[7].stub_compute_ns, Some(1241));
        assert_eq!(timing[499].stub_compute_ns, None);
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn site_frame_is_east_north_up_at_the_scenario_site() {
        let mut cfg = oils_emulator::config::ScenarioConfig::default();
        cfg.site.latitude_deg = 0.0;
        cfg.site.longitude_deg = 0.0;
        cfg.moon.rotation_rate_rad_s = 0.0;
        let site = Site::of_scenario(&cfg);
        assert!((site.origin_mci_m(0.0) - Vector3::new(1_737_400.0, 0.0, 0.0)).norm() < 1e-6);
        // 1 km north (mci +Z here) and 100 m up of the site.
        let p = site.site_of(&Vector3::new(1_737_500.0, 0.0, 1000.0), 0.0);
        assert!((p - Vector3::new(0.0, 1000.0, 100.0)).norm() < 1e-6, "{p}");
        // East is mci +Y at this point.
        let e = site.site_of(&Vector3::new(1_737_400.0, 50.0, 0.0), 0.0);
        assert!((e - Vector3::new(50.0, 0.0, 0.0)).norm() < 1e-6, "{e}");
        // On a turning Moon the site moves east in mci: a point fixed in mci drifts
        // west in the site frame, omega R t after t seconds.
        cfg.moon.rotation_rate_rad_s = 2.6617e-6;
        let site = Site::of_scenario(&cfg);
        let w = site.site_of(&Vector3::new(1_737_400.0, 0.0, 0.0), 100.0);
        assert!((w.x + 2.6617e-6 * 1_737_400.0 * 100.0).abs() < 1e-3, "{w}");
    }

    /// The records of an MCAP byte range: (position, opcode, body range).
    fn records_in(bytes: &[u8], from: usize) -> Vec<(usize, u8, std::ops::Range<usize>)> {
        let mut out = Vec::new();
        let mut at = from;
        while at + 9 <= bytes.len() {
            let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
            out.push((at, bytes[at], at + 9..at + 9 + len));
            at += 9 + len;
        }
        out
    }

    /// A message inside a zstd chunk whose declared length is absurd is an error, not an
    /// attempt to allocate it: mcap 0.26's MessageStream reserved the declared length and
    /// aborted the process (found by the `mcap` fuzz target).
    #[test]
    fn a_huge_record_length_inside_a_chunk_is_an_error() {
        // A one-message file, chunked but not compressed, so its records can be edited.
        let mut plain = Vec::new();
        {
            let mut w = WriteOptions::new()
                .compression(None)
                .create(std::io::Cursor::new(&mut plain))
                .unwrap();
            let channel = w.add_channel(0, "/t", "json", &BTreeMap::new()).unwrap();
            let header = mcap::records::MessageHeader {
                channel_id: channel,
                sequence: 7,
                log_time: 1,
                publish_time: 1,
            };
            w.write_to_known_channel(&header, b"{}").unwrap();
            w.finish().unwrap();
        }
        let intact: Vec<_> = mcap_messages(&plain).collect::<Result<_, _>>().unwrap();
        assert_eq!(
            (intact.len(), &*intact[0].topic, intact[0].sequence),
            (1, "/t", 7)
        );

        // Rebuild its chunk as zstd (crc 0: unchecked) with the message's length set to
        // 2^61 bytes. Chunk body: start, end, uncompressed size, crc, compression, records.
        let (at, _, body) = records_in(&plain, 8)
            .into_iter()
            .find(|r| r.1 == 0x06)
            .expect("a chunk");
        let b = &plain[body.clone()];
        let compression_len = u32::from_le_bytes(b[28..32].try_into().unwrap()) as usize;
        let mut inner = b[32 + compression_len + 8..].to_vec();
        let (msg, _, _) = records_in(&inner, 0)
            .into_iter()
            .find(|r| r.1 == 0x05)
            .expect("the message in the chunk");
        inner[msg + 1..msg + 9].copy_from_slice(&(1u64 << 61).to_le_bytes());
        let packed = zstd::bulk::compress(&inner, 1).unwrap();
        let mut chunk = b[..16].to_vec();
        chunk.extend((inner.len() as u64).to_le_bytes());
        chunk.extend(0u32.to_le_bytes());
        chunk.extend(4u32.to_le_bytes());
        chunk.extend(b"zstd");
        chunk.extend((packed.len() as u64).to_le_bytes());
        chunk.extend(&packed);
        let mut bytes = plain[..at].to_vec();
        bytes.push(0x06);
        bytes.extend((chunk.len() as u64).to_le_bytes());
        bytes.extend(&chunk);
        bytes.extend(&plain[body.end..]);

        let err = mcap_messages(&bytes)
            .collect::<Result<Vec<_>, _>>()
            .expect_err("a damaged length is an error");
        assert!(err.to_string().contains("exceeds limit"), "{err}");
    }

    /// A record the readers do not use is skipped unparsed: mcap 0.26's parser panicked
    /// on an attachment shorter than its fixed fields (found by the `mcap` fuzz target).
    /// A truncated MCAP file (kill -9, a full disk: the file is a prefix of what it
    /// would have been) was refused whole. Every cut now gives the records of its whole
    /// chunks, in order, and says the file ends early.
    #[test]
    fn a_truncated_mcap_file_keeps_its_whole_chunks() {
        let path = temp("cut.mcap");
        let mut records: Vec<Record> = (0..6000).map(record).collect();
        records[5999].flags = REC_END_OF_RUN;
        let log = Log {
            header_json: oils_emulator::session::log_header(
                &oils_emulator::run_config::RunConfig::default(),
                0xdeadbeef01234567,
            ),
            records,
            ..Log::default()
        };
        export_mcap(&log, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let whole = parse_mcap(&path, &bytes).unwrap();
        assert!(
            whole.complete && whole.warnings.is_empty(),
            "{:?}",
            whole.warnings
        );
        assert_eq!(whole.records.len(), 6000);
        let mut recovered_some = false;
        for cut in [
            bytes.len() / 4,
            bytes.len() / 2,
            bytes.len() * 3 / 4,
            bytes.len() - 100,
        ] {
            let part = parse_mcap(&path, &bytes[..cut]).unwrap();
            assert!(!part.complete);
            assert!(part.records.len() <= 6000);
            // (The truth's NaN internals compare unequal to themselves: the packets.)
            for (a, b) in part.records.iter().zip(&whole.records) {
                assert_eq!((a.telemetry, a.command), (b.telemetry, b.command));
            }
            assert!(
                part.warnings
                    .iter()
                    .any(|w| w.contains("whole records recovered")),
                "{:?}",
                part.warnings
            );
            recovered_some |= !part.records.is_empty();
        }
        assert!(recovered_some);
        std::fs::remove_file(&path).ok();
    }

    #[test]
    fn a_short_attachment_record_is_skipped() {
        let path = temp("attachment.mcap");
        let log = Log {
            header_json: oils_emulator::session::log_header(
                &oils_emulator::run_config::RunConfig::default(),
                0xdeadbeef01234567,
            ),
            records: (0..3).map(record).collect(),
            ..Log::default()
        };
        export_mcap(&log, &path).unwrap();
        let good = std::fs::read(&path).unwrap();
        let (_, _, first) = records_in(&good, 8)[0].clone();
        let mut bytes = good[..first.end].to_vec();
        // Log time, create time, empty name and media type, data length 0, and no room
        // for the CRC after them.
        bytes.push(0x09);
        bytes.extend(32u64.to_le_bytes());
        bytes.extend([0u8; 32]);
        bytes.extend(&good[first.end..]);
        let log = parse_mcap(&path, &bytes).expect("the attachment is skipped");
        assert_eq!(log.records.len(), 3);
        let _ = std::fs::remove_file(path);
    }

    #[test]
    fn not_mcap_and_not_oils_are_errors() {
        let path = temp("bad.mcap");
        std::fs::write(&path, b"\x89MCAP0\r\ngarbage").unwrap();
        assert!(read_mcap(&path).is_err());
        std::fs::write(&path, b"hello").unwrap();
        assert!(!is_mcap(&path));
        std::fs::remove_file(&path).ok();
    }
}
