"""ctypes mirrors of the oils wire packets (protocol v4).

Field for field the Rust structs of ``shared/src/lib.rs`` and the C structs of
``shared/include/oils.h``; ``docs/protocol.md`` gives every unit and frame. The test
``python/tests/test_layout.py`` checks every size and offset, the schema string and its
hash against what the Rust side prints (``cargo run -p oils-shared --example layout_json``).
"""

import ctypes

PROTOCOL_VERSION = 4
ENGINE_COUNT = 4
THRUSTER_COUNT = 8
VELOCIMETER_BEAMS = 3
IMU_SAMPLES_MAX = 8
STAR_TRACKER_SAMPLES_MAX = 2
ALTIMETER_SAMPLES_MAX = 2
VELOCIMETER_SAMPLES_MAX = 2
FRAMES_MAX = 4  # frame announcements a SensorFrame can carry (protocol v4)
FRAME_DEVICE_CAMERA = 1  # service oils/<run>/frame/camera
FRAME_DEVICE_LIDAR = 2  # service oils/<run>/frame/lidar
FRAME_DEVICE_TEST_CARD = 3  # service oils/<run>/frame/test-card
FRAME_FORMAT_U16_LE = 1  # uint16 little-endian DN, row-major
FRAME_FORMAT_F32_LE_M = 2  # float32 little-endian range in metres, row-major; 0 = no return
FRAME_FLAG_SATURATED = 1 << 0
FRAME_FLAG_OUTAGE = 1 << 1
FRAME_FLAG_FROZEN = 1 << 2
TLM_FLAG_END_OF_RUN = 1 << 0  # last telemetry of the run: answer nothing
TLM_FLAG_NAV_NOISE = 1 << 1  # navigation values carry seeded noise
TLM_FLAG_FOOTPAD_CONTACT = 1 << 2  # a footpad touches the ground: engines off
TLM_FLAG_IDEAL_NAV = 1 << 3  # nav, accel_body_m_s2, altitude_m hold the ideal navigation source
TLM_FLAG_SENSORS = 1 << 4  # sensors holds the device samples since the last cycle
TLM_FLAG_STATE_VECTOR = 1 << 5  # nav holds the ground's state vector to start from
TLM_FLAG_COMPUTER_RESET = 1 << 6  # the computer is resetting: state is lost
NAV_FLAG_VALID = 1 << 0  # FswReport: the navigation fields hold an estimate
NAV_FLAG_FROM_SENSORS = 1 << 1
NAV_FLAG_STAR_TRACKER_USED = 1 << 2
NAV_FLAG_LASER_USED = 1 << 3
NAV_FLAG_RF_USED = 1 << 4
NAV_FLAG_VELOCIMETER_USED = 1 << 5
NAV_FLAG_LASER_LOST = 1 << 6
NAV_FLAG_REINIT = 1 << 7
NAV_FLAG_TERRAIN_USED = 1 << 8
NAV_FLAG_TERRAIN_LOST = 1 << 9
NAV_FLAG_HAZARD_MAPPED = 1 << 10
NAV_FLAG_HAZARD_UNMAPPED = 1 << 11
RATE_GROUPS = 4
SAMPLE_FLAG_SATURATED = 1 << 0
SAMPLE_FLAG_NO_LOCK = 1 << 1  # no return: out of range, grazing, nothing in the beam
SAMPLE_FLAG_INHIBITED = 1 << 2
SAMPLE_FLAG_OUTAGE = 1 << 3
ATTITUDE_MODE_IDEAL_TORQUE = 0  # torque_cmd_body_nm is applied (saturated)
ATTITUDE_MODE_THRUSTERS = 1  # thruster_on_time_ns fire the attitude thrusters

#: The layout as text; its FNV-1a 64 hash travels in every packet header.
SCHEMA = (
    "PacketHeader{protocol_version:u32@0,flags:u32@4,schema_hash:u64@8,run_id:u64@16,step:u64@24,t_ns:i64@32}=40|"
    "NavState{pos_mci_m:[f64;3]@0,vel_mci_m_s:[f64;3]@24,q_mci_from_body:[f64;4]@48,rate_body_rad_s:[f64;3]@80}=104|"
    "EngineReading{thrust_n:f64@0,chamber_pressure_pa:f64@8,valve_open:u32@16,flags:u32@20}=24|"
    "PropulsionReadings{gas_pressure_pa:f64@0,fuel_tank_pressure_pa:f64@8,ox_tank_pressure_pa:f64@16,engines:[EngineReading;4]@24}=120|"
    "ImuSample{t_ns:i64@0,delta_v_body_m_s:[f64;3]@8,delta_theta_body_rad:[f64;3]@32,valid:u32@56,flags:u32@60}=64|"
    "StarTrackerSample{t_ns:i64@0,q_mci_from_body:[f64;4]@8,valid:u32@40,flags:u32@44}=48|"
    "AltimeterSample{t_ns:i64@0,range_m:f64@8,valid:u32@16,flags:u32@20}=24|"
    "VelocimeterSample{t_ns:i64@0,los_velocity_m_s:[f64;3]@8,range_m:[f64;3]@32,valid:[u32;3]@56,flags:u32@68}=72|"
    "FrameAnnouncement{device:u32@0,format:u32@4,width:u32@8,height:u32@12,seq:u64@16,t_ns:i64@24,exposure_ns:u64@32,bytes:u32@40,flags:u32@44,hash:u64@48}=56|"
    "SensorFrame{imu_count:u32@0,star_tracker_count:u32@4,laser_altimeter_count:u32@8,rf_altimeter_count:u32@12,velocimeter_count:u32@16,frame_count:u32@20,imu:[ImuSample;8]@24,star_tracker:[StarTrackerSample;2]@536,laser_altimeter:[AltimeterSample;2]@632,rf_altimeter:[AltimeterSample;2]@680,velocimeter:[VelocimeterSample;2]@728,frames:[FrameAnnouncement;4]@872}=1096|"
    "Telemetry{header:PacketHeader@0,nav:NavState@40,accel_body_m_s2:[f64;3]@144,altitude_m:f64@168,mass_estimate_kg:f64@176,propulsion:PropulsionReadings@184,sensors:SensorFrame@304}=1400|"
    "FswReport{nav_pos_mci_m:[f64;3]@0,nav_vel_mci_m_s:[f64;3]@24,nav_pos_sigma_m:[f64;3]@48,nav_vel_sigma_m_s:[f64;3]@72,nav_altitude_m:f64@96,nav_altitude_sigma_m:f64@104,group_compute_ns:[u32;4]@112,nav_flags:u32@128,phase:u32@132,boot_count:u32@136,cycle_slips:u32@140}=144|"
    "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72,torque_cmd_body_nm:[f64;3]@88,stub_compute_ns:u64@112,thruster_on_time_ns:[u64;8]@120,attitude_mode:u32@184,reserved:u32@188,fsw:FswReport@192}=336|"
)


def fnv1a64(text: str) -> int:
    """FNV-1a 64 of ``text``'s UTF-8 bytes (how the schema hash is made)."""
    h = 0xCBF29CE484222325
    for b in text.encode():
        h ^= b
        h = (h * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


SCHEMA_HASH = fnv1a64(SCHEMA)

_f64 = ctypes.c_double
_u32 = ctypes.c_uint32
_u64 = ctypes.c_uint64
_i64 = ctypes.c_int64


class PacketHeader(ctypes.Structure):
    """At offset 0 of both packets."""

    _fields_ = [
        ("protocol_version", _u32),  # PROTOCOL_VERSION
        ("flags", _u32),  # telemetry: TLM_FLAG_*; command: 0
        ("schema_hash", _u64),  # SCHEMA_HASH
        ("run_id", _u64),
        ("step", _u64),  # k
        ("t_ns", _i64),  # simulated time of step k, ns
    ]


class NavState(ctypes.Structure):
    """Navigation state, Moon-centred inertial (mci); quaternion [w, x, y, z] body->mci."""

    _fields_ = [
        ("pos_mci_m", _f64 * 3),
        ("vel_mci_m_s", _f64 * 3),
        ("q_mci_from_body", _f64 * 4),
        ("rate_body_rad_s", _f64 * 3),
    ]


class EngineReading(ctypes.Structure):
    """One main engine."""

    _fields_ = [
        ("thrust_n", _f64),
        ("chamber_pressure_pa", _f64),
        ("valve_open", _u32),  # 0/1
        ("flags", _u32),  # reserved, 0
    ]


class PropulsionReadings(ctypes.Structure):
    """Propulsion system readings."""

    _fields_ = [
        ("gas_pressure_pa", _f64),
        ("fuel_tank_pressure_pa", _f64),
        ("ox_tank_pressure_pa", _f64),
        ("engines", EngineReading * ENGINE_COUNT),
    ]


class ImuSample(ctypes.Structure):
    """Velocity and angle increments over the IMU period ending at t_ns, body axes."""

    _fields_ = [
        ("t_ns", _i64),
        ("delta_v_body_m_s", _f64 * 3),
        ("delta_theta_body_rad", _f64 * 3),
        ("valid", _u32),
        ("flags", _u32),  # SAMPLE_FLAG_*
    ]


class StarTrackerSample(ctypes.Structure):
    """Measured attitude [w, x, y, z], body -> mci."""

    _fields_ = [
        ("t_ns", _i64),
        ("q_mci_from_body", _f64 * 4),
        ("valid", _u32),
        ("flags", _u32),
    ]


class AltimeterSample(ctypes.Structure):
    """Slant range along the beam to the terrain."""

    _fields_ = [
        ("t_ns", _i64),
        ("range_m", _f64),
        ("valid", _u32),
        ("flags", _u32),
    ]


class VelocimeterSample(ctypes.Structure):
    """Per beam: velocity relative to the ground along the beam, and range."""

    _fields_ = [
        ("t_ns", _i64),
        ("los_velocity_m_s", _f64 * VELOCIMETER_BEAMS),
        ("range_m", _f64 * VELOCIMETER_BEAMS),
        ("valid", _u32 * VELOCIMETER_BEAMS),
        ("flags", _u32),
    ]


class FrameAnnouncement(ctypes.Structure):
    """A frame published on oils/<run>/frame/<device> before this telemetry (protocol v4).

    Its pixels are the sample's payload (``bytes`` long, ``format``), this struct its user
    header; ``hash`` is XXH3-64 (seed 0) of the pixels."""

    _fields_ = [
        ("device", _u32),  # FRAME_DEVICE_*
        ("format", _u32),  # FRAME_FORMAT_*
        ("width", _u32),
        ("height", _u32),
        ("seq", _u64),  # the device's frame counter from 0
        ("t_ns", _i64),  # time of validity (mid-exposure)
        ("exposure_ns", _u64),
        ("bytes", _u32),
        ("flags", _u32),  # FRAME_FLAG_*
        ("hash", _u64),
    ]

    @staticmethod
    def type_name() -> str:
        """The iceoryx2 user-header type name, as the Rust struct declares it."""
        return "oils.v4.FrameAnnouncement"


class SensorFrame(ctypes.Structure):
    """Every device sample since the last cycle; *_count entries of each array are used."""

    _fields_ = [
        ("imu_count", _u32),
        ("star_tracker_count", _u32),
        ("laser_altimeter_count", _u32),
        ("rf_altimeter_count", _u32),
        ("velocimeter_count", _u32),
        ("frame_count", _u32),
        ("imu", ImuSample * IMU_SAMPLES_MAX),
        ("star_tracker", StarTrackerSample * STAR_TRACKER_SAMPLES_MAX),
        ("laser_altimeter", AltimeterSample * ALTIMETER_SAMPLES_MAX),
        ("rf_altimeter", AltimeterSample * ALTIMETER_SAMPLES_MAX),
        ("velocimeter", VelocimeterSample * VELOCIMETER_SAMPLES_MAX),
        ("frames", FrameAnnouncement * FRAMES_MAX),
    ]


class Telemetry(ctypes.Structure):
    """Emulator -> flight software, once per cycle, at t_k (1400 bytes)."""

    _fields_ = [
        ("header", PacketHeader),
        ("nav", NavState),
        ("accel_body_m_s2", _f64 * 3),  # specific force, body axes (ideal navigation)
        ("altitude_m", _f64),  # footpads above the surface (ideal navigation)
        ("mass_estimate_kg", _f64),
        ("propulsion", PropulsionReadings),
        ("sensors", SensorFrame),  # with TLM_FLAG_SENSORS
    ]

    @staticmethod
    def type_name() -> str:
        """iceoryx2 type name (must match the Rust side)."""
        return "oils.v4.Telemetry"


class FswReport(ctypes.Structure):
    """What the flight software says of itself each cycle (144 bytes; all zero: nothing)."""

    _fields_ = [
        ("nav_pos_mci_m", _f64 * 3),  # its position estimate, mci
        ("nav_vel_mci_m_s", _f64 * 3),  # its velocity estimate, mci
        ("nav_pos_sigma_m", _f64 * 3),  # its own 1-sigma per axis (0: not known)
        ("nav_vel_sigma_m_s", _f64 * 3),
        ("nav_altitude_m", _f64),  # its height above the ground below
        ("nav_altitude_sigma_m", _f64),
        ("group_compute_ns", _u32 * RATE_GROUPS),  # wall clock (not in the digest)
        ("nav_flags", _u32),  # NAV_FLAG_*
        ("phase", _u32),  # its own phase code
        ("boot_count", _u32),  # 1 after the first start, +1 per computer reset
        ("cycle_slips", _u32),  # rate-group overruns so far (not in the digest)
    ]


class Command(ctypes.Structure):
    """Flight software -> emulator, once per cycle: held over [t_k, t_k+1) (336 bytes)."""

    _fields_ = [
        ("header", PacketHeader),  # echo run_id, step, t_ns of the telemetry answered
        ("thrust_cmd_n", _f64 * ENGINE_COUNT),  # 0..800 N
        ("engine_on", _u32 * ENGINE_COUNT),  # 0 or 1
        ("torque_cmd_body_nm", _f64 * 3),  # ideal torque, body axes (attitude_mode 0)
        ("stub_compute_ns", _u64),  # your step's compute time (not in the digest)
        ("thruster_on_time_ns", _u64 * THRUSTER_COUNT),  # from the cycle start (attitude_mode 1)
        ("attitude_mode", _u32),  # ATTITUDE_MODE_*
        ("reserved", _u32),
        ("fsw", FswReport),  # optional: what the flight software says of itself
    ]

    @staticmethod
    def type_name() -> str:
        """iceoryx2 type name (must match the Rust side)."""
        return "oils.v4.Command"
