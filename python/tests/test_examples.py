"""The examples in python/examples: on a made-up scene (a scripted fake daemon), and against the
real daemon on the simulated scene.

Each needs its optional package (``mujoco``; ``rerun-sdk``, with its ``rerun`` command): without
it the example's tests are skipped, naming the package, before the daemon is started for them.
"""

from __future__ import annotations

import importlib
import importlib.util
import math
import os
import shutil
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import numpy as np
import numpy.typing as npt
import pytest

from tacmesh import (
    Body,
    BodySolid,
    Hull,
    Message,
    Pose,
    Primitive,
    PrimitiveKind,
    Scene,
    Session,
    Shape,
    SnapshotDone,
    Stats,
    Subscriber,
    tessellate,
)
from tacmesh.wire import (
    FIRST_SUPPORT_ID,
    PROTOCOL_VERSION,
    SHAPE_CLOSED,
    SHAPE_SUPPORT,
    Hello,
    inertia_matrix,
)

from test_daemon import Daemon, daemon  # noqa: F401  (the fixture)
from test_subscriber import FakeDaemon, Peer, wait_for_close

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def missing(module: str, package: str) -> str | None:
    """Why the tests that import ``module`` cannot run (``package`` is not installed), or None."""
    try:
        importlib.import_module(module)
    except ImportError as error:
        return f"the {package} package is not installed (pip install {package}): {error}"
    return None


def rerun_command() -> Path | None:
    """rerun-sdk's ``rerun`` command: beside this Python (a virtual environment's), or on PATH."""
    beside = Path(sys.executable).parent / "rerun"
    if beside.is_file() and os.access(beside, os.X_OK):
        return beside
    found = shutil.which("rerun")
    return Path(found) if found is not None else None


def skip_without(reason: str | None) -> pytest.MarkDecorator:
    return pytest.mark.skipif(reason is not None, reason=reason or "")


WITHOUT_MUJOCO = missing("mujoco", "mujoco")
WITHOUT_RERUN = missing("rerun", "rerun-sdk") or (
    None
    if rerun_command() is not None
    else "rerun-sdk's `rerun` command (to read the recording) is neither beside "
    f"{sys.executable} nor on PATH"
)
needs_mujoco = skip_without(WITHOUT_MUJOCO)
needs_rerun = skip_without(WITHOUT_RERUN)


def example(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


# ---- a made-up scene -------------------------------------------------------------------------


def box(
    size: tuple[float, float, float],
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    """A closed box centred on its frame's origin, counter-clockwise seen from outside."""
    half = np.array(size) / 2
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    faces = [
        [0, 1, 3, 2],  # x = -1
        [4, 6, 7, 5],  # x = +1
        [0, 4, 5, 1],  # y = -1
        [2, 3, 7, 6],  # y = +1
        [0, 2, 6, 4],  # z = -1
        [1, 5, 7, 3],  # z = +1
    ]
    triangles = [t for a, b, c, d in faces for t in ([a, b, c], [a, c, d])]
    return corners.astype(np.float32), np.array(triangles, np.uint32)


def pose(
    object_id: int, version: int, t_ns: int, xyz: tuple[float, float, float], yaw: float
) -> Pose:
    return Pose(
        object_id,
        version,
        t_ns,
        t_ns + 10**18,
        t_ns,
        rotation=(0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)),
        translation=xyz,
    )


def made_up_shapes() -> list[Shape]:
    """A 2 m table (z = 0, up +z) and three boxes standing on it, each placed by its pose."""
    table = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    shapes = [
        Shape(
            pose(FIRST_SUPPORT_ID, 1, 100, (0.0, 0.0, 0.0), 0.0),
            100,
            100 + 10**18,
            SHAPE_SUPPORT,
            2,
            2,
            0.0,
            table,
            np.array([[0, 1, 2], [0, 2, 3]], np.uint32),
        )
    ]
    for object_id, size, x in [
        (1, (0.2, 0.2, 0.3), -0.3),
        (2, (0.1, 0.1, 0.1), 0.0),
        (3, (0.1, 0.2, 0.1), 0.3),
    ]:
        vertices, triangles = box(size)
        shapes.append(
            Shape(
                pose(object_id, 1, 100, (x, 0.0, size[2] / 2), 0.3),
                100,
                100 + 10**18,
                SHAPE_CLOSED,
                12,
                12,
                0.001,
                vertices,
                triangles,
            )
        )
    return shapes


#: Box 1's primitive: a box of 0.2 × 0.4 × 0.2 m turned a quarter about x (its long side
#: upright), its centre 5 cm above the object frame's origin: its top is 25 cm above the
#: origin, 10 cm above its shape's, so that a test tells which one is collided.
BOX_1_PRIMITIVE = Primitive(
    PrimitiveKind.BOX,
    (0.1, 0.2, 0.1),
    rotation=(math.sqrt(0.5), 0.0, 0.0, math.sqrt(0.5)),
    centre=(0.0, 0.0, 0.05),
)
#: Box 3's hull: a box as wide as its shape and twice as tall (0.1 × 0.2 × 0.2 m), standing on
#: the table: its top 20 cm above the table, 10 cm above its shape's.
BOX_3_HULL = tessellate(Primitive(PrimitiveKind.BOX, (0.05, 0.1, 0.1), centre=(0.0, 0.0, 0.05)))


def made_up_bodies() -> list[Body]:
    """Box 1 is a primitive, box 3 a fallback body of one hull, box 2 has no body."""
    inertia = inertia_matrix(1e-4, 1e-4, 1e-4, 0.0, 0.0, 0.0)
    vertices, triangles = tessellate(BOX_1_PRIMITIVE)
    primitive = Body(
        1,
        1,
        BodySolid.PRIMITIVE,
        0.0,
        0.016,
        np.array(BOX_1_PRIMITIVE.centre, np.float32),
        inertia,
        primitive=BOX_1_PRIMITIVE,
        hulls=(Hull(vertices, triangles.astype(np.uint8)),),
    )
    vertices, triangles = BOX_3_HULL
    fallback = Body(
        3,
        1,
        BodySolid.SHADOW_VOLUME,
        0.0,
        0.004,
        np.array([0.0, 0.0, 0.05], np.float32),
        inertia,
        vertices=vertices,
        triangles=triangles,
        hulls=(Hull(vertices, triangles.astype(np.uint8)),),
    )
    return [primitive, fallback]


def made_up_scene(bodies: bool = False) -> Scene:
    """The made-up shapes, and with ``bodies`` the made-up bodies."""
    scene = Scene()
    messages: list[Message] = [Session(1, 2), *made_up_shapes(), SnapshotDone()]
    if bodies:
        messages += made_up_bodies()
    for message in messages:
        scene.apply(message)
    return scene


@needs_mujoco
def test_mujoco_made_up_the_probe_rests_on_the_tallest_box() -> None:
    mujoco_scene = example("mujoco_scene")
    scene = made_up_scene()
    rest, top = mujoco_scene.drop_probe(scene)
    assert top == pytest.approx(0.3, abs=1e-5)
    assert abs(rest - (top + mujoco_scene.PROBE_RADIUS_M)) < 0.01, (rest, top)
    assert mujoco_scene.model_of(scene).nmesh == 3


@needs_mujoco
def test_mujoco_made_up_bodies_are_collided_as_their_primitive_and_hulls() -> None:
    mujoco_scene = example("mujoco_scene")
    mujoco = mujoco_scene.mujoco  # the example's own import
    scene = made_up_scene(bodies=True)
    model = mujoco_scene.model_of(scene)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # Box 1: MuJoCo's box of the primitive's half sides, at its centre and rotation.
    geom = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "object1")
    assert model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_BOX
    np.testing.assert_allclose(model.geom_size[geom], BOX_1_PRIMITIVE.sizes)
    placed = scene.objects[1].pose
    np.testing.assert_allclose(
        data.geom_xpos[geom], placed.to_world(BOX_1_PRIMITIVE.centre)[0], atol=1e-6
    )
    turn = placed.rotation_matrix() @ BOX_1_PRIMITIVE.rotation_matrix()
    np.testing.assert_allclose(data.geom_xmat[geom].reshape(3, 3), turn, atol=1e-6)
    # Box 3 is its hull, box 2 its shape: two meshes.
    assert model.nmesh == 2
    hull = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "object3_hull0")
    assert hull >= 0 and model.geom_type[hull] == mujoco.mjtGeom.mjGEOM_MESH
    # A ray straight down onto box 3 meets its hull's top (20 cm), not its shape's (10 cm).
    hit = np.array([-1], np.int32)
    distance = mujoco.mj_ray(model, data, [0.3, 0.0, 1.0], [0, 0, -1], None, 1, -1, hit)
    assert hit[0] == hull and distance == pytest.approx(0.8, abs=1e-5)
    # The probe rests on box 1's primitive, 40 cm up, not on its shape's top at 30 cm.
    rest, top = mujoco_scene.drop_probe(scene)
    assert top == pytest.approx(0.4, abs=1e-5)
    assert abs(rest - (top + mujoco_scene.PROBE_RADIUS_M)) < 0.01, (rest, top)


@needs_mujoco
def test_mujoco_made_up_a_body_arriving_rebuilds_the_model() -> None:
    mujoco_scene = example("mujoco_scene")
    scene = made_up_scene()
    live = mujoco_scene.LiveModel()
    assert live.update(scene) is True and live.model.nmesh == 3
    primitive, fallback = made_up_bodies()
    scene.apply(primitive)
    assert live.update(scene) is True and live.model.nmesh == 2
    # The same Body again changes nothing: the bodies are only moved.
    scene.apply(primitive)
    assert live.update(scene) is False
    scene.apply(fallback)
    assert live.update(scene) is True and (live.rebuilds, live.moves) == (3, 1)


@needs_mujoco
def test_mujoco_made_up_a_pose_moves_a_body_without_a_rebuild() -> None:
    mujoco_scene = example("mujoco_scene")
    scene = made_up_scene()
    live = mujoco_scene.LiveModel()
    assert live.update(scene) is True
    moved = pose(2, 1, 200, (0.1, 0.2, 0.05), 1.0)
    scene.apply(moved)
    assert live.update(scene) is False
    assert (live.rebuilds, live.moves) == (1, 1)
    position, quat = live.body_pose(2)
    np.testing.assert_allclose(position, moved.translation)
    np.testing.assert_allclose(quat, [math.cos(0.5), 0, 0, math.sin(0.5)], atol=1e-7)
    # Where MuJoCo has the geom is where the scene has the object.
    import mujoco  # type: ignore[import-untyped]

    geom = mujoco.mj_name2id(live.model, mujoco.mjtObj.mjOBJ_GEOM, "object2")
    centre = scene.objects[2].mesh.vertices.mean(axis=0)
    np.testing.assert_allclose(live.data.geom_xpos[geom], centre, atol=1e-5)
    # A new shape version rebuilds it.
    scene.apply(
        replace(
            made_up_shapes()[2],
            pose=replace(moved, shape_version=2, pose_time_ns=300, last_seen_ns=300),
        )
    )
    assert live.update(scene) is True and live.rebuilds == 2


@needs_rerun
def test_rerun_made_up_meshes_in_their_frames_and_poses_as_transforms(
    tmp_path: Path,
) -> None:
    import rerun as rr

    def script(peer: Peer) -> None:
        peer.send(
            Hello(PROTOCOL_VERSION, "fake"),
            Session(1, 2),
            *made_up_shapes(),
            SnapshotDone(),
        )
        peer.receive()
        peer.send(pose(1, 1, 200, (-0.25, 0.0, 0.15), 0.5), Stats(monotonic_ns=300))
        peer.send(pose(1, 1, 300, (-0.2, 0.0, 0.15), 0.6), Stats(monotonic_ns=400))
        wait_for_close(peer)

    rerun_log = example("rerun_log")
    fake = FakeDaemon(tmp_path / "d.sock", script)
    recording = tmp_path / "scene.rrd"
    rr.init("tacmesh-test")
    rr.save(recording)
    counts = rerun_log.log_stream(tmp_path / "d.sock", 0.2)
    rr.disconnect()
    fake.join()
    assert counts["shapes"] == 4 and counts["poses"] >= 1 and counts["stats"] >= 1, counts
    printed = rrd_print(recording)
    meshes = entities_with(printed, "Mesh3D:vertex_positions")
    assert {"/objects/1", "/objects/2", "/objects/3", "/supports/0"} <= meshes, printed[-3000:]
    assert {"/objects/1", "/supports/0"} <= entities_with(printed, "Transform3D:"), printed[-3000:]


def rrd_print(recording: Path) -> str:
    """Rerun's own reading of a recording."""
    command = rerun_command()
    assert command is not None
    return subprocess.run(
        [str(command), "rrd", "print", str(recording)],
        capture_output=True,
        text=True,
        check=True,
    ).stdout


def entities_with(printed: str, component: str) -> set[str]:
    """The entity paths `rerun rrd print` shows a chunk of `component` for (its lines read
    "Chunk(…) with N rows (…) - /entity/path - data columns: […]")."""
    return {
        line.split(" - ")[1]
        for line in printed.splitlines()
        if component in line and line.count(" - ") >= 2
    }


# ---- against the daemon ----------------------------------------------------------------------


def scene_after(daemon: Daemon, seconds: float) -> Scene:
    deadline = time.monotonic() + seconds
    with Subscriber(daemon.socket_path, reconnect=False, timeout_s=10) as subscriber:
        for _ in subscriber:
            if subscriber.scene.complete and time.monotonic() > deadline:
                break
    return subscriber.scene


@needs_mujoco
def test_mujoco_a_probe_dropped_on_an_object_rests_on_its_top(daemon: Daemon) -> None:
    mujoco_scene = example("mujoco_scene")
    scene = scene_after(daemon, 3.0)
    # Read 0.6 s after the drop: it lands after 0.25 s and settles in 0.1 s. A sphere rolls on
    # any tilt, and the cube's one-view mesh can have its far top corner 3 cm low: by 1.5 s
    # the probe had rolled 13 cm across the top and off that corner (1 run in 4 here).
    rest, top = mujoco_scene.drop_probe(scene, seconds=0.6)
    # The probe's centre rests one radius above the object's top (of its primitive, its hulls
    # or its shape's hull), not on the support below it and not inside the object.
    assert abs(rest - (top + mujoco_scene.PROBE_RADIUS_M)) < 0.01, (rest, top)
    # Each object is a mocap body of its primitive's geom, its hulls, or its shape.
    mujoco = mujoco_scene.mujoco  # the example's own import
    model = mujoco_scene.model_of(scene)
    objects = mujoco_scene.modelled(scene)
    assert len(objects) >= 3
    assert any(o.body is not None for o in objects), "no body yet"
    meshes = 0
    for o in objects:
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"object{o.object_id}")
        assert body >= 0, o.object_id
        types = [
            int(model.geom_type[g]) for g in range(model.ngeom) if model.geom_bodyid[g] == body
        ]
        primitive = mujoco_scene.primitive_of(o)
        if primitive is not None:
            expected = getattr(mujoco.mjtGeom, f"mjGEOM_{primitive.kind.name}")
            assert types == [int(expected)], (o.object_id, primitive)
        else:
            pieces = len(mujoco_scene.hulls_of(o)) or 1
            assert types == [int(mujoco.mjtGeom.mjGEOM_MESH)] * pieces, o.object_id
            meshes += pieces
    assert model.nmesh == meshes


@needs_mujoco
def test_mujoco_the_live_model_follows_poses_without_rebuilding(daemon: Daemon) -> None:
    mujoco_scene = example("mujoco_scene")
    scene, live = mujoco_scene.follow(str(daemon.socket_path), 4.0)
    # The cone slides by Poses: the bodies move far more often than the model is rebuilt.
    assert live.moves > 0 and live.rebuilds >= 1, (live.moves, live.rebuilds)
    for o in mujoco_scene.modelled(scene):
        if o.object_id in live._mocap:
            position, _ = live.body_pose(o.object_id)
            np.testing.assert_allclose(position, o.pose.translation, atol=1e-6)


@needs_rerun
def test_rerun_the_stream_is_logged_as_meshes_transforms_and_scalars(
    daemon: Daemon, tmp_path: Path
) -> None:
    import rerun as rr

    rerun_log = example("rerun_log")
    recording = tmp_path / "scene.rrd"
    rr.init("tacmesh-test")
    rr.save(recording)
    counts = rerun_log.log_stream(daemon.socket_path, 3.0, encoding="compact")
    rr.disconnect()
    assert counts["shapes"] >= 4 and counts["poses"] >= 1 and counts["stats"] >= 1, counts
    printed = rrd_print(recording)
    meshes = entities_with(printed, "Mesh3D:vertex_positions")
    assert any(m.startswith("/objects/") for m in meshes), printed[-3000:]
    assert any(m.startswith("/supports/") for m in meshes), printed[-3000:]
    assert any(m.startswith("/objects/") for m in entities_with(printed, "Transform3D:"))
    assert "/stats/frames_in" in printed


# ---- without the optional packages ---------------------------------------------------------


def test_without_mujoco_or_rerun_the_examples_tests_are_skipped_naming_the_package(
    tmp_path: Path,
) -> None:
    # Modules of the same names, first on the path, that fail to import as a missing one does.
    hidden = tmp_path / "hidden"
    hidden.mkdir()
    for module in ("mujoco", "rerun"):
        (hidden / f"{module}.py").write_text(
            f'raise ModuleNotFoundError("No module named {module!r}", name={module!r})\n'
        )
    path = os.pathsep.join([str(hidden), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    done = subprocess.run(
        [
            sys.executable,
            *("-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider"),
            *("-k", "not skipped_naming_the_package"),  # all but this test
            str(Path(__file__)),
        ],
        cwd=Path(__file__).parent,
        env={**os.environ, "PYTHONPATH": path},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert "8 skipped" in output and "passed" not in output, output
    assert "the mujoco package is not installed (pip install mujoco)" in output, output
    assert "the rerun-sdk package is not installed (pip install rerun-sdk)" in output, output
