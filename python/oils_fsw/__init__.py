"""Python flight software for the oils bench, over the run's iceoryx2 services.

``packets`` mirrors the wire packets with ctypes; ``loop.fly`` opens a run's services,
checks the protocol, and calls your ``step(telemetry) -> Command`` once per step until
the end of the run. See ``oils_fsw/examples/terminal_descent.py`` and docs/protocol.md.
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
    "FlightError",
    "Summary",
    "fly",
]
