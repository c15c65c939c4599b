"""Subscribing to a running daemon over its Unix socket, and keeping the current scene.

>>> from tacmesh import Subscriber, Scene
>>> scene = Scene()
>>> for message in Subscriber("/run/tacmesh/tacmesh.sock"):  # doctest: +SKIP
...     scene.apply(message)
...     print(len(scene.objects), "objects")
"""

from __future__ import annotations

import socket
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from .wire import (
    SUPPORTED_VERSIONS,
    FrameDecoder,
    Goodbye,
    Hello,
    Message,
    ProtocolError,
    Remove,
    SnapshotDone,
    Upsert,
    encode_subscribe,
)


class Refused(ConnectionError):
    """The daemon did not admit this client (its Goodbye instead of the Hello says why)."""


class VersionMismatch(ConnectionError):
    """The daemon speaks a protocol version this client does not read."""


class Subscriber:
    """The daemon's messages, in order, as an iterator.

    The first message of every connection is a :class:`~tacmesh.wire.Hello` (checked: a version
    this client does not read raises :class:`VersionMismatch`), then the snapshot's Upserts,
    SnapshotDone, and updates. With ``reconnect`` (the default), a lost connection or the
    daemon's Goodbye is followed by new attempts with exponential backoff (``backoff_s`` doubling
    up to ``max_backoff_s``), and the next connection starts again with its Hello and a full
    snapshot (:class:`Scene` starts afresh on a Hello). Without it, iteration ends after a
    Goodbye or when the connection closes. A frame that breaks the protocol raises
    :class:`~tacmesh.wire.ProtocolError` either way: a daemon sending garbage is not retried.

    ``timeout_s`` bounds each wait for data (None: wait for ever); a timeout raises
    :class:`TimeoutError`.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        reconnect: bool = True,
        timeout_s: float | None = None,
        backoff_s: float = 0.1,
        max_backoff_s: float = 5.0,
        send_subscribe: bool = True,
    ) -> None:
        self.path = Path(path)
        self.reconnect = reconnect
        self.timeout_s = timeout_s
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self.send_subscribe = send_subscribe
        #: Connections made so far.
        self.connections = 0
        self._sock: socket.socket | None = None
        self._decoder = FrameDecoder()
        self._expect_hello = True
        self._finished = False

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
            except (TimeoutError, Refused, VersionMismatch):
                self.close()
                raise
            except (OSError, EOFError):
                # Not there yet, gone, or restarting: worth waiting for, unless told not to.
                self.close()
                if not self.reconnect:
                    self._finished = True
                    raise StopIteration from None
                time.sleep(delay)
                delay = min(2 * delay, self.max_backoff_s)
                continue
            if isinstance(message, Goodbye):
                self.close()
                self._finished = not self.reconnect
            return message

    def _connect(self) -> None:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(self.timeout_s)
            sock.connect(str(self.path))
        except BaseException:
            sock.close()
            raise
        self._sock = sock
        self._decoder = FrameDecoder()
        self._expect_hello = True
        self.connections += 1

    def _read_message(self) -> Message:
        assert self._sock is not None
        while True:
            message = self._decoder.next_message()
            if message is not None:
                break
            data = self._sock.recv(65536)
            if not data:
                if self._decoder.buffered:
                    raise ProtocolError(
                        f"the connection closed inside a frame ({self._decoder.buffered} bytes)"
                    )
                raise EOFError("the daemon closed the connection")
            self._decoder.push(data)
        if self._expect_hello:
            self._expect_hello = False
            if isinstance(message, Goodbye):
                self.close()
                raise Refused(f"the daemon refused this client: {message.reason}")
            if not isinstance(message, Hello):
                raise ProtocolError(f"the first message is {type(message).__name__}, not Hello")
            if message.protocol_version not in SUPPORTED_VERSIONS:
                self.close()
                raise VersionMismatch(
                    f"the daemon ({message.server}) speaks protocol version "
                    f"{message.protocol_version}; this client reads {sorted(SUPPORTED_VERSIONS)}"
                )
            if self.send_subscribe:
                self._sock.sendall(encode_subscribe())
        return message

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> Subscriber:
        return self

    def __exit__(self, *_: object) -> None:
        self.close()


@dataclass(frozen=True, eq=False)
class SceneObject:
    """The latest mesh of one object (or support plane), world frame, metres."""

    object_id: int
    version: int
    capture_time_ns: int
    vertices: npt.NDArray[np.float32]
    triangles: npt.NDArray[np.uint32]
    max_residual_m: float
    is_plane: bool


class Scene:
    """What the daemon says is there now: the latest Upsert of each id, forgotten on Remove.

    ``complete`` is True once the connection's snapshot has ended (SnapshotDone). A Hello
    (a new connection) empties the scene: the new snapshot replaces it whole.
    """

    def __init__(self) -> None:
        self.objects: dict[int, SceneObject] = {}
        self.complete = False

    def apply(self, message: Message) -> None:
        if isinstance(message, Hello):
            self.objects.clear()
            self.complete = False
        elif isinstance(message, Upsert):
            known = self.objects.get(message.object_id)
            if known is not None and message.version <= known.version:
                raise ProtocolError(
                    f"object {message.object_id}: version {message.version} after "
                    f"{known.version}; versions never go backwards"
                )
            self.objects[message.object_id] = SceneObject(
                object_id=message.object_id,
                version=message.version,
                capture_time_ns=message.capture_time_ns,
                vertices=message.vertices,
                triangles=message.triangles,
                max_residual_m=message.max_residual_m,
                is_plane=message.is_plane,
            )
        elif isinstance(message, Remove):
            self.objects.pop(message.object_id, None)
        elif isinstance(message, SnapshotDone):
            self.complete = True
