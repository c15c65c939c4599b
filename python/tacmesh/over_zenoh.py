"""The daemon's objects over Zenoh, from another machine (the daemon's ``[zenoh]`` section;
docs/operating.md, "Across the network"). Needs the ``eclipse-zenoh`` package
(``pip install './python[zenoh]'``).

Every sample carries one frame of docs/protocol.md; the keys are, under ``tacmesh/<robot>``:
``objects/<id>/shape``, ``objects/<id>/body``, ``objects/<id>/pose``, ``objects/<id>/removed``
and ``stats``. A query on ``tacmesh/<robot>/objects/**`` answers with the current scene, which
:class:`ZenohSubscriber` yields first (its Shapes, then the Bodies and the Poses newer than
them, then ``SnapshotDone``), then every sample as it comes, keeping
:attr:`ZenohSubscriber.scene` (whose rules hold wherever Shapes and Bodies travel apart).
"""

from __future__ import annotations

import json
import queue
import re
from collections import deque
from collections.abc import Iterator, Sequence
from types import TracebackType
from typing import Any

from .subscriber import Scene
from .wire import (
    FrameDecoder,
    Message,
    Shape,
    SnapshotDone,
    Subscribe,
    SubscribeV1,
    WireError,
)

#: A robot name: letters, digits, ``-`` and ``_`` (it is part of every key expression).
ROBOT_NAME = re.compile(r"^[A-Za-z0-9_-]+$")


def decode_sample(key: str, payload: bytes) -> list[Message]:
    """The frames one sample carries; a :class:`WireError` naming the key if it is not whole
    frames of the protocol."""
    decoder = FrameDecoder("server")
    decoder.push(payload)
    messages: list[Message] = []
    try:
        while (message := decoder.next_message()) is not None:
            if isinstance(message, (Subscribe, SubscribeV1)):  # the decoder refuses these
                raise WireError(f"a client's message: {message}")
            messages.append(message)
    except WireError as error:
        raise WireError(f"the sample on {key}: {error}") from error
    if decoder.buffered:
        raise WireError(f"the sample on {key} ends inside a frame ({decoder.buffered} bytes)")
    return messages


class ZenohSubscriber:
    """Joins Zenoh (``connect`` endpoints such as ``tcp/192.0.2.10:7447``, multicast scouting
    off unless a ``config_file`` turns it on), asks for the scene of ``robot``, then yields its
    messages. ``timeout_s`` bounds each wait for a sample (``TimeoutError``); ``None`` waits for
    ever."""

    def __init__(
        self,
        robot: str,
        connect: Sequence[str],
        *,
        mode: str = "peer",
        config_file: str | None = None,
        query_timeout_s: float = 5.0,
        timeout_s: float | None = None,
    ) -> None:
        if not ROBOT_NAME.match(robot):
            raise ValueError(f"robot name {robot!r}: use letters, digits, '-' and '_' only")
        try:
            import zenoh
        except ImportError as error:
            raise ImportError(
                "reading over Zenoh needs the eclipse-zenoh package: pip install './python[zenoh]'"
            ) from error
        config = zenoh.Config.from_file(config_file) if config_file else zenoh.Config()
        config.insert_json5("mode", json.dumps(mode))
        config.insert_json5("connect/endpoints", json.dumps(list(connect)))
        if config_file is None:
            config.insert_json5("scouting/multicast/enabled", "false")
        self.robot = robot
        self.timeout_s = timeout_s
        self.scene = Scene()
        self._samples: queue.Queue[tuple[str, bytes]] = queue.Queue()
        self._session: Any = zenoh.open(config)
        prefix = f"tacmesh/{robot}"

        def on_sample(sample: Any) -> None:
            self._samples.put((str(sample.key_expr), sample.payload.to_bytes()))

        # Subscribed before the query, so that nothing published meanwhile is missed (an
        # update that the scene's answer already holds is applied again, harmlessly: the
        # scene keeps the newest version).
        self._subscriber: Any = self._session.declare_subscriber(f"{prefix}/**", on_sample)
        shapes: list[Message] = []
        others: list[Message] = []
        replies = self._session.get(
            f"{prefix}/objects/**",
            consolidation=zenoh.ConsolidationMode.NONE,
            timeout=query_timeout_s,
        )
        for reply in replies:
            sample = reply.ok
            if sample is None:
                continue
            for message in decode_sample(str(sample.key_expr), sample.payload.to_bytes()):
                (shapes if isinstance(message, Shape) else others).append(message)
        self._pending: deque[Message] = deque(shapes + others)
        self._pending.append(SnapshotDone())

    def __iter__(self) -> Iterator[Message]:
        return self

    def __next__(self) -> Message:
        while not self._pending:
            try:
                key, payload = self._samples.get(timeout=self.timeout_s)
            except queue.Empty:
                raise TimeoutError(f"no sample from robot {self.robot!r} in {self.timeout_s} s")
            self._pending.extend(decode_sample(key, payload))
        message = self._pending.popleft()
        self.scene.apply(message)
        return message

    def close(self) -> None:
        self._subscriber.undeclare()
        self._session.close()

    def __enter__(self) -> ZenohSubscriber:
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self.close()
