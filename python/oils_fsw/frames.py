"""Frames (protocol v4): an imaging device's frames read in place from their iceoryx2
services, as numpy views of the shared memory (docs/protocol.md, "Frames").

Each frame travels on ``oils/<run>/frame/<device>`` as a dynamic ``u8`` slice whose user
header is its :class:`~oils_fsw.packets.FrameAnnouncement`; the next telemetry announces
it in ``sensors.frames``. :class:`FrameReader` opens the services the emulator lists in
its ``oils.frames`` attribute and hands a frame to a callback as a read-only numpy array
over the sample's payload: no copy, valid only during the call (the sample is released
after it). ``fly(step, run_id, frame=callback)`` does this before each ``step``.

numpy is needed only here (``pip install './python[data]'`` brings it).
"""

import ctypes
import ctypes.util
from typing import Any, Callable, Dict, Optional

import iceoryx2 as iox2

from .packets import (
    FRAME_DEVICE_CAMERA,
    FRAME_DEVICE_LIDAR,
    FRAME_DEVICE_TEST_CARD,
    FRAME_FORMAT_F32_LE_M,
    FRAME_FORMAT_U16_LE,
    FRAMES_MAX,
    TLM_FLAG_COMPUTER_RESET,
    TLM_FLAG_END_OF_RUN,
    FrameAnnouncement,
    Telemetry,
)

#: Service name of each frame device (the last segment of ``oils/<run>/frame/<name>``).
DEVICE_NAMES = {
    FRAME_DEVICE_CAMERA: "camera",
    FRAME_DEVICE_LIDAR: "lidar",
    FRAME_DEVICE_TEST_CARD: "test-card",
}


def parse_frames_attribute(value: Optional[str]) -> Dict[int, int]:
    """``oils.frames`` (``device:max_bytes,...``) as ``{device: max_bytes}``."""
    out: Dict[int, int] = {}
    for part in (value or "").split(","):
        if part:
            device, max_bytes = part.split(":")
            out[int(device)] = int(max_bytes)
    return out


def announced(tlm: Telemetry):
    """The frames ``tlm`` announces that a flight software is handed (none in an
    end-of-run telemetry or while the computer resets)."""
    if tlm.header.flags & (TLM_FLAG_END_OF_RUN | TLM_FLAG_COMPUTER_RESET):
        return []
    n = min(tlm.sensors.frame_count, FRAMES_MAX)
    return [tlm.sensors.frames[i] for i in range(n)]


def pixels(ann: FrameAnnouncement, payload: memoryview) -> Any:
    """The frame's bytes as a read-only numpy array over ``payload`` (no copy): ``(height,
    width)`` of ``<u2`` digital numbers or ``<f4`` metres, or the raw ``u8`` bytes for
    another format."""
    import numpy as np

    raw = np.frombuffer(payload, dtype=np.uint8, count=ann.bytes)
    if ann.format == FRAME_FORMAT_U16_LE:
        view = raw.view("<u2").reshape(ann.height, ann.width)
    elif ann.format == FRAME_FORMAT_F32_LE_M:
        view = raw.view("<f4").reshape(ann.height, ann.width)
    else:
        view = raw
    view.flags.writeable = False
    return view


_xxh3 = None


def xxh3_64(data: Any) -> int:
    """XXH3-64 (seed 0) of a buffer (a numpy array, bytes, a memoryview), through the
    machine's libxxhash (``XXH3_64bits``), without a copy: the hash a
    :class:`FrameAnnouncement` carries."""
    global _xxh3
    if _xxh3 is None:
        name = ctypes.util.find_library("xxhash") or "libxxhash.so.0"
        lib = ctypes.CDLL(name)
        lib.XXH3_64bits.argtypes = (ctypes.c_void_p, ctypes.c_size_t)
        lib.XXH3_64bits.restype = ctypes.c_uint64
        _xxh3 = lib.XXH3_64bits
    view = memoryview(data).cast("B")
    if view.readonly:
        # ctypes needs a writable buffer to take its address; the bytes are only read.
        import numpy as np

        arr = np.frombuffer(view, dtype=np.uint8)
        return int(_xxh3(arr.ctypes.data, arr.nbytes))
    buf = (ctypes.c_char * view.nbytes).from_buffer(view)
    return int(_xxh3(ctypes.addressof(buf), view.nbytes))


class FrameReader:
    """Subscribers to a run's frame services (those ``oils.frames`` lists)."""

    def __init__(self, node: Any, run_id: int, frames_attribute: Optional[str]):
        self._subscribers: Dict[int, Any] = {}
        self._services = []
        for device in parse_frames_attribute(frames_attribute):
            name = DEVICE_NAMES.get(device)
            if name is None:
                continue
            service = (
                node.service_builder(iox2.ServiceName.new(f"oils/{run_id:016x}/frame/{name}"))
                .publish_subscribe(iox2.Slice[ctypes.c_uint8])
                .user_header(FrameAnnouncement)
                .open()
            )
            self._services.append(service)
            self._subscribers[device] = service.subscriber_builder().create()

    def devices(self):
        """The frame devices read."""
        return list(self._subscribers)

    def with_frame(self, ann: FrameAnnouncement, read: Callable[[FrameAnnouncement, Any], Any]):
        """Calls ``read(header, pixels)`` with the frame ``ann`` announces: its header as
        published and a read-only numpy view of its bytes in shared memory (see
        :func:`pixels`), valid during the call only; returns what ``read`` returns, or
        ``None`` when the frame is not there (lost). Older frames are dropped."""
        sub = self._subscribers.get(ann.device)
        if sub is None:
            return None
        while True:
            sample = sub.receive()
            if sample is None:
                return None
            header = sample.user_header().contents
            if header.seq < ann.seq:
                del sample
                continue
            if header.seq > ann.seq:
                return None
            try:
                header_copy = FrameAnnouncement.from_buffer_copy(header)
                view = sample.payload().as_memory_view()
                return read(header_copy, pixels(ann, view))
            finally:
                del sample
