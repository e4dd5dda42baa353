"""A run's log and a campaign's results as numpy arrays and pandas DataFrames.

Needs the ``data`` extra (``pip install './python[data]'``: numpy, pandas, and mcap for
MCAP logs); the flight-software client (``oils_fsw`` itself) does not.

* :func:`read_log` -- a log (OILSLOG7 or OILSLOG6 binary records, or MCAP) as a DataFrame whose
  columns are those of ``oils export LOG --csv``, in the same order, with the same values.
* :func:`read_log_arrays` -- the same columns as a dict of numpy arrays.
* :func:`read_records` -- the binary log's records as one numpy structured array (the
  stored columns), unpacked from the log's zstd frames by numpy (no parser loop in Python).
* :func:`read_layout` -- the record layout a log describes itself with.
* :func:`read_campaign` -- ``cases.csv`` of an ``oils mc run`` directory as a DataFrame,
  ``summary.json`` in its ``attrs``.

Nothing here knows an offset or a size: the layout comes from the description the bench
writes into every log's JSON header (``"layout"``, made from the same table the CSV
export uses; ``emulator/src/log_layout.rs``). A log from before headers carried it is read
with ``layout=`` the file ``oils export LOG --layout OUT.json`` writes.

Columns the CSV computes rather than stores (``telemetry.t_s``, the record-flag bits,
``truth.rate_body_deg_s``, the site-frame position and velocity, the speeds and tilt) are
computed as the description says, vectorised. Stored columns and the simple derivations
(scale, bit, degrees) are bit for bit the CSV's; the site-frame ones come from numpy's
sin/cos/acos instead of Rust's and may differ in the last bits (tilt near zero: about
1e-6 degree, since acos is steep at 1).
"""

from __future__ import annotations

import json
import os
import struct
import warnings
import zlib
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

import numpy as np
import pandas as pd

PathLike = Union[str, "os.PathLike[str]"]

LAYOUT_FORMAT = "oils-log-layout-1"
MCAP_MAGIC = b"\x89MCAP0\r\n"
OILSLOG_MAGIC = b"OILSLOG8"
# The same zstd frames with protocol v3 records (read by the layout their header carries).
OILSLOG7_MAGIC = b"OILSLOG7"
# Protocol v3 records uncompressed, one after the other (still read, by their layout).
OILSLOG6_MAGIC = b"OILSLOG6"

__all__ = [
    "LogError",
    "read_layout",
    "read_records",
    "read_log_arrays",
    "read_log",
    "read_campaign",
]


class LogError(ValueError):
    """The file is not a log this reader can read (or its records are damaged)."""


# --- the layout -------------------------------------------------------------------


def _load_layout(layout: Union[PathLike, Dict[str, Any], None], header: Dict[str, Any], path: Path) -> Dict[str, Any]:
    if layout is None:
        layout = header.get("layout")
        if layout is None:
            raise LogError(
                f"{path}: its header has no record layout (a log from before the bench wrote it); "
                f"write one with `oils export {path} --layout LAYOUT.json` and pass layout='LAYOUT.json'"
            )
    elif not isinstance(layout, dict):
        with open(layout, encoding="utf-8") as f:
            layout = json.load(f)
    if "error" in layout:
        raise LogError(f"{path}: the bench could not describe its records: {layout['error']}")
    if layout.get("format") != LAYOUT_FORMAT:
        raise LogError(f"{path}: record layout format {layout.get('format')!r}, this reader reads {LAYOUT_FORMAT!r}")
    if layout.get("byte_order") != "little":
        raise LogError(f"{path}: byte order {layout.get('byte_order')!r} (this reader reads little-endian)")
    return layout


def _read_header(path: Path, data) -> Dict[str, Any]:
    """The JSON header of an OILSLOG7 or OILSLOG6 file (its CRC checked)."""
    if len(data) < 16 or bytes(data[:8]) not in (OILSLOG_MAGIC, OILSLOG7_MAGIC, OILSLOG6_MAGIC):
        raise LogError(f"{path}: not an OILSLOG8, OILSLOG7 or OILSLOG6 log (magic {bytes(data[:8])!r})")
    n = int.from_bytes(bytes(data[8:12]), "little")
    crc = int.from_bytes(bytes(data[12:16]), "little")
    if 16 + n > len(data):
        raise LogError(f"{path}: truncated header")
    text = bytes(data[16:16 + n])
    if zlib.crc32(text) != crc:
        raise LogError(f"{path}: its header's CRC does not match (edited or damaged)")
    try:
        return json.loads(text)
    except ValueError as e:
        raise LogError(f"{path}: header is not JSON: {e}") from None


def read_layout(path: PathLike) -> Dict[str, Any]:
    """The record layout an OILSLOG7, OILSLOG6 or MCAP log carries in its header."""
    path = Path(path)
    header = _mcap_header(path) if _is_mcap(path) else _read_header(path, _map(path))
    return _load_layout(None, header, path)


def _map(path: Path):
    if os.path.getsize(path) == 0:
        return np.zeros(0, np.uint8)
    return np.memmap(path, dtype=np.uint8, mode="r")


def _is_mcap(path: Path) -> bool:
    with open(path, "rb") as f:
        return f.read(8) == MCAP_MAGIC


def _records_dtype(layout: Dict[str, Any]) -> np.dtype:
    stored = [c for c in layout["columns"] if "offset" in c]
    return np.dtype({
        "names": [c["name"] for c in stored],
        "formats": [c["dtype"] for c in stored],
        "offsets": [c["offset"] for c in stored],
        "itemsize": layout["record_size"],
    })


# --- binary logs ---------------------------------------------------------------------


def _binary_records(path: Path, layout, verify: bool):
    data = _map(path)
    header = _read_header(path, data)
    layout = _load_layout(layout, header, path)
    size = int(layout["record_size"])
    start = int(layout["header_start"]) + int.from_bytes(bytes(data[8:12]), "little")
    body = data[start:]
    trailer = layout["trailer"]
    tsize, tmagic = int(trailer["size"]), trailer["magic"].encode()
    count = None
    problems = []
    if bytes(data[:8]) in (OILSLOG_MAGIC, OILSLOG7_MAGIC):
        body, count, problems = _unframe(path, body, layout)
    elif len(body) >= tsize and (len(body) - tsize) % size == 0:
        t = bytes(body[len(body) - tsize:])
        if t[:8] == tmagic and zlib.crc32(t[:16]) == int.from_bytes(t[16:20], "little"):
            count = int.from_bytes(t[8:16], "little")
            body = body[:len(body) - tsize]
    held = len(body) // size
    if len(body) % size:
        problems.append(f"{len(body) % size} trailing bytes of a torn record ignored")
    if count is None:
        problems.append(f"log ends without its trailer: run interrupted after {held} records")
    elif count != held:
        problems.append(f"its trailer counts {count} records, the file holds {held}")
    raw = body[:held * size]
    records = np.ndarray((held,), dtype=_records_dtype(layout), buffer=raw) if held else np.zeros(0, _records_dtype(layout))
    if held:
        flags_col = layout.get("flags_column")
        end_flag = int(layout.get("end_of_run_flag", 0))
        if flags_col and end_flag and not int(records[flags_col][-1]) & end_flag and count is not None:
            problems.append("its last record is not the end-of-run record")
    if verify and held:
        crc_at = int(layout["crc"]["offset"])
        rows = np.asarray(raw).reshape(held, size)
        stored = rows[:, crc_at:crc_at + 4].copy().view("<u4").ravel()
        # Two zlib calls per record over the mapped bytes (C, no copy); the records'
        # fields are never parsed in Python.
        mv = memoryview(np.ascontiguousarray(raw)).cast("B")
        bad = [i for i in range(held)
               if zlib.crc32(mv[i * size + crc_at + 4:(i + 1) * size],
                             zlib.crc32(mv[i * size:i * size + crc_at])) != stored[i]]
        if bad:
            shown = ", ".join(map(str, bad[:10])) + (", ..." if len(bad) > 10 else "")
            raise LogError(f"{path}: {len(bad)} damaged records (CRC mismatch), at positions {shown}")
    for p in problems:
        warnings.warn(f"{path}: {p}", stacklevel=3)
    return records, layout, header


def _unframe(path: Path, body, layout: Dict[str, Any]):
    """An OILSLOG7 body's records, unpacked from their zstd frames, as one uint8 array;
    the trailer's record count (None without a trailer) and what to warn about. The
    frames and their packing are as the layout's ``frames`` describes them."""
    import zstandard  # the `data` extra installs it

    frames = layout["frames"]
    if frames.get("codec") != "zstd":
        raise LogError(f"{path}: frames of codec {frames.get('codec')!r}, this reader reads zstd")
    hsize, most = int(frames["header_size"]), int(frames["max_records"])
    size = int(layout["record_size"])
    trailer = layout["trailer"]
    tsize, tmagic = int(trailer["size"]), trailer["magic"].encode()
    body = bytes(body)
    unzip = zstandard.ZstdDecompressor()
    parts, at, position = [], 0, 0
    while len(body) - at >= hsize:
        n, packed_len, crc = struct.unpack_from("<III", body, at)
        if crc != zlib.crc32(body[at:at + 8]) or not 0 < n <= most or at + hsize + packed_len > len(body):
            break
        try:
            packed = unzip.decompress(body[at + hsize:at + hsize + packed_len], max_output_size=n * size)
        except zstandard.ZstdError:
            packed = b""
        if len(packed) != n * size:
            raise LogError(f"{path}: {n} damaged records (a frame that does not decompress), at positions {position} to {position + n - 1}")
        # Byte planes back to words, then the second differences summed twice (uint64
        # sums wrap, as the writer's differences did).
        d2 = np.ascontiguousarray(np.frombuffer(packed, np.uint8).reshape(size, n).T).view("<u8")
        words = np.cumsum(np.cumsum(d2, axis=0, dtype=np.uint64), axis=0, dtype=np.uint64)
        parts.append(words.astype("<u8", copy=False).tobytes())
        at += hsize + packed_len
        position += n
    rest = body[at:]
    count = None
    if len(rest) == tsize and rest[:8] == tmagic and zlib.crc32(rest[:16]) == int.from_bytes(rest[16:20], "little"):
        count = int.from_bytes(rest[8:16], "little")
    problems = []
    if rest and count is None:
        problems.append(f"{len(rest)} bytes after the last whole frame ignored")
    return np.frombuffer(b"".join(parts), np.uint8), count, problems


def read_records(path: PathLike, layout=None, verify: bool = True) -> np.ndarray:
    """The binary log's records as a numpy structured array: one field per stored CSV
    column (named as the CSV names it), at the offset and with the dtype the layout
    gives (read-only; over the memory-mapped file for an OILSLOG6 log). Derived columns are not in it
    (:func:`read_log_arrays` has them).

    An OILSLOG7 log's records are unpacked from its zstd frames into memory (an OILSLOG6
    log's are mapped from the file). A log without its trailer (an interrupted run) or
    with a torn last frame or record is read with a warning, every whole record kept, as ``oils export`` does; damaged records
    (CRC mismatch) raise :class:`LogError` unless ``verify=False``.
    """
    path = Path(path)
    if _is_mcap(path):
        raise LogError(f"{path}: an MCAP log has no fixed-size records; use read_log or read_log_arrays")
    return _binary_records(path, layout, verify)[0]


def _as_kind(kind: str, values: np.ndarray) -> np.ndarray:
    """A stored column as the values the CSV writes: flags as bool, integers stored as
    f64 (slot fields) as integers; optional integers stay f64 with NaN for absent."""
    if kind == "bool":
        return values != 0
    if kind in ("u32", "u64", "hex") and values.dtype.kind == "f":
        return values.astype(np.uint64)
    if kind == "i64" and values.dtype.kind == "f":
        return values.astype(np.int64)
    if kind in ("opt_u64", "opt_i64") and values.dtype.kind != "f":
        return values.astype(np.float64)
    return np.array(values)


def _derive(layout: Dict[str, Any], out: Dict[str, np.ndarray]) -> None:
    """Computes the derived columns in place, as the description says."""
    site_cache: Dict[str, np.ndarray] = {}
    for c in layout["columns"]:
        d = c.get("derive")
        if d is None:
            continue
        op = d.get("op")
        if op == "scale":
            v = out[d["of"]].astype(np.float64) * float(d["factor"])
        elif op == "bit":
            v = (out[d["of"]].astype(np.uint64) & np.uint64(d["mask"])) != 0
        elif op == "degrees":
            # Rust's to_degrees: x * (180 / pi).
            v = out[d["of"]].astype(np.float64) * (180.0 / np.pi)
        elif op == "site":
            if not site_cache:
                site_cache.update(_site_quantities(layout["site"], out))
            q = site_cache[d["quantity"]]
            v = q[:, d["index"]] if "index" in d else q
        elif op == "nav_error":
            # estimate - truth where the flight software reported an estimate, else NaN.
            valid = (out[d["flags"]].astype(np.uint64) & np.uint64(d["mask"])) != 0
            diff = out[d["estimate"]].astype(np.float64) - out[d["truth"]].astype(np.float64)
            v = np.where(valid, diff, np.nan)
        else:
            raise LogError(f"column {c['name']}: unknown derivation {op!r} (a newer bench; update oils_fsw)")
        out[c["name"]] = _as_kind(c["kind"], v)


def _mat_vec(m: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rows of ``v`` (n x 3) times the 3x3 ``m`` (or n x 3 x 3), summed in nalgebra's order."""
    if m.ndim == 2:
        m = m[None, :, :]
    return np.stack([(m[:, i, 0] * v[:, 0] + m[:, i, 1] * v[:, 1]) + m[:, i, 2] * v[:, 2] for i in range(3)], axis=1)


def _site_quantities(site: Dict[str, Any], cols: Dict[str, np.ndarray]) -> Dict[str, np.ndarray]:
    """``log_fields::Derived::of``, vectorised: speeds relative to the turning surface,
    tilt from the local vertical, position and velocity in the site frame."""
    t = cols[site["t_ns"]].astype(np.float64) * 1e-9
    r = np.stack([cols[n] for n in site["pos_mci_m"]], axis=1).astype(np.float64)
    vin = np.stack([cols[n] for n in site["vel_mci_m_s"]], axis=1).astype(np.float64)
    qw, qx, qy, qz = (cols[n].astype(np.float64) for n in site["q_mci_from_body"])
    rate = float(site["moon_rotation_rate_rad_s"])
    # v - omega x r, omega = (0, 0, rate).
    v = np.stack([vin[:, 0] - (0.0 * r[:, 2] - rate * r[:, 1]),
                  vin[:, 1] - (rate * r[:, 0] - 0.0 * r[:, 2]),
                  vin[:, 2] - (0.0 * r[:, 1] - 0.0 * r[:, 0])], axis=1)
    norm = np.sqrt(r[:, 0] * r[:, 0] + r[:, 1] * r[:, 1] + r[:, 2] * r[:, 2])
    with np.errstate(invalid="ignore", divide="ignore"):
        up = np.where((norm > 1e-9)[:, None], r / norm[:, None], np.array([0.0, 0.0, 1.0]))
    vertical = v[:, 0] * up[:, 0] + v[:, 1] * up[:, 1] + v[:, 2] * up[:, 2]
    h = v - up * vertical[:, None]
    horizontal = np.sqrt(h[:, 0] * h[:, 0] + h[:, 1] * h[:, 1] + h[:, 2] * h[:, 2])
    # The body +Z axis in mci: q normalised and applied to z as nalgebra does (its
    # 4-vector dot product sums (x^2 + z^2) + (y^2 + w^2)): (t w + imag x t) + v, with
    # t = 2 (imag x v).
    qn = np.sqrt((qx * qx + qz * qz) + (qy * qy + qw * qw))
    qw, qx, qy, qz = qw / qn, qx / qn, qy / qn, qz / qn
    tx, ty, tz = (qy - qz * 0.0) * 2.0, (qz * 0.0 - qx) * 2.0, (qx * 0.0 - qy * 0.0) * 2.0
    ax = (tx * qw + (qy * tz - qz * ty)) + 0.0
    ay = (ty * qw + (qz * tx - qx * tz)) + 0.0
    az = (tz * qw + (qx * ty - qy * tx)) + 1.0
    cos_tilt = np.clip(ax * up[:, 0] + ay * up[:, 1] + az * up[:, 2], -1.0, 1.0)
    tilt = np.arccos(cos_tilt) * (180.0 / np.pi)
    # Moon-fixed from inertial at t: a rotation by -rate * t about Z.
    ang = -rate * t
    c, s = np.cos(ang), np.sin(ang)
    z, one = np.zeros_like(c), np.ones_like(c)
    mcmf_from_mci = np.stack([np.stack([c, -s, z], 1), np.stack([s, c, z], 1), np.stack([z, z, one], 1)], 1)
    rot = np.array(site["rot_site_from_mcmf"], dtype=np.float64)
    origin = np.array(site["origin_mcmf_m"], dtype=np.float64)
    pos_site = _mat_vec(rot, _mat_vec(mcmf_from_mci, r) - origin)
    vel_site = _mat_vec(rot, _mat_vec(mcmf_from_mci, v))
    return {
        "vertical_speed_m_s": vertical,
        "horizontal_speed_m_s": horizontal,
        "tilt_deg": tilt,
        "pos_site_m": pos_site,
        "vel_site_m_s": vel_site,
    }


# --- MCAP logs -----------------------------------------------------------------------


def _mcap_reader(f):
    try:
        from mcap.reader import make_reader
    except ImportError:  # pragma: no cover - the [data] extra brings it
        raise ImportError("reading MCAP logs needs the mcap package: pip install './python[data]'") from None
    return make_reader(f)


def _mcap_header(path: Path) -> Dict[str, Any]:
    with open(path, "rb") as f:
        for m in _mcap_reader(f).iter_metadata():
            if m.name == "oils" and "header_json" in m.metadata:
                return json.loads(m.metadata["header_json"])
    raise LogError(f"{path}: no `oils` metadata record (not an oils MCAP log)")


def _topic_of(name: str) -> str:
    """The MCAP topic (after `/oils/`) of a CSV column: its first dotted part; the device
    columns (`imu_t_ns[0]`, no dot) are the `devices` message's."""
    return name.split(".", 1)[0] if "." in name else "devices"


def _path_keys(name: str) -> List[Union[str, int]]:
    """`topic.a.b[2].c` (a CSV column) as the keys into the topic's JSON message:
    ['a', 'b', 2, 'c']; a device column `imu_t_ns[3]` as ['imu_t_ns', 3]."""
    keys: List[Union[str, int]] = []
    parts = name.split(".")[1:] if "." in name else [name]
    for part in parts:
        while "[" in part:
            head, rest = part.split("[", 1)
            if head:
                keys.append(head)
            index, part = rest.split("]", 1)
            keys.append(int(index))
        if part:
            keys.append(part)
    return keys


def _pick(messages: List[Any], keys: List[Union[str, int]]) -> Optional[List[Any]]:
    """The value at `keys` of every message; None when the messages lack it (a file
    from before the field was added: oils-mcap-1 has no truth.faults_active)."""
    values = messages
    try:
        for k in keys:
            values = [v[k] for v in values]
    except (KeyError, IndexError, TypeError):
        return None
    return values


def _mcap_columns(path: Path, layout) -> Dict[str, np.ndarray]:
    header = _mcap_header(path)
    layout = _load_layout(layout, header, path)
    topics = sorted({_topic_of(c["name"]) for c in layout["columns"]})
    raw: Dict[str, List[bytes]] = {t: [] for t in topics}
    with open(path, "rb") as f:
        reader = _mcap_reader(f)
        for _schema, channel, message in reader.iter_messages(topics=[f"/oils/{t}" for t in topics]):
            raw[channel.topic[len("/oils/"):]].append(message.data)
    lengths = {t: len(r) for t, r in raw.items()}
    if len(set(lengths.values())) > 1:
        raise LogError(f"{path}: per-step topics hold different numbers of messages: {lengths}")
    # One JSON parse per topic (the messages joined as one array), then one list
    # comprehension per column and key.
    messages = {t: json.loads(b"[" + b",".join(r) + b"]") for t, r in raw.items()}
    n = next(iter(lengths.values()), 0)
    out: Dict[str, np.ndarray] = {}
    for c in layout["columns"]:
        name, kind = c["name"], c["kind"]
        vals = _pick(messages[_topic_of(name)], _path_keys(name))
        if vals is None:
            vals = [None] * n
        if kind == "hex":
            arr = np.array([0 if v is None else int(v, 16) for v in vals], dtype=np.uint64)
        elif kind == "bool":
            arr = np.array([bool(v) for v in vals], dtype=bool)
        elif kind in ("u32", "u64", "i64"):
            dtype = {"u32": np.uint32, "u64": np.uint64, "i64": np.int64}[kind]
            arr = np.array([0 if v is None else v for v in vals], dtype=dtype)
        else:  # f64 and optional integers: null is NaN
            arr = np.array([np.nan if v is None else v for v in vals], dtype=np.float64)
        out[name] = arr
    return out


# --- the public readers ------------------------------------------------------------


def read_log_arrays(path: PathLike, layout=None, verify: bool = True) -> Dict[str, np.ndarray]:
    """Every column of ``oils export LOG --csv``, in its order, as numpy arrays (a dict).

    Binary logs: the records mapped onto a structured dtype (see :func:`read_records`),
    derived columns computed from them. MCAP logs: the per-step JSON messages, flattened
    to the same names (these messages hold the derived values as the bench computed
    them; echo fields and the Foxglove channels are left out).
    """
    path = Path(path)
    if _is_mcap(path):
        return _mcap_columns(path, layout)
    records, layout, _ = _binary_records(path, layout, verify)
    out: Dict[str, np.ndarray] = {}
    for c in layout["columns"]:
        if "offset" in c:
            out[c["name"]] = _as_kind(c["kind"], records[c["name"]])
    _derive(layout, out)
    return {c["name"]: out[c["name"]] for c in layout["columns"]}


def read_log(path: PathLike, layout=None, verify: bool = True) -> pd.DataFrame:
    """A log (OILSLOG7, OILSLOG6 or MCAP) as a DataFrame with the CSV export's columns, in order.

    Integers are integers (ids ``uint64``), flags ``bool``, floats ``float64``; optional
    figures (timing) are ``float64`` with NaN where a step has none, as in the CSV.
    ``df.attrs["header"]`` is the log's JSON header (the run's whole configuration).
    ``layout``: a layout JSON file (``oils export LOG --layout``) for a log whose header
    has none.
    """
    path = Path(path)
    arrays = read_log_arrays(path, layout, verify)
    df = pd.DataFrame(arrays, copy=False)
    header = _mcap_header(path) if _is_mcap(path) else _read_header(path, _map(path))
    df.attrs["header"] = {k: v for k, v in header.items() if k != "layout"}
    df.attrs["path"] = str(path)
    return df


def read_campaign(directory: PathLike) -> pd.DataFrame:
    """An ``oils mc run`` directory's ``cases.csv`` (one row per case) as a DataFrame;
    ``summary.json`` (statistics, drivers, spec) in ``df.attrs["summary"]`` when present."""
    directory = Path(directory)
    cases = directory / "cases.csv"
    if not cases.is_file():
        raise FileNotFoundError(f"{directory}: no cases.csv (not a merged campaign directory?)")
    # Floats as written (pandas >= 3 parses them exactly by default; older ones need
    # round_trip); a digest of only decimal digits stays a string.
    exact = {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
    text = {
        "outcome": str,
        "outcome_reason": str,
        "faults": str,
        "digest": str,
        "error": str,
    }
    df = pd.read_csv(cases, dtype=text, **exact)
    for c in text:
        if c in df:
            df[c] = df[c].fillna("")
    summary = directory / "summary.json"
    if summary.is_file():
        with open(summary, encoding="utf-8") as f:
            df.attrs["summary"] = json.load(f)
    df.attrs["directory"] = str(directory)
    return df
