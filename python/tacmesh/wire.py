"""The tacmesh wire protocol, version 4 (docs/protocol.md in the repository): every message
decoded strictly and encoded.

Every message is one frame: a little-endian ``u32`` length (the kind byte and the payload), a
kind byte, and the payload laid out as the document says. A frame that breaks any rule of the
document raises a :class:`WireError` subclass naming what is wrong (:class:`UnknownKind`,
:class:`WrongDirection`, :class:`Truncated`, :class:`TrailingBytes`, :class:`InvalidText`,
:class:`TextTooLong`, :class:`CountOverCap`, :class:`InvalidFlags`, :class:`InvalidEnum`,
:class:`NonFinite`, :class:`NotUnitQuaternion`, :class:`TimesOutOfOrder`,
:class:`IndexOutOfRange`, :class:`BadBox`, :class:`InvalidNumber`, :class:`BadBody`,
:class:`BadHull`, :class:`FrameTooLarge`, :class:`EmptyFrame`): garbage is never skipped silently.

Entry points: :class:`FrameDecoder` (bytes in, messages out), :func:`encode` (a message to its
frame), :func:`encode_subscribe`, and the message dataclasses. Geometry is numpy: vertices
``float32 (V, 3)`` in the object's frame, triangles ``uint32 (T, 3)`` (``uint8`` in a Body's
hulls, as on the wire); a Body's :class:`Primitive` is plain numbers.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass, field, replace
from typing import Any, Literal, NamedTuple, Union

import numpy as np
import numpy.typing as npt

#: The protocol version this module speaks.
PROTOCOL_VERSION = 4
#: Protocol versions this client reads (a Hello of another version is refused).
SUPPORTED_VERSIONS = frozenset({PROTOCOL_VERSION})

#: The largest ``length`` a frame may carry (64 MiB).
MAX_FRAME_BYTES = 64 * 1024 * 1024
#: Caps on string fields, bytes of UTF-8.
MAX_NAME_BYTES = 64
MAX_REASON_BYTES = 1024
#: The most object ids a Subscribe may list.
MAX_SUBSCRIBE_IDS = 1024
#: The lowest non-zero ``max_rate_hz`` (one update every 100 s) and the highest.
MIN_RATE_HZ = 0.01
MAX_RATE_HZ = 10_000.0
#: How far from 1 a rotation quaternion's norm may be.
UNIT_QUATERNION_TOLERANCE = 1e-3
#: The steps of a compact encoding's quantisation, per axis.
COMPACT_STEPS = 65535
#: The most vertices a compact Shape may have and still carry u16 indices.
COMPACT_U16_VERTICES = 65536
#: The most convex hulls a Body may carry.
MAX_HULLS = 16
#: The fewest and the most vertices a hull may have.
MIN_HULL_VERTICES = 4
MAX_HULL_VERTICES = 255

KIND_HELLO = 0x01
KIND_REMOVE = 0x03
KIND_SNAPSHOT_DONE = 0x04
KIND_GOODBYE = 0x06
KIND_SESSION = 0x07
KIND_SHAPE = 0x08
KIND_POSE = 0x09
KIND_STATS = 0x0A
KIND_BODY = 0x0C
KIND_SUBSCRIBE_V1 = 0x80
KIND_SUBSCRIBE = 0x81
#: Kind numbers a later version retired, with what they were; never valid again.
RETIRED_KINDS = {
    0x02: "version 1's Upsert",
    0x05: "version 1's Stats",
    0x0B: "version 3's Body",
}

#: Support planes (tables, floors) have ids from here up; objects have ids from 1 below it.
FIRST_SUPPORT_ID = 1 << 32
#: The name version 1 of this package used for :data:`FIRST_SUPPORT_ID`.
FIRST_PLANE_ID = FIRST_SUPPORT_ID

#: Shape flags.
SHAPE_CLOSED = 0x01
SHAPE_SUPPORT = 0x02
#: The object's frame is not its earlier shapes' frame: a Body of an earlier version no longer fits.
SHAPE_NEW_FRAME = 0x04
#: Every Shape flag this version defines.
SHAPE_FLAGS = SHAPE_CLOSED | SHAPE_SUPPORT | SHAPE_NEW_FRAME
#: Subscribe flags.
SUBSCRIBE_RESEND = 0x01
SUBSCRIBE_EXTRAPOLATE = 0x02

#: Fixed sizes, bytes of payload.
POSE_BYTES = 92
SHAPE_HEADER_BYTES = 130
BODY_HEADER_BYTES = 115
#: A Body's primitive block: the kind byte, three sizes, the rotation, the centre, the residual.
PRIMITIVE_BYTES = 1 + 3 * 4 + 4 * 4 + 3 * 4 + 4
HULL_HEADER_BYTES = 3
COMPACT_BOX_BYTES = 24
SUBSCRIBE_HEADER_BYTES = 11
SESSION_HEADER_BYTES = 16
STATS_HEADER_BYTES = 168
STAGE_FIXED_BYTES = 2 + 4 + 4


# ---------------------------------------------------------------------------------------------
# Errors


class WireError(ValueError):
    """A frame that breaks docs/protocol.md; the connection it came on cannot be trusted.

    Each rule of the document's "A receiver refuses…" list has its own subclass. The encoder
    raises the same errors for a message a receiver would refuse.
    """


#: The name version 1 of this package used for :class:`WireError`.
ProtocolError = WireError


class FrameTooLarge(WireError):
    """A length prefix over :data:`MAX_FRAME_BYTES`."""


class EmptyFrame(WireError):
    """A length prefix of 0: the frame has no kind."""


class UnknownKind(WireError):
    """A kind this version does not define (kind 0 and the retired ones included)."""


class WrongDirection(WireError):
    """A kind the other side sends: a client kind from a server, or the reverse."""


class Truncated(WireError):
    """A payload shorter than its layout says."""


class TrailingBytes(WireError):
    """A payload longer than its layout says."""


class InvalidText(WireError):
    """A string that is not UTF-8."""


class TextTooLong(WireError):
    """A string over its cap."""


class CountOverCap(WireError):
    """A count over its cap (a Subscribe's ids, a Body's hulls)."""


class InvalidFlags(WireError):
    """A flag bit this document does not define (or a ``kinds`` of neither objects nor
    support planes)."""


class InvalidEnum(WireError):
    """An enumeration value this document does not define (an encoding other than 0 or 1, a
    Body's solid other than 0 to 4, a primitive kind other than 0 to 4)."""


class NonFinite(WireError):
    """A vertex coordinate, pose, velocity or box that is NaN or infinite (a Body's centre of
    mass, inertia and primitive's rotation and centre included)."""


class NotUnitQuaternion(WireError):
    """A rotation whose norm is more than 10⁻³ from 1."""


class TimesOutOfOrder(WireError):
    """A last-seen time before the pose time."""


class IndexOutOfRange(WireError):
    """A triangle index not below the frame's vertex count."""


class BadBox(WireError):
    """A compact box whose maximum is below its minimum (or one the encoder cannot hold)."""


class InvalidNumber(WireError):
    """A residual, rate, latency or margin that is NaN, infinite or negative."""


class BadBody(WireError):
    """A Body whose volume is not finite and positive, whose solid breaks its kind's rule (a
    mesh on a ``shape`` or ``primitive`` solid, a primitive on another solid, none on a
    ``primitive`` one), whose primitive's sizes are not finite and positive (the sizes its kind
    does not use exactly 0), or whose absent primitive (kind 0) has a byte that is not 0."""


class BadHull(WireError):
    """A hull of a Body with fewer than 4 or more than 255 vertices, or more triangles than
    twice its vertices."""


class StreamEndedInFrame(WireError):
    """The byte stream ended inside a frame (a client dropped for not reading sees this)."""


# ---------------------------------------------------------------------------------------------
# Messages


class Encoding(enum.IntEnum):
    """How a Shape's vertices and triangles are laid out."""

    FULL = 0
    COMPACT = 1


class Kinds(enum.IntFlag):
    """What a client is sent: bit 0 objects, bit 1 support planes, bit 2 the objects' bodies.
    At least one of objects and support planes."""

    OBJECTS = 1
    SUPPORTS = 2
    BODIES = 4
    ALL = 7


class BodySolid(enum.IntEnum):
    """What a Body is: the solid its mass properties and hulls are of, best first. The first
    three are the object completed where it was not seen; the last two are conservative
    fallbacks that take in all the space behind what was seen (:attr:`is_fallback`)."""

    #: The Shape is closed and is its own solid; the Body carries no mesh.
    SHAPE = 0
    #: The object is a primitive (:attr:`Body.primitive`); the Body carries no mesh.
    PRIMITIVE = 1
    #: The seen shell closed by the object's symmetry (a mirror plane or an axis of revolution),
    #: bounded by its support and by space the sensor saw as free.
    COMPLETED = 2
    #: Fallback: the open shell swept away from the sensor along its rays to the support plane.
    SHADOW_VOLUME = 3
    #: Fallback: the open shell swept straight down onto the support plane (no sensor position
    #: known).
    EXTRUSION = 4

    @property
    def carries_mesh(self) -> bool:
        """Whether the Body carries the solid's surface as a mesh (the shape and a primitive
        need none)."""
        return self not in (BodySolid.SHAPE, BodySolid.PRIMITIVE)

    @property
    def is_fallback(self) -> bool:
        """Whether the solid is a conservative fallback (the shadow volume or the extrusion):
        larger than the object by the unseen space behind it, and so are its mass properties.
        Treat the object's mass as uncertain."""
        return self in (BodySolid.SHADOW_VOLUME, BodySolid.EXTRUSION)

    @property
    def label(self) -> str:
        """The document's name: ``shape``, ``primitive``, ``completed``, ``shadow volume``,
        ``extrusion``."""
        return self.name.lower().replace("_", " ")


class PrimitiveKind(enum.IntEnum):
    """What a Body's :class:`Primitive` is (0 on the wire is no primitive)."""

    #: ``sizes``: half its sides along its own x, y, z.
    BOX = 1
    #: ``sizes``: radius, half its height (its axis is its own z), 0.
    CYLINDER = 2
    #: ``sizes``: radius, 0, 0.
    SPHERE = 3
    #: ``sizes``: radius, half the length of its axis segment (its own z; the whole capsule is
    #: ``2 · (half + radius)`` long), 0.
    CAPSULE = 4

    @property
    def used_sizes(self) -> int:
        """How many of the three ``sizes`` the kind uses; the rest are 0."""
        return {
            PrimitiveKind.BOX: 3,
            PrimitiveKind.CYLINDER: 2,
            PrimitiveKind.SPHERE: 1,
            PrimitiveKind.CAPSULE: 2,
        }[self]


Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]


@dataclass(frozen=True)
class Hello:
    """Server → client, first on every connection; its layout is the same in every version."""

    protocol_version: int
    #: The daemon's name and version, at most 64 bytes of UTF-8.
    server: str


@dataclass(frozen=True)
class Subscribe:
    """Client → server (0x81): what the client wants; also the options a Session reports."""

    encoding: Encoding = Encoding.FULL
    #: Send a fresh snapshot (Session, Shapes, SnapshotDone) under the new options.
    resend: bool = False
    #: At most this many updates a second per object; 0 for no cap.
    max_rate_hz: float = 0.0
    kinds: Kinds = Kinds.ALL
    #: Only these objects (of the kinds asked for); empty for all. At most 1,024.
    object_ids: tuple[int, ...] = ()
    #: The client extrapolates each pose by its velocity (:meth:`Pose.extrapolated`): the daemon
    #: sends a Pose only when that would be off by more than 2 mm or 1°, or once a second.
    extrapolate: bool = False

    def admits(self, object_id: int) -> bool:
        """Whether an object of this id passes the filter (its kind, and the ids if any)."""
        kind = Kinds.SUPPORTS if object_id >= FIRST_SUPPORT_ID else Kinds.OBJECTS
        if not self.kinds & kind:
            return False
        return not self.object_ids or object_id in self.object_ids

    @property
    def bodies(self) -> bool:
        """Whether the client asks for Body messages (bit 2 of ``kinds``)."""
        return bool(self.kinds & Kinds.BODIES)

    def admits_body(self, object_id: int) -> bool:
        """Whether a Body of this object is sent: bodies asked for, and the object admitted."""
        return self.bodies and self.admits(object_id)

    def same_options(self, other: Subscribe) -> bool:
        """Whether the two ask for the same stream: everything but ``resend`` equal (the ids as
        a set, the rate as the f32 on the wire)."""
        return (
            self.encoding == other.encoding
            and self.extrapolate == other.extrapolate
            and _f32(self.max_rate_hz) == _f32(other.max_rate_hz)
            and self.kinds == other.kinds
            and set(self.object_ids) == set(other.object_ids)
        )


#: The options a server follows until a client sends a Subscribe.
DEFAULT_OPTIONS = Subscribe()


@dataclass(frozen=True)
class SubscribeV1:
    """Client → server (0x80): version 1's empty Subscribe. A server of version 2 or later
    refuses it with a Goodbye; this client never sends it (the encoder is here for tests).
    """


@dataclass(frozen=True)
class Session:
    """Server → client: a snapshot begins; the server's clocks now and the options in effect."""

    #: The server's CLOCK_MONOTONIC when the message was written, ns.
    monotonic_ns: int
    #: Its CLOCK_REALTIME (ns since the Unix epoch) at the same moment.
    realtime_ns: int
    options: Subscribe = DEFAULT_OPTIONS

    @property
    def realtime_offset_ns(self) -> int:
        """Add to a monotonic time of the stream for its wall-clock time."""
        return self.realtime_ns - self.monotonic_ns


@dataclass(frozen=True)
class Pose:
    """Server → client (0x09), and the start of every Shape: where an object is.

    ``rotation`` (x, y, z, w) and ``translation`` (metres) are ``world_from_object``.
    """

    object_id: int
    #: The version of the shape this pose places.
    shape_version: int
    #: Capture time of the frame the pose was estimated from, CLOCK_MONOTONIC ns.
    pose_time_ns: int
    #: The same instant on CLOCK_REALTIME.
    pose_time_realtime_ns: int
    #: Capture time of the newest frame that saw the object at this pose, CLOCK_MONOTONIC ns.
    last_seen_ns: int
    rotation: Quat = (0.0, 0.0, 0.0, 1.0)
    translation: Vec3 = (0.0, 0.0, 0.0)
    #: Of the object frame's origin, world frame, m/s.
    linear_velocity: Vec3 = (0.0, 0.0, 0.0)
    #: World frame, rad/s (rotation axis × rate).
    angular_velocity: Vec3 = (0.0, 0.0, 0.0)

    @property
    def is_support(self) -> bool:
        return self.object_id >= FIRST_SUPPORT_ID

    def rotation_matrix(self) -> npt.NDArray[np.float64]:
        """The rotation as a 3 × 3 matrix (of the quaternion normalised)."""
        return quaternion_matrix(self.rotation)

    def world_from_object(self) -> npt.NDArray[np.float64]:
        """The pose as a 4 × 4 homogeneous matrix."""
        matrix = np.eye(4)
        matrix[:3, :3] = self.rotation_matrix()
        matrix[:3, 3] = self.translation
        return matrix

    def to_world(self, points: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Points ``(N, 3)`` of the object frame in the world frame, float32."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        world = p @ self.rotation_matrix().T + np.asarray(self.translation, dtype=np.float64)
        return world.astype(np.float32)

    def extrapolated(self, time_ns: int) -> Pose:
        """This pose carried to ``time_ns`` (``CLOCK_MONOTONIC``) by its velocities: the
        translation along ``linear_velocity``, the rotation turned by ``angular_velocity``
        (about the world axis) over the time since ``pose_time_ns`` (dead reckoning). The times
        are kept as they are."""
        dt = (time_ns - self.pose_time_ns) * 1e-9
        omega = np.asarray(self.angular_velocity, dtype=np.float64) * dt
        angle = float(np.linalg.norm(omega))
        turn = (0.0, 0.0, 0.0, 1.0)
        if angle > 0.0:
            axis = omega / angle
            half = 0.5 * angle
            turn = (*(axis * np.sin(half)).tolist(), float(np.cos(half)))
        tx, ty, tz, tw = turn
        qx, qy, qz, qw = self.rotation
        rotation = (
            tw * qx + tx * qw + ty * qz - tz * qy,
            tw * qy - tx * qz + ty * qw + tz * qx,
            tw * qz + tx * qy - ty * qx + tz * qw,
            tw * qw - tx * qx - ty * qy - tz * qz,
        )
        moved = np.asarray(self.translation) + np.asarray(self.linear_velocity) * dt
        return replace(
            self,
            rotation=rotation,
            translation=(float(moved[0]), float(moved[1]), float(moved[2])),
        )


@dataclass(frozen=True, eq=False)
class Shape:
    """Server → client (0x08): a new object or a new shape of one, with the pose placing it.

    ``vertices`` (``float32 (V, 3)``, metres) are in the object's frame: :meth:`world_vertices`
    places them. A compact Shape is decoded (dequantised) to the same arrays;
    ``max_residual_m`` then includes the quantisation bound.
    """

    pose: Pose
    #: Capture time of the newest frame fused into the shape, CLOCK_MONOTONIC ns.
    shape_time_ns: int
    shape_time_realtime_ns: int
    #: :data:`SHAPE_CLOSED`, :data:`SHAPE_SUPPORT`, :data:`SHAPE_NEW_FRAME`.
    flags: int
    faces_in: int
    faces_out: int
    max_residual_m: float
    #: ``float32 (V, 3)``, object frame.
    vertices: npt.NDArray[np.float32]
    #: ``uint32 (T, 3)``, each index below V.
    triangles: npt.NDArray[np.uint32]
    encoding: Encoding = Encoding.FULL

    @property
    def object_id(self) -> int:
        return self.pose.object_id

    @property
    def shape_version(self) -> int:
        return self.pose.shape_version

    @property
    def is_closed(self) -> bool:
        return bool(self.flags & SHAPE_CLOSED)

    @property
    def is_support(self) -> bool:
        """A support plane (a table or floor), by its flag."""
        return bool(self.flags & SHAPE_SUPPORT)

    @property
    def is_new_frame(self) -> bool:
        """The object's frame is not the one its earlier shapes were in: a Body of an earlier
        version no longer fits."""
        return bool(self.flags & SHAPE_NEW_FRAME)

    def world_vertices(self) -> npt.NDArray[np.float32]:
        """The vertices mapped into the world by the shape's own pose."""
        return self.pose.to_world(self.vertices)


class Hull(NamedTuple):
    """One convex part of a Body, in the object's frame."""

    #: ``float32 (n, 3)``, 4 ≤ n ≤ 255, metres.
    vertices: npt.NDArray[np.float32]
    #: ``(t, 3)`` indices below n (``uint8`` as decoded; any unsigned integers to encode),
    #: t ≤ 2·n, counter-clockwise seen from outside.
    triangles: npt.NDArray[np.unsignedinteger[Any]]


def inertia_matrix(
    ixx: float, iyy: float, izz: float, ixy: float, ixz: float, iyz: float
) -> npt.NDArray[np.float32]:
    """The symmetric ``float32 (3, 3)`` inertia tensor of the six entries in the wire's order
    (MuJoCo's ``fullinertia``): ``ixy`` is the tensor's entry, ``−∫ x y dV``."""
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]], np.float32)


def inertia_terms(
    inertia: npt.ArrayLike,
) -> tuple[float, float, float, float, float, float]:
    """The six entries of a ``(3, 3)`` inertia tensor in the wire's order: ``ixx``, ``iyy``,
    ``izz``, ``ixy``, ``ixz``, ``iyz`` (its diagonal, then its upper triangle)."""
    m = np.asarray(inertia, dtype=np.float64).reshape(3, 3)
    return (
        float(m[0, 0]),
        float(m[1, 1]),
        float(m[2, 2]),
        float(m[0, 1]),
        float(m[0, 2]),
        float(m[1, 2]),
    )


@dataclass(frozen=True)
class Primitive:
    """The primitive a Body's object is (:attr:`BodySolid.PRIMITIVE`), in the object's frame:
    what an engine collides as its native geom (MuJoCo's ``size`` is
    ``sizes[: kind.used_sizes]``, its ``pos`` the ``centre``, its ``quat`` the ``rotation`` as
    w, x, y, z)."""

    kind: PrimitiveKind
    #: Metres, by ``kind``: a box's half sides along its own x, y, z; a cylinder's or a
    #: capsule's radius and half height (of its axis segment, for a capsule), 0; a sphere's
    #: radius, 0, 0. The sizes the kind uses are finite and > 0, the rest exactly 0.
    sizes: Vec3
    #: From the primitive's frame to the object's: a unit quaternion x, y, z, w.
    rotation: Quat = (0.0, 0.0, 0.0, 1.0)
    #: The primitive's centre, object frame, metres.
    centre: Vec3 = (0.0, 0.0, 0.0)
    #: The 95th percentile of the seen surface's distances from the primitive, metres.
    residual_m: float = 0.0

    def rotation_matrix(self) -> npt.NDArray[np.float64]:
        """The rotation as a 3 × 3 matrix (of the quaternion normalised)."""
        return quaternion_matrix(self.rotation)

    def to_object(self, points: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """Points ``(N, 3)`` of the primitive's frame in the object's frame, float32."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        placed = p @ self.rotation_matrix().T + np.asarray(self.centre, dtype=np.float64)
        return placed.astype(np.float32)


def _empty_vertices() -> npt.NDArray[np.float32]:
    return np.zeros((0, 3), np.float32)


def _empty_triangles() -> npt.NDArray[np.uint32]:
    return np.zeros((0, 3), np.uint32)


@dataclass(frozen=True, eq=False)
class Body:
    """Server → client (0x0C): an object's collision body, made from the Shape whose version it
    names: the solid a physics engine gives mass to (the object completed where the sensor did
    not see it, or a flagged fallback: ``solid``), the convex hulls covering it and its mass
    properties at a density of 1 kg/m³. Everything is in the object's frame (that shape's),
    placed by the object's current pose.

    A :attr:`BodySolid.SHAPE` solid is the closed Shape itself and a
    :attr:`BodySolid.PRIMITIVE` one is ``primitive``: for both ``vertices`` and ``triangles``
    are empty. ``primitive`` is there exactly when ``solid`` is ``PRIMITIVE``. A compact Body's
    mesh is decoded (dequantised) to the same arrays; the hulls are always full precision.
    """

    object_id: int
    #: The version of the shape the body was made from.
    shape_version: int
    solid: BodySolid
    #: How far the solid was grown outward from the seen surface, metres (0 for ``SHAPE`` and
    #: ``PRIMITIVE``).
    margin_m: float
    #: The solid's volume, m³, > 0: its mass in kg per kg/m³ of density.
    volume_m3: float
    #: ``float32 (3,)``: the solid's centre of mass, object frame, metres.
    centre_of_mass: npt.NDArray[np.float32]
    #: ``float32 (3, 3)``, symmetric: the inertia tensor about the centre of mass along the
    #: object frame's axes, kg·m² per kg/m³ (:func:`inertia_matrix` of the wire's six).
    inertia: npt.NDArray[np.float32]
    #: The primitive the object is, for a ``PRIMITIVE`` solid; None for every other.
    primitive: Primitive | None = None
    #: ``float32 (V, 3)``: the solid's vertices, object frame (none for ``SHAPE`` and
    #: ``PRIMITIVE``).
    vertices: npt.NDArray[np.float32] = field(default_factory=_empty_vertices)
    #: ``uint32 (T, 3)``: the solid's triangles, counter-clockwise seen from outside.
    triangles: npt.NDArray[np.uint32] = field(default_factory=_empty_triangles)
    #: At most 16 convex parts whose union covers the solid (for a primitive, its tessellation
    #: grown to contain it).
    hulls: tuple[Hull, ...] = ()
    #: How the solid's vertices and triangles are laid out.
    encoding: Encoding = Encoding.FULL

    @property
    def inertia_terms(self) -> tuple[float, float, float, float, float, float]:
        """``ixx``, ``iyy``, ``izz``, ``ixy``, ``ixz``, ``iyz``, the wire's order."""
        return inertia_terms(self.inertia)


@dataclass(frozen=True)
class Remove:
    """Server → client: the object is gone; forget it."""

    object_id: int


@dataclass(frozen=True)
class SnapshotDone:
    """Server → client: every object of the snapshot has been sent."""


@dataclass(frozen=True)
class StageLatency:
    stage: str
    p50_ms: float
    p99_ms: float


@dataclass(frozen=True)
class Stats:
    """Server → client, about once a second: counters since the daemon's start, latencies."""

    monotonic_ns: int = 0
    realtime_ns: int = 0
    frames_in: int = 0
    frames_dropped: int = 0
    invalid_pixels: int = 0
    malformed_frames: int = 0
    source_errors: int = 0
    source_restarts: int = 0
    objects_tracked: int = 0
    objects_born: int = 0
    objects_removed: int = 0
    meshing_runs: int = 0
    meshing_failures: int = 0
    shapes_published: int = 0
    poses_published: int = 0
    bytes_sent: int = 0
    clients_connected: int = 0
    clients_dropped: int = 0
    clients_refused: int = 0
    latency_window: int = 0
    frame_to_publish_p50_ms: float = 0.0
    frame_to_publish_p99_ms: float = 0.0
    stages: tuple[StageLatency, ...] = field(default_factory=tuple)

    @property
    def realtime_offset_ns(self) -> int:
        """Add to a monotonic time of the stream for its wall-clock time."""
        return self.realtime_ns - self.monotonic_ns


@dataclass(frozen=True)
class Goodbye:
    """Server → client: shutting down, or this client is refused; the connection closes."""

    reason: str


#: What a server sends.
Message = Union[Hello, Session, Shape, Pose, Body, Remove, SnapshotDone, Stats, Goodbye]
#: What a client sends.
ClientMessage = Union[Subscribe, SubscribeV1]
AnyMessage = Union[Message, ClientMessage]

Sender = Literal["server", "client"]

_NAMES = {
    KIND_HELLO: "Hello",
    KIND_REMOVE: "Remove",
    KIND_SNAPSHOT_DONE: "SnapshotDone",
    KIND_GOODBYE: "Goodbye",
    KIND_SESSION: "Session",
    KIND_SHAPE: "Shape",
    KIND_POSE: "Pose",
    KIND_STATS: "Stats",
    KIND_BODY: "Body",
    KIND_SUBSCRIBE_V1: "Subscribe (version 1)",
    KIND_SUBSCRIBE: "Subscribe",
}


# ---------------------------------------------------------------------------------------------
# Geometry helpers


def quaternion_matrix(q: Quat) -> npt.NDArray[np.float64]:
    """The rotation matrix of the unit quaternion ``(x, y, z, w)`` (normalised first)."""
    x, y, z, w = (float(c) for c in q)
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n == 0.0:
        raise ValueError("a zero quaternion is no rotation")
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _length_f32(v: npt.NDArray[np.float32]) -> np.float32:
    x, y, z = (np.float32(c) for c in v)
    return np.float32(np.sqrt(x * x + y * y + z * z, dtype=np.float32))


def quantisation_bound_m(box_min: npt.ArrayLike, box_max: npt.ArrayLike) -> float:
    """The farthest a vertex a receiver decodes is from the vertex the encoder had, in the
    compact encoding of a box: half a step per axis, ``½ · |box_max − box_min| / 65535``, plus
    the receiver's f32 rounding, ``2⁻²⁴ · (3 · |box_max − box_min| + |c|)`` (c per axis the
    larger magnitude of ``box_min`` and ``box_max``). Computed in f32, in the order the
    reference implementation does, so that both write the same residual."""
    lo = np.asarray(box_min, np.float32)
    hi = np.asarray(box_max, np.float32)
    extent = np.maximum(hi - lo, np.float32(0)).astype(np.float32)
    length = _length_f32(extent)
    corner = _length_f32(np.maximum(np.abs(lo), np.abs(hi)).astype(np.float32))
    half_step = np.float32(np.float32(0.5) * length) / np.float32(COMPACT_STEPS)
    rounding = np.float32(2.0**-24) * np.float32(np.float32(3) * length + corner)
    return float(np.float32(half_step + rounding))


def dequantise(
    box_min: npt.NDArray[np.float32],
    box_max: npt.NDArray[np.float32],
    q: npt.NDArray[np.uint16],
) -> npt.NDArray[np.float32]:
    """Compact vertices: ``box_min + q · ((box_max − box_min) / 65535)`` per axis, in float32."""
    step = (box_max.astype(np.float32) - box_min.astype(np.float32)) / np.float32(COMPACT_STEPS)
    out = box_min.astype(np.float32) + q.astype(np.float32) * step.astype(np.float32)
    return out.astype(np.float32).reshape(-1, 3)


def quantise(
    vertices: npt.NDArray[np.float32],
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.uint16]]:
    """The compact encoding's box (the vertices' smallest and largest x, y, z; zeros for an
    empty shape) and each coordinate rounded to the nearest of its 65,536 steps (0 on an axis
    where the box is flat)."""
    v = np.asarray(vertices, dtype=np.float32).reshape(-1, 3)
    if len(v) == 0:
        zeros = np.zeros(3, np.float32)
        return zeros, zeros.copy(), np.zeros((0, 3), np.uint16)
    box_min = v.min(axis=0)
    box_max = v.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        top = dequantise(box_min, box_max, np.full((1, 3), COMPACT_STEPS, np.uint16))
        if not (np.all(np.isfinite(box_max - box_min)) and np.all(np.isfinite(top))):
            raise BadBox(
                f"the shape's vertices span {box_min.tolist()} to {box_max.tolist()}, more "
                "than the compact encoding's box can hold in f32: send it in the full encoding"
            )
    lo = box_min.astype(np.float64)
    extent = box_max.astype(np.float64) - lo
    flat = extent <= 0
    t = (v.astype(np.float64) - lo) / np.where(flat, 1.0, extent)
    # Halves round up (away from zero), as the reference implementation rounds them.
    q = np.clip(np.floor(t * COMPACT_STEPS + 0.5), 0, COMPACT_STEPS)
    return box_min, box_max, np.where(flat, 0.0, q).astype(np.uint16)


def _f32(value: float) -> float:
    result: float = struct.unpack("<f", struct.pack("<f", value))[0]
    return result


# ---------------------------------------------------------------------------------------------
# Decoding


class _Reader:
    """Takes fields off one payload in order; every read is bounds-checked."""

    def __init__(self, payload: bytes, what: str) -> None:
        self._payload = payload
        self._at = 0
        self.what = what

    @property
    def left(self) -> int:
        return len(self._payload) - self._at

    def take(self, n: int, field_name: str) -> bytes:
        if n > self.left:
            raise Truncated(
                f"{self.what} frame ends inside `{field_name}`: it needs {n} bytes, "
                f"{self.left} are left"
            )
        chunk = self._payload[self._at : self._at + n]
        self._at += n
        return chunk

    def u8(self, name: str) -> int:
        return self.take(1, name)[0]

    def u16(self, name: str) -> int:
        value: int = struct.unpack("<H", self.take(2, name))[0]
        return value

    def u32(self, name: str) -> int:
        value: int = struct.unpack("<I", self.take(4, name))[0]
        return value

    def u64(self, name: str) -> int:
        value: int = struct.unpack("<Q", self.take(8, name))[0]
        return value

    def f32(self, name: str) -> float:
        value: float = struct.unpack("<f", self.take(4, name))[0]
        return value

    def vec3(self, name: str) -> Vec3:
        x, y, z = struct.unpack("<3f", self.take(12, name))
        return (x, y, z)

    def quat(self, name: str) -> Quat:
        x, y, z, w = struct.unpack("<4f", self.take(16, name))
        return (x, y, z, w)

    def number(self, name: str) -> float:
        """A residual, rate or latency: finite and ≥ 0."""
        value = self.f32(name)
        _check_number(self.what, name, value)
        return value

    def text(self, name: str, cap: int) -> str:
        n = self.u16(name)
        if n > cap:
            raise TextTooLong(f"`{name}` of {self.what} is {n} bytes, more than the cap of {cap}")
        raw = self.take(n, name)
        try:
            return raw.decode("utf-8")
        except UnicodeDecodeError as error:
            raise InvalidText(
                f"`{name}` of {self.what} is not UTF-8 (valid up to byte {error.start})"
            ) from None

    def end(self) -> None:
        if self.left:
            raise TrailingBytes(f"{self.what} frame has {self.left} bytes after its last field")


def _check_number(what: str, name: str, value: float) -> None:
    if not math.isfinite(value) or value < 0.0:
        raise InvalidNumber(
            f"`{name}` of {what} is {value}, but it must be finite and not negative"
        )


def _check_rate(what: str, value: float) -> None:
    # The bounds as the f32s the daemon compares with (a NaN fails both comparisons).
    if not (value == 0.0 or _f32(MIN_RATE_HZ) <= value <= _f32(MAX_RATE_HZ)):
        raise InvalidNumber(
            f"`max_rate_hz` of {what} is {value}, but it must be 0 (no cap) or from "
            f"{MIN_RATE_HZ} to {MAX_RATE_HZ} updates a second"
        )


def _check_finite(what: str, name: str, values: tuple[float, ...]) -> None:
    for value in values:
        if not math.isfinite(value):
            raise NonFinite(
                f"`{name}` of {what} has a non-finite component ({value}): it must be finite"
            )


def _check_pose(what: str, pose: Pose) -> None:
    _check_finite(what, "rotation", pose.rotation)
    _check_finite(what, "translation", pose.translation)
    _check_finite(what, "linear_velocity", pose.linear_velocity)
    _check_finite(what, "angular_velocity", pose.angular_velocity)
    norm = math.sqrt(sum(c * c for c in pose.rotation))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise NotUnitQuaternion(
            f"the rotation of object {pose.object_id} has norm {norm:.6g}: it must be a unit "
            f"quaternion (norm within {UNIT_QUATERNION_TOLERANCE:g} of 1)"
        )
    if pose.last_seen_ns < pose.pose_time_ns:
        raise TimesOutOfOrder(
            f"object {pose.object_id} was last seen at {pose.last_seen_ns} ns, before its pose "
            f"time {pose.pose_time_ns} ns: last seen is never earlier than the pose time"
        )


def _read_pose(r: _Reader) -> Pose:
    pose = Pose(
        object_id=r.u64("object_id"),
        shape_version=r.u64("shape_version"),
        pose_time_ns=r.u64("pose_time_ns"),
        pose_time_realtime_ns=r.u64("pose_time_realtime_ns"),
        last_seen_ns=r.u64("last_seen_ns"),
        rotation=r.quat("rotation"),
        translation=r.vec3("translation"),
        linear_velocity=r.vec3("linear_velocity"),
        angular_velocity=r.vec3("angular_velocity"),
    )
    _check_pose(r.what, pose)
    return pose


def _check_kinds(what: str, kinds: int) -> None:
    """Subscribe's ``kinds``: only bits 0–2, and at least one of bits 0 and 1."""
    if kinds & ~int(Kinds.ALL):
        raise InvalidFlags(
            f"`kinds` of {what} is 0x{kinds:02x}, but only the bits 0x{int(Kinds.ALL):02x} are "
            "defined"
        )
    if not kinds & int(Kinds.OBJECTS | Kinds.SUPPORTS):
        raise InvalidFlags(
            f"`kinds` of {what} is 0x{kinds:02x}: it must ask for objects (bit 0), support "
            "planes (bit 1) or both; bodies (bit 2) come only with them"
        )


def _read_options(r: _Reader) -> Subscribe:
    encoding = r.u8("encoding")
    if encoding not in (0, 1):
        raise InvalidEnum(
            f"`encoding` of {r.what} is {encoding}, which is not a defined value "
            "(0 full, 1 compact)"
        )
    flags = r.u8("flags")
    defined = SUBSCRIBE_RESEND | SUBSCRIBE_EXTRAPOLATE
    if flags & ~defined:
        raise InvalidFlags(
            f"`flags` of {r.what} is 0x{flags:02x}, but only the bits 0x{defined:02x} are defined"
        )
    max_rate_hz = r.number("max_rate_hz")
    _check_rate(r.what, max_rate_hz)
    kinds = r.u8("kinds")
    _check_kinds(r.what, kinds)
    n = r.u32("id_count")
    if n > MAX_SUBSCRIBE_IDS:
        raise CountOverCap(
            f"{r.what} lists {n} object ids, more than the cap of {MAX_SUBSCRIBE_IDS}"
        )
    ids = struct.unpack(f"<{n}Q", r.take(8 * n, "object_ids"))
    return Subscribe(
        encoding=Encoding(encoding),
        resend=bool(flags & SUBSCRIBE_RESEND),
        extrapolate=bool(flags & SUBSCRIBE_EXTRAPOLATE),
        max_rate_hz=max_rate_hz,
        kinds=Kinds(kinds),
        object_ids=tuple(ids),
    )


def _read_encoding(r: _Reader, what: str) -> Encoding:
    value = r.u8("encoding")
    if value not in (0, 1):
        raise InvalidEnum(
            f"`encoding` of {what} is {value}, which is not a defined value (0 full, 1 compact)"
        )
    return Encoding(value)


def _geometry_bytes(encoding: Encoding, v: int, t: int) -> int:
    """The bytes of a mesh of ``v`` vertices and ``t`` triangles laid out in ``encoding``."""
    if encoding is Encoding.FULL:
        return 12 * v + 12 * t
    return COMPACT_BOX_BYTES + 6 * v + (6 if v <= COMPACT_U16_VERTICES else 12) * t


def _check_indices(what: str, triangles: npt.NDArray[Any], v: int) -> None:
    if len(triangles) and int(triangles.max()) >= v:
        row = int(np.argwhere(triangles >= v)[0][0])
        raise IndexOutOfRange(
            f"triangle {row} of {what} uses vertex {int(triangles[row].max())}, but the mesh "
            f"has only {v} vertices"
        )


def _check_vertices_finite(what: str, vertices: npt.NDArray[np.float32]) -> None:
    bad = ~np.isfinite(vertices)
    if bad.any():
        index = int(np.argwhere(bad)[0][0])
        raise NonFinite(
            f"vertex {index} of {what} has a non-finite coordinate "
            f"({vertices[index].tolist()}): coordinates are finite metres"
        )


def _read_compact_vertices(r: _Reader, what: str, v: int) -> npt.NDArray[np.float32]:
    box_min = np.frombuffer(r.take(12, "box_min"), dtype="<f4")
    box_max = np.frombuffer(r.take(12, "box_max"), dtype="<f4")
    _check_finite(what, "box_min", tuple(box_min.tolist()))
    _check_finite(what, "box_max", tuple(box_max.tolist()))
    for axis, lo, hi in zip("xyz", box_min.tolist(), box_max.tolist()):
        if hi < lo:
            raise BadBox(
                f"the compact box of {what} has its {axis} maximum {hi} below its minimum {lo}"
            )
    q = np.frombuffer(r.take(6 * v, "vertices"), dtype="<u2").reshape(v, 3)
    vertices = dequantise(box_min, box_max, q)
    if not np.all(np.isfinite(vertices)):
        raise NonFinite(f"the compact box of {what} spans more than f32 holds")
    return vertices


def _read_geometry(
    r: _Reader, what: str, encoding: Encoding, v: int, t: int
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    """A mesh's vertices and triangles as Shape lays them out in ``encoding``, each checked
    (finite vertices, a well-formed box, indices below ``v``). The caller has checked that the
    payload holds them."""
    if encoding is Encoding.FULL:
        vertices = np.frombuffer(r.take(12 * v, "vertices"), dtype="<f4").reshape(v, 3)
        _check_vertices_finite(what, vertices)
        index_type = "<u4"
    else:
        vertices = _read_compact_vertices(r, what, v)
        index_type = "<u2" if v <= COMPACT_U16_VERTICES else "<u4"
    width = np.dtype(index_type).itemsize
    triangles = np.frombuffer(r.take(3 * width * t, "triangles"), dtype=index_type)
    triangles = triangles.reshape(t, 3)
    _check_indices(what, triangles, v)
    return vertices.astype(np.float32), triangles.astype(np.uint32)


def _read_shape(r: _Reader) -> Shape:
    pose = _read_pose(r)
    what = f"the Shape of object {pose.object_id}"
    shape_time_ns = r.u64("shape_time_ns")
    shape_time_realtime_ns = r.u64("shape_time_realtime_ns")
    flags = r.u8("flags")
    if flags & ~SHAPE_FLAGS:
        raise InvalidFlags(
            f"`flags` of {what} is 0x{flags:02x}, but only the bits 0x{SHAPE_FLAGS:02x} are "
            "defined"
        )
    faces_in = r.u32("faces_in")
    faces_out = r.u32("faces_out")
    max_residual_m = r.number("max_residual_m")
    encoding = _read_encoding(r, what)
    v = r.u32("vertex_count")
    t = r.u32("triangle_count")
    # The counts are checked against the payload before any array they size is made.
    geometry = _geometry_bytes(encoding, v, t)
    if geometry != r.left:
        error = Truncated if geometry > r.left else TrailingBytes
        raise error(
            f"Shape of object {pose.object_id}: {v} vertices and {t} triangles "
            f"({encoding.name.lower()}) take {SHAPE_HEADER_BYTES + geometry} bytes of payload, "
            f"it has {SHAPE_HEADER_BYTES + r.left}"
        )
    vertices, triangles = _read_geometry(r, what, encoding, v, t)
    return Shape(
        pose=pose,
        shape_time_ns=shape_time_ns,
        shape_time_realtime_ns=shape_time_realtime_ns,
        flags=flags,
        faces_in=faces_in,
        faces_out=faces_out,
        max_residual_m=max_residual_m,
        vertices=vertices,
        triangles=triangles,
        encoding=encoding,
    )


def _read_solid(r: _Reader, what: str) -> BodySolid:
    value = r.u8("solid")
    if value not in {int(solid) for solid in BodySolid}:
        raise InvalidEnum(
            f"`solid` of {what} is {value}, which is not a defined value (0 shape, 1 primitive, "
            "2 completed, 3 shadow volume, 4 extrusion)"
        )
    return BodySolid(value)


def _check_volume(what: str, volume_m3: float) -> None:
    if not (math.isfinite(volume_m3) and volume_m3 > 0.0):
        raise BadBody(f"{what} has volume {volume_m3} m³: it must be finite and positive")


def _check_solid_primitive(what: str, solid: BodySolid, has_primitive: bool) -> None:
    """A primitive is there exactly when the solid is one."""
    if has_primitive and solid is not BodySolid.PRIMITIVE:
        raise BadBody(
            f"{what} has solid {int(solid)} ({solid.label}), yet carries a primitive (only "
            "solid 1, primitive, does)"
        )
    if not has_primitive and solid is BodySolid.PRIMITIVE:
        raise BadBody(f"{what} has solid 1 (primitive), yet carries no primitive (kind 0)")


def _check_solid_mesh(what: str, solid: BodySolid, v: int, t: int) -> None:
    """A solid that is the shape or a primitive carries no mesh."""
    if not solid.carries_mesh and (v or t):
        raise BadBody(
            f"{what} has solid {int(solid)} ({solid.label}), yet carries a mesh of {v} vertices "
            f"and {t} triangles (solids 0, shape, and 1, primitive, carry none)"
        )


def _positive_zero(value: float) -> bool:
    """Whether ``value`` is 0 with all its bits 0 (not −0)."""
    return value == 0.0 and math.copysign(1.0, value) > 0.0


def _check_primitive(what: str, primitive: Primitive) -> None:
    """A primitive's kind is defined, the sizes it uses finite and positive and the others
    exactly 0, its rotation a unit quaternion, its centre finite, its residual finite and not
    negative."""
    if int(primitive.kind) not in {int(kind) for kind in PrimitiveKind}:
        raise InvalidEnum(
            f"the primitive kind of {what} is {int(primitive.kind)}, which is not a defined "
            "value (1 box, 2 cylinder, 3 sphere, 4 capsule)"
        )
    kind = PrimitiveKind(primitive.kind)
    sizes = tuple(float(size) for size in primitive.sizes)
    used = kind.used_sizes
    good = len(sizes) == 3 and all(
        (math.isfinite(size) and size > 0.0) if k < used else _positive_zero(size)
        for k, size in enumerate(sizes)
    )
    if not good:
        raise BadBody(
            f"the {kind.name.lower()} primitive of {what} has sizes {list(sizes)}: the "
            f"{used} its kind uses must be finite and positive, the others 0"
        )
    _check_finite(what, "primitive rotation", primitive.rotation)
    norm = math.sqrt(sum(c * c for c in primitive.rotation))
    if abs(norm - 1.0) > UNIT_QUATERNION_TOLERANCE:
        raise NotUnitQuaternion(
            f"the primitive rotation of {what} has norm {norm:.6g}: it must be a unit "
            f"quaternion (norm within {UNIT_QUATERNION_TOLERANCE:g} of 1)"
        )
    _check_finite(what, "primitive centre", primitive.centre)
    _check_number(what, "primitive residual_m", primitive.residual_m)


def _read_primitive(r: _Reader, what: str) -> Primitive | None:
    """A Body's primitive block: None for kind 0, whose 44 bytes after it must all be 0."""
    kind = r.u8("primitive kind")
    raw = r.take(PRIMITIVE_BYTES - 1, "primitive")
    if kind == 0:
        if any(raw):
            at = next(i for i, byte in enumerate(raw) if byte)
            raise BadBody(
                f"{what} has no primitive (kind 0), yet byte {62 + at} of its payload is "
                f"0x{raw[at]:02x}: the 44 bytes after kind 0 must all be 0"
            )
        return None
    if kind not in {int(k) for k in PrimitiveKind}:
        raise InvalidEnum(
            f"the primitive kind of {what} is {kind}, which is not a defined value (0 none, "
            "1 box, 2 cylinder, 3 sphere, 4 capsule)"
        )
    values = struct.unpack("<3f4f3ff", raw)
    primitive = Primitive(
        kind=PrimitiveKind(kind),
        sizes=(values[0], values[1], values[2]),
        rotation=(values[3], values[4], values[5], values[6]),
        centre=(values[7], values[8], values[9]),
        residual_m=values[10],
    )
    _check_primitive(what, primitive)
    return primitive


def _check_hull_counts(what: str, index: int, n: int, t: int) -> None:
    if not MIN_HULL_VERTICES <= n <= MAX_HULL_VERTICES or t > 2 * n:
        raise BadHull(
            f"hull {index} of {what} has {n} vertices and {t} triangles: a hull has "
            f"{MIN_HULL_VERTICES} to {MAX_HULL_VERTICES} vertices and at most twice as many "
            "triangles"
        )


def _check_hull_count(what: str, h: int) -> None:
    if h > MAX_HULLS:
        raise CountOverCap(f"{what} has {h} hulls, more than the cap of {MAX_HULLS}")


def _read_hull(r: _Reader, what: str, index: int) -> Hull:
    n = r.u8("hull vertex_count")
    t = r.u16("hull triangle_count")
    _check_hull_counts(what, index, n, t)
    hull = f"hull {index} of {what}"
    vertices = np.frombuffer(r.take(12 * n, "hull vertices"), dtype="<f4").reshape(n, 3)
    _check_vertices_finite(hull, vertices)
    triangles = np.frombuffer(r.take(3 * t, "hull triangles"), dtype=np.uint8).reshape(t, 3)
    _check_indices(hull, triangles, n)
    return Hull(vertices.astype(np.float32), triangles.copy())


def _read_body(r: _Reader) -> Body:
    object_id = r.u64("object_id")
    shape_version = r.u64("shape_version")
    what = f"the Body of object {object_id}"
    solid = _read_solid(r, what)
    margin_m = r.f32("margin_m")
    _check_number(what, "margin_m", margin_m)
    volume_m3 = r.f32("volume_m3")
    _check_volume(what, volume_m3)
    centre_of_mass = r.vec3("centre_of_mass")
    _check_finite(what, "centre_of_mass", centre_of_mass)
    inertia: tuple[float, ...] = struct.unpack("<6f", r.take(24, "inertia"))
    _check_finite(what, "inertia", inertia)
    primitive = _read_primitive(r, what)
    _check_solid_primitive(what, solid, primitive is not None)
    encoding = _read_encoding(r, what)
    v = r.u32("vertex_count")
    t = r.u32("triangle_count")
    _check_solid_mesh(what, solid, v, t)
    # The counts are checked against the payload before any array they size is made.
    geometry = _geometry_bytes(encoding, v, t)
    if geometry > r.left:
        raise Truncated(
            f"Body of object {object_id}: {v} vertices and {t} triangles "
            f"({encoding.name.lower()}) take {BODY_HEADER_BYTES + geometry} bytes of payload "
            f"before the hulls, it has {BODY_HEADER_BYTES + r.left}"
        )
    vertices, triangles = _read_geometry(r, what, encoding, v, t)
    h = r.u8("hull_count")
    _check_hull_count(what, h)
    hulls = tuple(_read_hull(r, what, index) for index in range(h))
    return Body(
        object_id=object_id,
        shape_version=shape_version,
        solid=solid,
        margin_m=margin_m,
        volume_m3=volume_m3,
        centre_of_mass=np.array(centre_of_mass, np.float32),
        inertia=inertia_matrix(*inertia),
        primitive=primitive,
        vertices=vertices,
        triangles=triangles,
        hulls=hulls,
        encoding=encoding,
    )


_STATS_COUNTERS = (
    "monotonic_ns",
    "realtime_ns",
    "frames_in",
    "frames_dropped",
    "invalid_pixels",
    "malformed_frames",
    "source_errors",
    "source_restarts",
    "objects_tracked",
    "objects_born",
    "objects_removed",
    "meshing_runs",
    "meshing_failures",
    "shapes_published",
    "poses_published",
    "bytes_sent",
    "clients_connected",
    "clients_dropped",
    "clients_refused",
)


def _read_stats(r: _Reader) -> Stats:
    counters = {name: r.u64(name) for name in _STATS_COUNTERS}
    latency_window = r.u32("latency_window")
    p50 = r.number("frame_to_publish_p50_ms")
    p99 = r.number("frame_to_publish_p99_ms")
    n = r.u32("stage_count")
    if n * STAGE_FIXED_BYTES > r.left:
        raise Truncated(
            f"Stats frame ends inside `stages`: {n} stages need at least "
            f"{n * STAGE_FIXED_BYTES} bytes, {r.left} are left"
        )
    stages = tuple(
        StageLatency(r.text("stage", MAX_NAME_BYTES), r.number("p50_ms"), r.number("p99_ms"))
        for _ in range(n)
    )
    return Stats(
        **counters,
        latency_window=latency_window,
        frame_to_publish_p50_ms=p50,
        frame_to_publish_p99_ms=p99,
        stages=stages,
    )


def decode_payload(kind: int, payload: bytes, sender: Sender = "server") -> AnyMessage:
    """One message from its kind and payload (the frame without its length and kind), as sent
    by ``sender`` (a client decodes what the server sends, the default)."""
    name = _NAMES.get(kind)
    if name is None:
        if kind in RETIRED_KINDS:
            raise UnknownKind(
                f"kind 0x{kind:02x} is retired ({RETIRED_KINDS[kind]}): the peer speaks an "
                f"older protocol version than {PROTOCOL_VERSION}"
            )
        raise UnknownKind(
            f"unknown message kind 0x{kind:02x}: the peer speaks another protocol version or "
            "is not a tacmesh peer"
        )
    from_client = kind >= 0x80
    if from_client != (sender == "client"):
        other = "client" if from_client else "server"
        raise WrongDirection(
            f"{name} (kind 0x{kind:02x}) is sent by a {other}, but this decoder reads what a "
            f"{sender} sends"
        )
    r = _Reader(payload, name)
    message: AnyMessage
    if kind == KIND_HELLO:
        message = Hello(r.u16("protocol_version"), r.text("server", MAX_NAME_BYTES))
    elif kind == KIND_SESSION:
        message = Session(r.u64("monotonic_ns"), r.u64("realtime_ns"), _read_options(r))
    elif kind == KIND_SHAPE:
        message = _read_shape(r)
    elif kind == KIND_POSE:
        message = _read_pose(r)
    elif kind == KIND_BODY:
        message = _read_body(r)
    elif kind == KIND_REMOVE:
        message = Remove(r.u64("object_id"))
    elif kind == KIND_SNAPSHOT_DONE:
        message = SnapshotDone()
    elif kind == KIND_STATS:
        message = _read_stats(r)
    elif kind == KIND_GOODBYE:
        message = Goodbye(r.text("reason", MAX_REASON_BYTES))
    elif kind == KIND_SUBSCRIBE:
        message = _read_options(r)
    else:
        assert kind == KIND_SUBSCRIBE_V1
        message = SubscribeV1()
    r.end()
    return message


class FrameDecoder:
    """Bytes from the socket in (:meth:`push`), whole messages out (:meth:`next_message`).

    ``sender`` is whose messages these are: ``"server"`` (the default, for a client) or
    ``"client"`` (for a server, or a test playing one). A length prefix over the cap is refused
    as soon as its four bytes are there, before any of the body is buffered. After an error,
    drop the connection.
    """

    def __init__(self, sender: Sender = "server") -> None:
        self.sender: Sender = sender
        self._buffer = bytearray()
        #: Bytes of the last frame taken out, its length prefix included.
        self.last_frame_bytes = 0

    def push(self, data: bytes) -> None:
        self._buffer += data

    @property
    def buffered(self) -> int:
        """Bytes received and not yet taken out as a message."""
        return len(self._buffer)

    def _length(self) -> int:
        (length,) = struct.unpack_from("<I", self._buffer)
        if length == 0:
            raise EmptyFrame("frame length 0: every frame holds at least its message kind byte")
        if length > MAX_FRAME_BYTES:
            raise FrameTooLarge(
                f"frame length {length} exceeds the cap of {MAX_FRAME_BYTES} bytes: the peer "
                "is not speaking the tacmesh protocol"
            )
        return int(length)

    def next_message(self) -> AnyMessage | None:
        """The next whole message, or None until more bytes arrive."""
        if len(self._buffer) < 4:
            return None
        length = self._length()
        if len(self._buffer) < 4 + length:
            return None
        kind = self._buffer[4]
        payload = bytes(self._buffer[5 : 4 + length])
        del self._buffer[: 4 + length]
        self.last_frame_bytes = 4 + length
        return decode_payload(kind, payload, self.sender)


def decode_all(data: bytes, sender: Sender = "server") -> list[AnyMessage]:
    """Every message in ``data``, which must end at a frame boundary."""
    decoder = FrameDecoder(sender)
    decoder.push(data)
    out: list[AnyMessage] = []
    while (message := decoder.next_message()) is not None:
        out.append(message)
    if decoder.buffered:
        raise StreamEndedInFrame(f"the data ends inside a frame ({decoder.buffered} bytes)")
    return out


# ---------------------------------------------------------------------------------------------
# Encoding


def _text(value: str, what: str, name: str, cap: int, validate: bool) -> bytes:
    raw = value.encode("utf-8")
    if len(raw) > cap and validate:
        raise TextTooLong(f"`{name}` of {what} is {len(raw)} bytes, more than the cap of {cap}")
    return struct.pack("<H", len(raw)) + raw


def _options_payload(options: Subscribe, what: str, validate: bool) -> bytes:
    if validate:
        _check_rate(what, options.max_rate_hz)
        if len(options.object_ids) > MAX_SUBSCRIBE_IDS:
            raise CountOverCap(
                f"{what} lists {len(options.object_ids)} object ids, more than the cap of "
                f"{MAX_SUBSCRIBE_IDS}"
            )
        _check_kinds(what, int(options.kinds))
        if int(options.encoding) not in (0, 1):
            raise InvalidEnum(f"`encoding` of {what} is {int(options.encoding)}")
    return struct.pack(
        f"<BBfBI{len(options.object_ids)}Q",
        int(options.encoding),
        (SUBSCRIBE_RESEND if options.resend else 0)
        | (SUBSCRIBE_EXTRAPOLATE if options.extrapolate else 0),
        options.max_rate_hz,
        int(options.kinds),
        len(options.object_ids),
        *options.object_ids,
    )


def _pose_payload(pose: Pose, validate: bool) -> bytes:
    if validate:
        _check_pose("Pose", pose)
    return struct.pack(
        "<5Q4f3f3f3f",
        pose.object_id,
        pose.shape_version,
        pose.pose_time_ns,
        pose.pose_time_realtime_ns,
        pose.last_seen_ns,
        *pose.rotation,
        *pose.translation,
        *pose.linear_velocity,
        *pose.angular_velocity,
    )


def _mesh_arrays(
    vertices: npt.ArrayLike, triangles: npt.ArrayLike
) -> tuple[npt.NDArray[np.float32], npt.NDArray[Any]]:
    """Vertices as little-endian ``f32 (V, 3)`` and triangles as ``(T, 3)``, for the encoder."""
    v = np.ascontiguousarray(vertices, dtype="<f4").reshape(-1, 3)
    t = np.ascontiguousarray(triangles).reshape(-1, 3)
    return v, t


def _check_mesh(what: str, vertices: npt.NDArray[np.float32], triangles: npt.NDArray[Any]) -> None:
    """What a receiver checks of a mesh: finite vertices, indices below the vertex count."""
    if not np.all(np.isfinite(vertices)):
        raise NonFinite(f"a vertex of {what} is NaN or infinite")
    if len(triangles) and (int(triangles.max()) >= len(vertices) or int(triangles.min()) < 0):
        raise IndexOutOfRange(
            f"a triangle of {what} uses vertex {int(triangles.max())}, but the mesh has only "
            f"{len(vertices)} vertices"
        )


def _geometry_payload(
    vertices: npt.NDArray[np.float32], triangles: npt.NDArray[Any], encoding: Encoding
) -> tuple[bytes, float]:
    """A mesh laid out as Shape's geometry in ``encoding``, and the quantisation bound that
    layout adds (0 for full)."""
    if encoding != Encoding.COMPACT:
        return vertices.tobytes() + triangles.astype("<u4").tobytes(), 0.0
    box_min, box_max, q = quantise(vertices)
    width = "<u2" if len(vertices) <= COMPACT_U16_VERTICES else "<u4"
    geometry = (
        box_min.astype("<f4").tobytes()
        + box_max.astype("<f4").tobytes()
        + q.astype("<u2").tobytes()
        + triangles.astype(width).tobytes()
    )
    return geometry, quantisation_bound_m(box_min, box_max)


def _shape_payload(shape: Shape, validate: bool) -> bytes:
    what = f"the Shape of object {shape.object_id}"
    vertices, triangles = _mesh_arrays(shape.vertices, shape.triangles)
    if validate:
        _check_number(what, "max_residual_m", shape.max_residual_m)
        if shape.flags & ~SHAPE_FLAGS:
            raise InvalidFlags(f"`flags` of {what} is 0x{shape.flags:02x}")
        _check_mesh(what, vertices, triangles)
    geometry, bound = _geometry_payload(vertices, triangles, shape.encoding)
    residual = shape.max_residual_m
    if shape.encoding == Encoding.COMPACT:
        residual = float(np.float32(residual) + np.float32(bound))
        if validate:
            _check_number(what, "max_residual_m", residual)
    head = _pose_payload(shape.pose, validate) + struct.pack(
        "<QQBIIfBII",
        shape.shape_time_ns,
        shape.shape_time_realtime_ns,
        shape.flags,
        shape.faces_in,
        shape.faces_out,
        residual,
        int(shape.encoding),
        len(vertices),
        len(triangles),
    )
    return head + geometry


def _check_body(
    body: Body,
    what: str,
    vertices: npt.NDArray[np.float32],
    triangles: npt.NDArray[Any],
) -> None:
    """What a receiver checks of a Body's fixed fields, primitive and mesh, and that its inertia
    is a symmetric 3 × 3 tensor (the wire carries only its upper triangle)."""
    if int(body.solid) not in {int(solid) for solid in BodySolid}:
        raise InvalidEnum(f"`solid` of {what} is {int(body.solid)}")
    if int(body.encoding) not in (0, 1):
        raise InvalidEnum(f"`encoding` of {what} is {int(body.encoding)}")
    _check_number(what, "margin_m", body.margin_m)
    _check_volume(what, body.volume_m3)
    centre = np.asarray(body.centre_of_mass, dtype=np.float64).reshape(3)
    _check_finite(what, "centre_of_mass", tuple(centre.tolist()))
    inertia = np.asarray(body.inertia, dtype=np.float64)
    if inertia.shape != (3, 3) or not np.array_equal(inertia, inertia.T):
        raise ValueError(
            f"the inertia of {what} is not a symmetric 3 × 3 tensor: {inertia.tolist()}"
        )
    _check_finite(what, "inertia", inertia_terms(inertia))
    if body.primitive is not None:
        _check_primitive(what, body.primitive)
    solid = BodySolid(body.solid)
    _check_solid_primitive(what, solid, body.primitive is not None)
    _check_solid_mesh(what, solid, len(vertices), len(triangles))
    _check_mesh(what, vertices, triangles)


def _hull_payload(hull: Hull, what: str, index: int, validate: bool) -> bytes:
    vertices, triangles = _mesh_arrays(hull.vertices, hull.triangles)
    if validate:
        _check_hull_counts(what, index, len(vertices), len(triangles))
        _check_mesh(f"hull {index} of {what}", vertices, triangles)
    head = struct.pack("<BH", len(vertices), len(triangles))
    return head + vertices.tobytes() + triangles.astype(np.uint8).tobytes()


def _primitive_payload(primitive: Primitive | None) -> bytes:
    """The primitive block: kind 0 and 44 zero bytes for none."""
    if primitive is None:
        return bytes(PRIMITIVE_BYTES)
    return struct.pack(
        "<B3f4f3ff",
        int(primitive.kind),
        *primitive.sizes,
        *primitive.rotation,
        *primitive.centre,
        primitive.residual_m,
    )


def _body_payload(body: Body, validate: bool) -> bytes:
    what = f"the Body of object {body.object_id}"
    vertices, triangles = _mesh_arrays(body.vertices, body.triangles)
    if validate:
        _check_body(body, what, vertices, triangles)
        _check_hull_count(what, len(body.hulls))
    head = (
        struct.pack(
            "<QQBff3f6f",
            body.object_id,
            body.shape_version,
            int(body.solid),
            body.margin_m,
            body.volume_m3,
            *np.asarray(body.centre_of_mass, dtype=np.float64).reshape(3).tolist(),
            *inertia_terms(body.inertia),
        )
        + _primitive_payload(body.primitive)
        + struct.pack("<BII", int(body.encoding), len(vertices), len(triangles))
    )
    geometry, _ = _geometry_payload(vertices, triangles, body.encoding)
    hulls = b"".join(
        _hull_payload(hull, what, index, validate) for index, hull in enumerate(body.hulls)
    )
    return head + geometry + struct.pack("<B", len(body.hulls)) + hulls


def _stats_payload(stats: Stats, validate: bool) -> bytes:
    latencies = [
        ("frame_to_publish_p50_ms", stats.frame_to_publish_p50_ms),
        ("frame_to_publish_p99_ms", stats.frame_to_publish_p99_ms),
    ]
    for stage in stats.stages:
        latencies += [("p50_ms", stage.p50_ms), ("p99_ms", stage.p99_ms)]
    if validate:
        for name, value in latencies:
            _check_number("Stats", name, value)
    out = struct.pack("<19Q", *(getattr(stats, name) for name in _STATS_COUNTERS))
    out += struct.pack(
        "<IffI",
        stats.latency_window,
        stats.frame_to_publish_p50_ms,
        stats.frame_to_publish_p99_ms,
        len(stats.stages),
    )
    for stage in stats.stages:
        out += _text(stage.stage, "Stats", "stage", MAX_NAME_BYTES, validate)
        out += struct.pack("<ff", stage.p50_ms, stage.p99_ms)
    return out


def encode_payload(message: AnyMessage, *, validate: bool = True) -> tuple[int, bytes]:
    """The kind and payload of ``message``. See :func:`encode`."""
    if isinstance(message, Hello):
        return KIND_HELLO, struct.pack("<H", message.protocol_version) + _text(
            message.server, "Hello", "server", MAX_NAME_BYTES, validate
        )
    if isinstance(message, Session):
        return KIND_SESSION, struct.pack(
            "<QQ", message.monotonic_ns, message.realtime_ns
        ) + _options_payload(message.options, "Session", validate)
    if isinstance(message, Shape):
        return KIND_SHAPE, _shape_payload(message, validate)
    if isinstance(message, Pose):
        return KIND_POSE, _pose_payload(message, validate)
    if isinstance(message, Body):
        return KIND_BODY, _body_payload(message, validate)
    if isinstance(message, Remove):
        return KIND_REMOVE, struct.pack("<Q", message.object_id)
    if isinstance(message, SnapshotDone):
        return KIND_SNAPSHOT_DONE, b""
    if isinstance(message, Stats):
        return KIND_STATS, _stats_payload(message, validate)
    if isinstance(message, Goodbye):
        return KIND_GOODBYE, _text(message.reason, "Goodbye", "reason", MAX_REASON_BYTES, validate)
    if isinstance(message, Subscribe):
        return KIND_SUBSCRIBE, _options_payload(message, "Subscribe", validate)
    if isinstance(message, SubscribeV1):
        return KIND_SUBSCRIBE_V1, b""
    raise TypeError(f"not a tacmesh message: {message!r}")


def encode(message: AnyMessage, *, validate: bool = True) -> bytes:
    """``message`` as one frame.

    A Shape is laid out in its ``encoding``: compact quantises its vertices to the nearest step
    of their box and adds the quantisation bound to ``max_residual_m``. A Body's mesh is laid
    out the same way (a Body's mesh has no residual), its hulls always in full; its primitive
    block is 45 zero bytes when it has none. With ``validate`` (the
    default) a message a receiver would refuse raises the :class:`WireError` the decoder would;
    without it the bytes are written as they are (for tests of the refusals).
    """
    kind, payload = encode_payload(message, validate=validate)
    length = 1 + len(payload)
    if length > MAX_FRAME_BYTES and validate:
        raise FrameTooLarge(f"a frame of {length} bytes, over the cap of {MAX_FRAME_BYTES}")
    return struct.pack("<IB", length, kind) + payload


def encode_subscribe(options: Subscribe = DEFAULT_OPTIONS) -> bytes:
    """The Subscribe frame (0x81) asking for ``options``."""
    return encode(options)


def encode_subscribe_v1() -> bytes:
    """Version 1's empty Subscribe (0x80), which a server of version 2 or later refuses with a
    Goodbye."""
    return encode(SubscribeV1())
