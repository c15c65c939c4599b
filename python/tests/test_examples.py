"""The examples in python/examples, run against the real daemon on the simulated scene."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType

from tacmesh import Scene, Subscriber

from test_daemon import Daemon, daemon  # noqa: F401  (the fixture)

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def example(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def scene_after(daemon: Daemon, seconds: float) -> Scene:
    scene = Scene()
    deadline = time.monotonic() + seconds
    with Subscriber(daemon.socket_path, reconnect=False, timeout_s=10) as subscriber:
        for message in subscriber:
            scene.apply(message)
            if scene.complete and time.monotonic() > deadline:
                break
    return scene


def test_mujoco_a_probe_dropped_on_an_object_rests_on_its_top(daemon: Daemon) -> None:
    mujoco_scene = example("mujoco_scene")
    scene = scene_after(daemon, 3.0)
    rest, top = mujoco_scene.drop_probe(scene)
    # The probe's centre rests one radius above the object's top (the hull's top face), not
    # on the support below it and not inside the object.
    assert abs(rest - (top + mujoco_scene.PROBE_RADIUS_M)) < 0.01, (rest, top)
    model = mujoco_scene.model_of(scene)
    objects = sum(not o.is_plane and len(o.triangles) >= 4 for o in scene.objects.values())
    assert model.nmesh == objects >= 3


def test_rerun_the_stream_is_logged_as_meshes_and_scalars(daemon: Daemon, tmp_path: Path) -> None:
    import rerun as rr

    rerun_log = example("rerun_log")
    recording = tmp_path / "scene.rrd"
    rr.init("tacmesh-test")
    rr.save(recording)
    counts = rerun_log.log_stream(daemon.socket_path, 2.0)
    rr.disconnect()
    assert counts["upserts"] >= 4 and counts["stats"] >= 1, counts
    # Read it back with Rerun's own tool: each object's mesh and the plane are there.
    printed = subprocess.run(
        [str(Path(sys.executable).parent / "rerun"), "rrd", "print", str(recording)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    meshes = {
        line.split(" - ")[1] for line in printed.splitlines() if "Mesh3D:vertex_positions" in line
    }
    assert any(m.startswith("/objects/") for m in meshes), printed[-2000:]
    assert "/planes/0" in meshes, printed[-2000:]
    assert "/stats/frames_in" in printed
