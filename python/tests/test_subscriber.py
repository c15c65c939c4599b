"""The Subscriber against a scripted fake daemon: the Hello check, the Subscribe it sends and
the snapshot it takes the scene from, bodies, changing options, reconnection, no daemon yet; and
who serves the socket (SO_PEERCRED), against a server of another user when run as root.
"""

from __future__ import annotations

import logging
import os
import pickle
import pwd
import shutil
import signal
import socket
import tempfile
import threading
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest

from tacmesh import (
    DEFAULT_OPTIONS,
    PROTOCOL_VERSION,
    Body,
    BodySolid,
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
    UntrustedServer,
    VersionMismatch,
    WireError,
    connect,
    trusted_uids,
)
from tacmesh import subscriber as subscriber_module
from tacmesh.subscriber import PeerCredentials, check_server, server_credentials
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
        solid=BodySolid.SHADOW_VOLUME,
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


def test_a_server_of_another_version_is_refused_saying_both_versions(
    sock: Path,
) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(Hello(9, "tacmesh 9")))
    with pytest.raises(VersionMismatch, match=r"version 9.*version 4"):
        next(iter(Subscriber(sock, reconnect=False, timeout_s=5)))
    daemon.join()


@pytest.mark.parametrize("version", [2, 3])
def test_a_server_of_an_earlier_version_is_refused(sock: Path, version: int) -> None:
    daemon = FakeDaemon(sock, lambda peer: peer.send(Hello(version, "tacmesh 0.1.0")))
    with pytest.raises(VersionMismatch, match=rf"version {version}; this client speaks version 4"):
        next(iter(Subscriber(sock, reconnect=False, timeout_s=5)))
    daemon.join()


def test_a_goodbye_instead_of_the_hello_is_a_refusal_with_its_reason(
    sock: Path,
) -> None:
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
        sock,
        encoding="compact",
        max_rate_hz=5,
        kinds="objects",
        reconnect=False,
        timeout_s=5,
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


def test_bodies_are_asked_for_by_default_and_kept_beside_their_shapes(
    sock: Path,
) -> None:
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
    solid = held.world_solid
    assert solid is not None
    # The shape's pose, a translation by (1, 0, 0), places the body too.
    np.testing.assert_allclose(solid.vertices, held.body.vertices + [1, 0, 0], atol=1e-7)
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
    assert f"connected to the daemon at {sock} again" in caplog.text
    assert "no daemon" not in caplog.text


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


# ---- no daemon at the path ------------------------------------------------------------------


def test_without_reconnect_no_socket_is_an_error_saying_so(tmp_path: Path) -> None:
    path = tmp_path / "never.sock"
    with pytest.raises(FileNotFoundError, match="no such socket") as raised:
        next(iter(Subscriber(path, reconnect=False, timeout_s=5)))
    message = str(raised.value)
    assert str(path) in message and "is the daemon running?" in message, message
    assert "tacmesh run" in message and "systemctl status tacmesh" in message, message


def test_without_reconnect_a_socket_nobody_listens_on_is_an_error_saying_so(
    tmp_path: Path,
) -> None:
    path = tmp_path / "stale.sock"
    stale = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    stale.bind(str(path))  # bound, not listening: a daemon that died without removing it
    try:
        with pytest.raises(ConnectionRefusedError, match="nothing listens") as raised:
            next(iter(Subscriber(path, reconnect=False, timeout_s=5)))
    finally:
        stale.close()
    assert str(path) in str(raised.value) and "tacmesh run" in str(raised.value)


def test_with_reconnect_no_daemon_yet_is_one_warning_then_the_connection(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    path = tmp_path / "later.sock"
    started: list[FakeDaemon] = []
    # The daemon comes 0.4 s later: about six attempts in between (backoff from 0.01 s).
    timer = threading.Timer(
        0.4, lambda: started.append(FakeDaemon(path, lambda peer: peer.send(HELLO)))
    )
    caplog.set_level(logging.INFO, logger="tacmesh")
    timer.start()
    try:
        with Subscriber(path, timeout_s=5, backoff_s=0.01) as sub:
            assert next(iter(sub)) == HELLO
    finally:
        timer.join()
    started[0].join()
    lines = [r.getMessage() for r in caplog.records if r.name == "tacmesh"]
    assert lines == [
        f"tacmesh: no daemon at {path} yet (no such socket); waiting for one to start "
        "(`tacmesh run`, or `systemctl status tacmesh`)",
        f"tacmesh: connected to the daemon at {path}",
    ], lines


# ---- who serves the socket ------------------------------------------------------------------

T = TypeVar("T")


def within(seconds: float, call: Callable[[], T]) -> T:
    """``call()``'s result or exception, failing (not hanging) if it takes over ``seconds``."""
    outcome: list[T] = []
    errors: list[BaseException] = []

    def run() -> None:
        try:
            outcome.append(call())
        except BaseException as error:  # re-raised below
            errors.append(error)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(seconds)
    assert not thread.is_alive(), f"still running after {seconds} s (retrying for ever?)"
    if errors:
        raise errors[0]
    return outcome[0]


def test_the_trusted_users_are_me_root_the_service_user_and_those_given(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    service = pwd.struct_passwd(("tacmesh", "x", 990, 990, "", "/", "/usr/sbin/nologin"))
    mallory = pwd.struct_passwd(("mallory", "x", 1234, 1234, "", "/home/m", "/bin/sh"))

    def getpwnam(name: str) -> pwd.struct_passwd:
        if name == "tacmesh":
            return service
        raise KeyError(name)

    def getpwuid(uid: int) -> pwd.struct_passwd:
        if uid == 1234:
            return mallory
        raise KeyError(uid)

    monkeypatch.setattr(os, "geteuid", lambda: 1000)
    monkeypatch.setattr(pwd, "getpwnam", getpwnam)
    monkeypatch.setattr(pwd, "getpwuid", getpwuid)
    assert trusted_uids() == {1000, 0, 990}
    assert trusted_uids([1234, 5678]) == {1000, 0, 990, 1234, 5678}
    for uid in (1000, 0, 990):
        check_server("/run/tacmesh/tacmesh.sock", PeerCredentials(1, uid, uid))
    check_server("/x.sock", PeerCredentials(1, 1234, 1234), trust_uids=[1234])
    with pytest.raises(UntrustedServer) as raised:
        check_server("/run/tacmesh/tacmesh.sock", PeerCredentials(4242, 1234, 1234))
    error = raised.value
    assert isinstance(error, ConnectionError)
    assert (error.uid, error.user, error.pid) == (1234, "mallory", 4242)
    assert str(pickle.loads(pickle.dumps(error))) == str(error)
    assert str(error) == (
        "the socket /run/tacmesh/tacmesh.sock is served by uid 1234 (mallory), pid 4242, not by "
        "you (uid 1000), root or the tacmesh service user: another local user may be "
        "impersonating the daemon; pass trust_uids=[1234] if you meant to connect to it"
    )
    # A uid without a name, and a host without the service user.
    with pytest.raises(UntrustedServer, match=r"served by uid 5678, pid 7, not by you"):
        check_server("/x.sock", PeerCredentials(7, 5678, 5678))
    monkeypatch.setattr(pwd, "getpwnam", lambda name: getpwnam("not " + name))
    assert trusted_uids() == {1000, 0}
    with pytest.raises(UntrustedServer):
        check_server("/x.sock", PeerCredentials(1, 990, 990))


def test_an_untrusted_server_is_not_retried_with_reconnect(
    sock: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The fake daemon runs as this user: make it look like someone else's.
    monkeypatch.setattr(
        subscriber_module,
        "server_credentials",
        lambda _: PeerCredentials(4242, 54321, 54321),
    )
    daemon = FakeDaemon(sock, wait_for_close)
    sub = Subscriber(sock, timeout_s=5, backoff_s=0.01)
    with pytest.raises(UntrustedServer, match=r"uid 54321.*trust_uids=\[54321\]"):
        within(10, lambda: next(iter(sub)))
    assert sub.connections == 0 and sub._sock is None
    daemon.join()
    # Trusted, it is the daemon.
    trusted = sock.with_name("trusted.sock")
    daemon = FakeDaemon(trusted, lambda peer: peer.send(HELLO))
    with Subscriber(trusted, reconnect=False, timeout_s=5, trust_uids=[54321]) as sub:
        assert next(iter(sub)) == HELLO
    daemon.join()


NOBODY = 65534


class ServerOfAnotherUser:
    """A process that serves a Hello on a Unix socket as ``uid`` (root forks it and it drops to
    that user before it listens, so that SO_PEERCRED names it), in a directory of its own.
    """

    def __init__(self, uid: int) -> None:
        self.directory = Path(tempfile.mkdtemp(prefix="tacmesh-peercred-"))
        # Only that user may write there (root still may, as root).
        os.chown(self.directory, uid, uid)
        os.chmod(self.directory, 0o755)
        self.path = self.directory / "tacmesh.sock"
        hello = encode(HELLO)
        ready, told = os.pipe()
        self.pid = os.fork()
        if self.pid == 0:  # the child: system calls only, and never back into pytest
            try:
                os.close(ready)
                os.setgroups([])
                os.setgid(uid)
                os.setuid(uid)
                listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
                listener.bind(str(self.path))
                listener.listen(4)
                os.write(told, b"1")
                while True:
                    connection, _ = listener.accept()
                    connection.settimeout(5)
                    try:
                        connection.sendall(hello)
                        while connection.recv(65536):
                            pass
                    except OSError:
                        pass
                    connection.close()
            finally:
                os._exit(1)
        os.close(told)
        try:
            assert os.read(ready, 1) == b"1", f"the server as uid {uid} did not start"
        except BaseException:
            self.stop()
            raise
        finally:
            os.close(ready)

    def stop(self) -> None:
        os.kill(self.pid, signal.SIGKILL)
        os.waitpid(self.pid, 0)
        shutil.rmtree(self.directory, ignore_errors=True)


@pytest.mark.skipif(
    os.geteuid() != 0,
    reason="needs root: it serves the socket as another user (nobody, uid 65534), and only root "
    "can become another user",
)
def test_a_server_of_another_user_is_refused_unless_trusted() -> None:
    server = ServerOfAnotherUser(NOBODY)
    try:
        path = server.path
        with pytest.raises(UntrustedServer) as raised:
            next(iter(Subscriber(path, reconnect=False, timeout_s=5)))
        error = raised.value
        assert (error.uid, error.pid, error.path) == (NOBODY, server.pid, path)
        name = subscriber_module.user_name(NOBODY)
        who = f"uid {NOBODY}" + (f" ({name})" if name is not None else "")
        message = str(error)
        assert f"the socket {path} is served by {who}, pid {server.pid}" in message, message
        assert f"pass trust_uids=[{NOBODY}]" in message, message
        # With reconnect too: raised, not retried.
        with pytest.raises(UntrustedServer):
            within(10, lambda: next(iter(Subscriber(path, timeout_s=5, backoff_s=0.01))))
        with pytest.raises(UntrustedServer):
            connect(path, timeout_s=5)
        # Trusted, it is read.
        with Subscriber(path, reconnect=False, timeout_s=5, trust_uids=[NOBODY]) as sub:
            assert next(iter(sub)) == HELLO
        with connect(path, timeout_s=5, trust_uids=[NOBODY]) as connection:
            assert server_credentials(connection) == (server.pid, NOBODY, NOBODY)
    finally:
        server.stop()


def test_a_server_of_my_own_user_is_trusted(sock: Path) -> None:
    daemon = FakeDaemon(sock, wait_for_close)
    with connect(sock, timeout_s=5) as connection:
        credentials = server_credentials(connection)
        assert credentials.uid == os.geteuid() and credentials.pid == os.getpid()
    daemon.join()
