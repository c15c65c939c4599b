"""The tacmesh wire protocol (docs/protocol.md in the repository), decoded strictly.

Every message is one frame: a little-endian ``u32`` length (the kind byte and the payload), a
kind byte, and the payload laid out as the document says. A frame that breaks any rule of the
document (an unknown kind or one of the other direction, a payload shorter or longer than its
layout, a string that is not UTF-8 or over its cap, a non-finite vertex, a triangle index out of
range, a latency or residual that is NaN, infinite or negative, a length over the cap) raises
:class:`ProtocolError`: garbage is never skipped silently.

Entry points: :class:`FrameDecoder` (bytes in, messages out) and :func:`encode_subscribe`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import Union

import numpy as np
import numpy.typing as npt

#: Protocol versions this client reads.
SUPPORTED_VERSIONS = frozenset({1})

#: The largest ``length`` a frame may carry (64 MiB).
MAX_FRAME_BYTES = 64 * 1024 * 1024
#: Caps on string fields, bytes of UTF-8.
MAX_NAME_BYTES = 64
MAX_REASON_BYTES = 1024

KIND_HELLO = 0x01
KIND_UPSERT = 0x02
KIND_REMOVE = 0x03
KIND_SNAPSHOT_DONE = 0x04
KIND_STATS = 0x05
KIND_GOODBYE = 0x06
KIND_SUBSCRIBE = 0x80

#: Support planes (tables, floors) have ids from here up; objects have ids below.
FIRST_PLANE_ID = 1 << 32


class ProtocolError(ValueError):
    """A frame that breaks docs/protocol.md; the connection it came on cannot be trusted."""


@dataclass(frozen=True)
class Hello:
    protocol_version: int
    server: str


@dataclass(frozen=True, eq=False)
class Upsert:
    """A new object, or a new mesh of one: vertices in metres, world frame."""

    object_id: int
    version: int
    #: Capture time of the newest depth frame in this mesh, ns on the host's CLOCK_MONOTONIC.
    capture_time_ns: int
    faces_in: int
    faces_out: int
    max_residual_m: float
    #: ``float32 (V, 3)``.
    vertices: npt.NDArray[np.float32]
    #: ``uint32 (T, 3)``, each index below V.
    triangles: npt.NDArray[np.uint32]

    @property
    def is_plane(self) -> bool:
        """Whether this is a support plane (a table or floor), not an object."""
        return self.object_id >= FIRST_PLANE_ID


@dataclass(frozen=True)
class Remove:
    object_id: int


@dataclass(frozen=True)
class SnapshotDone:
    pass


@dataclass(frozen=True)
class StageLatency:
    stage: str
    p50_ms: float
    p99_ms: float


@dataclass(frozen=True)
class Stats:
    frames_in: int
    frames_dropped: int
    invalid_pixels: int
    objects_tracked: int
    meshing_runs: int
    meshes_published: int
    bytes_sent: int
    frame_to_publish_p50_ms: float
    frame_to_publish_p99_ms: float
    stages: list[StageLatency] = field(default_factory=list)


@dataclass(frozen=True)
class Goodbye:
    reason: str


Message = Union[Hello, Upsert, Remove, SnapshotDone, Stats, Goodbye]


def encode_subscribe() -> bytes:
    """The Subscribe frame (version 1: no payload)."""
    return struct.pack("<IB", 1, KIND_SUBSCRIBE)


class _Reader:
    """Takes fields off one payload in order; every read is bounds-checked."""

    def __init__(self, payload: bytes, what: str) -> None:
        self._payload = payload
        self._at = 0
        self._what = what

    def take(self, n: int, field_name: str) -> bytes:
        if self._at + n > len(self._payload):
            raise ProtocolError(
                f"{self._what}: the payload ends inside {field_name} "
                f"({len(self._payload)} bytes)"
            )
        chunk = self._payload[self._at : self._at + n]
        self._at += n
        return chunk

    def u16(self, name: str) -> int:
        value: int = struct.unpack("<H", self.take(2, name))[0]
        return value

    def u32(self, name: str) -> int:
        value: int = struct.unpack("<I", self.take(4, name))[0]
        return value

    def u64(self, name: str) -> int:
        value: int = struct.unpack("<Q", self.take(8, name))[0]
        return value

    def latency(self, name: str) -> float:
        value: float = struct.unpack("<f", self.take(4, name))[0]
        if not np.isfinite(value) or value < 0.0:
            raise ProtocolError(f"{self._what}: {name} is {value}, not a finite value >= 0")
        return value

    def text(self, name: str, cap: int) -> str:
        n = self.u16(name)
        if n > cap:
            raise ProtocolError(f"{self._what}: {name} is {n} bytes, over its cap of {cap}")
        raw = self.take(n, name)
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as error:
            raise ProtocolError(f"{self._what}: {name} is not UTF-8 ({error})") from None

    def end(self) -> None:
        left = len(self._payload) - self._at
        if left:
            raise ProtocolError(f"{self._what}: {left} bytes after the last field")


def decode_payload(kind: int, payload: bytes) -> Message:
    """One message from its kind and payload (the frame without its length and kind)."""
    if kind == KIND_HELLO:
        r = _Reader(payload, "Hello")
        hello = Hello(r.u16("protocol_version"), r.text("server", MAX_NAME_BYTES))
        r.end()
        return hello
    if kind == KIND_UPSERT:
        return _upsert(payload)
    if kind == KIND_REMOVE:
        r = _Reader(payload, "Remove")
        remove = Remove(r.u64("object_id"))
        r.end()
        return remove
    if kind == KIND_SNAPSHOT_DONE:
        _Reader(payload, "SnapshotDone").end()
        return SnapshotDone()
    if kind == KIND_STATS:
        return _stats(payload)
    if kind == KIND_GOODBYE:
        r = _Reader(payload, "Goodbye")
        goodbye = Goodbye(r.text("reason", MAX_REASON_BYTES))
        r.end()
        return goodbye
    if kind >= 0x80:
        raise ProtocolError(f"kind 0x{kind:02x} is a client's; a server never sends it")
    raise ProtocolError(f"unknown kind 0x{kind:02x}")


def _upsert(payload: bytes) -> Upsert:
    r = _Reader(payload, "Upsert")
    object_id = r.u64("object_id")
    version = r.u64("version")
    capture_time_ns = r.u64("capture_time_ns")
    faces_in = r.u32("faces_in")
    faces_out = r.u32("faces_out")
    max_residual_m = r.latency("max_residual_m")
    v = r.u32("vertex_count")
    t = r.u32("triangle_count")
    # Checked before reading so a huge count cannot make a huge array.
    expected = 44 + 12 * v + 12 * t
    if expected != len(payload):
        raise ProtocolError(
            f"Upsert of object {object_id}: {v} vertices and {t} triangles take "
            f"{expected} bytes, the payload has {len(payload)}"
        )
    vertices = np.frombuffer(r.take(12 * v, "vertices"), dtype="<f4").reshape(v, 3)
    triangles = np.frombuffer(r.take(12 * t, "triangles"), dtype="<u4").reshape(t, 3)
    r.end()
    if not np.all(np.isfinite(vertices)):
        raise ProtocolError(f"Upsert of object {object_id}: a vertex is NaN or infinite")
    if t and int(triangles.max()) >= v:
        raise ProtocolError(
            f"Upsert of object {object_id}: triangle index {int(triangles.max())} "
            f"is not below the vertex count {v}"
        )
    return Upsert(
        object_id=object_id,
        version=version,
        capture_time_ns=capture_time_ns,
        faces_in=faces_in,
        faces_out=faces_out,
        max_residual_m=max_residual_m,
        vertices=vertices.astype(np.float32),
        triangles=triangles.astype(np.uint32),
    )


def _stats(payload: bytes) -> Stats:
    r = _Reader(payload, "Stats")
    frames_in = r.u64("frames_in")
    frames_dropped = r.u64("frames_dropped")
    invalid_pixels = r.u64("invalid_pixels")
    objects_tracked = r.u64("objects_tracked")
    meshing_runs = r.u64("meshing_runs")
    meshes_published = r.u64("meshes_published")
    bytes_sent = r.u64("bytes_sent")
    p50 = r.latency("frame_to_publish_p50_ms")
    p99 = r.latency("frame_to_publish_p99_ms")
    stages = [
        StageLatency(r.text("stage", MAX_NAME_BYTES), r.latency("p50_ms"), r.latency("p99_ms"))
        for _ in range(r.u32("stage_count"))
    ]
    r.end()
    return Stats(
        frames_in=frames_in,
        frames_dropped=frames_dropped,
        invalid_pixels=invalid_pixels,
        objects_tracked=objects_tracked,
        meshing_runs=meshing_runs,
        meshes_published=meshes_published,
        bytes_sent=bytes_sent,
        frame_to_publish_p50_ms=p50,
        frame_to_publish_p99_ms=p99,
        stages=stages,
    )


class FrameDecoder:
    """Bytes from the socket in (:meth:`push`), whole messages out (:meth:`next_message`)."""

    def __init__(self) -> None:
        self._buffer = bytearray()

    def push(self, data: bytes) -> None:
        self._buffer += data

    @property
    def buffered(self) -> int:
        """Bytes received and not yet taken out as a message."""
        return len(self._buffer)

    def next_message(self) -> Message | None:
        """The next whole message, or None until more bytes arrive."""
        if len(self._buffer) < 4:
            return None
        (length,) = struct.unpack_from("<I", self._buffer)
        if length == 0:
            raise ProtocolError("a frame of length 0 (it has no kind)")
        if length > MAX_FRAME_BYTES:
            raise ProtocolError(f"a frame of {length} bytes, over the cap of {MAX_FRAME_BYTES}")
        if len(self._buffer) < 4 + length:
            return None
        kind = self._buffer[4]
        payload = bytes(self._buffer[5 : 4 + length])
        del self._buffer[: 4 + length]
        return decode_payload(kind, payload)
