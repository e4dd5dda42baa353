//! Wire protocol of the oils bench: the only crate a flight-software author needs.
//!
//! Two packets cross the link every flight-software cycle, both fixed-size `#[repr(C)]`
//! structs sent zero-copy through iceoryx2 shared memory:
//!
//! * [`Telemetry`]`(k)`: emulator -> onboard computer, at `t_k`: the propulsion readings,
//!   a [`SensorFrame`] with every device sample produced since cycle `k-1` (each with its
//!   own timestamp), and, as an "ideal navigation" source, the true state (+ noise);
//! * [`Command`]`(k)`: onboard computer -> emulator, held over cycle `k`: main-engine
//!   throttles and on/off, attitude-thruster on-times (or an ideal body torque).
//!
//! Protocol v2 carries the devices in one frame per cycle rather than one service per
//! sensor: lockstep and the run digest stay one exchange per cycle, and C and Python
//! clients keep their single subscription (see `docs/protocol.md`).
//!
//! Protocol v4 adds imaging devices: a frame (hundreds of kilobytes) travels on its own
//! service, `oils/<run>/frame/<device>`, as a zero-copy dynamic slice whose user header
//! is its [`FrameAnnouncement`]; the next telemetry announces it in
//! [`SensorFrame::frames`], so lockstep and the digest still cover every exchange.
//!
//! Every field is `f64`, `u64`, `i64` or `u32` and every struct is padded by hand to a
//! multiple of 8 bytes, so the layout is the same in Rust, C, C++ and Python `ctypes`.
//! `docs/protocol.md` lists every offset; the test `layout_is_pinned` fails if one moves.
//!
//! Frames: `mci` is Moon-centred inertial (the Moon turns in it at the sidereal rate);
//! `body` has +Z along the main-engine thrust (up at touchdown), engines on the -Z deck.
//! Quaternions are `[w, x, y, z]`, scalar first, rotating body vectors into `mci`.
#![warn(missing_docs)]

use iceoryx2::prelude::ZeroCopySend;

pub mod c_abi;
pub mod clock;
pub mod domain;
pub mod fsw;
pub mod link;
pub mod plane_fit;
pub mod profile;
pub mod realtime;
pub mod service;
pub mod signals;

/// Protocol version; bump on any change to a packet layout or meaning.
pub const PROTOCOL_VERSION: u32 = 4;

/// Number of main engines.
pub const ENGINE_COUNT: usize = 4;
/// Number of attitude thrusters.
pub const THRUSTER_COUNT: usize = 8;
/// Beams of the laser Doppler velocimeter.
pub const VELOCIMETER_BEAMS: usize = 3;
/// IMU samples a [`SensorFrame`] can carry: enough for a 40 ms cycle at 200 Hz.
pub const IMU_SAMPLES_MAX: usize = 8;
/// Star-tracker samples a [`SensorFrame`] can carry.
pub const STAR_TRACKER_SAMPLES_MAX: usize = 2;
/// Samples of each altimeter a [`SensorFrame`] can carry.
pub const ALTIMETER_SAMPLES_MAX: usize = 2;
/// Velocimeter samples a [`SensorFrame`] can carry.
pub const VELOCIMETER_SAMPLES_MAX: usize = 2;
/// Frame announcements a [`SensorFrame`] can carry: one per imaging device per cycle
/// (a frame device's period is at least the flight-software cycle, checked before tick 0).
pub const FRAMES_MAX: usize = 4;

/// [`FrameAnnouncement::device`]: the navigation camera (service `.../frame/camera`).
pub const FRAME_DEVICE_CAMERA: u32 = 1;
/// [`FrameAnnouncement::device`]: the flash lidar (service `.../frame/lidar`).
pub const FRAME_DEVICE_LIDAR: u32 = 2;
/// [`FrameAnnouncement::device`]: the test card, a deterministic pattern for checking a
/// frame path (service `.../frame/test-card`).
pub const FRAME_DEVICE_TEST_CARD: u32 = 3;

/// The name of frame device `device` (`FRAME_DEVICE_*`): its service's last segment
/// (`oils/<run>/frame/<name>`) and the prefix of its exported files.
pub const fn frame_device_name(device: u32) -> Option<&'static str> {
    match device {
        FRAME_DEVICE_CAMERA => Some("camera"),
        FRAME_DEVICE_LIDAR => Some("lidar"),
        FRAME_DEVICE_TEST_CARD => Some("test-card"),
        _ => None,
    }
}

/// Bytes per pixel of frame format `format` (`FRAME_FORMAT_*`).
pub const fn frame_format_bytes_per_pixel(format: u32) -> Option<usize> {
    match format {
        FRAME_FORMAT_U16_LE => Some(2),
        FRAME_FORMAT_F32_LE_M => Some(4),
        _ => None,
    }
}

/// [`FrameAnnouncement::format`]: unsigned 16-bit little-endian digital numbers, row-major
/// from the top-left pixel.
pub const FRAME_FORMAT_U16_LE: u32 = 1;
/// [`FrameAnnouncement::format`]: 32-bit little-endian IEEE floats, range in metres,
/// row-major from the top-left pixel; 0 = no return.
pub const FRAME_FORMAT_F32_LE_M: u32 = 2;

/// Frame flag: at least one pixel saturated.
pub const FRAME_FLAG_SATURATED: u32 = 1 << 0;
/// Frame flag: the device is in an outage (blinded, a dropout): the pixels mean nothing.
pub const FRAME_FLAG_OUTAGE: u32 = 1 << 1;
/// Frame flag: the device is frozen: these are the pixels of an earlier frame.
pub const FRAME_FLAG_FROZEN: u32 = 1 << 2;

/// Telemetry flag: this is the last telemetry of the run; the stub answers nothing and exits.
pub const TLM_FLAG_END_OF_RUN: u32 = 1 << 0;
/// Telemetry flag: navigation values carry seeded sensor noise.
pub const TLM_FLAG_NAV_NOISE: u32 = 1 << 1;
/// Telemetry flag: at least one footpad touches the ground (the legs' touchdown
/// switches); flight software shuts the engines down on it.
pub const TLM_FLAG_FOOTPAD_CONTACT: u32 = 1 << 2;
/// Telemetry flag: `nav`, `accel_body_m_s2` and `altitude_m` hold the ideal navigation
/// source (the truth, plus noise with [`TLM_FLAG_NAV_NOISE`]); without it they are zero.
pub const TLM_FLAG_IDEAL_NAV: u32 = 1 << 3;
/// Telemetry flag: `sensors` holds the device samples since the last cycle.
pub const TLM_FLAG_SENSORS: u32 = 1 << 4;
/// Telemetry flag: `nav` holds the ground's state vector (orbit determination, with its
/// documented error) for the flight software to start its navigation from; sent on the
/// first cycle of a `sensors` run and on the first cycle after a computer reset (never
/// with [`TLM_FLAG_IDEAL_NAV`]: a `both` run starts from the ideal navigation).
pub const TLM_FLAG_STATE_VECTOR: u32 = 1 << 5;
/// Telemetry flag: the onboard computer is resetting: the flight software's state is
/// lost; it restarts on the first telemetry without this flag. Commands answered to a
/// flagged telemetry are ignored (the engines and thrusters hold what they had).
pub const TLM_FLAG_COMPUTER_RESET: u32 = 1 << 6;

/// `FswReport::nav_flags`: the report's navigation fields hold an estimate.
pub const NAV_FLAG_VALID: u32 = 1 << 0;
/// `FswReport::nav_flags`: the estimate comes from the device samples (not the ideal
/// navigation source).
pub const NAV_FLAG_FROM_SENSORS: u32 = 1 << 1;
/// `FswReport::nav_flags`: the star tracker updated the filter in the last 2 s.
pub const NAV_FLAG_STAR_TRACKER_USED: u32 = 1 << 2;
/// `FswReport::nav_flags`: the laser altimeter updated the filter in the last 2 s.
pub const NAV_FLAG_LASER_USED: u32 = 1 << 3;
/// `FswReport::nav_flags`: the RF altimeter updated the filter in the last 2 s.
pub const NAV_FLAG_RF_USED: u32 = 1 << 4;
/// `FswReport::nav_flags`: the velocimeter updated the filter in the last 2 s.
pub const NAV_FLAG_VELOCIMETER_USED: u32 = 1 << 5;
/// `FswReport::nav_flags`: the flight software has declared the laser altimeter lost
/// (no valid sample for 10 s while in range) and navigates on the rest.
pub const NAV_FLAG_LASER_LOST: u32 = 1 << 6;
/// `FswReport::nav_flags`: the flight software is re-initialising after a reset.
pub const NAV_FLAG_REINIT: u32 = 1 << 7;
/// `FswReport::nav_flags`: a terrain-relative position fix (camera against the onboard
/// map) updated the filter in the last 2 s.
pub const NAV_FLAG_TERRAIN_USED: u32 = 1 << 8;
/// `FswReport::nav_flags`: terrain-relative navigation is expected (over the map, in
/// its height band) but no fix has been accepted for 10 s: the estimate is the inertial
/// and altimeter one.
pub const NAV_FLAG_TERRAIN_LOST: u32 = 1 << 9;
/// `FswReport::nav_flags`: hazard detection mapped the ground at the hover and chose a
/// spot (diverting there if it is not under the vehicle).
pub const NAV_FLAG_HAZARD_MAPPED: u32 = 1 << 10;
/// `FswReport::nav_flags`: hazard avoidance is on but the final descent began without a
/// hazard map (no lidar frame in the hover): it lands at the nominal point.
pub const NAV_FLAG_HAZARD_UNMAPPED: u32 = 1 << 11;

/// Rate groups a flight software may time in [`FswReport::group_compute_ns`].
pub const RATE_GROUPS: usize = 4;

/// Sample flag: the device saturated (an IMU axis at its range limit).
pub const SAMPLE_FLAG_SATURATED: u32 = 1 << 0;
/// Sample flag: no return (beyond maximum range, below minimum, grazing incidence, or
/// nothing in the beam).
pub const SAMPLE_FLAG_NO_LOCK: u32 = 1 << 1;
/// Sample flag: the device is inhibited (a safety switch, a fault) and reports nothing.
pub const SAMPLE_FLAG_INHIBITED: u32 = 1 << 2;
/// Sample flag: the device is in an outage (a star tracker blinded, a dropout).
pub const SAMPLE_FLAG_OUTAGE: u32 = 1 << 3;

/// `Command::attitude_mode`: the ideal body-torque actuator (`torque_cmd_body_nm`,
/// saturated by the plant); thruster on-times are ignored.
pub const ATTITUDE_MODE_IDEAL_TORQUE: u32 = 0;
/// `Command::attitude_mode`: the attitude thrusters fire for `thruster_on_time_ns`;
/// `torque_cmd_body_nm` is ignored.
pub const ATTITUDE_MODE_THRUSTERS: u32 = 1;

/// Human-readable schema: one entry per struct, `Struct{field:type@offset,...}=size|`. Its hash,
/// [`SCHEMA_HASH`], travels in every header so two peers compiled from different
/// layouts refuse each other with a clear message instead of misreading bytes.
pub const SCHEMA: &str = concat!(
    "PacketHeader{protocol_version:u32@0,flags:u32@4,schema_hash:u64@8,run_id:u64@16,step:u64@24,t_ns:i64@32}=40|",
    "NavState{pos_mci_m:[f64;3]@0,vel_mci_m_s:[f64;3]@24,q_mci_from_body:[f64;4]@48,rate_body_rad_s:[f64;3]@80}=104|",
    "EngineReading{thrust_n:f64@0,chamber_pressure_pa:f64@8,valve_open:u32@16,flags:u32@20}=24|",
    "PropulsionReadings{gas_pressure_pa:f64@0,fuel_tank_pressure_pa:f64@8,ox_tank_pressure_pa:f64@16,engines:[EngineReading;4]@24}=120|",
    "ImuSample{t_ns:i64@0,delta_v_body_m_s:[f64;3]@8,delta_theta_body_rad:[f64;3]@32,valid:u32@56,flags:u32@60}=64|",
    "StarTrackerSample{t_ns:i64@0,q_mci_from_body:[f64;4]@8,valid:u32@40,flags:u32@44}=48|",
    "AltimeterSample{t_ns:i64@0,range_m:f64@8,valid:u32@16,flags:u32@20}=24|",
    "VelocimeterSample{t_ns:i64@0,los_velocity_m_s:[f64;3]@8,range_m:[f64;3]@32,valid:[u32;3]@56,flags:u32@68}=72|",
    "FrameAnnouncement{device:u32@0,format:u32@4,width:u32@8,height:u32@12,seq:u64@16,t_ns:i64@24,exposure_ns:u64@32,bytes:u32@40,flags:u32@44,hash:u64@48}=56|",
    "SensorFrame{imu_count:u32@0,star_tracker_count:u32@4,laser_altimeter_count:u32@8,rf_altimeter_count:u32@12,velocimeter_count:u32@16,frame_count:u32@20,imu:[ImuSample;8]@24,star_tracker:[StarTrackerSample;2]@536,laser_altimeter:[AltimeterSample;2]@632,rf_altimeter:[AltimeterSample;2]@680,velocimeter:[VelocimeterSample;2]@728,frames:[FrameAnnouncement;4]@872}=1096|",
    "Telemetry{header:PacketHeader@0,nav:NavState@40,accel_body_m_s2:[f64;3]@144,altitude_m:f64@168,mass_estimate_kg:f64@176,propulsion:PropulsionReadings@184,sensors:SensorFrame@304}=1400|",
    "FswReport{nav_pos_mci_m:[f64;3]@0,nav_vel_mci_m_s:[f64;3]@24,nav_pos_sigma_m:[f64;3]@48,nav_vel_sigma_m_s:[f64;3]@72,nav_altitude_m:f64@96,nav_altitude_sigma_m:f64@104,group_compute_ns:[u32;4]@112,nav_flags:u32@128,phase:u32@132,boot_count:u32@136,cycle_slips:u32@140}=144|",
    "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72,torque_cmd_body_nm:[f64;3]@88,stub_compute_ns:u64@112,thruster_on_time_ns:[u64;8]@120,attitude_mode:u32@184,reserved:u32@188,fsw:FswReport@192}=336|",
);

/// FNV-1a over [`SCHEMA`], evaluated at compile time.
///
/// Written by hand because it is six lines and must be a `const fn`; no crate offers
/// a const 64-bit hash that C and Python authors could reproduce as simply.
pub const fn schema_hash_of(schema: &str) -> u64 {
    let bytes = schema.as_bytes();
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u64;
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    hash
}

/// Hash of this build's [`SCHEMA`].
pub const SCHEMA_HASH: u64 = schema_hash_of(SCHEMA);

/// Header at the start of every packet.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.PacketHeader")]
pub struct PacketHeader {
    /// [`PROTOCOL_VERSION`] of the sender.
    pub protocol_version: u32,
    /// `TLM_FLAG_*` bits for telemetry; zero for commands.
    pub flags: u32,
    /// [`SCHEMA_HASH`] of the sender.
    pub schema_hash: u64,
    /// Identifies the run; also part of the service names.
    pub run_id: u64,
    /// Step index k; Command(k) answers Telemetry(k).
    pub step: u64,
    /// Simulated time of step k in integer nanoseconds since the start of the run.
    pub t_ns: i64,
}

impl PacketHeader {
    /// A header stamped with this build's protocol version and schema hash.
    pub const fn new(run_id: u64, step: u64, t_ns: i64) -> Self {
        Self {
            protocol_version: PROTOCOL_VERSION,
            flags: 0,
            schema_hash: SCHEMA_HASH,
            run_id,
            step,
            t_ns,
        }
    }

    /// Checks that the peer speaks this build's protocol.
    pub fn check_peer(&self) -> Result<(), ProtocolMismatch> {
        if self.protocol_version != PROTOCOL_VERSION || self.schema_hash != SCHEMA_HASH {
            return Err(ProtocolMismatch {
                ours_version: PROTOCOL_VERSION,
                ours_schema_hash: SCHEMA_HASH,
                peer_version: self.protocol_version,
                peer_schema_hash: self.schema_hash,
            });
        }
        Ok(())
    }
}

/// The peer's packet was built from another protocol version or layout.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ProtocolMismatch {
    /// Our [`PROTOCOL_VERSION`].
    pub ours_version: u32,
    /// Our [`SCHEMA_HASH`].
    pub ours_schema_hash: u64,
    /// The peer's protocol version.
    pub peer_version: u32,
    /// The peer's schema hash.
    pub peer_schema_hash: u64,
}

impl core::fmt::Display for ProtocolMismatch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(
            f,
            "protocol mismatch: this side speaks oils protocol v{} (schema {:#018x}), \
             the peer speaks v{} (schema {:#018x}); rebuild both sides from the same oils-shared",
            self.ours_version, self.ours_schema_hash, self.peer_version, self.peer_schema_hash
        )
    }
}

impl core::error::Error for ProtocolMismatch {}

/// Navigation state as the onboard computer sees it (possibly with seeded noise).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.NavState")]
pub struct NavState {
    /// Position of the centre of mass, Moon-centred inertial, metres.
    pub pos_mci_m: [f64; 3],
    /// Velocity, Moon-centred inertial, m/s.
    pub vel_mci_m_s: [f64; 3],
    /// Attitude quaternion `[w, x, y, z]`, rotates body vectors into `mci`.
    pub q_mci_from_body: [f64; 4],
    /// Angular rate of the body relative to `mci`, in body axes, rad/s.
    pub rate_body_rad_s: [f64; 3],
}

/// One main engine's readings.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.EngineReading")]
pub struct EngineReading {
    /// Thrust as sensed (the propulsion model's output), newtons.
    pub thrust_n: f64,
    /// Combustion chamber pressure, pascals (0 where the model has no chamber).
    pub chamber_pressure_pa: f64,
    /// 1 when the engine's valves are commanded open, else 0.
    pub valve_open: u32,
    /// Reserved for engine fault bits; zero today.
    pub flags: u32,
}

/// Propulsion system readings.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.PropulsionReadings")]
pub struct PropulsionReadings {
    /// Helium bottle pressure, pascals.
    pub gas_pressure_pa: f64,
    /// Fuel (MMH) tank ullage pressure, pascals.
    pub fuel_tank_pressure_pa: f64,
    /// Oxidiser (MON-3) tank ullage pressure, pascals.
    pub ox_tank_pressure_pa: f64,
    /// Per-engine readings.
    pub engines: [EngineReading; ENGINE_COUNT],
}

/// One IMU sample: velocity and angle increments over the IMU period ending at `t_ns`.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.ImuSample")]
pub struct ImuSample {
    /// End of the integration period (time of validity), ns since the start of the run.
    pub t_ns: i64,
    /// Integrated specific force over the period, IMU (= body) axes, m/s.
    pub delta_v_body_m_s: [f64; 3],
    /// Integrated angular rate over the period, IMU (= body) axes, rad.
    pub delta_theta_body_rad: [f64; 3],
    /// 1 when the sample is good, 0 when it must not be used.
    pub valid: u32,
    /// `SAMPLE_FLAG_*` bits.
    pub flags: u32,
}

/// One star-tracker sample: the body attitude it measured.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.StarTrackerSample")]
pub struct StarTrackerSample {
    /// Time of validity, ns since the start of the run.
    pub t_ns: i64,
    /// Measured attitude `[w, x, y, z]`, rotates body vectors into `mci` (the tracker's
    /// mounting already removed).
    pub q_mci_from_body: [f64; 4],
    /// 1 when the sample is good.
    pub valid: u32,
    /// `SAMPLE_FLAG_*` bits.
    pub flags: u32,
}

/// One altimeter sample: slant range along the beam to the terrain.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.AltimeterSample")]
pub struct AltimeterSample {
    /// Time of validity, ns since the start of the run.
    pub t_ns: i64,
    /// Slant range along the beam, metres (0 when not valid).
    pub range_m: f64,
    /// 1 when the sample is good.
    pub valid: u32,
    /// `SAMPLE_FLAG_*` bits.
    pub flags: u32,
}

/// One laser Doppler velocimeter sample: per beam, the line-of-sight velocity relative
/// to the surface and the range.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.VelocimeterSample")]
pub struct VelocimeterSample {
    /// Time of validity, ns since the start of the run.
    pub t_ns: i64,
    /// Velocity of the vehicle relative to the ground projected on each beam's unit
    /// vector (positive moving along the beam, towards the ground), m/s.
    pub los_velocity_m_s: [f64; VELOCIMETER_BEAMS],
    /// Range along each beam, metres.
    pub range_m: [f64; VELOCIMETER_BEAMS],
    /// Per beam, 1 when good.
    pub valid: [u32; VELOCIMETER_BEAMS],
    /// `SAMPLE_FLAG_*` bits (of any beam).
    pub flags: u32,
}

/// One frame published on its own service since the last cycle (protocol v4): what it
/// is, when it is valid, and the XXH3-64 hash of its pixel bytes. The frame's bytes
/// travel as an iceoryx2 dynamic slice on `oils/<run>/frame/<device>` with this struct as
/// the sample's user header, published before the telemetry that announces it; the run
/// digest covers the telemetry, hence every frame through its hash.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.FrameAnnouncement")]
pub struct FrameAnnouncement {
    /// `FRAME_DEVICE_*`.
    pub device: u32,
    /// `FRAME_FORMAT_*`: how to read the pixel bytes.
    pub format: u32,
    /// Pixels per row.
    pub width: u32,
    /// Rows.
    pub height: u32,
    /// The device's frame counter, from 0 (a gap means a frame was lost).
    pub seq: u64,
    /// Time of validity (mid-exposure), ns since the start of the run.
    pub t_ns: i64,
    /// Exposure (integration) time, ns.
    pub exposure_ns: u64,
    /// Length of the pixel bytes: `width * height * bytes per pixel`.
    pub bytes: u32,
    /// `FRAME_FLAG_*` bits.
    pub flags: u32,
    /// XXH3-64 (seed 0) of the pixel bytes.
    pub hash: u64,
}

impl FrameAnnouncement {
    /// Whether `pixels` are the frame this announces: their length and XXH3-64 hash.
    pub fn matches(&self, pixels: &[u8]) -> bool {
        pixels.len() == self.bytes as usize && frame_hash(pixels) == self.hash
    }
}

/// The hash a [`FrameAnnouncement`] carries: XXH3-64 with seed 0 (`xxhash`'s
/// `XXH3_64bits`, Python's `xxhash.xxh3_64_intdigest`).
pub fn frame_hash(pixels: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(pixels)
}

/// Every device sample produced since the last cycle, oldest first per device; the
/// counts say how many entries of each array hold samples (the rest are zero).
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.SensorFrame")]
pub struct SensorFrame {
    /// Entries of `imu` in use.
    pub imu_count: u32,
    /// Entries of `star_tracker` in use.
    pub star_tracker_count: u32,
    /// Entries of `laser_altimeter` in use.
    pub laser_altimeter_count: u32,
    /// Entries of `rf_altimeter` in use.
    pub rf_altimeter_count: u32,
    /// Entries of `velocimeter` in use.
    pub velocimeter_count: u32,
    /// Entries of `frames` in use (protocol v4; the field was `reserved` in v3).
    pub frame_count: u32,
    /// IMU samples.
    pub imu: [ImuSample; IMU_SAMPLES_MAX],
    /// Star-tracker samples.
    pub star_tracker: [StarTrackerSample; STAR_TRACKER_SAMPLES_MAX],
    /// Laser altimeter samples.
    pub laser_altimeter: [AltimeterSample; ALTIMETER_SAMPLES_MAX],
    /// RF (Ka-band) altimeter samples.
    pub rf_altimeter: [AltimeterSample; ALTIMETER_SAMPLES_MAX],
    /// Laser Doppler velocimeter samples.
    pub velocimeter: [VelocimeterSample; VELOCIMETER_SAMPLES_MAX],
    /// The frames published since the last cycle, one per device at most, in device
    /// order ([`FrameAnnouncement`]); independent of [`TLM_FLAG_SENSORS`].
    pub frames: [FrameAnnouncement; FRAMES_MAX],
}

/// Emulator -> onboard computer, once per flight-software cycle, at `t_k`.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.Telemetry")]
pub struct Telemetry {
    /// Packet header.
    pub header: PacketHeader,
    /// Navigation state.
    pub nav: NavState,
    /// Measured specific force (non-gravitational acceleration), body axes, m/s^2.
    pub accel_body_m_s2: [f64; 3],
    /// Height of the landing-leg footpads above the local surface, metres.
    pub altitude_m: f64,
    /// Vehicle mass estimate, kilograms.
    pub mass_estimate_kg: f64,
    /// Propulsion readings.
    pub propulsion: PropulsionReadings,
    /// Device samples since the last cycle (with [`TLM_FLAG_SENSORS`]).
    pub sensors: SensorFrame,
}

/// What the flight software says of itself each cycle: its navigation estimate with its
/// own 1-sigma (so the bench can log estimate minus truth and check consistency), the
/// phase it flies, how often it has booted, and its rate groups' compute times. The
/// bench never acts on it. All zero (`nav_flags` 0) means "nothing said".
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.FswReport")]
pub struct FswReport {
    /// Estimated position, `mci`, metres.
    pub nav_pos_mci_m: [f64; 3],
    /// Estimated velocity, `mci`, m/s.
    pub nav_vel_mci_m_s: [f64; 3],
    /// The estimate's own 1-sigma per `mci` axis, metres (0: not known).
    pub nav_pos_sigma_m: [f64; 3],
    /// The estimate's own 1-sigma per `mci` axis, m/s (0: not known).
    pub nav_vel_sigma_m_s: [f64; 3],
    /// Estimated height above the ground below, metres.
    pub nav_altitude_m: f64,
    /// Its 1-sigma, metres (0: not known).
    pub nav_altitude_sigma_m: f64,
    /// Wall-clock compute time of each rate group that ran this cycle, nanoseconds
    /// (0: did not run); excluded from the run digest, like `stub_compute_ns`.
    pub group_compute_ns: [u32; RATE_GROUPS],
    /// `NAV_FLAG_*` bits.
    pub nav_flags: u32,
    /// The flight software's own phase code (the reference GNC's: `docs/gnc.md`).
    pub phase: u32,
    /// Boots so far (1 after the first start; +1 per computer reset).
    pub boot_count: u32,
    /// Rate-group cycle slips so far (a group whose compute time exceeded its period,
    /// wall clock); excluded from the run digest.
    pub cycle_slips: u32,
}

/// Onboard computer -> emulator, once per step: held over `[t_k, t_k+1)`.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("oils.v4.Command")]
pub struct Command {
    /// Packet header; `step` must echo the telemetry it answers.
    pub header: PacketHeader,
    /// Thrust command per main engine, newtons.
    pub thrust_cmd_n: [f64; ENGINE_COUNT],
    /// 1 = engine on, 0 = off (any other value is rejected and treated as off).
    pub engine_on: [u32; ENGINE_COUNT],
    /// Ideal body torque, body axes, N m (saturated by the plant); used with
    /// [`ATTITUDE_MODE_IDEAL_TORQUE`] only.
    pub torque_cmd_body_nm: [f64; 3],
    /// The flight software's own compute time for this step, nanoseconds (wall clock,
    /// measured by the stub; excluded from the run digest).
    pub stub_compute_ns: u64,
    /// Per attitude thruster, its on-time from the start of this cycle, nanoseconds
    /// (clamped to the cycle); used with [`ATTITUDE_MODE_THRUSTERS`] only.
    pub thruster_on_time_ns: [u64; THRUSTER_COUNT],
    /// [`ATTITUDE_MODE_IDEAL_TORQUE`] or [`ATTITUDE_MODE_THRUSTERS`] (any other value is
    /// rejected and treated as ideal torque with zero torque).
    pub attitude_mode: u32,
    /// Zero.
    pub reserved: u32,
    /// What the flight software says of itself (navigation, phase, boots, rate groups).
    pub fsw: FswReport,
}

/// Views a packet as bytes, for digests and log records.
///
/// # Safety contract (upheld here)
/// Only implemented for the `repr(C)` packets above, which have no padding bytes (the
/// layout test checks that the field sizes add up to the struct size).
pub trait AsBytes: Copy {
    /// The packet's bytes in memory order (little-endian on every supported target).
    fn as_bytes(&self) -> &[u8];
    /// Rebuilds a packet from exactly `size_of::<Self>()` bytes; `None` on a wrong length.
    fn from_bytes(bytes: &[u8]) -> Option<Self>;
}

macro_rules! impl_as_bytes {
    ($t:ty) => {
        impl AsBytes for $t {
            fn as_bytes(&self) -> &[u8] {
                // SAFETY: repr(C), no padding (pinned by `layout_is_pinned`), every field
                // is plain old data, so all bytes are initialised.
                unsafe {
                    core::slice::from_raw_parts(
                        (self as *const Self).cast::<u8>(),
                        core::mem::size_of::<Self>(),
                    )
                }
            }
            fn from_bytes(bytes: &[u8]) -> Option<Self> {
                if bytes.len() != core::mem::size_of::<Self>() {
                    return None;
                }
                let mut out = Self::default();
                // SAFETY: lengths match; every bit pattern is a valid f64/u64/u32/i64.
                unsafe {
                    core::ptr::copy_nonoverlapping(
                        bytes.as_ptr(),
                        (&mut out as *mut Self).cast::<u8>(),
                        bytes.len(),
                    );
                }
                Some(out)
            }
        }
    };
}
impl_as_bytes!(Telemetry);
impl_as_bytes!(Command);

#[cfg(test)]
mod tests {
    use super::*;
    use core::mem::{offset_of, size_of};

    #[test]
    fn layout_is_pinned() {
        assert_eq!(size_of::<PacketHeader>(), 40);
        assert_eq!(offset_of!(PacketHeader, protocol_version), 0);
        assert_eq!(offset_of!(PacketHeader, flags), 4);
        assert_eq!(offset_of!(PacketHeader, schema_hash), 8);
        assert_eq!(offset_of!(PacketHeader, run_id), 16);
        assert_eq!(offset_of!(PacketHeader, step), 24);
        assert_eq!(offset_of!(PacketHeader, t_ns), 32);

        assert_eq!(size_of::<NavState>(), 104);
        assert_eq!(offset_of!(NavState, pos_mci_m), 0);
        assert_eq!(offset_of!(NavState, vel_mci_m_s), 24);
        assert_eq!(offset_of!(NavState, q_mci_from_body), 48);
        assert_eq!(offset_of!(NavState, rate_body_rad_s), 80);

        assert_eq!(size_of::<EngineReading>(), 24);
        assert_eq!(offset_of!(EngineReading, thrust_n), 0);
        assert_eq!(offset_of!(EngineReading, chamber_pressure_pa), 8);
        assert_eq!(offset_of!(EngineReading, valve_open), 16);
        assert_eq!(offset_of!(EngineReading, flags), 20);

        assert_eq!(size_of::<PropulsionReadings>(), 120);
        assert_eq!(offset_of!(PropulsionReadings, gas_pressure_pa), 0);
        assert_eq!(offset_of!(PropulsionReadings, fuel_tank_pressure_pa), 8);
        assert_eq!(offset_of!(PropulsionReadings, ox_tank_pressure_pa), 16);
        assert_eq!(offset_of!(PropulsionReadings, engines), 24);

        assert_eq!(size_of::<ImuSample>(), 64);
        assert_eq!(offset_of!(ImuSample, delta_v_body_m_s), 8);
        assert_eq!(offset_of!(ImuSample, delta_theta_body_rad), 32);
        assert_eq!(offset_of!(ImuSample, valid), 56);
        assert_eq!(size_of::<StarTrackerSample>(), 48);
        assert_eq!(offset_of!(StarTrackerSample, valid), 40);
        assert_eq!(size_of::<AltimeterSample>(), 24);
        assert_eq!(size_of::<VelocimeterSample>(), 72);
        assert_eq!(offset_of!(VelocimeterSample, valid), 56);
        assert_eq!(offset_of!(VelocimeterSample, flags), 68);
        assert_eq!(size_of::<FrameAnnouncement>(), 56);
        assert_eq!(offset_of!(FrameAnnouncement, seq), 16);
        assert_eq!(offset_of!(FrameAnnouncement, t_ns), 24);
        assert_eq!(offset_of!(FrameAnnouncement, exposure_ns), 32);
        assert_eq!(offset_of!(FrameAnnouncement, bytes), 40);
        assert_eq!(offset_of!(FrameAnnouncement, flags), 44);
        assert_eq!(offset_of!(FrameAnnouncement, hash), 48);
        assert_eq!(size_of::<SensorFrame>(), 1096);
        assert_eq!(offset_of!(SensorFrame, frame_count), 20);
        assert_eq!(offset_of!(SensorFrame, imu), 24);
        assert_eq!(offset_of!(SensorFrame, star_tracker), 536);
        assert_eq!(offset_of!(SensorFrame, laser_altimeter), 632);
        assert_eq!(offset_of!(SensorFrame, rf_altimeter), 680);
        assert_eq!(offset_of!(SensorFrame, velocimeter), 728);
        assert_eq!(offset_of!(SensorFrame, frames), 872);

        assert_eq!(size_of::<Telemetry>(), 1400);
        assert_eq!(offset_of!(Telemetry, header), 0);
        assert_eq!(offset_of!(Telemetry, nav), 40);
        assert_eq!(offset_of!(Telemetry, accel_body_m_s2), 144);
        assert_eq!(offset_of!(Telemetry, altitude_m), 168);
        assert_eq!(offset_of!(Telemetry, mass_estimate_kg), 176);
        assert_eq!(offset_of!(Telemetry, propulsion), 184);
        assert_eq!(offset_of!(Telemetry, sensors), 304);

        assert_eq!(size_of::<FswReport>(), 144);
        assert_eq!(offset_of!(FswReport, nav_pos_sigma_m), 48);
        assert_eq!(offset_of!(FswReport, nav_altitude_m), 96);
        assert_eq!(offset_of!(FswReport, group_compute_ns), 112);
        assert_eq!(offset_of!(FswReport, nav_flags), 128);
        assert_eq!(offset_of!(FswReport, cycle_slips), 140);
        assert_eq!(size_of::<Command>(), 336);
        assert_eq!(offset_of!(Command, header), 0);
        assert_eq!(offset_of!(Command, thrust_cmd_n), 40);
        assert_eq!(offset_of!(Command, engine_on), 72);
        assert_eq!(offset_of!(Command, torque_cmd_body_nm), 88);
        assert_eq!(offset_of!(Command, stub_compute_ns), 112);
        assert_eq!(offset_of!(Command, thruster_on_time_ns), 120);
        assert_eq!(offset_of!(Command, attitude_mode), 184);
        assert_eq!(offset_of!(Command, reserved), 188);
        assert_eq!(offset_of!(Command, fsw), 192);
    }

    #[test]
    fn no_padding_anywhere() {
        // Field sizes add up to the struct size: no padding bytes for as_bytes to expose.
        assert_eq!(4 + 4 + 8 + 8 + 8 + 8, size_of::<PacketHeader>());
        assert_eq!(8 * (3 + 3 + 4 + 3), size_of::<NavState>());
        assert_eq!(8 + 8 + 4 + 4, size_of::<EngineReading>());
        assert_eq!(
            8 * 3 + 4 * size_of::<EngineReading>(),
            size_of::<PropulsionReadings>()
        );
        assert_eq!(8 + 24 + 24 + 4 + 4, size_of::<ImuSample>());
        assert_eq!(8 + 32 + 4 + 4, size_of::<StarTrackerSample>());
        assert_eq!(8 + 8 + 4 + 4, size_of::<AltimeterSample>());
        assert_eq!(8 + 24 + 24 + 12 + 4, size_of::<VelocimeterSample>());
        assert_eq!(4 * 4 + 8 * 3 + 4 * 2 + 8, size_of::<FrameAnnouncement>());
        assert_eq!(
            6 * 4
                + IMU_SAMPLES_MAX * size_of::<ImuSample>()
                + STAR_TRACKER_SAMPLES_MAX * size_of::<StarTrackerSample>()
                + 2 * ALTIMETER_SAMPLES_MAX * size_of::<AltimeterSample>()
                + VELOCIMETER_SAMPLES_MAX * size_of::<VelocimeterSample>()
                + FRAMES_MAX * size_of::<FrameAnnouncement>(),
            size_of::<SensorFrame>()
        );
        assert_eq!(
            40 + 104 + 24 + 8 + 8 + 120 + size_of::<SensorFrame>(),
            size_of::<Telemetry>()
        );
        assert_eq!(
            8 * (3 + 3 + 3 + 3 + 1 + 1) + 4 * 4 + 4 * 4,
            size_of::<FswReport>()
        );
        assert_eq!(
            40 + 32 + 16 + 24 + 8 + 64 + 4 + 4 + size_of::<FswReport>(),
            size_of::<Command>()
        );
    }

    #[test]
    fn schema_string_matches_layout() {
        // Every "=size;" in SCHEMA must be a real size: a layout change without a
        // SCHEMA change (and so a new hash) fails here.
        for (name, size) in [
            ("PacketHeader", size_of::<PacketHeader>()),
            ("NavState", size_of::<NavState>()),
            ("EngineReading", size_of::<EngineReading>()),
            ("PropulsionReadings", size_of::<PropulsionReadings>()),
            ("ImuSample", size_of::<ImuSample>()),
            ("StarTrackerSample", size_of::<StarTrackerSample>()),
            ("AltimeterSample", size_of::<AltimeterSample>()),
            ("VelocimeterSample", size_of::<VelocimeterSample>()),
            ("FrameAnnouncement", size_of::<FrameAnnouncement>()),
            ("SensorFrame", size_of::<SensorFrame>()),
            ("Telemetry", size_of::<Telemetry>()),
            ("FswReport", size_of::<FswReport>()),
            ("Command", size_of::<Command>()),
        ] {
            let entry = SCHEMA
                .split('|')
                .find(|e| e.starts_with(&format!("{name}{{")))
                .unwrap_or_else(|| panic!("{name} missing from SCHEMA"));
            assert!(entry.ends_with(&format!("}}={size}")), "{entry} vs {size}");
        }
    }

    #[test]
    fn peer_check_names_both_versions() {
        let mut h = PacketHeader::new(1, 0, 0);
        assert!(h.check_peer().is_ok());
        h.protocol_version = 7;
        h.schema_hash = 0xdead;
        let err = h.check_peer().unwrap_err().to_string();
        assert!(err.contains("v4") && err.contains("v7"), "{err}");
        assert!(err.contains("0x000000000000dead"), "{err}");
    }

    #[test]
    fn bytes_round_trip() {
        let t = Telemetry {
            header: PacketHeader::new(42, 7, 70_000_000),
            altitude_m: 123.5,
            ..Default::default()
        };
        let back = Telemetry::from_bytes(t.as_bytes()).unwrap();
        assert_eq!(back, t);
        assert!(Telemetry::from_bytes(&[0u8; 3]).is_none());
        let c = Command {
            stub_compute_ns: 9,
            ..Default::default()
        };
        assert_eq!(Command::from_bytes(c.as_bytes()).unwrap(), c);
    }
}
