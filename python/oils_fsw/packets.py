"""ctypes mirrors of the oils wire packets (protocol v1).

Field for field the Rust structs of ``shared/src/lib.rs`` and the C structs of
``shared/include/oils.h``; ``docs/protocol.md`` gives every unit and frame. The test
``python/tests/test_layout.py`` checks every size and offset, the schema string and its
hash against what the Rust side prints (``cargo run -p oils-shared --example layout_json``).
"""

import ctypes

PROTOCOL_VERSION = 1
ENGINE_COUNT = 4
TLM_FLAG_END_OF_RUN = 1 << 0  # last telemetry of the run: answer nothing
TLM_FLAG_NAV_NOISE = 1 << 1  # navigation values carry seeded noise
TLM_FLAG_FOOTPAD_CONTACT = 1 << 2  # a footpad touches the ground: engines off

#: The layout as text; its FNV-1a 64 hash travels in every packet header.
SCHEMA = (
    "PacketHeader{protocol_version:u32@0,flags:u32@4,schema_hash:u64@8,run_id:u64@16,step:u64@24,t_ns:i64@32}=40|"
    "NavState{pos_mci_m:[f64;3]@0,vel_mci_m_s:[f64;3]@24,q_mci_from_body:[f64;4]@48,rate_body_rad_s:[f64;3]@80}=104|"
    "EngineReading{thrust_n:f64@0,chamber_pressure_pa:f64@8,valve_open:u32@16,flags:u32@20}=24|"
    "PropulsionReadings{gas_pressure_pa:f64@0,fuel_tank_pressure_pa:f64@8,ox_tank_pressure_pa:f64@16,engines:[EngineReading;4]@24}=120|"
    "Telemetry{header:PacketHeader@0,nav:NavState@40,accel_body_m_s2:[f64;3]@144,altitude_m:f64@168,mass_estimate_kg:f64@176,propulsion:PropulsionReadings@184}=304|"
    "Command{header:PacketHeader@0,thrust_cmd_n:[f64;4]@40,engine_on:[u32;4]@72,torque_cmd_body_nm:[f64;3]@88,stub_compute_ns:u64@112}=120|"
)


def fnv1a64(text: str) -> int:
    """FNV-1a 64 of ``text``'s UTF-8 bytes (how the schema hash is made)."""
    h = 0xCBF29CE484222325
    for b in text.encode():
        h ^= b
        h = (h * 0x100000001B3) & 0xFFFFFFFFFFFFFFFF
    return h


SCHEMA_HASH = fnv1a64(SCHEMA)  # 0xa8f0da5f8f0aee6e

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


class Telemetry(ctypes.Structure):
    """Emulator -> flight software, once per step: the state at t_k (304 bytes)."""

    _fields_ = [
        ("header", PacketHeader),
        ("nav", NavState),
        ("accel_body_m_s2", _f64 * 3),  # specific force, body axes
        ("altitude_m", _f64),  # footpads above the surface
        ("mass_estimate_kg", _f64),
        ("propulsion", PropulsionReadings),
    ]

    @staticmethod
    def type_name() -> str:
        """iceoryx2 type name (must match the Rust side)."""
        return "oils.v1.Telemetry"


class Command(ctypes.Structure):
    """Flight software -> emulator, once per step: held over [t_k, t_k+1) (120 bytes)."""

    _fields_ = [
        ("header", PacketHeader),  # echo run_id, step, t_ns of the telemetry answered
        ("thrust_cmd_n", _f64 * ENGINE_COUNT),  # 0..800 N
        ("engine_on", _u32 * ENGINE_COUNT),  # 0 or 1
        ("torque_cmd_body_nm", _f64 * 3),  # attitude thrusters, body axes
        ("stub_compute_ns", _u64),  # your step's compute time (not in the digest)
    ]

    @staticmethod
    def type_name() -> str:
        """iceoryx2 type name (must match the Rust side)."""
        return "oils.v1.Command"
