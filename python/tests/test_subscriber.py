"""The Subscriber against a scripted fake daemon: the Hello check, the Subscribe it sends and
the snapshot it takes the scene from, bodies, changing options, reconnection."""

from __future__ import annotations

import logging
import socket
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tacmesh import (
    DEFAULT_OPTIONS,
    PROTOCOL_VERSION,
    Body,
    BodyProxy,
    Encoding,
    Goodbye,
    Hello,
    Hull,
    Kinds,
    Pose,
    Refused,
    Remove,
    Session,
    Shape,
    SnapshotDone,
    Stats,
    Subscribe,
    Subscriber,
    VersionMismatch,
    WireError,
)
from tacmesh.wire import (
    FIRST_SUPPORT_ID,
    SHAPE_SUPPORT,
    AnyMessage,
    FrameDecoder,
    UnknownKind,
    encode,
    inertia_matrix,
)

HELLO = Hello(PROTOCOL_VERSION, "fake tacmesh")


def shape(object_id: int, version: int = 1, encoding: Encoding = Encoding.FULL) -> Shape:
    pose = Pose(object_id, version, 10, 20, 10, translation=(1.0, 0.0, 0.0))
    return Shape(
        pose=pose,
        shape_time_ns=10,
        shape_time_realtime_ns=20,
        flags=SHAPE_SUPPORT if object_id >= FIRST_SUPPORT_ID else 0,
        faces_in=1,
        faces_out=1,
        max_residual_m=0.0,
        vertices=np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]], np.float32),
        triangles=np.array([[0, 1, 2]], np.uint32),
        encoding=encoding,
    )


def body(object_id: int, version: int = 1) -> Body:
    """A tetrahedron's shadow volume, its own single hull."""
    vertices = np.array([[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]], np.float32)
    triangles = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]], np.uint32)
    return Body(
        object_id=object_id,
        shape_version=version,
        proxy=BodyProxy.SHADOW_VOLUME,
        margin_m=0.0,
        volume_m3=1e-3 / 6,
        centre_of_mass=np.full(3, 0.025, np.float32),
        inertia=inertia_matrix(1e-5, 1e-5, 1e-5, 0.0, 0.0, 0.0),
        vertices=vertices,
        triangles=triangles,
        hulls=(Hull(vertices, triangles.astype(np.uint8)),),
    )


class Peer:
    """The fake daemon's side of one connection."""

    def __init__(self, connection: socket.socket) -> None:
        self.connection = connection
        self.connection.settimeout(5)
        self.decoder = FrameDecoder("client")
        #: What the client sent.
        self.received: list[AnyMessage] = []

    def send(self, *messages: AnyMessage) -> None:
        self.connection.sendall(b"".join(encode(m) for m in messages))

    def send_bytes(self, data: bytes) -> None:
        self.connection.sendall(data)

    def receive(self) -> AnyMessage:
        while (message := self.decoder.next_message()) is None:
            data = self.connection.recv(65536)
            if not data:
                raise EOFError("the client closed the connection")
            self.decoder.push(data)
        self.received.append(message)
        return message


Script = Callable[[Peer], None]


class FakeDaemon:
    """Serves one script per connection, in order, on a Unix socket."""

    def __init__(self, path: Path, *scripts: Script) -> None:
        self.path = path
        self.peers: list[Peer] = []
        self.errors: list[BaseException] = []
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self.listener.bind(str(path))
        self.listener.listen(4)
        self.thread = threading.Thread(target=self._serve, args=(scripts,), daemon=True)
        self.thread.start()

    def _serve(self, scripts: tuple[Script, ...]) -> None:
        try:
            for script in scripts:
                connection, _ = self.listener.accept()
                peer = Peer(connection)
                self.peers.append(peer)
                try:
                    script(peer)
                finally:
                    connection.close()
        except BaseException as error:  # reported by join()
            self.errors.append(error)
        finally:
            self.listener.close()

    def join(self) -> None:
        self.thread.join(timeout=10)
        assert not self.thread.is_alive(), "the fake daemon's script did not finish"
        if self.errors:
            raise self.errors[0]


@pytest.fixture
def sock(tmp_path: Path) -> Iterator[Path]:
    yield tmp_path / "d.sock"


def wait_for_close(peer: Peer) -> None:
    """Until the client closes its side."""
    try:
        while peer.connection.recv(65536):
            pass
    except OSError:
        pass


def test_a_server_of_another_version_is_refused_saying_both_versions(sock: Path) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(Hello(9, "tacmesh 9")))
    with pytest.raises(VersionMismatch, match=r"version 9.*version 3"):
        next(iter(Subscriber(sock, reconnect=False, timeout_s=5)))
    daemon.join()


def test_a_version_2_server_is_refused(sock: Path) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(Hello(2, "tacmesh 0.1.0")))
    with pytest.raises(VersionMismatch, match=r"version 2; this client speaks version 3"):
        next(iter(Subscriber(sock, reconnect=False, timeout_s=5)))
    daemon.join()


def test_a_goodbye_instead_of_the_hello_is_a_refusal_with_its_reason(sock: Path) -> None:
    reason = "uid 1000 is not in socket.allow_users"
    daemon = FakeDaemon(sock, lambda peer: peer.send(Goodbye(reason)))
    with pytest.raises(Refused, match="allow_users"):
        next(iter(Subscriber(sock, timeout_s=5)))
    daemon.join()


def test_garbage_from_the_server_is_an_error_not_skipped(sock: Path) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send_bytes(b"\x05\x00\x00\x00\x42junk"))
    with pytest.raises(UnknownKind, match="unknown message kind 0x42"):
        next(iter(Subscriber(sock, timeout_s=5)))
    daemon.join()


def test_a_first_message_other_than_hello_is_an_error(sock: Path) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(SnapshotDone()))
    with pytest.raises(WireError, match="not Hello"):
        next(iter(Subscriber(sock, reconnect=False, timeout_s=5)))
    daemon.join()


def test_with_the_default_options_the_first_snapshot_is_the_scene(sock: Path) -> None:
    def script(peer: Peer) -> None:
        peer.send(HELLO, Session(100, 200), shape(1), shape(FIRST_SUPPORT_ID), SnapshotDone())
        assert peer.receive() == DEFAULT_OPTIONS
        peer.send(replace(shape(1).pose, pose_time_ns=50, last_seen_ns=60), Remove(1))

    daemon = FakeDaemon(sock, script)
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        seen = [type(m) for m in sub]
    daemon.join()
    assert seen == [Hello, Session, Shape, Shape, SnapshotDone, Pose, Remove]
    assert sub.hello == HELLO and sub.skipped == 0
    assert set(sub.scene.objects) == {FIRST_SUPPORT_ID} and sub.scene.complete


def test_other_options_are_subscribed_with_resend_and_the_answer_is_the_scene(
    sock: Path,
) -> None:
    wanted = Subscribe(Encoding.COMPACT, True, 5.0, Kinds.OBJECTS, ())

    def script(peer: Peer) -> None:
        # The first snapshot, under the defaults, goes out before the Subscribe is read.
        peer.send(HELLO, Session(1, 2), shape(1), shape(FIRST_SUPPORT_ID), SnapshotDone())
        peer.send(replace(shape(1).pose, pose_time_ns=11, last_seen_ns=11))
        assert peer.receive() == wanted
        answer = replace(wanted, resend=False)
        peer.send(Stats(frames_in=5))
        peer.send(Session(3, 4, answer), shape(1, 2, Encoding.COMPACT), SnapshotDone())
        peer.send(replace(shape(1, 2).pose, pose_time_ns=12, last_seen_ns=12))
        peer.send(Goodbye("SIGTERM received"))

    daemon = FakeDaemon(sock, script)
    with Subscriber(
        sock, encoding="compact", max_rate_hz=5, kinds="objects", reconnect=False, timeout_s=5
    ) as sub:
        messages = list(sub)
    daemon.join()
    assert [type(m) for m in messages] == [
        Hello,
        Stats,
        Session,
        Shape,
        SnapshotDone,
        Pose,
        Goodbye,
    ]
    assert sub.skipped == 5
    session = messages[2]
    assert isinstance(session, Session) and session.options.encoding is Encoding.COMPACT
    held = sub.scene.objects[1]
    assert held.shape.encoding is Encoding.COMPACT and held.pose_time_ns == 12
    assert set(sub.scene.objects) == {1}


def test_changing_options_and_asking_for_a_resend_mid_stream(sock: Path) -> None:
    def script(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(1), shape(2), shape(FIRST_SUPPORT_ID))
        peer.send(SnapshotDone())
        assert peer.receive() == DEFAULT_OPTIONS
        # The client narrows its filter without a resend ...
        assert peer.receive() == Subscribe(kinds=Kinds.SUPPORTS)
        # ... and a Shape sent before the server read it is not taken.
        peer.send(shape(2, 2), shape(FIRST_SUPPORT_ID, 2))
        # Then it asks for a fresh snapshot of objects 1 and 2.
        asked = peer.receive()
        assert asked == Subscribe(resend=True, object_ids=(1, 2))
        peer.send(shape(2, 3), Session(5, 6, replace(asked, resend=False)), shape(1), shape(2))
        peer.send(SnapshotDone())
        wait_for_close(peer)

    daemon = FakeDaemon(sock, script)
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        for message in sub:
            if isinstance(message, SnapshotDone) and sub.scene.session == Session(1, 2):
                assert len(sub.scene.objects) == 3
                sub.subscribe(kinds="supports", resend=False)
                assert set(sub.scene.objects) == {FIRST_SUPPORT_ID}
            if isinstance(message, Shape) and message.object_id == FIRST_SUPPORT_ID:
                if message.shape_version == 2:
                    sub.subscribe(kinds=("objects", "supports", "bodies"), object_ids=[1, 2])
            session = sub.scene.session
            if isinstance(message, SnapshotDone) and session and session.monotonic_ns == 5:
                break
    daemon.join()
    assert set(sub.scene.objects) == {1, 2} and sub.scene.complete
    assert sub.scene.objects[2].shape_version == 1
    assert (sub.skipped, sub.filtered) == (1, 1)


def test_bodies_are_asked_for_by_default_and_kept_beside_their_shapes(sock: Path) -> None:
    def script(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(1), body(1), shape(2), SnapshotDone())
        assert peer.receive() == DEFAULT_OPTIONS
        assert DEFAULT_OPTIONS.kinds is Kinds.ALL and int(DEFAULT_OPTIONS.kinds) == 7
        peer.send(body(9), Stats())  # of an object the client does not hold: stale

    daemon = FakeDaemon(sock, script)
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        seen = [type(m) for m in sub]
    daemon.join()
    assert seen == [Hello, Session, Shape, Body, Shape, SnapshotDone, Body, Stats]
    held = sub.scene.objects[1]
    assert held.body is not None and held.body.volume_m3 == pytest.approx(1e-3 / 6)
    proxy = held.world_proxy
    assert proxy is not None
    # The shape's pose, a translation by (1, 0, 0), places the body too.
    np.testing.assert_allclose(proxy.vertices, held.body.vertices + [1, 0, 0], atol=1e-7)
    assert sub.scene.objects[2].body is None and sub.scene.stale == 1


def test_a_client_that_stops_asking_for_bodies_forgets_them(sock: Path) -> None:
    without_bodies = Subscribe(kinds=Kinds.OBJECTS | Kinds.SUPPORTS)

    def script(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(1), body(1), SnapshotDone())
        assert peer.receive() == DEFAULT_OPTIONS
        assert peer.receive() == without_bodies
        # Sent before the server read the new options: not taken.
        peer.send(body(1, 1), Stats())

    daemon = FakeDaemon(sock, script)
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        for message in sub:
            if isinstance(message, SnapshotDone):
                assert sub.scene.objects[1].body is not None
                sub.subscribe(kinds=("objects", "supports"), resend=False)
                assert sub.scene.objects[1].body is None
    daemon.join()
    assert sub.filtered == 1 and sub.scene.objects[1].body is None


def test_resend_asks_for_a_fresh_snapshot_of_the_same_options(sock: Path) -> None:
    def script(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(1), SnapshotDone())
        peer.receive()
        assert peer.receive() == Subscribe(resend=True)
        peer.send(Session(3, 4), shape(1), SnapshotDone())

    daemon = FakeDaemon(sock, script)
    sessions = 0
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        for message in sub:
            sessions += isinstance(message, Session)
            if isinstance(message, SnapshotDone) and sessions == 1:
                sub.resend()
    daemon.join()
    assert sessions == 2 and sub.scene.complete and set(sub.scene.objects) == {1}


def test_a_lost_daemon_is_reconnected_to_and_the_options_sent_again(
    sock: Path, caplog: pytest.LogCaptureFixture
) -> None:
    wanted = Subscribe(Encoding.COMPACT, resend=True)

    def first(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(1), SnapshotDone())
        assert peer.receive() == wanted
        peer.send(Session(3, 4, replace(wanted, resend=False)), shape(1), SnapshotDone())
        peer.send(Goodbye("restarting"))

    def second(peer: Peer) -> None:
        # Closes in the middle of a frame, as the daemon drops a client that does not read.
        peer.send(HELLO, Session(1, 2))
        assert peer.receive() == wanted
        peer.send_bytes(encode(shape(5))[:20])

    def third(peer: Peer) -> None:
        peer.send(HELLO, Session(1, 2), shape(3), SnapshotDone())
        assert peer.receive() == wanted
        peer.send(Session(3, 4, replace(wanted, resend=False)), shape(2), SnapshotDone())
        wait_for_close(peer)

    daemon = FakeDaemon(sock, first, second, third)
    caplog.set_level(logging.WARNING, logger="tacmesh")
    seen: list[type] = []
    with Subscriber(sock, encoding="compact", timeout_s=5, backoff_s=0.01) as sub:
        for message in sub:
            seen.append(type(message))
            if sub.connections == 3 and isinstance(message, SnapshotDone):
                break
    daemon.join()
    assert seen.count(Hello) == 3 and Goodbye in seen
    assert set(sub.scene.objects) == {2} and sub.scene.complete
    assert "reconnecting" in caplog.text and "Goodbye (restarting)" in caplog.text
    assert "inside a frame" in caplog.text


def test_without_reconnect_the_end_of_the_connection_ends_iteration(sock: Path) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(HELLO, Session(1, 2), SnapshotDone()))
    with Subscriber(sock, reconnect=False, timeout_s=5) as sub:
        assert [type(m) for m in sub] == [Hello, Session, SnapshotDone]
    daemon.join()


def test_options_are_checked() -> None:
    with pytest.raises(ValueError, match="compact"):
        Subscriber("/nonexistent", encoding="small")
    with pytest.raises(ValueError, match="objects"):
        Subscriber("/nonexistent", kinds=())
    with pytest.raises(ValueError, match="'bodies' comes only with them"):
        Subscriber("/nonexistent", kinds="bodies")
    with pytest.raises(ValueError, match="'objects', 'supports' or 'bodies'"):
        Subscriber("/nonexistent", kinds="hulls")
    assert Subscriber("/nonexistent").options == DEFAULT_OPTIONS
    assert Subscriber("/nonexistent", kinds=("supports", "bodies")).options.kinds == 6
    for rate in (-1.0, 1e-45, 0.001, 1e5, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="max_rate_hz"):
            Subscriber("/nonexistent", max_rate_hz=rate)
    assert Subscriber("/nonexistent", max_rate_hz=0.01).options.max_rate_hz == 0.01
