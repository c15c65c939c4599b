"""The client over Zenoh against the real daemon publishing on loopback (a build with the
`zenoh` feature: TACMESH_ZENOH_BIN, or TACMESH_BIN if it has it). Skipped, with the reason,
when eclipse-zenoh is not installed or no such build is named.
"""

from __future__ import annotations

import os
import socket
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from tacmesh import Body, Pose, Shape, SnapshotDone, Subscriber, ZenohSubscriber
from tacmesh.over_zenoh import decode_sample
from tacmesh.wire import WireError

pytest.importorskip("zenoh", reason="eclipse-zenoh is not installed")

ROBOT = "py-rig"


def zenoh_binary() -> Path:
    named = os.environ.get("TACMESH_ZENOH_BIN")
    if not named:
        pytest.skip("TACMESH_ZENOH_BIN names no tacmesh built with the `zenoh` feature")
    return Path(named)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.bind(("127.0.0.1", 0))
        port: int = probe.getsockname()[1]
        return port


class ZenohDaemon:
    def __init__(self, folder: Path) -> None:
        self.port = free_port()
        config = folder / "daemon.toml"
        config.write_text(f'[zenoh]\nrobot = "{ROBOT}"\nlisten = ["tcp/127.0.0.1:{self.port}"]\n')
        self.socket_path = folder / "tacmesh.sock"
        self.process = subprocess.Popen(
            [
                str(zenoh_binary()),
                "run",
                "--sensor",
                "sim:demo",
                "--config",
                str(config),
                "--socket",
                str(self.socket_path),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        deadline = time.monotonic() + 30
        while not self.socket_path.exists():
            assert self.process.poll() is None, "the daemon exited at start"
            assert time.monotonic() < deadline, "the daemon's socket did not appear"
            time.sleep(0.05)

    @property
    def endpoint(self) -> str:
        return f"tcp/127.0.0.1:{self.port}"


@pytest.fixture(scope="module")
def daemon(tmp_path_factory: pytest.TempPathFactory) -> Iterator[ZenohDaemon]:
    running = ZenohDaemon(tmp_path_factory.mktemp("zenoh-daemon"))
    try:
        # Until the socket's subscriber has the demo's objects and table.
        with Subscriber(running.socket_path, reconnect=False, timeout_s=10) as sub:
            deadline = time.monotonic() + 60
            for _ in sub:
                if sub.scene.complete and len(sub.scene.non_supports) >= 4:
                    break
                assert time.monotonic() < deadline, "the demo's objects did not appear"
        yield running
    finally:
        running.process.terminate()
        running.process.wait(timeout=30)


def test_a_late_joiner_gets_the_scene_by_query_then_the_moves(
    daemon: ZenohDaemon,
) -> None:
    with ZenohSubscriber(ROBOT, [daemon.endpoint], timeout_s=10) as sub:
        snapshot: list[object] = []
        for message in sub:
            snapshot.append(message)
            if isinstance(message, SnapshotDone):
                break
        shapes = [m for m in snapshot if isinstance(m, Shape)]
        assert len(shapes) >= 5, f"{len(shapes)} shapes in the scene's answer"
        # The scene's answer: each object's shape, its collision body when it has one (protocol
        # 3), its newer pose.
        assert all(isinstance(m, (Shape, Body, Pose)) for m in snapshot[:-1])
        bodies = [m for m in snapshot if isinstance(m, Body)]
        assert all(b.object_id in {s.object_id for s in shapes} for b in bodies)
        first = {o.object_id: np.array(o.pose.translation) for o in sub.scene.non_supports}
        moves = 0
        deadline = time.monotonic() + 5
        for message in sub:
            moves += isinstance(message, Pose)
            if time.monotonic() > deadline:
                break
        assert moves >= 30, f"only {moves} poses in 5 s"
        # Where each object's frame went (a new shape of a standing object leaves its pose).
        moved = {
            object_id: float(
                np.linalg.norm(np.array(sub.scene.objects[object_id].pose.translation) - at)
            )
            for object_id, at in first.items()
            if object_id in sub.scene.objects
        }
        # The cone slides at 0.1 m/s; the others stand still.
        assert sorted(moved.values())[-1] > 0.2, moved
        assert sorted(moved.values())[-2] < 0.01, moved


def test_the_same_objects_as_over_the_socket(daemon: ZenohDaemon) -> None:
    with ZenohSubscriber(ROBOT, [daemon.endpoint], timeout_s=10) as over_zenoh:
        for message in over_zenoh:
            if isinstance(message, SnapshotDone):
                break
        with Subscriber(daemon.socket_path, reconnect=False, timeout_s=10) as over_socket:
            for _ in over_socket:
                if over_socket.scene.complete:
                    break
        assert set(over_zenoh.scene.objects) == set(over_socket.scene.objects)
        for object_id, there in over_zenoh.scene.objects.items():
            here = over_socket.scene.objects[object_id]
            if here.shape_version == there.shape_version:
                # Compact over Zenoh (the daemon's default there), full over the socket.
                bound = there.max_residual_m - here.max_residual_m + 1e-6
                assert np.abs(there.vertices - here.vertices).max() <= bound


def test_a_sample_that_is_not_a_frame_names_its_key() -> None:
    with pytest.raises(WireError, match="tacmesh/r/objects/1/pose"):
        decode_sample("tacmesh/r/objects/1/pose", bytes([1, 2, 3, 4, 5, 6]))


def test_a_robot_name_that_cannot_be_a_key_is_refused() -> None:
    with pytest.raises(ValueError, match="robot name"):
        ZenohSubscriber("a/b", ["tcp/127.0.0.1:1"])
