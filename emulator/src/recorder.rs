//! The recorder: every step's wire packets, the command the plant applied and the
//! plant's true state go to a log file, written by a thread of its own so the stepping
//! thread never touches the disk.
//!
//! File layout (little-endian):
//! ```text
//! magic      8 bytes  "OILSLOG8"
//! header_len u32      length of the JSON header that follows
//! header_crc u32      CRC-32 of the header bytes (an edited header is refused)
//! header     JSON     the run's whole configuration (RunConfig), run id, protocol version
//! frames     each:    records u32 | packed_len u32 | crc32 u32 (of the 8 bytes before it)
//!                     | packed_len bytes: one zstd frame (with its content checksum) of
//!                     `records` records, packed (see below)
//! trailer    TRAILER_SIZE bytes, written when the log is closed:
//!            "OILSEND8" | records u64 | crc32 u32 (of the 16 bytes before it)
//! ```
//! A record is RECORD_SIZE bytes:
//! flags u32 | crc32 u32 | Telemetry (1400 bytes) | Command (336 bytes) | applied
//! command, true state, active faults and the step's timing: TRUTH_VALUES f64s, the slots
//! of `log_fields::FIELDS` (a timing figure the step has not is NaN). Its CRC-32 covers
//! the flags and everything after the CRC, so a damaged record is found and named by its
//! position, never read as data.
//!
//! Packing ([`pack_frame`]): the records' bytes read as little-endian u64 words, each
//! word replaced by its second difference along the frame (word minus twice the previous
//! record's plus the one before, wrapping; the first records against zeros), then written
//! as byte planes (byte b of word j of every record together). Smooth values (positions,
//! masses, times) leave differences with few significant bytes, and the planes put equal
//! bytes next to each other: zstd level 3 then makes the default descent's 198.9 MB of
//! records 28 MB (docs/performance.md, "Log"). Frames hold up to [`FRAME_RECORDS`]
//! records and are written when full, when no record came for `IDLE_FLUSH` (a stalled
//! run) and when the log is closed; a crash loses at most the frame being filled.
//!
//! A log without its trailer (or whose trailer counts other records than it holds) is
//! read, with a warning: the run was interrupted (kill -9, a full disk) or the file was
//! cut; every whole frame before is read. The formats before, OILSLOG1 to OILSLOG7, are
//! refused with a message that says how to record them again (OILSLOG8 is OILSLOG7 with
//! protocol v4 packets: a longer telemetry, its frame announcements).
//!
//! The file is created 0600 and locked (`flock`, exclusive) for the whole run: a second
//! run given the same `--log` fails at once, before it touches the file.
//!
//! The stepping thread hands each record to a bounded crossbeam channel (a copy, no
//! allocation). The writer thread drains it, and hands every batch to the OS whenever the
//! channel runs dry, so a crash of either process loses at most the records still in
//! flight. [`Recorder::finish`] (or dropping the recorder, on any error path) closes the
//! channel, writes the rest and the trailer, and `fsync`s.

use crate::log_fields::{self, Access, Derived, Sample, Site, Value};
use crate::plant::{ActuatorCommand, TruthState};
use crossbeam::channel::{bounded, Receiver, RecvTimeoutError, Sender, TrySendError};
use oils_shared::{AsBytes, Command, Telemetry};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::thread::JoinHandle;
use thiserror::Error;

/// File magic of this format.
pub const MAGIC: &[u8; 8] = b"OILSLOG8";
/// Magic of the formats with protocol v3 packets: OILSLOG7 (these frames) and OILSLOG6
/// (uncompressed records): refused with a clear message.
const MAGIC_V7: &[u8; 8] = b"OILSLOG7";
const MAGIC_V6: &[u8; 8] = b"OILSLOG6";
/// Magic of the formats with protocol v1 packets (OILSLOG4; OILSLOG3 before the header
/// CRC and the trailer): refused with a clear message.
const MAGIC_V4: &[u8; 8] = b"OILSLOG4";
/// Magic of the format with protocol v2 packets.
const MAGIC_V5: &[u8; 8] = b"OILSLOG5";
const MAGIC_V3: &[u8; 8] = b"OILSLOG3";
/// Magic of the trailer that closes a log.
pub const TRAILER_MAGIC: &[u8; 8] = b"OILSEND8";
/// Bytes of a frame's header: records u32, packed length u32, their CRC-32.
pub const FRAME_HEADER_SIZE: usize = 12;
/// Records a frame holds when full: 2.1 MB of records, packed to about 0.3 MB for the
/// default descent; 10 s of a 10 ms run is what a crash may lose.
pub const FRAME_RECORDS: usize = 1024;
/// zstd level: 3 (zstd's default) packs a frame in a few milliseconds on the writer
/// thread; level 19 gains 3 % for twenty times the time (docs/performance.md, "Log").
const ZSTD_LEVEL: i32 = 3;
/// No record for this long: the writer writes the frame it is filling (the writer
/// thread's own timer; nothing in the loop reads it). A run recording at 100 Hz or more
/// never waits this long between records, so its frames stay full.
const IDLE_FLUSH: std::time::Duration = std::time::Duration::from_millis(200);
/// Bytes of the trailer.
pub const TRAILER_SIZE: usize = 20;
/// Magic of the format before per-step timing, refused with a clear message.
const MAGIC_V2: &[u8; 8] = b"OILSLOG2";
/// Magic of the first format (wire packets only), refused with a clear message.
const MAGIC_V1: &[u8; 8] = b"OILSLOG1";
/// Number of f64 values after the packets in a record.
pub const TRUTH_VALUES: usize = 70;
const TLM_SIZE: usize = core::mem::size_of::<Telemetry>();
const CMD_SIZE: usize = core::mem::size_of::<Command>();
/// Bytes per record.
pub const RECORD_SIZE: usize = 8 + TLM_SIZE + CMD_SIZE + 8 * TRUTH_VALUES;
/// Offset in a record of its first f64 value (after the flags, CRC and packets).
pub const VALUES_START: usize = 8 + TLM_SIZE + CMD_SIZE;
/// Record flag: the command field holds a command received from the flight software.
pub const REC_COMMAND_RECEIVED: u32 = 1 << 0;
/// Record flag: the command missed its deadline; the miss policy was applied.
pub const REC_DEADLINE_MISS: u32 = 1 << 1;
/// Record flag: some command values were rejected and replaced by safe values.
pub const REC_REJECTED_VALUES: u32 = 1 << 2;
/// Record flag: last record of the run (the final telemetry, no command).
pub const REC_END_OF_RUN: u32 = 1 << 3;
/// Record flag: a fault fired at this step (`faults_active` says which are active).
pub const REC_FAULT_FIRED: u32 = 1 << 4;
/// Record flag: a fault cleared at this step.
pub const REC_FAULT_CLEARED: u32 = 1 << 5;
/// Record flag, on the end record: this step's telemetry had gone to the flight software
/// before the run ended (it was aborted while waiting for, or checking, the command), so
/// a replay publishes it twice too.
pub const REC_ENDED_AFTER_PUBLISH: u32 = 1 << 6;

/// Records in flight between the stepping thread and the writer.
const CHANNEL_CAPACITY: usize = 8192;

/// One step as logged.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Record {
    /// `REC_*` bits.
    pub flags: u32,
    /// Telemetry(k), as published.
    pub telemetry: Telemetry,
    /// Command(k) as received (zeroed when none arrived).
    pub command: Command,
    /// What the plant was given over `[t_k, t_k+1)` (after sanitising and the miss policy).
    pub applied: ActuatorCommand,
    /// The true state at `t_k`, the instant Telemetry(k) describes.
    pub truth: TruthState,
    /// Faults active at this step: bit i for the i-th declared fault.
    pub faults_active: u64,
    /// This step's timing (wall-clock measurements: outside the digest).
    pub timing: StepTimes,
}

/// One step's timing, nanoseconds; `None` where the step has no such figure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct StepTimes {
    /// Telemetry(k) published until Command(k) received (in process: the call).
    pub round_trip_ns: Option<u64>,
    /// Step start minus its scheduled start (realtime only).
    pub wake_error_ns: Option<i64>,
    /// Round trip minus the stub's compute (across processes only).
    pub transport_ns: Option<u64>,
}

impl Record {
    /// The applied command, true state, active faults and timing as the log's f64
    /// values: the fields of [`log_fields::FIELDS`] with a slot, each at its slot.
    pub fn truth_values(&self) -> [f64; TRUTH_VALUES] {
        let mut v = [0.0; TRUTH_VALUES];
        for f in log_fields::FIELDS {
            if let Access::Slot {
                at, stride, get, ..
            } = f.access
            {
                for i in 0..f.count() {
                    v[at + i * stride] = f.kind.to_f64(get(self, i));
                }
            }
        }
        v
    }

    /// Sets every slot field from the log's f64 values.
    fn set_truth_values(&mut self, v: &[f64; TRUTH_VALUES]) {
        for f in log_fields::FIELDS {
            if let Access::Slot {
                at, stride, set, ..
            } = f.access
            {
                for i in 0..f.count() {
                    set(self, i, f.kind.from_f64(v[at + i * stride]));
                }
            }
        }
    }

    fn encode(&self, out: &mut [u8; RECORD_SIZE]) {
        out[0..4].copy_from_slice(&self.flags.to_le_bytes());
        out[8..8 + TLM_SIZE].copy_from_slice(self.telemetry.as_bytes());
        out[8 + TLM_SIZE..8 + TLM_SIZE + CMD_SIZE].copy_from_slice(self.command.as_bytes());
        let values = self.truth_values();
        for (chunk, v) in out[8 + TLM_SIZE + CMD_SIZE..]
            .chunks_exact_mut(8)
            .zip(values)
        {
            chunk.copy_from_slice(&v.to_le_bytes());
        }
        let crc = record_crc(out);
        out[4..8].copy_from_slice(&crc.to_le_bytes());
    }

    /// Decodes one record; `None` when its CRC does not match (damaged).
    fn decode(bytes: &[u8]) -> Option<Self> {
        if bytes.len() != RECORD_SIZE {
            return None;
        }
        let stored = u32::from_le_bytes(bytes[4..8].try_into().ok()?);
        if stored != record_crc(bytes) {
            return None;
        }
        let mut rec = Self {
            flags: u32::from_le_bytes(bytes[0..4].try_into().ok()?),
            telemetry: Telemetry::from_bytes(&bytes[8..8 + TLM_SIZE])?,
            command: Command::from_bytes(&bytes[8 + TLM_SIZE..8 + TLM_SIZE + CMD_SIZE])?,
            ..Default::default()
        };
        let mut values = [0.0; TRUTH_VALUES];
        for (v, chunk) in values
            .iter_mut()
            .zip(bytes[8 + TLM_SIZE + CMD_SIZE..].chunks_exact(8))
        {
            *v = f64::from_le_bytes(chunk.try_into().ok()?);
        }
        rec.set_truth_values(&values);
        Some(rec)
    }
}

/// A record's bytes, CRC included, as the writer writes them.
pub fn encode_record(r: &Record) -> [u8; RECORD_SIZE] {
    let mut out = [0u8; RECORD_SIZE];
    r.encode(&mut out);
    out
}

/// Decodes record bytes whatever their CRC says (it is set first): the layout's probe
/// ([`crate::log_layout`]).
pub(crate) fn decode_unchecked(bytes: &mut [u8; RECORD_SIZE]) -> Option<Record> {
    let crc = record_crc(bytes);
    bytes[4..8].copy_from_slice(&crc.to_le_bytes());
    Record::decode(bytes)
}

/// CRC-32 of a record's flags and body (everything but the CRC field itself).
fn record_crc(bytes: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(&bytes[0..4]);
    h.update(&bytes[8..]);
    h.finalize()
}

/// Log file errors.
#[derive(Debug, Error)]
pub enum RecorderError {
    /// The file could not be created, written or read.
    #[error("log {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS error.
        source: std::io::Error,
    },
    /// Writing a record failed (a full disk: "No space left on device").
    #[error("log {path}: writing the record of step {step} failed; the log holds the {written} records before it")]
    Write {
        /// The file.
        path: PathBuf,
        /// Step of the first record not written.
        step: u64,
        /// Whole records written to the file before it.
        written: u64,
        /// The OS error.
        source: std::io::Error,
    },
    /// Another process holds the log file's lock (a second run given the same `--log`).
    #[error("log {path} is being written by another run (it holds the file's lock); give this run another --log")]
    Locked {
        /// The file.
        path: PathBuf,
    },
    /// The writer thread is gone (it failed earlier; see its error).
    #[error("log writer stopped: {0}")]
    WriterGone(String),
    /// The file is not an oils log.
    #[error("{path} is not an oils log ({why})")]
    NotALog {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        why: String,
    },
}

/// The format of a run's log.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LogFormat {
    /// OILSLOG3: fixed-size binary records with a CRC each (this module).
    #[default]
    Oilslog,
    /// MCAP with JSON messages: opens in Foxglove. Written by a sink from the lab
    /// (`oils_lab::mcap_log`), handed to the session as a [`SinkOpener`].
    Mcap,
}

impl LogFormat {
    /// The default; lets the configuration leave it out.
    pub fn is_default(&self) -> bool {
        *self == Self::default()
    }

    /// The format a log file name asks for: `.mcap` is MCAP, anything else OILSLOG3.
    pub fn from_path(path: &std::path::Path) -> Self {
        match path.extension().and_then(|e| e.to_str()) {
            Some("mcap") => LogFormat::Mcap,
            _ => LogFormat::Oilslog,
        }
    }

    /// File extension of a log in this format.
    pub fn extension(&self) -> &'static str {
        match self {
            LogFormat::Oilslog => "oilslog",
            LogFormat::Mcap => "mcap",
        }
    }
}

impl std::str::FromStr for LogFormat {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "oilslog" => Ok(LogFormat::Oilslog),
            "mcap" => Ok(LogFormat::Mcap),
            other => Err(format!(
                "unknown log format `{other}` (expected oilslog or mcap)"
            )),
        }
    }
}

/// Opens a writer for a log format the core does not write itself (MCAP: the lab's
/// `oils_lab::mcap_log::McapOpener`). The session calls it before tick 0 with the log's
/// path and header; the sink then runs on the writer thread.
pub trait SinkOpener {
    /// The formats this opener writes.
    fn writes(&self, format: LogFormat) -> bool;
    /// Creates the file at `path` with `header_json` and returns its sink.
    fn open(
        &self,
        format: LogFormat,
        path: &Path,
        header_json: &str,
    ) -> Result<Box<dyn RecordSink>, RecorderError>;
}

/// Another format for the writer thread to write (the MCAP log): it gets every record,
/// in order, on the writer thread, never on the stepping thread.
pub trait RecordSink: Send {
    /// Writes one record.
    fn write(&mut self, rec: &Record) -> Result<(), RecorderError>;
    /// The channel ran dry: hand to the OS what the format can hand over now.
    fn caught_up(&mut self) -> Result<(), RecorderError>;
    /// No more records: close the file (summary, index), flush and sync it.
    fn finish(&mut self) -> Result<(), RecorderError>;
}

/// Hands records to the writer thread.
pub struct Recorder {
    tx: Option<Sender<Record>>,
    writer: Option<JoinHandle<Result<u64, RecorderError>>>,
    path: PathBuf,
}

/// Opens `path` for a run's log: created 0600 (a log holds the run's whole
/// configuration; share it on purpose), locked exclusively for as long as the file stays
/// open (a second run on the same path fails here, before it truncates anything), then
/// emptied. Also the MCAP writer's way to open its file.
pub fn create_locked(path: &Path) -> Result<File, RecorderError> {
    use std::os::unix::fs::OpenOptionsExt;
    let io = |source| RecorderError::Io {
        path: path.to_path_buf(),
        source,
    };
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create(true)
        .truncate(false)
        .mode(0o600)
        .open(path)
        .map_err(io)?;
    match file.try_lock() {
        Ok(()) => {}
        Err(std::fs::TryLockError::WouldBlock) => {
            return Err(RecorderError::Locked {
                path: path.to_path_buf(),
            })
        }
        Err(std::fs::TryLockError::Error(e)) => return Err(io(e)),
    }
    // Not a regular file (`/dev/full`, a pipe): nothing to empty.
    if file.metadata().is_ok_and(|m| m.is_file()) {
        file.set_len(0).map_err(io)?;
    }
    Ok(file)
}

impl Recorder {
    /// Creates the log file (see [`create_locked`]), writes the header and starts the
    /// writer thread.
    pub fn create(path: &Path, header_json: &str) -> Result<Self, RecorderError> {
        let file = create_locked(path)?;
        Self::over(path, Box::new(file), header_json)
    }

    /// A recorder writing OILSLOG6 to `out` (a file; in tests, a writer that fails);
    /// `path` names it in errors.
    pub fn over(path: &Path, out: Box<dyn Sink>, header_json: &str) -> Result<Self, RecorderError> {
        Self::framed(path, out, header_json, FRAME_RECORDS)
    }

    /// [`Recorder::over`] with frames of `frame_records` records (tests use small ones).
    pub fn framed(
        path: &Path,
        mut out: Box<dyn Sink>,
        header_json: &str,
        frame_records: usize,
    ) -> Result<Self, RecorderError> {
        let frame_records = frame_records.clamp(1, FRAME_RECORDS);
        let io = |source| RecorderError::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut head = Vec::with_capacity(16 + header_json.len());
        head.extend_from_slice(MAGIC);
        head.extend_from_slice(&(header_json.len() as u32).to_le_bytes());
        head.extend_from_slice(&crc32fast::hash(header_json.as_bytes()).to_le_bytes());
        head.extend_from_slice(header_json.as_bytes());
        out.write_all(&head).map_err(io)?;
        let (tx, rx) = bounded(CHANNEL_CAPACITY);
        let thread_path = path.to_path_buf();
        let writer = std::thread::Builder::new()
            .name("oils-recorder".into())
            .spawn(move || write_records(rx, out, thread_path, frame_records))
            .map_err(io)?;
        Ok(Self {
            tx: Some(tx),
            writer: Some(writer),
            path: path.to_path_buf(),
        })
    }

    /// Starts a writer thread that hands every record to `sink` (a format other than
    /// OILSLOG3, e.g. the lab's MCAP sink); same channel, same guarantees.
    pub fn with_sink(path: &Path, mut sink: Box<dyn RecordSink>) -> Result<Self, RecorderError> {
        let (tx, rx) = bounded::<Record>(CHANNEL_CAPACITY);
        let writer = std::thread::Builder::new()
            .name("oils-recorder".into())
            .spawn(move || {
                let mut written = 0u64;
                while let Ok(rec) = rx.recv() {
                    sink.write(&rec)?;
                    written += 1;
                    while let Ok(rec) = rx.try_recv() {
                        sink.write(&rec)?;
                        written += 1;
                    }
                    sink.caught_up()?;
                }
                sink.finish()?;
                Ok(written)
            })
            .map_err(|source| RecorderError::Io {
                path: path.to_path_buf(),
                source,
            })?;
        Ok(Self {
            tx: Some(tx),
            writer: Some(writer),
            path: path.to_path_buf(),
        })
    }

    /// The log file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Queues one record. When the writer is 8192 records behind (an in-process run
    /// outpaces the disk), waits for room by yielding, not by a blocking send: a
    /// blocking send registers the thread with the channel's waker list, which
    /// allocates, and the stepping thread must never allocate.
    pub fn record(&self, rec: &Record) -> Result<(), RecorderError> {
        let Some(tx) = &self.tx else {
            return Err(RecorderError::WriterGone("recorder finished".into()));
        };
        let mut rec = *rec;
        loop {
            match tx.try_send(rec) {
                Ok(()) => return Ok(()),
                Err(TrySendError::Full(r)) => {
                    rec = r;
                    std::thread::yield_now();
                }
                Err(TrySendError::Disconnected(_)) => {
                    return Err(RecorderError::WriterGone("channel closed".into()))
                }
            }
        }
    }

    /// Closes the channel, waits for the writer to write, flush and sync everything.
    /// Returns the number of records written.
    pub fn finish(mut self) -> Result<u64, RecorderError> {
        self.close()
    }

    fn close(&mut self) -> Result<u64, RecorderError> {
        drop(self.tx.take());
        match self.writer.take() {
            Some(h) => h
                .join()
                .map_err(|_| RecorderError::WriterGone("writer panicked".into()))?,
            None => Ok(0),
        }
    }
}

impl Drop for Recorder {
    /// Error paths drop the recorder: it still writes and syncs what it has.
    fn drop(&mut self) {
        let _ = self.close();
    }
}

/// Where the OILSLOG6 writer puts its bytes: a file (synced at the end), or a test's
/// writer.
pub trait Sink: Write + Send {
    /// Makes what was written durable (`fsync` for a file).
    fn sync(&mut self) -> std::io::Result<()>;
}

impl Sink for File {
    fn sync(&mut self) -> std::io::Result<()> {
        self.sync_all()
    }
}

/// Packs `n` records (`raw`, `n * RECORD_SIZE` bytes) for compression: each u64 word's
/// second difference along the records, as byte planes (the module's doc). `out` is
/// cleared and filled with as many bytes.
pub fn pack_frame(raw: &[u8], n: usize, out: &mut Vec<u8>) {
    out.clear();
    out.resize(n * RECORD_SIZE, 0);
    let word_at = |r: usize, j: usize| {
        let at = r * RECORD_SIZE + j * 8;
        let mut word = [0u8; 8];
        word.copy_from_slice(&raw[at..at + 8]);
        u64::from_le_bytes(word)
    };
    for j in 0..RECORD_SIZE / 8 {
        let (mut prev1, mut prev2) = (0u64, 0u64);
        let mut r = 0;
        // Eight records at a time: their eight differences, transposed as an 8x8 byte
        // block, become eight bytes of each of the word's eight planes (one store each,
        // not 64 byte stores).
        while r < n {
            let count = (n - r).min(8);
            let mut d2 = [0u64; 8];
            for (k, d) in d2.iter_mut().enumerate().take(count) {
                let v = word_at(r + k, j);
                *d = v.wrapping_sub(prev1.wrapping_mul(2)).wrapping_add(prev2);
                (prev2, prev1) = (prev1, v);
            }
            for b in 0..8 {
                let plane = (j * 8 + b) * n + r;
                let mut bytes = [0u8; 8];
                for (k, byte) in bytes.iter_mut().enumerate() {
                    *byte = (d2[k] >> (8 * b)) as u8;
                }
                if count == 8 {
                    // A fixed length: a store, not a call to memmove.
                    out[plane..plane + 8].copy_from_slice(&bytes);
                } else {
                    out[plane..plane + count].copy_from_slice(&bytes[..count]);
                }
            }
            r += count;
        }
    }
}

/// The inverse of [`pack_frame`]: `packed` (`n * RECORD_SIZE` bytes) back to the records.
pub fn unpack_frame(packed: &[u8], n: usize, out: &mut Vec<u8>) {
    out.clear();
    out.resize(n * RECORD_SIZE, 0);
    for j in 0..RECORD_SIZE / 8 {
        let (mut prev1, mut prev2) = (0u64, 0u64);
        for r in 0..n {
            let mut word = [0u8; 8];
            for (b, byte) in word.iter_mut().enumerate() {
                *byte = packed[(j * 8 + b) * n + r];
            }
            let v = u64::from_le_bytes(word)
                .wrapping_add(prev1.wrapping_mul(2))
                .wrapping_sub(prev2);
            (prev2, prev1) = (prev1, v);
            let at = r * RECORD_SIZE + j * 8;
            out[at..at + 8].copy_from_slice(&v.to_le_bytes());
        }
    }
}

/// A frame's 12-byte header.
fn frame_header(records: u32, packed_len: u32) -> [u8; FRAME_HEADER_SIZE] {
    let mut h = [0u8; FRAME_HEADER_SIZE];
    h[0..4].copy_from_slice(&records.to_le_bytes());
    h[4..8].copy_from_slice(&packed_len.to_le_bytes());
    let crc = crc32fast::hash(&h[0..8]);
    h[8..12].copy_from_slice(&crc.to_le_bytes());
    h
}

/// The writer thread: records into frames, each packed, compressed and handed to the OS
/// when full (and the last when the channel closes), then the trailer and an `fsync`.
/// Its buffers are allocated once, here, off the stepping thread.
fn write_records(
    rx: Receiver<Record>,
    mut out: Box<dyn Sink>,
    path: PathBuf,
    frame_records: usize,
) -> Result<u64, RecorderError> {
    let io_err = |source| RecorderError::Io {
        path: path.clone(),
        source,
    };
    let mut raw: Vec<u8> = Vec::with_capacity(frame_records * RECORD_SIZE);
    let mut packed: Vec<u8> = Vec::with_capacity(frame_records * RECORD_SIZE);
    let mut frame: Vec<u8> =
        Vec::with_capacity(FRAME_HEADER_SIZE + zstd::zstd_safe::compress_bound(raw.capacity()));
    let mut zstd = zstd::bulk::Compressor::new(ZSTD_LEVEL).map_err(io_err)?;
    zstd.include_checksum(true).map_err(io_err)?;
    let mut buf = [0u8; RECORD_SIZE];
    // Step of the frame's first record (for the error of a failed write).
    let mut first_step = 0u64;
    let mut written = 0u64;
    // Packs, compresses and writes the records in `raw`; counts them once the OS has
    // the whole frame.
    let mut flush = |raw: &mut Vec<u8>,
                     first_step: u64,
                     written: &mut u64,
                     out: &mut dyn Sink|
     -> Result<(), RecorderError> {
        let n = raw.len() / RECORD_SIZE;
        if n == 0 {
            return Ok(());
        }
        pack_frame(raw, n, &mut packed);
        frame.clear();
        frame.resize(
            FRAME_HEADER_SIZE + zstd::zstd_safe::compress_bound(packed.len()),
            0,
        );
        let len = zstd
            .compress_to_buffer(&packed[..], &mut frame[FRAME_HEADER_SIZE..])
            .map_err(|source| RecorderError::Io {
                path: path.clone(),
                source,
            })?;
        frame.truncate(FRAME_HEADER_SIZE + len);
        frame[..FRAME_HEADER_SIZE].copy_from_slice(&frame_header(n as u32, len as u32));
        raw.clear();
        let mut done = 0;
        while done < frame.len() {
            let e = match out.write(&frame[done..]) {
                Ok(0) => std::io::Error::new(
                    std::io::ErrorKind::WriteZero,
                    "the file took no more bytes",
                ),
                Ok(n) => {
                    done += n;
                    continue;
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(e) => e,
            };
            return Err(RecorderError::Write {
                path: path.clone(),
                step: first_step,
                written: *written,
                source: e,
            });
        }
        *written += n as u64;
        Ok(())
    };
    loop {
        let rec = match rx.recv_timeout(IDLE_FLUSH) {
            Ok(rec) => rec,
            // The run stalled (a flight software that never returns, a paused realtime
            // run): what it recorded goes to the file now, as a short frame, so a run
            // then killed keeps every step.
            Err(RecvTimeoutError::Timeout) => {
                flush(&mut raw, first_step, &mut written, out.as_mut())?;
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        };
        if raw.is_empty() {
            first_step = rec.telemetry.header.step;
        }
        rec.encode(&mut buf);
        raw.extend_from_slice(&buf);
        if raw.len() >= frame_records * RECORD_SIZE {
            flush(&mut raw, first_step, &mut written, out.as_mut())?;
        }
    }
    flush(&mut raw, first_step, &mut written, out.as_mut())?;
    let io = |source| RecorderError::Io {
        path: path.clone(),
        source,
    };
    let mut trailer = [0u8; TRAILER_SIZE];
    trailer[..8].copy_from_slice(TRAILER_MAGIC);
    trailer[8..16].copy_from_slice(&written.to_le_bytes());
    let crc = crc32fast::hash(&trailer[..16]);
    trailer[16..].copy_from_slice(&crc.to_le_bytes());
    out.write_all(&trailer).map_err(io)?;
    out.flush().map_err(io)?;
    out.sync().map_err(io)?;
    Ok(written)
}

/// A log file read back.
#[derive(Debug, Clone, Default)]
pub struct Log {
    /// The JSON header.
    pub header_json: String,
    /// The records whose CRC matched, in file order.
    pub records: Vec<Record>,
    /// Positions (0-based, in file order) of records whose CRC did not match.
    pub damaged_records: Vec<u64>,
    /// Bytes after the last whole record (a crash mid-write leaves some).
    pub trailing_bytes: usize,
    /// Whether the log holds its run's end: the end-of-run record, and (OILSLOG6) the
    /// trailer counting every record. `false`: the run was interrupted (kill -9, a full
    /// disk) or the file cut; every record before is still read.
    pub complete: bool,
    /// What a reader should tell its user (a log without its end, ...).
    pub warnings: Vec<String>,
}

impl Log {
    /// Sets [`Log::complete`] from the last record (and `trailer_ok`), with the warning
    /// a log without its end gets.
    pub fn check_end(&mut self, trailer_ok: bool) {
        let end_record = self
            .records
            .last()
            .is_some_and(|r| r.flags & REC_END_OF_RUN != 0);
        self.complete = end_record && trailer_ok && self.damaged_records.is_empty();
        if !end_record || !trailer_ok {
            let n = self.records.len() + self.damaged_records.len();
            self.warnings.push(format!(
                "log ends without its end record: run interrupted after {n} records"
            ));
        }
    }

    /// Refuses records of more than one run (two runs writing one file) and records of
    /// another run than the header's.
    fn check_one_run(&self, path: &Path) -> Result<(), RecorderError> {
        let header_id = serde_json::from_str::<serde_json::Value>(&self.header_json)
            .ok()
            .and_then(|h| h["run_id"].as_str().map(str::to_string))
            .and_then(|s| u64::from_str_radix(&s, 16).ok());
        let Some(first) = header_id.or(self.records.first().map(|r| r.telemetry.header.run_id))
        else {
            return Ok(());
        };
        if let Some((i, r)) = self
            .records
            .iter()
            .enumerate()
            .find(|(_, r)| r.telemetry.header.run_id != first)
        {
            return Err(RecorderError::NotALog {
                path: path.to_path_buf(),
                why: format!(
                    "it mixes runs: record {i} is of run {:016x}, the log's run is {first:016x} (two runs wrote one file?)",
                    r.telemetry.header.run_id
                ),
            });
        }
        Ok(())
    }
}

/// Reads a whole log file.
pub fn read_log(path: &Path) -> Result<Log, RecorderError> {
    let io = |source| RecorderError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut bytes = Vec::new();
    File::open(path)
        .map_err(io)?
        .read_to_end(&mut bytes)
        .map_err(io)?;
    parse_log(path, &bytes)
}

/// The record count of a valid trailer (`magic`) at the end of `body`, if there is one.
fn trailer_count(body: &[u8], magic: &[u8; 8]) -> Option<u64> {
    let at = body.len().checked_sub(TRAILER_SIZE)?;
    let t = &body[at..];
    if &t[..8] != magic {
        return None;
    }
    let crc = u32::from_le_bytes(t[16..20].try_into().ok()?);
    if crc != crc32fast::hash(&t[..16]) {
        return None;
    }
    Some(u64::from_le_bytes(t[8..16].try_into().ok()?))
}

/// One frame of an OILSLOG7 body, as its header describes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameAt {
    /// Offset of the frame's header in the body (after the file's JSON header).
    pub offset: usize,
    /// Records it holds.
    pub records: u32,
    /// Bytes of its zstd frame.
    pub packed_len: u32,
}

/// The frames of an OILSLOG7 body, in order, found by their headers (each says how long
/// its frame is: the index a reader seeks by), and the bytes after the last whole one
/// (a frame cut short, or a damaged header, ends the list).
pub fn frames(body: &[u8]) -> (Vec<FrameAt>, usize) {
    let mut out = Vec::new();
    let mut at = 0;
    while body.len() - at >= FRAME_HEADER_SIZE {
        let h = &body[at..at + FRAME_HEADER_SIZE];
        let word = |i: usize| u32::from_le_bytes([h[i], h[i + 1], h[i + 2], h[i + 3]]);
        let (records, packed_len) = (word(0), word(4));
        let whole = at + FRAME_HEADER_SIZE + packed_len as usize <= body.len();
        if word(8) != crc32fast::hash(&h[..8])
            || records == 0
            || records as usize > FRAME_RECORDS
            || !whole
        {
            break;
        }
        out.push(FrameAt {
            offset: at,
            records,
            packed_len,
        });
        at += FRAME_HEADER_SIZE + packed_len as usize;
    }
    (out, body.len() - at)
}

/// Parses a whole log file's bytes (`path` names it in errors). Never panics: any bytes
/// give a log or an error (fuzzed, see `fuzz/`).
pub fn parse_log(path: &Path, bytes: &[u8]) -> Result<Log, RecorderError> {
    let not_log = |why: &str| RecorderError::NotALog {
        path: path.to_path_buf(),
        why: why.into(),
    };
    if bytes.len() >= 8 && &bytes[..8] == MAGIC_V1 {
        return Err(not_log(
            "an OILSLOG1 log, the format before the true state was recorded; run again to get an OILSLOG8 log",
        ));
    }
    if bytes.len() >= 8 && &bytes[..8] == MAGIC_V2 {
        return Err(not_log(
            "an OILSLOG2 log, the format before per-step timing was recorded; run again (`oils run --config-from` its report) to get an OILSLOG8 log",
        ));
    }
    if bytes.len() >= 8 && (&bytes[..8] == MAGIC_V3 || &bytes[..8] == MAGIC_V4) {
        return Err(not_log(
            "an OILSLOG3/OILSLOG4 log, with protocol v1 packets; run again (`oils run --config-from` its report) to get an OILSLOG8 log",
        ));
    }
    if bytes.len() >= 8 && &bytes[..8] == MAGIC_V5 {
        return Err(not_log(
            "an OILSLOG5 log, with protocol v2 packets; run again (`oils run --config-from` its report) to get an OILSLOG8 log",
        ));
    }
    if bytes.len() >= 8 && (&bytes[..8] == MAGIC_V6 || &bytes[..8] == MAGIC_V7) {
        return Err(not_log(
            "an OILSLOG6/OILSLOG7 log, with protocol v3 packets; run again (`oils run --config-from` its report) to get an OILSLOG8 log",
        ));
    }
    let v3 = false;
    if bytes.len() < 12 || &bytes[..8] != MAGIC {
        return Err(not_log(
            "missing OILSLOG8 magic (this program reads OILSLOG8)",
        ));
    }
    let header_len = u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize;
    let header_start: usize = if v3 { 12 } else { 16 };
    let body_start = header_start
        .checked_add(header_len)
        .filter(|e| *e <= bytes.len())
        .ok_or_else(|| not_log("truncated header"))?;
    let header = &bytes[header_start..body_start];
    if !v3 {
        let stored = u32::from_le_bytes([bytes[12], bytes[13], bytes[14], bytes[15]]);
        if stored != crc32fast::hash(header) {
            return Err(not_log(
                "its header's CRC does not match: the header (the run's configuration) was edited or damaged",
            ));
        }
    }
    let header_json =
        String::from_utf8(header.to_vec()).map_err(|_| not_log("header is not UTF-8"))?;
    parse_frames(path, header_json, &bytes[body_start..])
}

/// The records of an OILSLOG8 body: every whole frame's, a frame that does not
/// decompress counted damaged record by record.
fn parse_frames(path: &Path, header_json: String, body: &[u8]) -> Result<Log, RecorderError> {
    let (list, rest) = frames(body);
    // The trailer is what follows the last whole frame, and all of it.
    let trailer = if rest == TRAILER_SIZE {
        trailer_count(body, TRAILER_MAGIC)
    } else {
        None
    };
    let mut log = Log {
        header_json,
        records: Vec::with_capacity(list.iter().map(|f| f.records as usize).sum()),
        trailing_bytes: if trailer.is_some() { 0 } else { rest },
        ..Log::default()
    };
    let mut decompress = zstd::bulk::Decompressor::new().map_err(|source| RecorderError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let (mut packed, mut raw) = (Vec::new(), Vec::new());
    let mut position = 0u64;
    for f in &list {
        let n = f.records as usize;
        let start = f.offset + FRAME_HEADER_SIZE;
        let data = &body[start..start + f.packed_len as usize];
        packed.clear();
        let whole = decompress
            .decompress_to_buffer(data, &mut packed_buffer(&mut packed, n))
            .ok()
            .filter(|len| *len == n * RECORD_SIZE);
        match whole {
            Some(len) => {
                packed.truncate(len);
                unpack_frame(&packed, n, &mut raw);
                for chunk in raw.chunks_exact(RECORD_SIZE) {
                    match Record::decode(chunk) {
                        Some(r) => log.records.push(r),
                        None => log.damaged_records.push(position),
                    }
                    position += 1;
                }
            }
            None => {
                log.damaged_records.extend(position..position + n as u64);
                position += n as u64;
            }
        }
    }
    log.check_one_run(path)?;
    log.check_end(trailer == Some(position));
    if rest > 0 && trailer.is_none() {
        log.warnings.push(format!(
            "{rest} bytes after the last whole frame (a frame cut short, or a damaged frame header) ignored"
        ));
    }
    if let Some(n) = trailer.filter(|n| *n != position) {
        log.warnings.push(format!(
            "its trailer counts {n} records, the file holds {position}"
        ));
    }
    Ok(log)
}

/// `buf` sized for `records` records, to decompress into (a frame says more: an error).
fn packed_buffer(buf: &mut Vec<u8>, records: usize) -> &mut Vec<u8> {
    buf.clear();
    buf.resize(records * RECORD_SIZE, 0);
    buf
}

/// Writes a log's records as CSV: one row per record, one column per value of every
/// field of [`log_fields::FIELDS`] but the echoes, named by topic and path with units
/// and frames (`truth.pos_mci_m[0]`, as Foxglove names the MCAP field). Every cell is a
/// number: flags 1/0, ids in decimal, an absent figure `NaN`.
pub fn export_csv(log: &Log, out: &mut impl Write) -> std::io::Result<()> {
    writeln!(out, "{}", log_fields::csv_columns().join(","))?;
    let site = Site::of_log_header(&log.header_json)
        .map_err(|why| std::io::Error::new(std::io::ErrorKind::InvalidData, why))?;
    let mut line = String::new();
    for r in &log.records {
        let derived = Derived::of(&r.truth, r.telemetry.header.t_ns as f64 * 1e-9, &site);
        let sample = Sample {
            record: r,
            derived: &derived,
        };
        line.clear();
        for f in log_fields::FIELDS.iter().filter(|f| f.in_csv()) {
            for i in 0..f.count() {
                use std::fmt::Write as _;
                if !line.is_empty() {
                    line.push(',');
                }
                // Writing to a String cannot fail.
                let _ = match f.get(&sample, i) {
                    Value::F64(x) => write!(line, "{x}"),
                    Value::Bool(b) => write!(line, "{}", u8::from(b)),
                    Value::U64(n) => write!(line, "{n}"),
                    Value::I64(n) => write!(line, "{n}"),
                    Value::Absent => write!(line, "NaN"),
                };
            }
        }
        writeln!(out, "{line}")?;
    }
    out.flush()
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("oils-rec-{}-{name}", std::process::id()))
    }

    #[test]
    fn records_round_trip_and_export() {
        let path = temp("rt.oilslog");
        let header = crate::session::log_header(&crate::run_config::RunConfig::default(), 0);
        let rec = Recorder::create(&path, &header).unwrap();
        for k in 0..1000u64 {
            let mut r = Record {
                flags: REC_COMMAND_RECEIVED,
                ..Default::default()
            };
            r.telemetry.header.step = k;
            r.telemetry.altitude_m = k as f64 * 0.5;
            r.command.thrust_cmd_n[2] = 400.0 + k as f64;
            rec.record(&r).unwrap();
        }
        assert_eq!(rec.finish().unwrap(), 1000);
        let log = read_log(&path).unwrap();
        assert_eq!(log.header_json, header);
        assert_eq!(log.records.len(), 1000);
        assert_eq!(log.trailing_bytes, 0);
        assert_eq!(log.records[999].telemetry.altitude_m, 499.5);
        assert_eq!(log.records[999].command.thrust_cmd_n[2], 1399.0);
        let mut csv = Vec::new();
        export_csv(&log, &mut csv).unwrap();
        let text = String::from_utf8(csv).unwrap();
        assert_eq!(text.lines().count(), 1001);
        let header: Vec<&str> = text.lines().next().unwrap().split(',').collect();
        let row: Vec<&str> = text.lines().nth(1000).unwrap().split(',').collect();
        assert_eq!(header.len(), row.len());
        assert_eq!(header[0], "telemetry.header.step");
        assert_eq!(row[0], "999");
        let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
        assert_eq!(row[col("telemetry.altitude_m")], "499.5");
        assert_eq!(row[col("command.thrust_cmd_n[2]")], "1399");
        assert_eq!(row[col("timing.round_trip_ns")], "NaN");
        assert!(row.iter().all(|v| v.parse::<f64>().is_ok()), "{row:?}");
        std::fs::remove_file(&path).ok();
    }

    /// A record with a different value in every field (so a field stored in the wrong
    /// place, or not at all, changes the bytes).
    pub(crate) fn distinct_record() -> Record {
        let mut x = 0.0;
        let mut next = || {
            x += 1.25;
            x
        };
        let mut r = Record {
            flags: REC_COMMAND_RECEIVED | REC_FAULT_FIRED,
            faults_active: 0b1011,
            timing: StepTimes {
                round_trip_ns: Some(12_345),
                wake_error_ns: Some(-678),
                transport_ns: Some(9_012),
            },
            ..Default::default()
        };
        r.telemetry.header = oils_shared::PacketHeader::new(0x1234_5678_9abc_def0, 77, 770_000_000);
        r.telemetry.header.flags = 2;
        let t = &mut r.telemetry;
        for v in t
            .nav
            .pos_mci_m
            .iter_mut()
            .chain(&mut t.nav.vel_mci_m_s)
            .chain(&mut t.nav.q_mci_from_body)
            .chain(&mut t.nav.rate_body_rad_s)
            .chain(&mut t.accel_body_m_s2)
        {
            *v = next();
        }
        t.altitude_m = next();
        t.mass_estimate_kg = next();
        t.propulsion.gas_pressure_pa = next();
        t.propulsion.fuel_tank_pressure_pa = next();
        t.propulsion.ox_tank_pressure_pa = next();
        for (e, eng) in t.propulsion.engines.iter_mut().enumerate() {
            eng.thrust_n = next();
            eng.chamber_pressure_pa = next();
            eng.valve_open = e as u32 % 2;
            eng.flags = e as u32 + 3;
        }
        r.command.header = r.telemetry.header;
        r.command.header.flags = 0;
        for v in r
            .command
            .thrust_cmd_n
            .iter_mut()
            .chain(&mut r.command.torque_cmd_body_nm)
        {
            *v = next();
        }
        r.command.engine_on = [1, 0, 1, 1];
        r.command.stub_compute_ns = 4321;
        // Protocol v3: the flight software's report.
        let fr = &mut r.command.fsw;
        for v in fr
            .nav_pos_mci_m
            .iter_mut()
            .chain(&mut fr.nav_vel_mci_m_s)
            .chain(&mut fr.nav_pos_sigma_m)
            .chain(&mut fr.nav_vel_sigma_m_s)
        {
            *v = next();
        }
        (fr.nav_altitude_m, fr.nav_altitude_sigma_m) = (next(), next());
        fr.group_compute_ns = [11, 12, 13, 14];
        (fr.nav_flags, fr.phase, fr.boot_count, fr.cycle_slips) = (0x2b, 3, 2, 1);
        r.applied.engines.thrust_cmd_n = [next(), next(), next(), next()];
        r.applied.engines.on = [true, false, false, true];
        r.applied.torque_cmd_body_nm = [next(), next(), next()];
        // Protocol v2: every device sample slot and the thruster command.
        let f = &mut r.telemetry.sensors;
        (f.imu_count, f.star_tracker_count) = (8, 2);
        (
            f.laser_altimeter_count,
            f.rf_altimeter_count,
            f.velocimeter_count,
        ) = (1, 2, 1);
        // Protocol v4: the frame announcements.
        f.frame_count = 3;
        for (k, a) in f.frames.iter_mut().enumerate() {
            let k = k as u32;
            (a.device, a.format, a.width, a.height) = (k + 1, k + 2, 100 + k, 200 + k);
            (a.seq, a.t_ns, a.exposure_ns) = (u64::from(k) + 40, 8_000_000 + i64::from(k), 4000);
            (a.bytes, a.flags, a.hash) = (300 + k, k, 0x1234_5678_9abc_def0 ^ u64::from(k));
        }
        for (k, s) in f.imu.iter_mut().enumerate() {
            s.t_ns = 5_000_000 + k as i64;
            s.delta_v_body_m_s = [next(), next(), next()];
            s.delta_theta_body_rad = [next(), next(), next()];
            (s.valid, s.flags) = (k as u32 % 2, k as u32 + 10);
        }
        for (k, s) in f.star_tracker.iter_mut().enumerate() {
            s.t_ns = 6_000_000 + k as i64;
            s.q_mci_from_body = [next(), next(), next(), next()];
            (s.valid, s.flags) = (1, k as u32 + 20);
        }
        for (k, s) in f
            .laser_altimeter
            .iter_mut()
            .chain(&mut f.rf_altimeter)
            .enumerate()
        {
            s.t_ns = 7_000_000 + k as i64;
            s.range_m = next();
            (s.valid, s.flags) = (k as u32 % 2, k as u32 + 30);
        }
        for (k, s) in f.velocimeter.iter_mut().enumerate() {
            s.t_ns = 8_000_000 + k as i64;
            s.los_velocity_m_s = [next(), next(), next()];
            s.range_m = [next(), next(), next()];
            s.valid = [1, 0, k as u32];
            s.flags = k as u32 + 40;
        }
        r.command.attitude_mode = 1;
        r.command.thruster_on_time_ns = [11, 22, 33, 44, 55, 66, 77, 88];
        r.applied.use_thrusters = true;
        r.applied.thruster_on_time_ns = [1, 2, 3, 4, 5, 6, 7, 8];
        let tr = &mut r.truth;
        for v in tr
            .pos_mci_m
            .iter_mut()
            .chain(&mut tr.vel_mci_m_s)
            .chain(&mut tr.q_mci_from_body)
            .chain(&mut tr.rate_body_rad_s)
        {
            *v = next();
        }
        tr.mass_kg = next();
        tr.altitude_m = next();
        tr.contact = true;
        let p = &mut tr.propulsion;
        for v in p
            .thrust_n
            .iter_mut()
            .chain(&mut p.mean_thrust_n)
            .chain(&mut p.chamber_pressure_pa)
        {
            *v = next();
        }
        p.gas_pressure_pa = next();
        p.fuel_tank_pressure_pa = next();
        p.ox_tank_pressure_pa = next();
        p.ejected_fuel_kg = next();
        p.ejected_ox_kg = next();
        p.fuel_flow_kg_s = next();
        p.ox_flow_kg_s = next();
        let i = &mut tr.internals;
        i.regulator_outlet_pa = next();
        i.manifold_pressure_pa = [next(), next()];
        for v in i.valve_position.iter_mut().flatten() {
            *v = next();
        }
        r
    }

    /// The record's byte layout, pinned: the CRC-32 of a record with a different value in
    /// every field, as OILSLOG8 writes it (protocol v4 packets, the devices' slots and
    /// frame announcements). A
    /// field moved, converted differently or dropped changes it.
    #[test]
    fn the_record_layout_is_pinned() {
        let r = distinct_record();
        let mut bytes = [0u8; RECORD_SIZE];
        r.encode(&mut bytes);
        assert_eq!(RECORD_SIZE, 2304);
        assert_eq!(crc32fast::hash(&bytes), 820_754_004, "layout changed");
        assert_eq!(Record::decode(&bytes), Some(r));
    }

    #[test]
    fn dropping_the_recorder_still_writes_everything() {
        let path = temp("drop.oilslog");
        {
            let rec = Recorder::create(&path, "{}").unwrap();
            for _ in 0..10 {
                rec.record(&Record::default()).unwrap();
            }
        }
        assert_eq!(read_log(&path).unwrap().records.len(), 10);
        std::fs::remove_file(&path).ok();
    }

    /// A log of `n` records of run `run_id`, closed (end record, trailer), one record a
    /// frame, as bytes.
    fn closed_log(name: &str, n: u64, run_id: u64) -> Vec<u8> {
        let path = temp(name);
        let file = create_locked(&path).unwrap();
        let header = format!(r#"{{"run_id":"{run_id:016x}"}}"#);
        let rec = Recorder::framed(&path, Box::new(file), &header, 1).unwrap();
        for k in 0..n {
            let mut r = Record::default();
            r.telemetry.header = oils_shared::PacketHeader::new(run_id, k, k as i64 * 10);
            if k + 1 == n {
                r.flags = REC_END_OF_RUN;
            }
            rec.record(&r).unwrap();
        }
        assert_eq!(rec.finish().unwrap(), n);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::remove_file(&path).ok();
        bytes
    }

    /// A log cut at a record boundary read as whole; now it is read with a warning that
    /// names how many records it holds.
    #[test]
    fn a_log_cut_at_a_record_boundary_says_so() {
        let bytes = closed_log("cut.oilslog", 10, 7);
        let whole = parse_log(Path::new("x"), &bytes).unwrap();
        assert!(whole.complete, "{:?}", whole.warnings);
        assert!(whole.warnings.is_empty());
        // Cut after 6 frames of one record: no end record, no trailer.
        let body = body_start(&bytes);
        let (list, _) = frames(&bytes[body..]);
        assert_eq!(list.len(), 10);
        let cut = body + list[6].offset;
        let log = parse_log(Path::new("x"), &bytes[..cut]).unwrap();
        assert_eq!(log.records.len(), 6);
        assert!(!log.complete);
        assert_eq!(
            log.warnings,
            ["log ends without its end record: run interrupted after 6 records"]
        );
        // Only the trailer lost (killed while closing): still not complete.
        let log = parse_log(Path::new("x"), &bytes[..bytes.len() - TRAILER_SIZE]).unwrap();
        assert_eq!(log.records.len(), 10);
        assert!(!log.complete);
    }

    /// An edited header went unnoticed; its CRC now refuses it.
    #[test]
    fn an_edited_header_is_refused() {
        let mut bytes = closed_log("hdr.oilslog", 3, 7);
        let at = 16 + 3;
        bytes[at] ^= 0x01;
        let e = parse_log(Path::new("x"), &bytes).unwrap_err().to_string();
        assert!(e.contains("header's CRC does not match"), "{e}");
    }

    /// Two runs writing one file: records of two run ids were read without complaint.
    #[test]
    fn a_log_mixing_runs_is_refused() {
        let a = closed_log("mix-a.oilslog", 4, 0xaaaa);
        let b = closed_log("mix-b.oilslog", 4, 0xbbbb);
        // a's first two frames, then b's last two (the headers are the same length).
        let (fa, fb) = (body_start(&a), body_start(&b));
        let at_a = fa + frames(&a[fa..]).0[2].offset;
        let at_b = fb + frames(&b[fb..]).0[2].offset;
        let mut mixed = a[..at_a].to_vec();
        mixed.extend_from_slice(&b[at_b..]);
        let e = parse_log(Path::new("x"), &mixed).unwrap_err().to_string();
        assert!(e.contains("mixes runs") && e.contains("record 2"), "{e}");
    }

    /// A second recorder on a file a run is writing fails at once, before it empties it.
    #[test]
    fn a_second_recorder_on_one_file_is_refused() {
        let path = temp("locked.oilslog");
        let first = Recorder::create(&path, "{}").unwrap();
        first.record(&Record::default()).unwrap();
        let e = Recorder::create(&path, "{}").err().unwrap();
        assert!(matches!(e, RecorderError::Locked { .. }), "{e}");
        assert_eq!(first.finish().unwrap(), 1);
        assert_eq!(read_log(&path).unwrap().records.len(), 1);
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o600, "{mode:o}");
        std::fs::remove_file(&path).ok();
    }

    /// Where a log's frames start: after the magic, the header's length and CRC, and
    /// the header.
    fn body_start(bytes: &[u8]) -> usize {
        16 + u32::from_le_bytes(bytes[8..12].try_into().unwrap()) as usize
    }

    /// Every record back as written, through frames of every size up to a full one and
    /// a last one partly filled; the packing is its own inverse on any bytes.
    #[test]
    fn frames_round_trip_records_and_packing_inverts() {
        let mut records = Vec::new();
        for k in 0..(2 * FRAME_RECORDS as u64 + 37) {
            let mut r = distinct_record();
            r.telemetry.header.step = k;
            r.telemetry.altitude_m = 1000.0 - k as f64 * 0.37;
            r.truth.pos_mci_m[0] = 1.7e6 + (k as f64).sin();
            records.push(r);
        }
        let path = temp("frames.oilslog");
        let rec = Recorder::create(&path, "{}").unwrap();
        for r in &records {
            rec.record(r).unwrap();
        }
        assert_eq!(rec.finish().unwrap(), records.len() as u64);
        let bytes = std::fs::read(&path).unwrap();
        let (list, rest) = frames(&bytes[body_start(&bytes)..]);
        let sizes: Vec<u32> = list.iter().map(|f| f.records).collect();
        assert_eq!(sizes, [FRAME_RECORDS as u32, FRAME_RECORDS as u32, 37]);
        assert_eq!(rest, TRAILER_SIZE);
        let log = read_log(&path).unwrap();
        assert_eq!(log.records, records);
        std::fs::remove_file(&path).ok();

        let raw: Vec<u8> = (0..5 * RECORD_SIZE)
            .map(|i| (i * 7919 % 251) as u8)
            .collect();
        let (mut packed, mut back) = (Vec::new(), Vec::new());
        pack_frame(&raw, 5, &mut packed);
        assert_ne!(packed, raw);
        unpack_frame(&packed, 5, &mut back);
        assert_eq!(back, raw);
    }

    /// A damaged byte inside a frame's compressed records: the frame's records are
    /// counted damaged by position, the other frames read.
    #[test]
    fn a_damaged_frame_names_its_records() {
        let mut bytes = closed_log("damaged.oilslog", 6, 7);
        let body = body_start(&bytes);
        let f = frames(&bytes[body..]).0[3];
        bytes[body + f.offset + FRAME_HEADER_SIZE + f.packed_len as usize / 2] ^= 0x10;
        let log = parse_log(Path::new("x"), &bytes).unwrap();
        assert_eq!(log.damaged_records, [3]);
        assert_eq!(log.records.len(), 5);
        assert!(!log.complete);
    }

    /// A disk that fills after `room` bytes.
    struct FillsUp {
        room: usize,
        bytes: std::sync::Arc<std::sync::Mutex<Vec<u8>>>,
    }

    impl Write for FillsUp {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            let mut bytes = self.bytes.lock().unwrap();
            let n = buf.len().min(self.room - bytes.len());
            if n == 0 {
                return Err(std::io::Error::from_raw_os_error(28)); // ENOSPC
            }
            bytes.extend_from_slice(&buf[..n]);
            Ok(n)
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Sink for FillsUp {
        fn sync(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    /// On a full disk the summary counted no records and named the step the loop saw the
    /// failure at. The writer's error now names the first record not written and counts
    /// the whole records the file holds, which read back.
    #[test]
    fn a_full_disk_names_the_failing_record_and_counts_the_written_ones() {
        let header = "{}";
        // Frames of 10 records; the disk fills 100 bytes into the fifth frame.
        let write = |room: usize| {
            let bytes = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
            let sink = FillsUp {
                room,
                bytes: bytes.clone(),
            };
            let rec =
                Recorder::framed(Path::new("full.oilslog"), Box::new(sink), header, 10).unwrap();
            for k in 0..100u64 {
                let mut r = Record::default();
                r.telemetry.header.step = k;
                if rec.record(&r).is_err() {
                    break;
                }
            }
            let end = rec.finish();
            let bytes = bytes.lock().unwrap().clone();
            (end, bytes)
        };
        let (whole, all) = write(usize::MAX / 2);
        assert_eq!(whole.unwrap(), 100);
        let body = body_start(&all);
        let room = body + frames(&all[body..]).0[4].offset + 100;
        let (end, bytes) = write(room);
        match end {
            Err(RecorderError::Write { step, written, .. }) => {
                assert_eq!((step, written), (40, 40));
            }
            other => panic!("{other:?}"),
        }
        let log = parse_log(Path::new("full.oilslog"), &bytes).unwrap();
        assert_eq!(log.records.len(), 40);
        assert_eq!(log.trailing_bytes, 100);
        assert!(!log.complete);
    }

    #[test]
    fn rejects_files_that_are_not_logs() {
        let path = temp("bad.oilslog");
        std::fs::write(&path, b"hello world, not a log").unwrap();
        assert!(matches!(
            read_log(&path),
            Err(RecorderError::NotALog { .. })
        ));
        std::fs::write(&path, b"OILSLOG3\xff\xff\xff\x00").unwrap();
        assert!(matches!(
            read_log(&path),
            Err(RecorderError::NotALog { .. })
        ));
        std::fs::write(&path, b"OILSLOG5\xff\xff\xff\x00").unwrap();
        assert!(matches!(
            read_log(&path),
            Err(RecorderError::NotALog { .. })
        ));
        std::fs::remove_file(&path).ok();
        assert!(matches!(read_log(&path), Err(RecorderError::Io { .. })));
    }
}

/// The commands a run applied, as a thrust-command profile (replay a closed-loop run
/// open loop: `oils run --fsw playback`, `oils hifi`, `oils validate`). Values pass
/// through the same sanitiser as in the run, so the profile holds what the plant got.
/// `every` keeps one step in `every` (each row holds until the next), `max_thrust_n` is
/// the engine rating the run used. Thrusts are rounded to 0.01 N, far below any throttle
/// valve's resolution (quantisation 0.1-0.5 % of 800 N), to keep profiles small.
pub fn commands_as_profile(
    log: &Log,
    every: usize,
    max_thrust_n: f64,
) -> Result<oils_shared::profile::ThrustProfile, oils_shared::profile::ProfileError> {
    let rows = log
        .records
        .iter()
        .filter(|r| r.flags & REC_COMMAND_RECEIVED != 0)
        .step_by(every.max(1))
        .map(|r| {
            let (applied, _) = crate::sanitize::sanitize(
                &r.command,
                max_thrust_n,
                r.telemetry.header.t_ns,
                u64::MAX,
            );
            oils_shared::profile::ProfileRow {
                t_ns: r.telemetry.header.t_ns,
                thrust_cmd_n: applied
                    .engines
                    .thrust_cmd_n
                    .map(|t| (t * 100.0).round() / 100.0),
                on: applied.engines.on,
            }
        })
        .collect();
    oils_shared::profile::ThrustProfile::from_rows(rows)
}

#[cfg(test)]
mod profile_tests {
    use super::*;

    #[test]
    fn applied_commands_become_a_profile() {
        let mut records = Vec::new();
        for k in 0..10u64 {
            let mut r = Record {
                flags: REC_COMMAND_RECEIVED,
                ..Default::default()
            };
            r.telemetry.header.t_ns = k as i64 * 10_000_000;
            r.command.thrust_cmd_n = [400.0 + k as f64 + 0.004, f64::NAN, 900.0, 500.0];
            r.command.engine_on = [1, 1, 1, 0];
            records.push(r);
        }
        records.push(Record {
            flags: REC_END_OF_RUN,
            ..Default::default()
        });
        let log = Log {
            header_json: "{}".into(),
            records,
            ..Log::default()
        };
        let p = commands_as_profile(&log, 5, 800.0).unwrap();
        assert_eq!(p.rows().len(), 2);
        let r = p.rows()[1];
        assert_eq!(r.t_ns, 50_000_000);
        assert_eq!(r.thrust_cmd_n, [405.0, 0.0, 800.0, 500.0]);
        assert_eq!(r.on, [true, false, true, false]);
    }
}
