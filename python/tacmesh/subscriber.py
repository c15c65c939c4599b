"""Subscribing to a running daemon over its Unix socket, and keeping the current scene.

>>> from tacmesh import Subscriber
>>> with Subscriber("/run/tacmesh/tacmesh.sock", encoding="compact") as sub:  # doctest: +SKIP
...     for message in sub:
...         print(len(sub.scene.objects), "objects")
"""

from __future__ import annotations

import errno
import logging
import os
import pwd
import socket
import struct
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from functools import cached_property
from pathlib import Path
from typing import NamedTuple, Union

import numpy as np
import numpy.typing as npt

from .wire import (
    DEFAULT_OPTIONS,
    FIRST_SUPPORT_ID,
    MAX_RATE_HZ,
    MIN_RATE_HZ,
    PROTOCOL_VERSION,
    SUPPORTED_VERSIONS,
    Body,
    BodySolid,
    Encoding,
    FrameDecoder,
    Goodbye,
    Hello,
    Kinds,
    Message,
    Pose,
    Remove,
    Session,
    Shape,
    SnapshotDone,
    Stats,
    Subscribe,
    SubscribeV1,
    WireError,
    encode_subscribe,
)
from .tessellation import tessellate

log = logging.getLogger("tacmesh")


class Refused(ConnectionError):
    """The daemon did not admit this client (its Goodbye instead of the Hello says why)."""


class VersionMismatch(ConnectionError):
    """The daemon speaks a protocol version this client does not read."""


#: The system user the daemon's systemd service runs as (systemd/tacmesh.sysusers).
SERVICE_USER = "tacmesh"


class UntrustedServer(ConnectionError):
    """The socket is served by a process of a user this client does not trust: not its own
    effective user, not root, not the ``tacmesh`` service user, and not one of the
    ``trust_uids`` it was given. Another local user may have bound the path first to feed it
    forged meshes: the connection is closed before anything is read from it, and it is not
    retried (not even with ``reconnect``). ``path``, ``uid``, ``user`` (None if the uid has no
    name) and ``pid`` say who serves it."""

    def __init__(self, path: str | Path, credentials: PeerCredentials) -> None:
        self.path = Path(path)
        self.credentials = credentials
        self.uid = credentials.uid
        self.pid = credentials.pid
        self.user = user_name(credentials.uid)
        who = f"uid {self.uid}" + (f" ({self.user})" if self.user is not None else "")
        super().__init__(
            f"the socket {self.path} is served by {who}, pid {self.pid}, not by you "
            f"(uid {os.geteuid()}), root or the {SERVICE_USER} service user: another local "
            f"user may be impersonating the daemon; pass trust_uids=[{self.uid}] if you meant "
            "to connect to it"
        )

    def __reduce__(self) -> tuple[type[UntrustedServer], tuple[Path, PeerCredentials]]:
        # Pickled (to another process) by what it was made of, not by its message.
        return type(self), (self.path, self.credentials)


class PeerCredentials(NamedTuple):
    """Who serves a Unix socket (``SO_PEERCRED``): the process, user and group that were
    listening on it."""

    pid: int
    uid: int
    gid: int


def server_credentials(sock: socket.socket) -> PeerCredentials:
    """The credentials of the server at the other end of a connected Unix socket: the process
    that listens on it, with the user and group it had when it began listening (Linux's
    ``SO_PEERCRED``)."""
    raw = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
    pid, uid, gid = struct.unpack("3i", raw)
    return PeerCredentials(pid, uid, gid)


def user_name(uid: int) -> str | None:
    """The name of the user ``uid``, None if it has none."""
    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return None


def trusted_uids(trust_uids: Iterable[int] = ()) -> frozenset[int]:
    """The users whose server a client takes for the daemon: the client's own effective uid,
    root (0), the ``tacmesh`` service user if this host has one, and ``trust_uids``."""
    trusted = {os.geteuid(), 0, *(int(uid) for uid in trust_uids)}
    try:
        trusted.add(pwd.getpwnam(SERVICE_USER).pw_uid)
    except KeyError:
        pass  # no service user here: the daemon runs as its user (or root)
    return frozenset(trusted)


def check_server(
    path: str | Path, credentials: PeerCredentials, trust_uids: Iterable[int] = ()
) -> None:
    """Raises :class:`UntrustedServer` unless the user serving the socket at ``path``
    (``credentials``, see :func:`server_credentials`) is one of :func:`trusted_uids`."""
    if credentials.uid not in trusted_uids(trust_uids):
        raise UntrustedServer(path, credentials)


#: What to do when there is no daemon at a socket's path.
START_ADVICE = "is the daemon running? (`tacmesh run`, or `systemctl status tacmesh`)"


def connect(
    path: str | Path, *, timeout_s: float | None = None, trust_uids: Iterable[int] = ()
) -> socket.socket:
    """A connection to the daemon's socket at ``path``, once its server is found to be a
    trusted user's (:func:`check_server`: else :class:`UntrustedServer`, the socket closed).
    ``timeout_s`` is the socket's timeout (None: blocking).

    No socket at ``path`` raises :class:`FileNotFoundError`, a socket nobody listens on (a
    daemon that stopped without removing it) :class:`ConnectionRefusedError`, each saying so
    and how to start the daemon; any other failure is the :class:`OSError` of ``connect``.
    """
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        sock.settimeout(timeout_s)
        try:
            sock.connect(str(path))
        except FileNotFoundError:
            raise FileNotFoundError(
                errno.ENOENT, f"{path}: no such socket: {START_ADVICE}"
            ) from None
        except ConnectionRefusedError:
            raise ConnectionRefusedError(
                errno.ECONNREFUSED,
                f"{path}: nothing listens on this socket (a daemon that stopped without "
                f"removing it?): {START_ADVICE}",
            ) from None
        check_server(path, server_credentials(sock), trust_uids)
    except BaseException:
        sock.close()
        raise
    return sock


class Mesh(NamedTuple):
    """A triangle mesh: an object's shape, its body's solid or one of its hulls."""

    #: ``float32 (V, 3)``, metres.
    vertices: npt.NDArray[np.float32]
    #: ``uint32 (T, 3)``.
    triangles: npt.NDArray[np.uint32]


@dataclass(frozen=True, eq=False)
class SceneObject:
    """One object (or support plane) as the scene holds it: its latest shape, the latest pose
    for that shape, and its newest collision body if it has one that fits the shape's frame.
    """

    shape: Shape
    pose: Pose
    #: The newest Body (by ``shape_version``) in the object's current frame; None before the
    #: first, for a support plane, for an object with no volume, or when bodies are not asked
    #: for. It may have been made from an older shape than ``shape`` (in the same frame).
    body: Body | None = None
    #: The version of the newest Shape held that said ``new_frame`` (0 if none has): a Body of
    #: an older version is in a frame before the current one and does not fit.
    frame_version: int = 0

    @property
    def object_id(self) -> int:
        return self.shape.object_id

    @property
    def shape_version(self) -> int:
        return self.shape.shape_version

    #: The name version 1 of this package used.
    version = shape_version

    @property
    def is_support(self) -> bool:
        """A support plane (a table or floor): its Shape's flag, or an id from 2^32."""
        return self.shape.is_support or self.object_id >= FIRST_SUPPORT_ID

    #: The name version 1 of this package used.
    is_plane = is_support

    @property
    def vertices(self) -> npt.NDArray[np.float32]:
        """``float32 (V, 3)`` in the object's frame."""
        return self.shape.vertices

    @property
    def triangles(self) -> npt.NDArray[np.uint32]:
        return self.shape.triangles

    @property
    def max_residual_m(self) -> float:
        return self.shape.max_residual_m

    @cached_property
    def world_vertices(self) -> npt.NDArray[np.float32]:
        """``float32 (V, 3)``: the shape's vertices mapped by the pose (``world_from_object``)."""
        return self.pose.to_world(self.shape.vertices)

    @property
    def mesh(self) -> Mesh:
        """The object's mesh in the world frame."""
        return Mesh(self.world_vertices, self.shape.triangles)

    @cached_property
    def world_solid(self) -> Mesh | None:
        """The body's solid in the world frame (mapped by the current pose), a closed surface;
        None without a body. For a :attr:`~tacmesh.wire.BodySolid.SHAPE` solid it is the held
        shape's :attr:`mesh`, for a :attr:`~tacmesh.wire.BodySolid.PRIMITIVE` one the
        primitive's :func:`~tacmesh.tessellation.tessellate` (its vertices on the primitive's
        surface), for any other the mesh the body carries."""
        if self.body is None:
            return None
        if self.body.solid is BodySolid.SHAPE:
            return self.mesh
        if self.body.solid is BodySolid.PRIMITIVE and self.body.primitive is not None:
            vertices, triangles = tessellate(self.body.primitive)
            return Mesh(self.pose.to_world(vertices), triangles)
        return Mesh(self.pose.to_world(self.body.vertices), self.body.triangles)

    @cached_property
    def world_hulls(self) -> tuple[Mesh, ...]:
        """The body's convex hulls in the world frame (mapped by the current pose), triangles
        ``uint32``; none without a body."""
        if self.body is None:
            return ()
        return tuple(
            Mesh(self.pose.to_world(hull.vertices), hull.triangles.astype(np.uint32))
            for hull in self.body.hulls
        )

    @property
    def world_centre_of_mass(self) -> npt.NDArray[np.float32] | None:
        """``float32 (3,)``: the body's centre of mass in the world frame; None without a body."""
        if self.body is None:
            return None
        centre: npt.NDArray[np.float32] = self.pose.to_world(self.body.centre_of_mass)[0]
        return centre

    @property
    def shape_time_ns(self) -> int:
        return self.shape.shape_time_ns

    @property
    def pose_time_ns(self) -> int:
        return self.pose.pose_time_ns

    @property
    def last_seen_ns(self) -> int:
        return self.pose.last_seen_ns


class Scene:
    """What the daemon says is there now, by the document's rules.

    - A Hello (a new connection) or a Session (a new snapshot) empties the scene; the Shapes up
      to SnapshotDone are the scene, and ``complete`` is True from SnapshotDone on.
    - Per object the Shape of the highest ``shape_version`` is kept (an older one is stale and
      ignored), with its own pose.
    - A Pose applies only to the shape version it names (another is stale and ignored), and
      never takes an object's pose time or last-seen time backwards.
    - A Body is kept beside the shape, the newest by ``shape_version``, and placed by the same
      pose. A Body of an object not held, older than the held one, or older than the newest
      Shape held that said ``new_frame`` (made in the frame before) is stale and ignored; a
      Shape with ``new_frame`` drops a held Body older than it.
    - A Remove forgets the object (its body with it).

    ``stale`` counts the Shapes, Bodies and Poses ignored. ``session`` and ``stats`` are the
    latest of each; :meth:`realtime_ns` maps a monotonic time of the stream onto the daemon's
    wall clock.
    """

    def __init__(self) -> None:
        self.objects: dict[int, SceneObject] = {}
        self.complete = False
        self.session: Session | None = None
        self.stats: Stats | None = None
        self.stale = 0
        self._realtime_offset_ns: int | None = None

    def apply(self, message: Message) -> None:
        if isinstance(message, Hello):
            self.clear()
        elif isinstance(message, Session):
            self.clear()
            self.session = message
            self._realtime_offset_ns = message.realtime_offset_ns
        elif isinstance(message, Shape):
            self._shape(message)
        elif isinstance(message, Pose):
            self._pose(message)
        elif isinstance(message, Body):
            self._body(message)
        elif isinstance(message, Remove):
            self.objects.pop(message.object_id, None)
        elif isinstance(message, SnapshotDone):
            self.complete = True
        elif isinstance(message, Stats):
            self.stats = message
            self._realtime_offset_ns = message.realtime_offset_ns

    def clear(self) -> None:
        self.objects.clear()
        self.complete = False

    def keep_only(self, options: Subscribe) -> None:
        """Forgets the objects outside the filter of ``options`` (its kinds and ids), and the
        bodies when it does not ask for them: what a client does after a Subscribe without
        ``resend``."""
        for object_id in [i for i in self.objects if not options.admits(i)]:
            del self.objects[object_id]
        if not options.bodies:
            for object_id, held in list(self.objects.items()):
                self.objects[object_id] = replace(held, body=None)

    def _shape(self, shape: Shape) -> None:
        held = self.objects.get(shape.object_id)
        if held is not None and shape.shape_version < held.shape_version:
            self.stale += 1
            return
        if held is not None and shape.shape_version == held.shape_version:
            # The same shape again: its pose is news only if it is newer.
            self._pose(shape.pose)
            return
        frame_version = held.frame_version if held is not None else 0
        if shape.is_new_frame:
            frame_version = shape.shape_version
        body = held.body if held is not None else None
        if body is not None and body.shape_version < frame_version:
            body = None  # made in the frame before this shape's
        self.objects[shape.object_id] = SceneObject(shape, shape.pose, body, frame_version)

    def _pose(self, pose: Pose) -> None:
        held = self.objects.get(pose.object_id)
        if (
            held is None
            or pose.shape_version != held.shape_version
            or pose.pose_time_ns < held.pose.pose_time_ns
            or pose.last_seen_ns < held.pose.last_seen_ns
        ):
            self.stale += 1
            return
        self.objects[pose.object_id] = replace(held, pose=pose)

    def _body(self, body: Body) -> None:
        held = self.objects.get(body.object_id)
        if (
            held is None
            or body.shape_version < held.frame_version
            or (held.body is not None and body.shape_version < held.body.shape_version)
        ):
            self.stale += 1
            return
        self.objects[body.object_id] = replace(held, body=body)

    def realtime_ns(self, monotonic_ns: int) -> int | None:
        """A monotonic time of the stream on the daemon's wall clock (``CLOCK_REALTIME``), by
        the latest Session or Stats; None before either."""
        if self._realtime_offset_ns is None:
            return None
        return monotonic_ns + self._realtime_offset_ns

    @property
    def supports(self) -> list[SceneObject]:
        return [o for o in self.objects.values() if o.is_support]

    @property
    def non_supports(self) -> list[SceneObject]:
        return [o for o in self.objects.values() if not o.is_support]


def local_age_s(monotonic_ns: int) -> float:
    """The age of a time of the stream, for a client on the daemon's host: its own
    ``time.monotonic_ns()`` minus the time (both ``CLOCK_MONOTONIC``)."""
    return (time.monotonic_ns() - monotonic_ns) * 1e-9


def remote_age_s(realtime_ns: int) -> float:
    """The age of a realtime field (``…_realtime_ns``), for a client on another host whose wall
    clock is synchronised with the daemon's: its ``time.time_ns()`` minus the time."""
    return (time.time_ns() - realtime_ns) * 1e-9


EncodingName = Union[str, Encoding]
KindName = Union[str, Kinds]
#: What a client asks for by default: objects, support planes and the objects' bodies.
ALL_KINDS: tuple[str, ...] = ("objects", "supports", "bodies")


def options_of(
    *,
    encoding: EncodingName = "full",
    max_rate_hz: float = 0.0,
    kinds: Iterable[KindName] | KindName = ALL_KINDS,
    object_ids: Iterable[int] = (),
    resend: bool = False,
    extrapolate: bool = False,
) -> Subscribe:
    """A :class:`~tacmesh.wire.Subscribe` from friendly values: ``encoding`` ``"full"`` or
    ``"compact"``, ``kinds`` any of ``"objects"``, ``"supports"``, ``"bodies"`` (at least one
    of the first two; all three by default)."""
    if isinstance(encoding, str):
        try:
            encoding = Encoding[encoding.upper()]
        except KeyError:
            raise ValueError(f"encoding {encoding!r}: it is 'full' or 'compact'") from None
    if isinstance(kinds, (str, Kinds)):
        kinds = [kinds]
    bits = Kinds(0)
    for kind in kinds:
        if isinstance(kind, str):
            try:
                kind = Kinds[kind.upper()]
            except KeyError:
                raise ValueError(
                    f"kind {kind!r}: it is 'objects', 'supports' or 'bodies'"
                ) from None
        bits |= kind
    if not bits & (Kinds.OBJECTS | Kinds.SUPPORTS):
        raise ValueError(
            "kinds: ask for 'objects', 'supports' or both ('bodies' comes only with them)"
        )
    if not (max_rate_hz == 0.0 or MIN_RATE_HZ <= max_rate_hz <= MAX_RATE_HZ):
        raise ValueError(
            f"max_rate_hz {max_rate_hz}: it is 0 (no cap) or from {MIN_RATE_HZ} to "
            f"{MAX_RATE_HZ} updates a second"
        )
    return Subscribe(
        encoding=Encoding(encoding),
        resend=resend,
        max_rate_hz=float(max_rate_hz),
        kinds=bits,
        object_ids=tuple(int(i) for i in object_ids),
        extrapolate=extrapolate,
    )


class Subscriber:
    """The daemon's messages, in order, as an iterator, and the scene they describe.

    Each connection starts with a :class:`~tacmesh.wire.Hello`, checked: another protocol
    version raises :class:`VersionMismatch` (naming both versions), a Goodbye instead of it
    raises :class:`Refused` with the daemon's reason. Then the client sends a Subscribe with its
    options (``encoding`` ``"full"`` or ``"compact"``, ``max_rate_hz``, ``kinds`` (any of
    ``"objects"``, ``"supports"``, ``"bodies"``; all three by default), ``object_ids``,
    ``extrapolate``: this client extrapolates poses by their velocity, see
    :meth:`~tacmesh.wire.Pose.extrapolated`), with ``resend`` when they differ from the
    defaults: the daemon's first snapshot (under the defaults) is then not yielded, and the
    scene is taken from the Session that answers the Subscribe. More generally, messages sent
    under options this client has since replaced (up to the Session of the new options) are
    skipped, Stats excepted, as are updates of objects outside the filter (and Bodies when
    bodies are not asked for).

    ``scene`` is the :class:`Scene` of everything yielded so far. :meth:`subscribe` changes the
    options (by default with a fresh snapshot), :meth:`resend` asks for a fresh snapshot.

    Every connection is checked to be served by a trusted user (:func:`connect`): this
    client's own, root, the ``tacmesh`` service user, or one of ``trust_uids``. Another raises
    :class:`UntrustedServer`, with or without ``reconnect``: it is not a daemon that went away.

    With ``reconnect`` (the default), a lost connection or the daemon's Goodbye is logged (the
    ``tacmesh`` logger) and followed by new attempts with exponential backoff (``backoff_s``
    doubling up to ``max_backoff_s``); the next connection starts again with its Hello and a
    snapshot, and the options are sent again. No daemon yet at the first attempt (no socket at
    ``path``, or nobody listening on it) is logged once, as waiting for one, and the connection
    when it comes. Without ``reconnect``, iteration ends after a Goodbye or when the connection
    closes, and no daemon at the first attempt raises :class:`FileNotFoundError` (or
    :class:`ConnectionRefusedError`) saying so. A frame that breaks the protocol raises a
    :class:`~tacmesh.wire.WireError` either way: a daemon sending garbage is not retried.

    ``timeout_s`` bounds each wait for data (None: wait for ever); a timeout raises
    :class:`TimeoutError`.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        encoding: EncodingName = "full",
        max_rate_hz: float = 0.0,
        kinds: Iterable[KindName] | KindName = ALL_KINDS,
        object_ids: Iterable[int] = (),
        extrapolate: bool = False,
        reconnect: bool = True,
        timeout_s: float | None = None,
        backoff_s: float = 0.1,
        max_backoff_s: float = 5.0,
        send_subscribe: bool = True,
        trust_uids: Iterable[int] = (),
    ) -> None:
        self.path = Path(path)
        #: Users trusted to serve the socket besides this client's own, root and the
        #: ``tacmesh`` service user.
        self.trust_uids = frozenset(int(uid) for uid in trust_uids)
        #: The options asked for (``resend`` False: it is set on each Subscribe as needed).
        self.options = options_of(
            encoding=encoding,
            max_rate_hz=max_rate_hz,
            kinds=kinds,
            object_ids=object_ids,
            extrapolate=extrapolate,
        )
        if not send_subscribe and not self.options.same_options(DEFAULT_OPTIONS):
            raise ValueError("options other than the defaults need send_subscribe")
        self.reconnect = reconnect
        self.timeout_s = timeout_s
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.send_subscribe = send_subscribe
        #: The scene of the messages yielded so far.
        self.scene = Scene()
        #: Connections made so far.
        self.connections = 0
        #: The daemon's Hello on the current (or last) connection.
        self.hello: Hello | None = None
        #: Bytes received on all connections, and the size of the last frame yielded.
        self.bytes_received = 0
        self.last_frame_bytes = 0
        #: Messages received and not yielded: sent under options since replaced (``skipped``),
        #: or about objects outside the filter (``filtered``: sent before the daemon read it).
        self.skipped = 0
        self.filtered = 0
        self._sock: socket.socket | None = None
        self._decoder = FrameDecoder()
        self._expect_hello = True
        self._finished = False
        # Sessions to come before the one that answers this client's latest options.
        self._sessions_to_skip = 0
        self._awaiting: Subscribe | None = None
        # Why the daemon is not there (logged once), from the first failed attempt to the next
        # connection.
        self._lost: str | None = None

    # -- changing what is sent ----------------------------------------------------------------

    def subscribe(
        self,
        *,
        encoding: EncodingName | None = None,
        max_rate_hz: float | None = None,
        kinds: Iterable[KindName] | KindName | None = None,
        object_ids: Iterable[int] | None = None,
        extrapolate: bool | None = None,
        resend: bool = True,
    ) -> None:
        """Changes the options (those given; the others stay) and sends them. With ``resend``
        (the default) the daemon sends a fresh snapshot under them, which replaces the scene;
        without it the scene forgets the objects outside the new filter."""
        old = self.options
        self.options = options_of(
            encoding=old.encoding if encoding is None else encoding,
            max_rate_hz=old.max_rate_hz if max_rate_hz is None else max_rate_hz,
            kinds=old.kinds if kinds is None else kinds,
            object_ids=old.object_ids if object_ids is None else object_ids,
            extrapolate=old.extrapolate if extrapolate is None else extrapolate,
        )
        if not resend:
            self.scene.keep_only(self.options)
        if self._sock is not None and not self._expect_hello:
            self._send(replace(self.options, resend=resend))
        # Not connected, or before the Hello: the options go out after the next Hello.

    def resend(self) -> None:
        """Asks for a fresh snapshot (Session, Shapes, SnapshotDone) under the current options."""
        self.subscribe(resend=True)

    def _send(self, options: Subscribe) -> None:
        assert self._sock is not None
        if options.resend:
            self._sessions_to_skip = 0 if self._awaiting is None else self._sessions_to_skip + 1
            self._awaiting = options
        try:
            self._sock.sendall(encode_subscribe(options))
        except OSError as error:
            # The connection is going; reading it says so.
            log.debug("sending Subscribe failed: %s", error)

    # -- iteration ----------------------------------------------------------------------------

    def __iter__(self) -> Iterator[Message]:
        return self

    def __next__(self) -> Message:
        if self._finished:
            raise StopIteration
        delay = self.backoff_s
        while True:
            try:
                if self._sock is None:
                    self._connect()
                message = self._read_message()
            except (TimeoutError, Refused, VersionMismatch, UntrustedServer):
                self.close()
                raise
            except (OSError, EOFError) as error:
                # Not there yet, gone, or restarting: worth waiting for, unless told not to.
                self.close()
                no_daemon = isinstance(error, (FileNotFoundError, ConnectionRefusedError))
                if not self.reconnect:
                    self._finished = True
                    if no_daemon and self.connections == 0:
                        raise  # the first attempt: say why there is nothing to read
                    raise StopIteration from None
                if self._lost is None:
                    self._lost = str(error) or type(error).__name__
                    self._log_lost(error, no_daemon)
                time.sleep(delay)
                delay = min(2 * delay, self.max_backoff_s)
                continue
            if message is None:
                continue
            self.scene.apply(message)
            if isinstance(message, Goodbye):
                self.close()
                if self.reconnect:
                    self._lost = f"Goodbye: {message.reason}"
                    log.warning(
                        "tacmesh: the daemon at %s said Goodbye (%s); reconnecting",
                        self.path,
                        message.reason,
                    )
                else:
                    self._finished = True
            return message

    def _log_lost(self, error: BaseException, no_daemon: bool) -> None:
        """The one warning of a wait for the daemon: none there yet, or gone."""
        if self.connections > 0:
            log.warning(
                "tacmesh: the daemon at %s went away (%s); reconnecting",
                self.path,
                self._lost,
            )
        elif no_daemon:
            what = "no such socket" if isinstance(error, FileNotFoundError) else "nobody listens"
            log.warning(
                "tacmesh: no daemon at %s yet (%s); waiting for one to start (`tacmesh run`, "
                "or `systemctl status tacmesh`)",
                self.path,
                what,
            )
        else:
            log.warning(
                "tacmesh: cannot connect to the daemon at %s (%s); retrying",
                self.path,
                self._lost,
            )

    def _connect(self) -> None:
        sock = connect(self.path, timeout_s=self.timeout_s, trust_uids=self.trust_uids)
        self._sock = sock
        self._decoder = FrameDecoder()
        self._expect_hello = True
        self._awaiting = None
        self._sessions_to_skip = 0
        if self._lost is not None:
            again = " again" if self.connections > 0 else ""
            log.warning("tacmesh: connected to the daemon at %s%s", self.path, again)
            self._lost = None
        self.connections += 1

    def _receive(self) -> Message:
        assert self._sock is not None
        while True:
            message = self._decoder.next_message()
            if message is not None:
                self.last_frame_bytes = self._decoder.last_frame_bytes
                if isinstance(message, (Subscribe, SubscribeV1)):  # the decoder refuses these
                    raise WireError(f"a client's message from the daemon: {message}")
                return message
            data = self._sock.recv(65536)
            if not data:
                if self._decoder.buffered:
                    # The daemon drops a client that reads nothing for 30 s, possibly in the
                    # middle of a frame: the end of the input, like any other.
                    raise EOFError(
                        f"the daemon closed the connection inside a frame "
                        f"({self._decoder.buffered} bytes of it received)"
                    )
                raise EOFError("the daemon closed the connection")
            self.bytes_received += len(data)
            self._decoder.push(data)

    def _read_message(self) -> Message | None:
        """The next message to yield, or None for one skipped."""
        message = self._receive()
        if self._expect_hello:
            self._check_first(message)
            return message
        if self._awaiting is not None:
            if isinstance(message, Session):
                if self._sessions_to_skip == 0 or message.options.same_options(self._awaiting):
                    self._awaiting = None
                    self._sessions_to_skip = 0
                    return message
                self._sessions_to_skip -= 1
            if not isinstance(message, (Stats, Goodbye)):
                self.skipped += 1
                return None
        if not self._admitted(message):
            # Sent before the daemon read a narrower filter.
            self.filtered += 1
            return None
        return message

    def _admitted(self, message: Message) -> bool:
        """Whether the current options let ``message`` through (its object, and for a Body
        whether bodies are asked for)."""
        if isinstance(message, Body):
            return self.options.admits_body(message.object_id)
        if isinstance(message, (Shape, Pose, Remove)):
            return self.options.admits(message.object_id)
        return True

    def _check_first(self, message: Message) -> None:
        self._expect_hello = False
        if isinstance(message, Goodbye):
            self.close()
            raise Refused(f"the daemon refused this client: {message.reason}")
        if not isinstance(message, Hello):
            raise WireError(f"the first message is {type(message).__name__}, not Hello")
        if message.protocol_version not in SUPPORTED_VERSIONS:
            self.close()
            raise VersionMismatch(
                f"the daemon ({message.server}) speaks protocol version "
                f"{message.protocol_version}; this client speaks version {PROTOCOL_VERSION}"
            )
        self.hello = message
        if self.send_subscribe:
            differs = not self.options.same_options(DEFAULT_OPTIONS)
            if differs:
                # The daemon's first snapshot (under the defaults) comes before it reads this.
                self._awaiting = replace(self.options, resend=True)
                self._sessions_to_skip = 1
            assert self._sock is not None
            try:
                self._sock.sendall(encode_subscribe(replace(self.options, resend=differs)))
            except OSError as error:
                log.debug("sending Subscribe failed: %s", error)

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()
