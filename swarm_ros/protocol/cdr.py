"""``sensor_msgs/PointCloud2`` in its serialized form (CDR, little-endian), written and read with numpy alone;
``nav_msgs/OccupancyGrid``, ``rosgraph_msgs/Clock`` and ``std_msgs/Int64MultiArray``, the graph's other per-tick
messages, written.

The graph's hot path publishes and takes clouds as serialized bytes: building a PointCloud2
message object costs a copy of its data through a Python ``array('B')`` and another through
rclpy's serializer, per message and per reader. Here a cloud is one ``bytes`` (its rows copied
in once), and a received one is read as a view whose ``data`` is a slice of the buffer.

The bytes are what ``rclpy.serialization.serialize_message`` gives for the same message, but
for the alignment padding, which is zeros here and whatever was in memory there; each reads
the other's (test/test_cdr.py), so the topics stay standard PointCloud2 for every other
reader: ``swarm-ros topics``, the bag, rosbags, RViz.

:func:`decode_cloud` takes bytes from anybody: every length and offset is checked against
the buffer before use, and what does not parse raises ``Rejected("malformed CDR")``.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

from swarm_ros.core.errors import Rejected
from swarm_ros.protocol.rows import FRAME_ID, TICK_SECONDS, is_tag, point_fields

ENCAPSULATION = b"\x00\x01\x00\x00"  #: CDR, little-endian (the only encoding read here)
MAX_FIELDS = 24  #: a cloud with more point fields is not one of the graph's (a rubenstein row has 18 and the tag)
MAX_STRING = 256  #: nor one with a longer frame id or field name

_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")


def _string(text: str) -> bytes:
    raw = text.encode() + b"\x00"
    return _U32.pack(len(raw)) + raw


def _pad(n: int) -> bytes:
    return b"\x00" * (-n % 4)


_PREFIXES: dict[tuple[str, np.dtype, bool], tuple[bytes, int]] = {}
TAG_DATATYPE = 2  #: the tag's point field: UINT8, count 0 (it holds no bytes of any point)


def _field(name: str, offset: int, datatype: int, count: int, at: int) -> bytes:
    """A PointField's bytes, written at ``at`` bytes after the stamp's start (for its alignment)."""
    out = bytearray(_string(name))
    out += _pad(at + len(out))
    out += _U32.pack(offset) + bytes([datatype])
    out += _pad(at + len(out))
    out += _U32.pack(count)
    return bytes(out)


def _fields_block(frame_id: str, dtype: np.dtype, tagged: bool) -> tuple[bytes, int]:
    """The bytes from the frame id to the layout's last point field (they depend on the layout only), and
    where height and width go in them. A tagged cloud counts one more field: the tag, after these."""
    key = (frame_id, dtype, tagged)
    if key not in _PREFIXES:
        out = bytearray(_string(frame_id))
        out += _pad(8 + len(out))  # the stamp's 8 bytes come first
        height_at = len(out)
        out += b"\x00" * 8  # height and width: filled per message
        fields = point_fields(dtype)
        out += _U32.pack(len(fields) + tagged)
        for name, offset, datatype, count in fields:
            out += _field(name, offset, datatype, count, 8 + len(out))
        _PREFIXES[key] = (bytes(out), height_at)
    return _PREFIXES[key]


def encode_cloud(rows: np.ndarray, tick: int, frame_id: str = FRAME_ID, tag: str = "") -> bytes:
    """A serialized PointCloud2 of ``rows`` (a record array of a row type: :mod:`swarm_ros.protocol.rows`), stamped
    with ``tick``: one row of ``rows.size`` points, little-endian, dense. With a ``tag``, one more point
    field after the layout's, named by the tag, holding nothing (:mod:`swarm_ros.protocol.tag`)."""
    return b"".join(cloud_parts(rows, tick, frame_id, tag))


def cloud_parts(
    rows: np.ndarray, tick: int, frame_id: str = FRAME_ID, tag: str = ""
) -> tuple[bytes, memoryview, bytes]:
    """:func:`encode_cloud`'s bytes in three parts, not joined: everything before the points (the tag
    included), the points as a view of ``rows`` (not copied), and the last byte (is_dense). A sealer takes its
    MAC over the parts and joins them once (:meth:`swarm_ros.protocol.tag.Sealer.seal`)."""
    block, height_at = _fields_block(frame_id, rows.dtype, bool(tag))
    block = block[:height_at] + struct.pack("<II", 1, rows.size) + block[height_at + 8 :]
    if tag:
        block += _field(tag, 0, TAG_DATATYPE, 0, 8 + len(block))
    block += b"\x00"  # is_bigendian
    block += _pad(8 + len(block))
    step = rows.dtype.itemsize
    data = np.ascontiguousarray(rows).view(np.uint8).data.cast("B")
    head = b"".join(
        (
            ENCAPSULATION,
            _STAMP.pack(int(tick) * TICK_SECONDS, 0),
            block,
            struct.pack("<III", step, step * rows.size, data.nbytes),
        )
    )
    return head, data, b"\x01"


def encode_ints(values: np.ndarray, label: str, tag: str = "") -> bytes:
    """A serialized ``std_msgs/Int64MultiArray`` of ``values`` (as int64): one layout dimension ``label`` (size and
    stride the number of values), data_offset 0; with a ``tag``, one more dimension named by it (size and stride
    1), where :func:`swarm_ros.ros.auth.put_tag` puts it. A few microseconds, where building the message object and
    serializing it costs rclpy some 60 (a monitor sends two a tick)."""
    data = np.ascontiguousarray(values, dtype="<i8")
    dims = ((label, data.size), (tag, 1)) if tag else ((label, data.size),)
    out = bytearray(_U32.pack(len(dims)))
    for name, size in dims:
        out += _string(name)
        out += _pad(len(out))
        out += struct.pack("<II", size, size)
    out += struct.pack("<II", 0, data.size)  # data_offset, then the values' count
    out += bytes(-len(out) % 8)  # int64s are 8-aligned (none or not, as Fast CDR writes it)
    return ENCAPSULATION + bytes(out) + data.tobytes()


def encode_clock(tick: int) -> bytes:
    """A serialized ``rosgraph_msgs/Clock`` at ``tick``."""
    return ENCAPSULATION + _STAMP.pack(int(tick) * TICK_SECONDS, 0)


def encode_grid(
    cells: np.ndarray, resolution: float, origin: tuple[float, float], tick: int, frame_id: str = FRAME_ID
) -> bytes:
    """A serialized ``nav_msgs/OccupancyGrid`` of ``cells`` (int8, ``[row, column]``, row 0 the bottom), stamped and
    loaded at ``tick``, its cell (0, 0)'s corner at ``origin`` (x, y), unrotated."""
    height, width = cells.shape
    stamp = _STAMP.pack(int(tick) * TICK_SECONDS, 0)
    out = bytearray(stamp + _string(frame_id))
    out += _pad(len(out))
    out += stamp + struct.pack("<fII", resolution, width, height)
    out += bytes(-len(out) % 8)  # the origin's float64s
    out += struct.pack("<7d", *origin, 0.0, 0.0, 0.0, 0.0, 1.0)
    data = np.ascontiguousarray(cells, dtype=np.int8).tobytes()
    out += _U32.pack(len(data))
    return ENCAPSULATION + bytes(out) + data


@dataclass(frozen=True)
class Stamp:
    sec: int
    nanosec: int


@dataclass(frozen=True)
class Header:
    stamp: Stamp
    frame_id: str


@dataclass(frozen=True)
class Field:
    name: str
    offset: int
    datatype: int
    count: int


@dataclass(frozen=True)
class Cloud:
    """A received PointCloud2, read in place: the attributes of the message, ``data`` a view of the buffer."""

    header: Header
    height: int
    width: int
    fields: tuple[Field, ...]
    is_bigendian: bool
    point_step: int
    row_step: int
    data: memoryview
    is_dense: bool
    tag: str = ""  #: the tag's text, if the last point field was one (it is not in ``fields``)


class _Reader:
    def __init__(self, buf: bytes) -> None:
        self.buf, self.at = memoryview(buf), 4  # after the encapsulation header

    def need(self, n: int) -> None:
        if n < 0 or self.at + n > len(self.buf):
            raise Rejected("malformed CDR", f"{n} bytes wanted at {self.at - 4} of {len(self.buf) - 4}")

    def align(self, k: int) -> None:
        self.at += -(self.at - 4) % k

    def u32(self) -> int:
        self.align(4)
        self.need(4)
        value = _U32.unpack_from(self.buf, self.at)[0]
        self.at += 4
        return value

    def u8(self) -> int:
        self.need(1)
        value = self.buf[self.at]
        self.at += 1
        return value

    def string(self) -> str:
        n = self.u32()
        if not 1 <= n <= MAX_STRING:
            raise Rejected("malformed CDR", f"a string of {n} bytes")
        self.need(n)
        raw = bytes(self.buf[self.at : self.at + n])
        self.at += n
        if raw[-1] != 0:
            raise Rejected("malformed CDR", "a string without its terminating zero")
        try:
            return raw[:-1].decode()
        except UnicodeDecodeError:
            raise Rejected("malformed CDR", "a string that is not UTF-8") from None


def decode_cloud(buf: bytes) -> Cloud:
    """The PointCloud2 serialized in ``buf`` (as a reader takes it: DDS may pad it to a multiple of 4).

    Raises:
        Rejected: not little-endian CDR, or a length or offset that does not fit the buffer.
    """
    if len(buf) < 4 or bytes(buf[:4]) != ENCAPSULATION:
        raise Rejected("malformed CDR", "not little-endian CDR")
    r = _Reader(buf)
    r.need(8)
    sec, nanosec = _STAMP.unpack_from(r.buf, r.at)
    r.at += 8
    frame_id = r.string()
    height, width = r.u32(), r.u32()
    known, more = _known_layout(r) if frame_id == FRAME_ID else ((), None)
    if more is None:
        more = r.u32()
        if more > MAX_FIELDS:
            raise Rejected("malformed CDR", f"{more} point fields")
    fields = list(known)
    for _ in range(more):
        name = r.string()
        offset = r.u32()
        datatype = r.u8()
        fields.append(Field(name, offset, datatype, r.u32()))
    tag = fields.pop().name if fields and is_tag(fields[-1].name) else ""
    bigendian = r.u8()
    point_step, row_step, size = r.u32(), r.u32(), r.u32()
    r.need(size)
    data = r.buf[r.at : r.at + size]
    r.at += size
    dense = r.u8()
    if bigendian > 1 or dense > 1 or any(b for b in bytes(r.buf[r.at :])):
        raise Rejected("malformed CDR", "a bool out of range or bytes after the message")
    return Cloud(
        Header(Stamp(sec, nanosec), frame_id),
        height,
        width,
        tuple(fields),
        bool(bigendian),
        point_step,
        row_step,
        data,
        bool(dense),
        tag,
    )


_LAYOUTS: list[tuple[bytes, tuple[Field, ...], int]] = []
_ROW_TYPES: list[np.dtype] = []  #: the row layouts the modules that define them made known (register_row_types)


def register_row_types(*dtypes: np.dtype) -> None:
    """Make the decoder know these row layouts (an algorithm's rows, when their module is imported: a node of one
    algorithm never imports another's)."""
    _ROW_TYPES.extend(d for d in dtypes if d not in _ROW_TYPES)
    _LAYOUTS.clear()


def _known_layout(r: _Reader) -> tuple[tuple[Field, ...], int | None]:
    """(fields, how many more to read) if the bytes at ``r`` are the field count and fields that
    :func:`encode_cloud` writes for one of the graph's own row layouts (then ``r`` moves past them);
    else ((), None), and ``r`` stays."""
    if not _LAYOUTS:
        for dtype in _ROW_TYPES:
            for tagged in (True, False):
                block, height_at = _fields_block(FRAME_ID, dtype, tagged)
                _LAYOUTS.append((block[height_at + 8 :], tuple(Field(*f) for f in point_fields(dtype)), int(tagged)))
    for block, fields, more in _LAYOUTS:
        if r.buf[r.at : r.at + len(block)] == block:
            r.at += len(block)
            return fields, more
    return (), None
