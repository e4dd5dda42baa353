//! The one table of a log record's fields ([`FIELDS`]). Each row names a field (its
//! path in a per-step message, units and frame in the leaf name), says how its values
//! are written, and how to get them from a [`Record`] (and set them back). The table
//! drives everything that writes or reads a record field by field:
//!
//! * the OILSLOG binary record: the f64 values after the two packets are the rows
//!   with [`Access::Slot`], each at its slot ([`crate::recorder`]);
//! * the CSV export: one column per value of every row but the [`Access::Echo`] ones,
//!   named `<topic>.<path>[i]`, as Foxglove names a message field;
//! * the MCAP log's per-step messages and their JSON schemas (`oils_lab::log_json`).
//!
//! Adding a field is adding a row: the binary record (if it has a slot), the CSV, the
//! MCAP message and its schema follow.

use crate::config::ScenarioConfig;
use crate::plant::frames::{MoonRotation, SiteFrame};
use crate::plant::TruthState;
use crate::recorder::{Record, REC_COMMAND_RECEIVED, REC_DEADLINE_MISS, REC_REJECTED_VALUES};
use nalgebra::{UnitQuaternion, Vector3};

/// The per-step message a field belongs to: the MCAP topic `/oils/<name>` and the CSV
/// column prefix `<name>.`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Topic {
    /// Telemetry(k) as published (navigation is noisy).
    Telemetry,
    /// Command(k) as received, the record's flags, and what the plant applied.
    Command,
    /// The true state at t_k, with speeds and tilt derived from it.
    Truth,
    /// The propulsion model's outputs and internals.
    Propulsion,
    /// The step's timing (wall-clock measurements).
    Timing,
    /// The devices: every sensor sample Telemetry(k) carries, by device, and the
    /// attitude-thruster command. Its CSV columns carry no topic prefix and start with
    /// the device (`imu_`, `star_tracker_`, `laser_altimeter_`, `rf_altimeter_`,
    /// `velocimeter_`, `thruster_`).
    Devices,
}

impl Topic {
    /// Every topic, in table order.
    pub const ALL: [Topic; 6] = [
        Topic::Telemetry,
        Topic::Command,
        Topic::Truth,
        Topic::Propulsion,
        Topic::Timing,
        Topic::Devices,
    ];

    /// Short name: `telemetry`, `command`, `truth`, `propulsion`, `timing`, `devices`.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Telemetry => "telemetry",
            Topic::Command => "command",
            Topic::Truth => "truth",
            Topic::Propulsion => "propulsion",
            Topic::Timing => "timing",
            Topic::Devices => "devices",
        }
    }
}

/// How a field's values are written (JSON type, and conversion to the binary record's
/// f64 values).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// A float; JSON `null` when not finite.
    F64,
    /// true/false (1/0 in the binary record and the CSV).
    Bool,
    /// An unsigned 32-bit integer.
    U32,
    /// An unsigned 64-bit integer.
    U64,
    /// A signed 64-bit integer.
    I64,
    /// A 64-bit id (run id, schema hash): 16 hex digits in JSON (JavaScript cannot hold
    /// it as a number), decimal in the CSV.
    Hex,
    /// An unsigned integer or nothing (JSON `null`, NaN in the binary record and CSV).
    OptU64,
    /// A signed integer or nothing.
    OptI64,
}

/// One value of a field.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value {
    /// A float.
    F64(f64),
    /// A flag.
    Bool(bool),
    /// An unsigned integer (also ids).
    U64(u64),
    /// A signed integer.
    I64(i64),
    /// No value (an optional figure a step has not).
    Absent,
}

impl Kind {
    /// The value as stored in the binary record.
    pub fn to_f64(self, v: Value) -> f64 {
        match v {
            Value::F64(x) => x,
            Value::Bool(b) => f64::from(u8::from(b)),
            // Exact below 2^53: fault masks of up to 53 faults, nanoseconds up to 104 days.
            Value::U64(n) => n as f64,
            Value::I64(n) => n as f64,
            Value::Absent => f64::NAN,
        }
    }

    /// The value a binary record's f64 stands for.
    pub fn from_f64(self, x: f64) -> Value {
        match self {
            Kind::F64 => Value::F64(x),
            Kind::Bool => Value::Bool(x != 0.0),
            Kind::U32 | Kind::U64 | Kind::Hex => Value::U64(x as u64),
            Kind::I64 => Value::I64(x as i64),
            Kind::OptU64 => match x.is_finite() {
                true => Value::U64(x as u64),
                false => Value::Absent,
            },
            Kind::OptI64 => match x.is_finite() {
                true => Value::I64(x as i64),
                false => Value::Absent,
            },
        }
    }
}

/// Reads element `i` of a field of a record.
pub type Get = fn(&Record, usize) -> Value;
/// Sets element `i` of a field of a record.
pub type Set = fn(&mut Record, usize, Value);

/// Where a field's values come from.
#[derive(Clone, Copy)]
pub enum Access {
    /// The record's flags or a packet field: stored as the record's own bytes.
    Packet {
        /// Getter.
        get: Get,
        /// Setter.
        set: Set,
    },
    /// One f64 per element after the packets, element `i` at `at + i * stride`.
    Slot {
        /// Slot of element 0.
        at: usize,
        /// Slots between elements (2 where two fields interleave).
        stride: usize,
        /// Getter.
        get: Get,
        /// Setter.
        set: Set,
    },
    /// Computed from the record and the run's site frame; not read back.
    Derived(fn(&Record, &Derived, usize) -> Value),
    /// A copy of another field, put in a second message to plot it there (MCAP only;
    /// not in the CSV, not read back).
    Echo(Get),
}

/// One row of the table.
#[derive(Clone, Copy)]
pub struct Field {
    /// The message it is in.
    pub topic: Topic,
    /// Its path in the message's JSON: objects joined by `.`, `name[]` an array of
    /// objects (element i of the field in object i). The leaf carries unit and frame.
    pub path: &'static str,
    /// `None`: one value; `Some(n)`: an array of n.
    pub len: Option<usize>,
    /// How values are written.
    pub kind: Kind,
    /// Where they come from.
    pub access: Access,
    /// The MCAP message format (`oils-mcap-N`) the field first appeared in: older files
    /// lack it, and read it as its default.
    pub since: u32,
}

impl Field {
    /// Number of values.
    pub fn count(&self) -> usize {
        self.len.unwrap_or(1)
    }

    /// Value `i` of the field in `sample`.
    pub fn get(&self, sample: &Sample<'_>, i: usize) -> Value {
        match self.access {
            Access::Packet { get, .. } | Access::Slot { get, .. } | Access::Echo(get) => {
                get(sample.record, i)
            }
            Access::Derived(get) => get(sample.record, sample.derived, i),
        }
    }

    /// The setter, for fields read back from a log.
    pub fn setter(&self) -> Option<Set> {
        match self.access {
            Access::Packet { set, .. } | Access::Slot { set, .. } => Some(set),
            Access::Derived(_) | Access::Echo(_) => None,
        }
    }

    /// Whether the CSV has it (everything but echoes).
    pub fn in_csv(&self) -> bool {
        !matches!(self.access, Access::Echo(_))
    }

    /// The CSV column (and Foxglove message path, without the `/oils/`) of value `i`:
    /// `truth.pos_mci_m[0]`, `telemetry.propulsion.engines[2].thrust_n`.
    pub fn column(&self, i: usize) -> String {
        if self.topic == Topic::Devices {
            // Device columns start with the device (`imu_delta_v_x_body_m_s[0]`).
            return match self.len {
                None => self.path.to_string(),
                Some(_) => format!("{}[{i}]", self.path),
            };
        }
        let topic = self.topic.name();
        match (self.len, self.path.contains("[]")) {
            (None, _) => format!("{topic}.{}", self.path),
            (Some(_), true) => {
                format!("{topic}.{}", self.path.replacen("[]", &format!("[{i}]"), 1))
            }
            (Some(_), false) => format!("{topic}.{}[{i}]", self.path),
        }
    }
}

/// A record and what is derived from it: what the table's getters read.
#[derive(Debug, Clone, Copy)]
pub struct Sample<'a> {
    /// The record.
    pub record: &'a Record,
    /// Its derived values.
    pub derived: &'a Derived,
}

/// The run's landing site: the Moon-fixed East-North-Up frame at the scenario's site
/// (`site` in the MCAP's frames), and the Moon's rotation that carries it.
#[derive(Debug, Clone, Copy)]
pub struct Site {
    /// The site frame, Moon-fixed.
    pub frame: SiteFrame,
    /// The Moon's rotation.
    pub rotation: MoonRotation,
}

impl Site {
    /// The site of a scenario.
    pub fn of_scenario(cfg: &ScenarioConfig) -> Self {
        Self {
            frame: SiteFrame::from_deg(
                cfg.site.latitude_deg,
                cfg.site.longitude_deg,
                cfg.moon.radius_m,
            ),
            rotation: MoonRotation {
                rate_rad_s: cfg.moon.rotation_rate_rad_s,
            },
        }
    }

    /// The site of the run whose log header is `header_json`, or why the header does not
    /// say (a log's site-relative figures from another site would be silently wrong).
    pub fn of_log_header(header_json: &str) -> Result<Self, String> {
        let (cfg, _) = crate::session::read_log_header(header_json)?;
        Ok(Self::of_scenario(&cfg.scenario))
    }

    /// An MCI position at `t_s` in site coordinates (east, north, up), metres.
    pub fn site_of(&self, p_mci: &Vector3<f64>, t_s: f64) -> Vector3<f64> {
        self.frame
            .site_from_mcmf(&(self.rotation.mcmf_from_mci(t_s) * p_mci))
    }

    /// An MCI vector at `t_s` in site axes.
    pub fn site_axes(&self, v_mci: &Vector3<f64>, t_s: f64) -> Vector3<f64> {
        self.frame
            .site_dir_from_mcmf(&(self.rotation.mcmf_from_mci(t_s) * v_mci))
    }

    /// The rotation from site axes to MCI at `t_s` (for the MCAP frame transforms).
    pub fn q_mci_from_site(&self, t_s: f64) -> UnitQuaternion<f64> {
        let mcmf_from_site =
            nalgebra::Rotation3::from_matrix_unchecked(self.frame.rot_site_from_mcmf().transpose());
        UnitQuaternion::from_rotation_matrix(
            &(self.rotation.mcmf_from_mci(t_s).inverse() * mcmf_from_site),
        )
    }

    /// The site frame's origin at `t_s`, MCI, metres.
    pub fn origin_mci_m(&self, t_s: f64) -> Vector3<f64> {
        self.rotation.mcmf_from_mci(t_s).inverse() * self.frame.origin_mcmf()
    }
}

/// Values derived from a record's true state (speeds and tilt relative to the local
/// vertical, the position in the site frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Derived {
    /// Radial velocity relative to the surface, m/s (negative: descending).
    pub vertical_speed_m_s: f64,
    /// Velocity relative to the surface across the local vertical, m/s.
    pub horizontal_speed_m_s: f64,
    /// Angle between the thrust axis (body +Z) and the local vertical, degrees.
    pub tilt_deg: f64,
    /// Position in the site frame (east, north, up), metres.
    pub pos_site_m: [f64; 3],
    /// Velocity relative to the surface, site axes, m/s.
    pub vel_site_m_s: [f64; 3],
}

impl Derived {
    /// What `truth` at `t_s` gives, with the run's `site`. Speeds are relative to the
    /// turning surface.
    pub fn of(truth: &TruthState, t_s: f64, site: &Site) -> Self {
        let r = Vector3::from(truth.pos_mci_m);
        let v = site
            .rotation
            .surface_relative_mci(&r, &Vector3::from(truth.vel_mci_m_s));
        let up = r.try_normalize(1e-9).unwrap_or(Vector3::z());
        let vertical = v.dot(&up);
        let horizontal = (v - up * vertical).norm();
        let [w, x, y, z] = truth.q_mci_from_body;
        let q = UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z));
        let axis = q * Vector3::z();
        let tilt = axis.dot(&up).clamp(-1.0, 1.0).acos().to_degrees();
        let p = site.site_of(&r, t_s);
        let vs = site.site_axes(&v, t_s);
        Self {
            vertical_speed_m_s: vertical,
            horizontal_speed_m_s: horizontal,
            tilt_deg: tilt,
            pos_site_m: [p.x, p.y, p.z],
            vel_site_m_s: [vs.x, vs.y, vs.z],
        }
    }
}

/// Rust values a field can hold.
pub trait Scalar: Copy {
    /// As a table value.
    fn value(self) -> Value;
    /// From a table value (of the field's kind).
    fn of(v: Value) -> Self;
}

impl Scalar for f64 {
    fn value(self) -> Value {
        Value::F64(self)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::F64(x) => x,
            Value::Bool(b) => f64::from(u8::from(b)),
            Value::U64(n) => n as f64,
            Value::I64(n) => n as f64,
            Value::Absent => f64::NAN,
        }
    }
}

impl Scalar for bool {
    fn value(self) -> Value {
        Value::Bool(self)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::Bool(b) => b,
            Value::F64(x) => x != 0.0,
            Value::U64(n) => n != 0,
            Value::I64(n) => n != 0,
            Value::Absent => false,
        }
    }
}

impl Scalar for u64 {
    fn value(self) -> Value {
        Value::U64(self)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::U64(n) => n,
            Value::I64(n) => n as u64,
            Value::F64(x) => x as u64,
            Value::Bool(b) => u64::from(b),
            Value::Absent => 0,
        }
    }
}

impl Scalar for u32 {
    fn value(self) -> Value {
        Value::U64(u64::from(self))
    }
    fn of(v: Value) -> Self {
        // Readers check the range; a binary record holds what was a u32.
        u64::of(v) as u32
    }
}

impl Scalar for i64 {
    fn value(self) -> Value {
        Value::I64(self)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::I64(n) => n,
            Value::U64(n) => n as i64,
            Value::F64(x) => x as i64,
            Value::Bool(b) => i64::from(b),
            Value::Absent => 0,
        }
    }
}

impl Scalar for Option<u64> {
    fn value(self) -> Value {
        self.map_or(Value::Absent, Value::U64)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::Absent => None,
            v => Some(u64::of(v)),
        }
    }
}

impl Scalar for Option<i64> {
    fn value(self) -> Value {
        self.map_or(Value::Absent, Value::I64)
    }
    fn of(v: Value) -> Self {
        match v {
            Value::Absent => None,
            v => Some(i64::of(v)),
        }
    }
}

/// A field in the record's flags or packets: `packet!(Topic, "path", Kind, |r| place)`,
/// or for an array of n, `packet!(Topic, "path", Kind, n, |r, i| place)`.
macro_rules! packet {
    ($topic:ident, $path:literal, $kind:ident, |$r:ident| $place:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: None,
            kind: Kind::$kind,
            access: Access::Packet {
                get: |$r: &Record, _| Scalar::value($place),
                set: |$r: &mut Record, _, v: Value| $place = Scalar::of(v),
            },
            since: 1,
        }
    };
    ($topic:ident, $path:literal, $kind:ident, $n:expr, |$r:ident, $i:ident| $place:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: Some($n),
            kind: Kind::$kind,
            access: Access::Packet {
                get: |$r: &Record, $i: usize| Scalar::value($place),
                set: |$r: &mut Record, $i: usize, v: Value| $place = Scalar::of(v),
            },
            since: 1,
        }
    };
}

/// A field stored as f64 values after the packets: `slot!(Topic, "path", Kind, at,
/// |r| place)`, or `slot!(Topic, "path", Kind, n, at, stride, |r, i| place)`.
macro_rules! slot {
    ($topic:ident, $path:literal, $kind:ident, $at:expr, |$r:ident| $place:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: None,
            kind: Kind::$kind,
            access: Access::Slot {
                at: $at,
                stride: 1,
                get: |$r: &Record, _| Scalar::value($place),
                set: |$r: &mut Record, _, v: Value| $place = Scalar::of(v),
            },
            since: 1,
        }
    };
    ($topic:ident, $path:literal, $kind:ident, $n:expr, $at:expr, $stride:expr,
     |$r:ident, $i:ident| $place:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: Some($n),
            kind: Kind::$kind,
            access: Access::Slot {
                at: $at,
                stride: $stride,
                get: |$r: &Record, $i: usize| Scalar::value($place),
                set: |$r: &mut Record, $i: usize, v: Value| $place = Scalar::of(v),
            },
            since: 1,
        }
    };
}

/// A derived field: `derived!(Topic, "path", Kind, |r, d| value)`, or
/// `derived!(Topic, "path", Kind, n, |r, d, i| value)`.
macro_rules! derived {
    ($topic:ident, $path:literal, $kind:ident, |$r:ident, $d:ident| $value:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: None,
            kind: Kind::$kind,
            access: Access::Derived(|$r: &Record, $d: &Derived, _| Scalar::value($value)),
            since: 1,
        }
    };
    ($topic:ident, $path:literal, $kind:ident, $n:expr, |$r:ident, $d:ident, $i:ident| $value:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: Some($n),
            kind: Kind::$kind,
            access: Access::Derived(|$r: &Record, $d: &Derived, $i: usize| Scalar::value($value)),
            since: 1,
        }
    };
}

/// A copy of another field for a second message: `echo!(Topic, "path", Kind, |r| value)`,
/// or `echo!(Topic, "path", Kind, n, |r, i| value)`.
macro_rules! echo {
    ($topic:ident, $path:literal, $kind:ident, |$r:ident| $value:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: None,
            kind: Kind::$kind,
            access: Access::Echo(|$r: &Record, _| Scalar::value($value)),
            since: 1,
        }
    };
    ($topic:ident, $path:literal, $kind:ident, $n:expr, |$r:ident, $i:ident| $value:expr) => {
        Field {
            topic: Topic::$topic,
            path: $path,
            len: Some($n),
            kind: Kind::$kind,
            access: Access::Echo(|$r: &Record, $i: usize| Scalar::value($value)),
            since: 1,
        }
    };
}

/// Engines.
const E: usize = oils_shared::ENGINE_COUNT;
/// Sample capacities of the sensor frame, and attitude thrusters.
const IMU_N: usize = oils_shared::IMU_SAMPLES_MAX;
const ST_N: usize = oils_shared::STAR_TRACKER_SAMPLES_MAX;
const ALT_N: usize = oils_shared::ALTIMETER_SAMPLES_MAX;
const VEL_N: usize = oils_shared::VELOCIMETER_SAMPLES_MAX;
const FRM_N: usize = oils_shared::FRAMES_MAX;
const THR_N: usize = oils_shared::THRUSTER_COUNT;

/// `estimate - truth` when the flight software's report holds an estimate, else NaN.
fn nav_error(r: &Record, estimate: f64, truth: f64) -> f64 {
    if r.command.fsw.nav_flags & oils_shared::NAV_FLAG_VALID != 0 {
        estimate - truth
    } else {
        f64::NAN
    }
}

/// Simulated time of a record, seconds.
fn t_s(r: &Record) -> f64 {
    r.telemetry.header.t_ns as f64 * 1e-9
}

/// Every field of a record, in message and CSV column order.
pub static FIELDS: &[Field] = &[
    // Telemetry(k) as published.
    packet!(Telemetry, "header.step", U64, |r| r.telemetry.header.step),
    packet!(Telemetry, "header.t_ns", I64, |r| r.telemetry.header.t_ns),
    packet!(Telemetry, "header.flags", U32, |r| r.telemetry.header.flags),
    packet!(Telemetry, "header.run_id", Hex, |r| r
        .telemetry
        .header
        .run_id),
    packet!(Telemetry, "header.schema_hash", Hex, |r| r
        .telemetry
        .header
        .schema_hash),
    packet!(Telemetry, "header.protocol_version", U32, |r| r
        .telemetry
        .header
        .protocol_version),
    derived!(Telemetry, "t_s", F64, |r, _d| t_s(r)),
    packet!(Telemetry, "nav.pos_mci_m", F64, 3, |r, i| r
        .telemetry
        .nav
        .pos_mci_m[i]),
    packet!(Telemetry, "nav.vel_mci_m_s", F64, 3, |r, i| r
        .telemetry
        .nav
        .vel_mci_m_s[i]),
    packet!(Telemetry, "nav.q_mci_from_body", F64, 4, |r, i| r
        .telemetry
        .nav
        .q_mci_from_body[i]),
    packet!(Telemetry, "nav.rate_body_rad_s", F64, 3, |r, i| r
        .telemetry
        .nav
        .rate_body_rad_s[i]),
    packet!(Telemetry, "accel_body_m_s2", F64, 3, |r, i| r
        .telemetry
        .accel_body_m_s2[i]),
    packet!(Telemetry, "altitude_m", F64, |r| r.telemetry.altitude_m),
    packet!(Telemetry, "mass_estimate_kg", F64, |r| r
        .telemetry
        .mass_estimate_kg),
    packet!(Telemetry, "propulsion.gas_pressure_pa", F64, |r| r
        .telemetry
        .propulsion
        .gas_pressure_pa),
    packet!(Telemetry, "propulsion.fuel_tank_pressure_pa", F64, |r| r
        .telemetry
        .propulsion
        .fuel_tank_pressure_pa),
    packet!(Telemetry, "propulsion.ox_tank_pressure_pa", F64, |r| r
        .telemetry
        .propulsion
        .ox_tank_pressure_pa),
    packet!(
        Telemetry,
        "propulsion.engines[].thrust_n",
        F64,
        E,
        |r, i| r.telemetry.propulsion.engines[i].thrust_n
    ),
    packet!(
        Telemetry,
        "propulsion.engines[].chamber_pressure_pa",
        F64,
        E,
        |r, i| r.telemetry.propulsion.engines[i].chamber_pressure_pa
    ),
    packet!(
        Telemetry,
        "propulsion.engines[].valve_open",
        U32,
        E,
        |r, i| r.telemetry.propulsion.engines[i].valve_open
    ),
    packet!(Telemetry, "propulsion.engines[].flags", U32, E, |r, i| r
        .telemetry
        .propulsion
        .engines[i]
        .flags),
    // The record's flags, Command(k) as received (zeroed when none arrived), and what
    // the plant applied over [t_k, t_k+1).
    packet!(Command, "record_flags", U32, |r| r.flags),
    derived!(Command, "received", Bool, |r, _d| r.flags
        & REC_COMMAND_RECEIVED
        != 0),
    derived!(Command, "deadline_miss", Bool, |r, _d| r.flags
        & REC_DEADLINE_MISS
        != 0),
    derived!(Command, "rejected_values", Bool, |r, _d| r.flags
        & REC_REJECTED_VALUES
        != 0),
    packet!(Command, "header.step", U64, |r| r.command.header.step),
    packet!(Command, "header.t_ns", I64, |r| r.command.header.t_ns),
    packet!(Command, "header.flags", U32, |r| r.command.header.flags),
    packet!(Command, "header.run_id", Hex, |r| r.command.header.run_id),
    packet!(Command, "header.schema_hash", Hex, |r| r
        .command
        .header
        .schema_hash),
    packet!(Command, "header.protocol_version", U32, |r| r
        .command
        .header
        .protocol_version),
    packet!(Command, "thrust_cmd_n", F64, E, |r, i| r
        .command
        .thrust_cmd_n[i]),
    packet!(Command, "engine_on", U32, E, |r, i| r.command.engine_on[i]),
    packet!(Command, "torque_cmd_body_nm", F64, 3, |r, i| r
        .command
        .torque_cmd_body_nm[i]),
    packet!(Command, "stub_compute_ns", U64, |r| r
        .command
        .stub_compute_ns),
    // What the flight software says of itself (protocol v3): its navigation estimate
    // with its own sigma, phase, boots and rate groups.
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_pos_mci_m", F64, 3, |r, i| r
            .command
            .fsw
            .nav_pos_mci_m[i])
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_vel_mci_m_s", F64, 3, |r, i| r
            .command
            .fsw
            .nav_vel_mci_m_s[i])
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_pos_sigma_m", F64, 3, |r, i| r
            .command
            .fsw
            .nav_pos_sigma_m[i])
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_vel_sigma_m_s", F64, 3, |r, i| r
            .command
            .fsw
            .nav_vel_sigma_m_s[i])
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_altitude_m", F64, |r| r
            .command
            .fsw
            .nav_altitude_m)
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_altitude_sigma_m", F64, |r| r
            .command
            .fsw
            .nav_altitude_sigma_m)
    },
    Field {
        since: 4,
        ..packet!(
            Command,
            "fsw.group_compute_ns",
            U32,
            oils_shared::RATE_GROUPS,
            |r, i| r.command.fsw.group_compute_ns[i]
        )
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.nav_flags", Hex, |r| r.command.fsw.nav_flags)
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.phase", U32, |r| r.command.fsw.phase)
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.boot_count", U32, |r| r.command.fsw.boot_count)
    },
    Field {
        since: 4,
        ..packet!(Command, "fsw.cycle_slips", U32, |r| r
            .command
            .fsw
            .cycle_slips)
    },
    slot!(Command, "applied.thrust_cmd_n", F64, E, 0, 1, |r, i| r
        .applied
        .engines
        .thrust_cmd_n[i]),
    slot!(Command, "applied.on", Bool, E, 4, 1, |r, i| r
        .applied
        .engines
        .on[i]),
    slot!(
        Command,
        "applied.torque_cmd_body_nm",
        F64,
        3,
        8,
        1,
        |r, i| r.applied.torque_cmd_body_nm[i]
    ),
    // The true state at t_k.
    echo!(Truth, "t_s", F64, |r| t_s(r)),
    slot!(Truth, "pos_mci_m", F64, 3, 11, 1, |r, i| r.truth.pos_mci_m
        [i]),
    slot!(Truth, "vel_mci_m_s", F64, 3, 14, 1, |r, i| r
        .truth
        .vel_mci_m_s[i]),
    slot!(Truth, "q_mci_from_body", F64, 4, 17, 1, |r, i| r
        .truth
        .q_mci_from_body[i]),
    slot!(Truth, "rate_body_rad_s", F64, 3, 21, 1, |r, i| r
        .truth
        .rate_body_rad_s[i]),
    slot!(Truth, "mass_kg", F64, 24, |r| r.truth.mass_kg),
    slot!(Truth, "altitude_m", F64, 25, |r| r.truth.altitude_m),
    slot!(Truth, "contact", Bool, 26, |r| r.truth.contact),
    derived!(Truth, "vertical_speed_m_s", F64, |_r, d| d
        .vertical_speed_m_s),
    derived!(Truth, "horizontal_speed_m_s", F64, |_r, d| d
        .horizontal_speed_m_s),
    derived!(Truth, "tilt_deg", F64, |_r, d| d.tilt_deg),
    derived!(Truth, "rate_body_deg_s", F64, 3, |r, _d, i| r
        .truth
        .rate_body_rad_s[i]
        .to_degrees()),
    derived!(Truth, "pos_site_m", F64, 3, |_r, d, i| d.pos_site_m[i]),
    derived!(Truth, "vel_site_m_s", F64, 3, |_r, d, i| d.vel_site_m_s[i]),
    Field {
        since: 2,
        ..slot!(Truth, "faults_active", U64, 57, |r| r.faults_active)
    },
    // Navigation error: the flight software's estimate minus the truth at t_k (NaN when
    // it reports none), `mci` and height above the ground.
    Field {
        since: 4,
        ..derived!(Truth, "nav_error.pos_mci_m", F64, 3, |r, _d, i| nav_error(
            r,
            r.command.fsw.nav_pos_mci_m[i],
            r.truth.pos_mci_m[i]
        ))
    },
    Field {
        since: 4,
        ..derived!(
            Truth,
            "nav_error.vel_mci_m_s",
            F64,
            3,
            |r, _d, i| nav_error(r, r.command.fsw.nav_vel_mci_m_s[i], r.truth.vel_mci_m_s[i])
        )
    },
    Field {
        since: 4,
        ..derived!(Truth, "nav_error.altitude_m", F64, |r, _d| nav_error(
            r,
            r.command.fsw.nav_altitude_m,
            r.truth.altitude_m
        ))
    },
    // The propulsion model's outputs and internals (NaN where a model has no such state).
    echo!(Propulsion, "t_s", F64, |r| t_s(r)),
    echo!(Propulsion, "thrust_cmd_n", F64, E, |r, i| r
        .applied
        .engines
        .thrust_cmd_n[i]),
    slot!(Propulsion, "thrust_n", F64, E, 27, 1, |r, i| r
        .truth
        .propulsion
        .thrust_n[i]),
    slot!(Propulsion, "mean_thrust_n", F64, E, 31, 1, |r, i| r
        .truth
        .propulsion
        .mean_thrust_n[i]),
    slot!(Propulsion, "chamber_pressure_pa", F64, E, 35, 1, |r, i| r
        .truth
        .propulsion
        .chamber_pressure_pa[i]),
    slot!(Propulsion, "gas_pressure_pa", F64, 39, |r| r
        .truth
        .propulsion
        .gas_pressure_pa),
    slot!(Propulsion, "fuel_tank_pressure_pa", F64, 40, |r| r
        .truth
        .propulsion
        .fuel_tank_pressure_pa),
    slot!(Propulsion, "ox_tank_pressure_pa", F64, 41, |r| r
        .truth
        .propulsion
        .ox_tank_pressure_pa),
    slot!(Propulsion, "ejected_fuel_kg", F64, 42, |r| r
        .truth
        .propulsion
        .ejected_fuel_kg),
    slot!(Propulsion, "ejected_ox_kg", F64, 43, |r| r
        .truth
        .propulsion
        .ejected_ox_kg),
    slot!(Propulsion, "fuel_flow_kg_s", F64, 44, |r| r
        .truth
        .propulsion
        .fuel_flow_kg_s),
    slot!(Propulsion, "ox_flow_kg_s", F64, 45, |r| r
        .truth
        .propulsion
        .ox_flow_kg_s),
    slot!(Propulsion, "regulator_outlet_pa", F64, 46, |r| r
        .truth
        .internals
        .regulator_outlet_pa),
    slot!(Propulsion, "manifold_pressure_pa", F64, 2, 47, 1, |r, i| r
        .truth
        .internals
        .manifold_pressure_pa[i]),
    // Fuel and oxidiser valves interleave per engine in the binary record.
    slot!(Propulsion, "fuel_valve_position", F64, E, 49, 2, |r, i| r
        .truth
        .internals
        .valve_position[i][0]),
    slot!(Propulsion, "ox_valve_position", F64, E, 50, 2, |r, i| r
        .truth
        .internals
        .valve_position[i][1]),
    // The step's timing, nanoseconds; null where a step has no such figure (no command
    // received; wake error outside realtime; transport in process).
    echo!(Timing, "step", U64, |r| r.telemetry.header.step),
    echo!(Timing, "t_s", F64, |r| t_s(r)),
    echo!(Timing, "stub_compute_ns", OptU64, |r| (r.flags
        & REC_COMMAND_RECEIVED
        != 0)
        .then_some(r.command.stub_compute_ns)),
    slot!(Timing, "round_trip_ns", OptU64, 58, |r| r
        .timing
        .round_trip_ns),
    slot!(Timing, "wake_error_ns", OptI64, 59, |r| r
        .timing
        .wake_error_ns),
    slot!(Timing, "transport_ns", OptU64, 60, |r| r
        .timing
        .transport_ns),
    // The devices: Telemetry(k)'s sensor samples by device (slot i of each array is
    // the i-th sample of the cycle, `*_count` of them in use), and the attitude-thruster
    // command as received and as applied.
    Field {
        since: 3,
        ..packet!(Devices, "imu_count", U32, |r| r.telemetry.sensors.imu_count)
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_t_ns", I64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .t_ns)
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_v_x_body_m_s", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_v_body_m_s[0])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_v_y_body_m_s", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_v_body_m_s[1])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_v_z_body_m_s", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_v_body_m_s[2])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_theta_x_body_rad", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_theta_body_rad[0])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_theta_y_body_rad", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_theta_body_rad[1])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_delta_theta_z_body_rad", F64, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .delta_theta_body_rad[2])
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_valid", U32, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .valid)
    },
    Field {
        since: 3,
        ..packet!(Devices, "imu_flags", U32, IMU_N, |r, i| r
            .telemetry
            .sensors
            .imu[i]
            .flags)
    },
    Field {
        since: 3,
        ..packet!(Devices, "star_tracker_count", U32, |r| r
            .telemetry
            .sensors
            .star_tracker_count)
    },
    Field {
        since: 3,
        ..packet!(Devices, "star_tracker_t_ns", I64, ST_N, |r, i| r
            .telemetry
            .sensors
            .star_tracker[i]
            .t_ns)
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "star_tracker_q_w_mci_from_body",
            F64,
            ST_N,
            |r, i| r.telemetry.sensors.star_tracker[i].q_mci_from_body[0]
        )
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "star_tracker_q_x_mci_from_body",
            F64,
            ST_N,
            |r, i| r.telemetry.sensors.star_tracker[i].q_mci_from_body[1]
        )
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "star_tracker_q_y_mci_from_body",
            F64,
            ST_N,
            |r, i| r.telemetry.sensors.star_tracker[i].q_mci_from_body[2]
        )
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "star_tracker_q_z_mci_from_body",
            F64,
            ST_N,
            |r, i| r.telemetry.sensors.star_tracker[i].q_mci_from_body[3]
        )
    },
    Field {
        since: 3,
        ..packet!(Devices, "star_tracker_valid", U32, ST_N, |r, i| r
            .telemetry
            .sensors
            .star_tracker[i]
            .valid)
    },
    Field {
        since: 3,
        ..packet!(Devices, "star_tracker_flags", U32, ST_N, |r, i| r
            .telemetry
            .sensors
            .star_tracker[i]
            .flags)
    },
    Field {
        since: 3,
        ..packet!(Devices, "laser_altimeter_count", U32, |r| r
            .telemetry
            .sensors
            .laser_altimeter_count)
    },
    Field {
        since: 3,
        ..packet!(Devices, "laser_altimeter_t_ns", I64, ALT_N, |r, i| r
            .telemetry
            .sensors
            .laser_altimeter[i]
            .t_ns)
    },
    Field {
        since: 3,
        ..packet!(Devices, "laser_altimeter_range_m", F64, ALT_N, |r, i| r
            .telemetry
            .sensors
            .laser_altimeter[i]
            .range_m)
    },
    Field {
        since: 3,
        ..packet!(Devices, "laser_altimeter_valid", U32, ALT_N, |r, i| r
            .telemetry
            .sensors
            .laser_altimeter[i]
            .valid)
    },
    Field {
        since: 3,
        ..packet!(Devices, "laser_altimeter_flags", U32, ALT_N, |r, i| r
            .telemetry
            .sensors
            .laser_altimeter[i]
            .flags)
    },
    Field {
        since: 3,
        ..packet!(Devices, "rf_altimeter_count", U32, |r| r
            .telemetry
            .sensors
            .rf_altimeter_count)
    },
    Field {
        since: 3,
        ..packet!(Devices, "rf_altimeter_t_ns", I64, ALT_N, |r, i| r
            .telemetry
            .sensors
            .rf_altimeter[i]
            .t_ns)
    },
    Field {
        since: 3,
        ..packet!(Devices, "rf_altimeter_range_m", F64, ALT_N, |r, i| r
            .telemetry
            .sensors
            .rf_altimeter[i]
            .range_m)
    },
    Field {
        since: 3,
        ..packet!(Devices, "rf_altimeter_valid", U32, ALT_N, |r, i| r
            .telemetry
            .sensors
            .rf_altimeter[i]
            .valid)
    },
    Field {
        since: 3,
        ..packet!(Devices, "rf_altimeter_flags", U32, ALT_N, |r, i| r
            .telemetry
            .sensors
            .rf_altimeter[i]
            .flags)
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_count", U32, |r| r
            .telemetry
            .sensors
            .velocimeter_count)
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_t_ns", I64, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .t_ns)
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "velocimeter_beam0_los_velocity_m_s",
            F64,
            VEL_N,
            |r, i| r.telemetry.sensors.velocimeter[i].los_velocity_m_s[0]
        )
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam0_range_m", F64, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .range_m[0])
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam0_valid", U32, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .valid[0])
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "velocimeter_beam1_los_velocity_m_s",
            F64,
            VEL_N,
            |r, i| r.telemetry.sensors.velocimeter[i].los_velocity_m_s[1]
        )
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam1_range_m", F64, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .range_m[1])
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam1_valid", U32, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .valid[1])
    },
    Field {
        since: 3,
        ..packet!(
            Devices,
            "velocimeter_beam2_los_velocity_m_s",
            F64,
            VEL_N,
            |r, i| r.telemetry.sensors.velocimeter[i].los_velocity_m_s[2]
        )
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam2_range_m", F64, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .range_m[2])
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_beam2_valid", U32, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .valid[2])
    },
    Field {
        since: 3,
        ..packet!(Devices, "velocimeter_flags", U32, VEL_N, |r, i| r
            .telemetry
            .sensors
            .velocimeter[i]
            .flags)
    },
    // Protocol v4: the frames announced (their pixels are not logged: a replay renders
    // them again, and these hashes must match).
    Field {
        since: 4,
        ..packet!(Devices, "frame_count", U32, |r| r
            .telemetry
            .sensors
            .frame_count)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_device", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .device)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_format", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .format)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_width", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .width)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_height", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .height)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_seq", U64, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .seq)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_t_ns", I64, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .t_ns)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_exposure_ns", U64, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .exposure_ns)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_bytes", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .bytes)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_flags", U32, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .flags)
    },
    Field {
        since: 4,
        ..packet!(Devices, "frame_hash", Hex, FRM_N, |r, i| r
            .telemetry
            .sensors
            .frames[i]
            .hash)
    },
    Field {
        since: 3,
        ..packet!(Devices, "thruster_attitude_mode", U32, |r| r
            .command
            .attitude_mode)
    },
    Field {
        since: 3,
        ..packet!(Devices, "thruster_on_time_ns", U64, THR_N, |r, i| r
            .command
            .thruster_on_time_ns[i])
    },
    Field {
        since: 3,
        ..slot!(Devices, "thruster_applied_use_thrusters", Bool, 61, |r| r
            .applied
            .use_thrusters)
    },
    Field {
        since: 3,
        ..slot!(
            Devices,
            "thruster_applied_on_time_ns",
            U64,
            THR_N,
            62,
            1,
            |r, i| r.applied.thruster_on_time_ns[i]
        )
    },
];

/// The newest MCAP message format: `oils-mcap-2` added `truth.faults_active`,
/// `oils-mcap-3` the `devices` message (protocol v2's sensor samples and thrusters),
/// `oils-mcap-4` the flight software's report (`command.fsw.*`) and the navigation
/// error (`truth.nav_error.*`).
pub const MESSAGE_FORMAT: u32 = 4;

/// The CSV header: one column per value of every field the CSV has.
pub fn csv_columns() -> Vec<String> {
    FIELDS
        .iter()
        .filter(|f| f.in_csv())
        .flat_map(|f| (0..f.count()).map(move |i| f.column(i)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::recorder::TRUTH_VALUES;
    use std::collections::HashSet;

    /// A log's site comes from its header or not at all: a header that does not parse is
    /// an error, never the default site in disguise.
    #[test]
    fn the_site_of_a_log_header_is_its_scenarios_or_an_error() {
        let mut cfg = crate::run_config::RunConfig::default();
        cfg.scenario.site.latitude_deg = 12.5;
        let header = crate::session::log_header(&cfg, 7);
        let site = Site::of_log_header(&header).unwrap();
        assert_eq!(site.frame.lat_rad, 12.5f64.to_radians());
        for bad in ["", "{}", r#"{"run_id":"0000000000000007"}"#, "not json"] {
            assert!(Site::of_log_header(bad).is_err(), "{bad:?}");
        }
    }

    /// Every slot of the binary record's values is one field's, exactly once.
    #[test]
    fn slots_cover_the_record_values_once() {
        let mut owner = [None; TRUTH_VALUES];
        for f in FIELDS {
            if let Access::Slot { at, stride, .. } = f.access {
                for i in 0..f.count() {
                    let s = at + i * stride;
                    assert!(s < TRUTH_VALUES, "{}: slot {s}", f.path);
                    assert!(
                        owner[s].is_none(),
                        "slot {s}: {:?} and {}",
                        owner[s],
                        f.path
                    );
                    owner[s] = Some(f.path);
                }
            }
        }
        assert!(owner.iter().all(Option::is_some), "{owner:?}");
    }

    #[test]
    fn columns_are_unique_and_name_their_topic() {
        let columns = csv_columns();
        let unique: HashSet<&String> = columns.iter().collect();
        assert_eq!(unique.len(), columns.len());
        assert!(columns.contains(&"truth.pos_mci_m[2]".to_string()));
        assert!(columns.contains(&"telemetry.propulsion.engines[3].thrust_n".to_string()));
        assert!(!columns.iter().any(|c| c.starts_with("timing.step")));
        // Every (topic, path) once.
        let paths: HashSet<(Topic, &str)> = FIELDS.iter().map(|f| (f.topic, f.path)).collect();
        assert_eq!(paths.len(), FIELDS.len());
    }

    #[test]
    fn setters_put_back_what_getters_read() {
        let r = crate::recorder::tests::distinct_record();
        let d = Derived::default();
        let s = Sample {
            record: &r,
            derived: &d,
        };
        let mut back = Record::default();
        for f in FIELDS {
            if let Some(set) = f.setter() {
                for i in 0..f.count() {
                    set(&mut back, i, f.get(&s, i));
                }
            }
        }
        assert_eq!(back, r);
    }
}
