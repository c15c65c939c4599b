"""The client against the real daemon on the simulated scene (`tacmesh run --sensor sim:demo`).

The daemon binary is TACMESH_BIN, or the repository's target/debug or target/release build
(`cargo build` first); the test fails, not skips, without one.
"""

from __future__ import annotations

import os
import socket
import struct
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tacmesh import (
    Goodbye,
    Hello,
    ProtocolError,
    Scene,
    SnapshotDone,
    Stats,
    Subscriber,
    Upsert,
    VersionMismatch,
)

REPO = Path(__file__).resolve().parents[2]


def daemon_binary() -> Path:
    named = os.environ.get("TACMESH_BIN")
    candidates = [Path(named)] if named else []
    candidates += [REPO / "target" / "debug" / "tacmesh", REPO / "target" / "release" / "tacmesh"]
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise AssertionError(
        f"no tacmesh binary among {[str(c) for c in candidates]}: run `cargo build` first"
    )


class Daemon:
    def __init__(self, socket_path: Path) -> None:
        self.socket_path = socket_path
        self.process = subprocess.Popen(
            [str(daemon_binary()), "run", "--sensor", "sim:demo", "--socket", str(socket_path)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + 30
        while not socket_path.exists():
            assert self.process.poll() is None, "the daemon exited at start"
            assert time.monotonic() < deadline, "the daemon's socket did not appear"
            time.sleep(0.05)

    def stop(self) -> None:
        self.process.terminate()
        self.process.wait(timeout=30)


@pytest.fixture
def daemon(tmp_path: Path) -> Iterator[Daemon]:
    running = Daemon(tmp_path / "tacmesh.sock")
    yield running
    if running.process.poll() is None:
        running.stop()


def test_the_demo_scene_arrives_as_numpy_meshes_with_stats(daemon: Daemon) -> None:
    scene = Scene()
    stats: list[Stats] = []
    first: object = None
    started = time.monotonic()
    with Subscriber(daemon.socket_path, reconnect=False, timeout_s=10) as subscriber:
        for message in subscriber:
            first = first or message
            scene.apply(message)
            if isinstance(message, Stats):
                stats.append(message)
            if scene.complete and stats and time.monotonic() - started > 3:
                break
    assert isinstance(first, Hello) and first.protocol_version == 1
    objects = [o for o in scene.objects.values() if not o.is_plane]
    planes = [o for o in scene.objects.values() if o.is_plane]
    assert len(objects) >= 3, f"{len(objects)} objects"
    assert len(planes) >= 1, "no support plane"
    for o in objects:
        assert o.vertices.dtype == np.float32 and o.vertices.ndim == 2
        assert o.vertices.shape[1] == 3 and o.triangles.shape[1] == 3
        assert len(o.triangles) > 0
        assert int(o.triangles.max()) < len(o.vertices)
        # The demo's objects stand on a table within a few metres of the camera.
        assert float(np.abs(o.vertices).max()) < 5.0
    # Capture times are on the host's CLOCK_MONOTONIC: the data is fresh.
    newest_ns = max(o.capture_time_ns for o in objects)
    assert time.monotonic_ns() - newest_ns < 10 * 10**9
    assert stats[-1].frames_in > 0
    assert {s.stage for s in stats[-1].stages} >= {"segment", "integrate"}


def test_a_restarted_daemon_is_reconnected_to_with_a_fresh_snapshot(tmp_path: Path) -> None:
    socket_path = tmp_path / "tacmesh.sock"
    first = Daemon(socket_path)
    second: Daemon | None = None
    seen: list[object] = []
    scene = Scene()
    with Subscriber(socket_path, timeout_s=30, backoff_s=0.05) as subscriber:
        for message in subscriber:
            scene.apply(message)
            seen.append(type(message))
            if isinstance(message, SnapshotDone) and subscriber.connections == 1:
                first.stop()
            if isinstance(message, Goodbye):
                second = Daemon(socket_path)
            # The new daemon starts empty: wait for its first object.
            if subscriber.connections == 2 and isinstance(message, Upsert):
                if not message.is_plane:
                    break
    assert second is not None, "no Goodbye from the first daemon"
    second.stop()
    assert Goodbye in seen
    assert seen.count(Hello) == 2
    assert scene.complete and any(not o.is_plane for o in scene.objects.values())


def fake_server(path: Path, frames: bytes) -> threading.Thread:
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(str(path))
    listener.listen(1)

    def serve() -> None:
        connection, _ = listener.accept()
        connection.sendall(frames)
        time.sleep(0.2)
        connection.close()
        listener.close()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return thread


def test_a_server_of_another_version_is_refused_clearly(tmp_path: Path) -> None:
    name = b"tacmesh 9"
    hello_v9 = struct.pack("<IBHH", 1 + 2 + 2 + len(name), 0x01, 9, len(name)) + name
    server = fake_server(tmp_path / "v9.sock", hello_v9)
    with pytest.raises(VersionMismatch, match="version 9"):
        next(iter(Subscriber(tmp_path / "v9.sock", reconnect=False, timeout_s=5)))
    server.join(timeout=5)


def test_garbage_from_the_server_is_an_error_not_skipped(tmp_path: Path) -> None:
    server = fake_server(tmp_path / "junk.sock", b"\x05\x00\x00\x00\x42junk")
    with pytest.raises(ProtocolError, match="unknown kind"):
        next(iter(Subscriber(tmp_path / "junk.sock", reconnect=False, timeout_s=5)))
    server.join(timeout=5)


def test_an_upsert_is_never_older_than_the_one_before() -> None:
    scene = Scene()
    mesh = np.zeros((3, 3), np.float32)
    tri = np.array([[0, 1, 2]], np.uint32)
    scene.apply(Upsert(1, 5, 0, 1, 1, 0.0, mesh, tri))
    with pytest.raises(ProtocolError, match="backwards"):
        scene.apply(Upsert(1, 4, 0, 1, 1, 0.0, mesh, tri))
