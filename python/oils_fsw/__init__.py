"""Python flight software for the oils bench, over the run's iceoryx2 services.

``packets`` mirrors the wire packets with ctypes; ``loop.fly`` opens a run's services,
checks the protocol, and calls your ``step(telemetry) -> Command`` once per step until
the end of the run. See ``oils_fsw/examples/terminal_descent.py`` and docs/protocol.md.

``read_log``, ``read_log_arrays``, ``read_records`` and ``read_campaign`` (from
``oils_fsw.data``, imported on first use) read a run's log and a campaign's results into
numpy and pandas; they need the ``data`` extra: ``pip install './python[data]'``.
"""

from .packets import (
    ENGINE_COUNT,
    PROTOCOL_VERSION,
    SCHEMA,
    SCHEMA_HASH,
    TLM_FLAG_END_OF_RUN,
    TLM_FLAG_FOOTPAD_CONTACT,
    TLM_FLAG_NAV_NOISE,
    Command,
    EngineReading,
    NavState,
    PacketHeader,
    PropulsionReadings,
    Telemetry,
    fnv1a64,
    THRUSTER_COUNT,
    TLM_FLAG_IDEAL_NAV,
    TLM_FLAG_SENSORS,
    ATTITUDE_MODE_IDEAL_TORQUE,
    ATTITUDE_MODE_THRUSTERS,
    SAMPLE_FLAG_SATURATED,
    SAMPLE_FLAG_NO_LOCK,
    SAMPLE_FLAG_INHIBITED,
    SAMPLE_FLAG_OUTAGE,
    ImuSample,
    StarTrackerSample,
    AltimeterSample,
    VelocimeterSample,
    SensorFrame,
    FrameAnnouncement,
    FRAMES_MAX,
    FRAME_DEVICE_CAMERA,
    FRAME_DEVICE_LIDAR,
    FRAME_DEVICE_TEST_CARD,
    FRAME_FORMAT_U16_LE,
    FRAME_FORMAT_F32_LE_M,
    FRAME_FLAG_SATURATED,
    FRAME_FLAG_OUTAGE,
    FRAME_FLAG_FROZEN,
    TLM_FLAG_STATE_VECTOR,
    TLM_FLAG_COMPUTER_RESET,
    NAV_FLAG_VALID,
    NAV_FLAG_FROM_SENSORS,
    NAV_FLAG_STAR_TRACKER_USED,
    NAV_FLAG_LASER_USED,
    NAV_FLAG_RF_USED,
    NAV_FLAG_VELOCIMETER_USED,
    NAV_FLAG_LASER_LOST,
    NAV_FLAG_REINIT,
    NAV_FLAG_TERRAIN_LOST,
    NAV_FLAG_TERRAIN_USED,
    RATE_GROUPS,
    FswReport,
)
from .loop import FlightError, Summary, fly

__all__ = [
    "ENGINE_COUNT",
    "PROTOCOL_VERSION",
    "SCHEMA",
    "SCHEMA_HASH",
    "TLM_FLAG_END_OF_RUN",
    "TLM_FLAG_FOOTPAD_CONTACT",
    "TLM_FLAG_NAV_NOISE",
    "Command",
    "EngineReading",
    "NavState",
    "PacketHeader",
    "PropulsionReadings",
    "Telemetry",
    "fnv1a64",
    "THRUSTER_COUNT",
    "TLM_FLAG_IDEAL_NAV",
    "TLM_FLAG_SENSORS",
    "ATTITUDE_MODE_IDEAL_TORQUE",
    "ATTITUDE_MODE_THRUSTERS",
    "SAMPLE_FLAG_SATURATED",
    "SAMPLE_FLAG_NO_LOCK",
    "SAMPLE_FLAG_INHIBITED",
    "SAMPLE_FLAG_OUTAGE",
    "ImuSample",
    "StarTrackerSample",
    "AltimeterSample",
    "VelocimeterSample",
    "SensorFrame",
    "FrameAnnouncement",
    "FRAMES_MAX",
    "FRAME_DEVICE_CAMERA",
    "FRAME_DEVICE_LIDAR",
    "FRAME_DEVICE_TEST_CARD",
    "FRAME_FORMAT_U16_LE",
    "FRAME_FORMAT_F32_LE_M",
    "FRAME_FLAG_SATURATED",
    "FRAME_FLAG_OUTAGE",
    "FRAME_FLAG_FROZEN",
    "TLM_FLAG_STATE_VECTOR",
    "TLM_FLAG_COMPUTER_RESET",
    "NAV_FLAG_VALID",
    "NAV_FLAG_FROM_SENSORS",
    "NAV_FLAG_STAR_TRACKER_USED",
    "NAV_FLAG_LASER_USED",
    "NAV_FLAG_RF_USED",
    "NAV_FLAG_VELOCIMETER_USED",
    "NAV_FLAG_LASER_LOST",
    "NAV_FLAG_REINIT",
    "NAV_FLAG_TERRAIN_LOST",
    "NAV_FLAG_TERRAIN_USED",
    "RATE_GROUPS",
    "FswReport",
    "FlightError",
    "Summary",
    "fly",
    "read_log",
    "read_log_arrays",
    "read_records",
    "read_campaign",
]

_DATA = ("read_log", "read_log_arrays", "read_records", "read_campaign")


def __getattr__(name):
    # The data readers import numpy and pandas: only when asked for.
    if name in _DATA:
        from . import data

        return getattr(data, name)
    raise AttributeError(f"module 'oils_fsw' has no attribute {name!r}")
