"""The flight-software loop over a run's four iceoryx2 services (docs/protocol.md).

Start-up: wait for the emulator to create the run's services (it may start after you),
check its ``oils.protocol_version`` and ``oils.schema_hash`` attributes before opening the
typed services, read its ``oils.wait`` strategy. Then per step: take Telemetry(k), stop
at END_OF_RUN, call ``step``, stamp and publish Command(k), and notify ``command-ready``
unless the emulator busy-polls.
"""

import ctypes
import dataclasses
import time
from typing import Callable, Optional

import iceoryx2 as iox2

from . import domain
from .packets import (
    PROTOCOL_VERSION,
    SCHEMA_HASH,
    TLM_FLAG_END_OF_RUN,
    Command,
    Telemetry,
)


class FlightError(RuntimeError):
    """The run could not be flown (no emulator, protocol mismatch, emulator silent)."""


@dataclasses.dataclass
class Summary:
    """How a run ended well."""

    commands: int
    last_step: int
    wait: str


def service_names(run_id: int) -> dict:
    """The run's four service names."""
    base = f"oils/{run_id:016x}"
    return {
        "telemetry": f"{base}/telemetry",
        "command": f"{base}/command",
        "telemetry_event": f"{base}/telemetry-ready",
        "command_event": f"{base}/command-ready",
    }


def _attribute(attributes, key: str) -> Optional[str]:
    values = attributes.key_values(iox2.AttributeKey.new(key))
    return values[0].to_string() if values else None


def _open_telemetry_event(node, name: str, timeout_s: float):
    """Opens ``telemetry-ready``, retrying until the emulator has created it."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            return node.service_builder(iox2.ServiceName.new(name)).event().open()
        except iox2.EventOpenError as e:
            if time.monotonic() >= deadline:
                raise FlightError(
                    f"no emulator created {name} within {timeout_s} s ({e})"
                ) from e
            time.sleep(0.005)


def fly(
    step: Callable[[Telemetry], Command],
    run_id: int,
    startup_timeout_s: float = 10.0,
    silence_timeout_s: float = 5.0,
    frame: Optional[Callable] = None,
) -> Summary:
    """Flies run ``run_id`` with ``step`` until the emulator's end-of-run telemetry.

    ``frame``, if given, is called before ``step`` as ``frame(announcement, pixels)`` for
    each frame Telemetry(k) announces (protocol v4), ``pixels`` a read-only numpy view of
    the frame in shared memory, valid during the call only (``oils_fsw.frames``).

    ``step`` gets Telemetry(k) (a copy, yours to keep) and returns a ``Command`` with
    ``thrust_cmd_n``, ``engine_on`` and ``torque_cmd_body_nm`` filled; this loop stamps
    the header and ``stub_compute_ns`` (the time ``step`` took, by
    ``time.perf_counter_ns``).
    """
    iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
    # The user's private oils domain, as the emulator's (docs/protocol.md, "Domain").
    node = iox2.NodeBuilder.new().config(domain.config()).create(iox2.ServiceType.Ipc)
    names = service_names(run_id)

    tlm_event = _open_telemetry_event(node, names["telemetry_event"], startup_timeout_s)
    version = _attribute(tlm_event.attributes, "oils.protocol_version")
    schema_hash = _attribute(tlm_event.attributes, "oils.schema_hash")
    if version != str(PROTOCOL_VERSION) or schema_hash is None or int(schema_hash, 16) != SCHEMA_HASH:
        raise FlightError(
            f"protocol mismatch: this client speaks oils protocol v{PROTOCOL_VERSION} "
            f"(schema {SCHEMA_HASH:#018x}), the emulator v{version} (schema {schema_hash})"
        )
    wait = _attribute(tlm_event.attributes, "oils.wait") or "hybrid"
    reader = None
    if frame is not None:
        from .frames import FrameReader

        reader = FrameReader(node, run_id, _attribute(tlm_event.attributes, "oils.frames"))

    svc = lambda name: node.service_builder(iox2.ServiceName.new(names[name]))  # noqa: E731
    command_service = svc("command").publish_subscribe(Command).open()
    telemetry_service = svc("telemetry").publish_subscribe(Telemetry).open()
    command_event = svc("command_event").event().open()
    publisher = command_service.publisher_builder().create()
    subscriber = telemetry_service.subscriber_builder().create()
    notifier = command_event.notifier_builder().create()
    listener = tlm_event.listener_builder().create()
    notify = wait != "busy"  # a busy-polling emulator never waits on command-ready
    slice_1ms = iox2.Duration.from_millis(1)

    def next_telemetry() -> Telemetry:
        deadline = time.monotonic() + silence_timeout_s
        while True:
            sample = subscriber.receive()
            if sample is not None:
                tlm = Telemetry()
                ctypes.memmove(ctypes.byref(tlm), sample.payload_ptr, ctypes.sizeof(Telemetry))
                del sample  # hand the slot back at once
                return tlm
            if time.monotonic() >= deadline:
                raise FlightError(f"emulator silent for {silence_timeout_s} s (did it die?)")
            if wait != "busy":
                # The emulator notifies telemetry-ready after each telemetry; sleep on it
                # in 1 ms slices so nothing is missed between receive and wait.
                listener.timed_wait(slice_1ms)

    commands = 0
    last_step = 0
    while True:
        tlm = next_telemetry()
        h = tlm.header
        if h.protocol_version != PROTOCOL_VERSION or h.schema_hash != SCHEMA_HASH:
            raise FlightError(
                f"protocol mismatch in telemetry: v{h.protocol_version} schema {h.schema_hash:#018x}"
            )
        if h.flags & TLM_FLAG_END_OF_RUN:
            return Summary(commands=commands, last_step=last_step, wait=wait)
        if reader is not None:
            from .frames import announced

            for ann in announced(tlm):
                reader.with_frame(ann, frame)
        started = time.perf_counter_ns()
        cmd = step(tlm)
        compute_ns = time.perf_counter_ns() - started
        cmd.header.protocol_version = PROTOCOL_VERSION
        cmd.header.flags = 0
        cmd.header.schema_hash = SCHEMA_HASH
        cmd.header.run_id = h.run_id
        cmd.header.step = h.step
        cmd.header.t_ns = h.t_ns
        cmd.stub_compute_ns = compute_ns
        publisher.send_copy(cmd)
        if notify:
            notifier.notify()
        commands += 1
        last_step = h.step
