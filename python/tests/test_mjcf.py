"""The MJCF scene the Rust writer produces (`tacmesh_physics::write_mjcf`) loads in MuJoCo and
behaves: a cube resting on the support plane stays there, a sphere dropped beside it lands and
settles, in a z-up world and in a y-up one. And the scene `tacmesh subscribe --out DIR --mjcf`
keeps of the daemon's demo scene loads, and its objects rest on the table.

The scene comes from the example `physics/examples/write_mjcf.rs`, named by
TACMESH_MJCF_EXAMPLE (`cargo build -p tacmesh-physics --example write_mjcf`, then
`TACMESH_MJCF_EXAMPLE=$CARGO_TARGET_DIR/debug/examples/write_mjcf`). Skipped, with the reason,
when it is not named or mujoco is not installed.
"""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest

from example_scene import write_example_scene
from test_daemon import Daemon, daemon, daemon_binary  # noqa: F401  (the fixture)

mujoco = pytest.importorskip("mujoco", reason="the mujoco package is not installed")

STEPS = 200  # 0.4 s at the scene's 2 ms step
CUBE_HALF_M = 0.05
SPHERE_RADIUS_M = 0.05


def body_position(model: Any, data: Any, name: str) -> npt.NDArray[np.float64]:
    body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
    assert body >= 0, f"no body {name}"
    position: npt.NDArray[np.float64] = np.array(data.xpos[body])
    return position


@pytest.mark.parametrize(
    ("up_axis", "up"),
    [("z", np.array([0.0, 0.0, 1.0])), ("y", np.array([0.0, 1.0, 0.0]))],
)
def test_cube_rests_and_sphere_lands(
    tmp_path: Path, up_axis: str, up: npt.NDArray[np.float64]
) -> None:
    model = mujoco.MjModel.from_xml_path(str(write_example_scene(tmp_path, up_axis)))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    cube_start = body_position(model, data, "cube")
    assert np.dot(cube_start, up) == pytest.approx(CUBE_HALF_M, abs=1e-6)
    # 0.001 m³ at the writer's default 500 kg/m³.
    cube_id = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "cube")
    assert model.body_mass[cube_id] == pytest.approx(0.5, rel=1e-5)

    for _ in range(STEPS):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))

    cube = body_position(model, data, "cube")
    # Resting: neither sinking through the plane nor thrown off it, nor sliding away.
    assert np.dot(cube, up) == pytest.approx(CUBE_HALF_M, abs=0.002)
    assert np.linalg.norm(cube - cube_start) < 0.003
    sphere = body_position(model, data, "sphere")
    # Landed from 0.2 m on its hull (of at most 64 of its 114 vertices, grown to cover them
    # all: 3 mm beyond the sphere's own mesh): on the plane, not through it.
    assert SPHERE_RADIUS_M - 0.001 < np.dot(sphere, up) < SPHERE_RADIUS_M + 0.005
    # Nothing is still moving fast (the sphere hit the plane at about 1.7 m/s).
    assert np.max(np.abs(data.qvel)) < 0.2
    # The desk top is a finite slab 0.4 m up: the cube on it rests there, and the cube on the
    # floor under it stays on the floor (an infinite plane of the desk would throw it out).
    on_desk = body_position(model, data, "on_desk")
    assert np.dot(on_desk, up) == pytest.approx(0.4 + CUBE_HALF_M, abs=0.002)
    under_desk = body_position(model, data, "under_desk")
    assert np.dot(under_desk, up) == pytest.approx(CUBE_HALF_M, abs=0.002)
    for name in ("desk", "table"):
        slab = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"{name}_slab")
        assert model.geom_type[slab] == mujoco.mjtGeom.mjGEOM_BOX, name


def resting_scene(socket_path: Path, out: Path, updates: int) -> tuple[Any, str]:
    """Runs ``tacmesh subscribe --out OUT --mjcf --count UPDATES`` on the daemon at
    ``socket_path``, loads the scene it kept in MuJoCo, steps it for 4 s and returns the model
    and what ``subscribe`` printed, after checking that every body rests where the daemon put
    it: standing on its support, not falling through it, not thrown off it."""
    done = subprocess.run(
        [
            str(daemon_binary()),
            "subscribe",
            "--socket",
            str(socket_path),
            "--out",
            str(out),
            "--mjcf",
            "--count",
            str(updates),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    model = mujoco.MjModel.from_xml_path(str(out / "scene.xml"))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    # Supports are finite slabs (boxes), never infinite planes.
    assert int(np.sum(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)) == 0, done.stdout
    slabs = [model.geom(g).name for g in range(model.ngeom) if model.geom(g).name.endswith("_slab")]
    assert slabs and all(name.startswith("plane-") for name in slabs), slabs
    start = np.array(data.xpos)
    for _ in range(10 * STEPS):
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    moved = np.linalg.norm(np.array(data.xpos)[1:] - start[1:], axis=1)
    names = [model.body(b).name for b in range(1, model.nbody)]
    assert np.all(moved < 0.01), dict(zip(names, np.round(moved, 4)))
    assert np.max(np.abs(data.qvel)) < 0.1
    return model, done.stdout + done.stderr


def test_the_scene_of_a_real_tabletop_recording_rests_on_its_table(
    tmp_path: Path,
) -> None:
    """The real data: the daemon on a recorded tabletop (PCL's milk carton scene, four things
    on a table and five at the far end of the room, testdata/pointclouds/pcl). Its one-view
    objects' published bodies (shadow volumes) stand on the table and stay; two of them reach
    into each other behind the objects, which the scene's bodies do not collide over, and one
    (a fragment 20 cm above the table, whose shadow leans off its foot) is held still.
    """
    recording = (
        Path(__file__).resolve().parents[2]
        / "testdata/pointclouds/pcl/milk_cartoon_all_small_clorox.pcd"
    )
    running = Daemon(tmp_path / "milk.sock", f"replay:{recording}", ("--loop",))
    try:
        # The snapshot and then the objects as they are meshed, with their bodies.
        model, printed = resting_scene(running.socket_path, tmp_path / "out", 30)
    finally:
        running.stop()
    assert model.nbody - 1 >= 4, printed
    # Bodies follow their shapes off the frame path: some may not have come by then (those
    # objects are their straight-down extrusions in the scene meanwhile).
    assert sum(line.startswith("body object") for line in printed.splitlines()) >= 2, printed
    # Most of them are free bodies; one that does not stand on the table by itself (a fragment
    # held up by another object) is held still (a body without a joint).
    free = int(np.sum(model.body_dofnum[1:] > 0))
    assert free >= 4 and free >= (model.nbody - 1) * 2 // 3, (free, model.nbody - 1)


def test_the_subscribers_scene_of_the_demo_rests_on_its_table(
    daemon: Daemon, tmp_path: Path
) -> None:
    # 200 updates, about 7 s of the sliding cone's poses: the bodies follow their shapes off
    # the frame path, one at a time, and the torus's convex decomposition alone can take a
    # second under load. With 40 (about 1.3 s), a fresh-clone CI run got 2 of its 3 bodies.
    model, printed = resting_scene(daemon.socket_path, tmp_path, 200)
    # The demo's objects (the world body is body 0) on its table, a plane.
    assert model.nbody - 1 >= 3, printed
    # Each object is the daemon's published collision body (protocol 4): its mass is that
    # body's solid's volume at 500 kg/m³, as `subscribe` printed it last ("volume V l").
    volumes_l: dict[int, float] = {}
    for line in printed.splitlines():
        if line.startswith("body object "):
            object_id = int(line.split()[2])
            volumes_l[object_id] = float(line.rsplit("volume ", 1)[1].split(" l")[0])
    assert len(volumes_l) >= 3, printed
    # An object that is a primitive ("object N is a box in the physics scene", the last such
    # line) weighs the primitive: the demo's 20 cm cube 8 l, 20 cm ball 4.19 l, 18 cm drum
    # 4.58 l of the truth, within the 0.8–1.25× issue 40 asks for.
    primitives: dict[int, str] = {}
    for line in printed.splitlines():
        if " in the physics scene (" in line and " is a " in line:
            words = line.split("object ", 1)[1].split()
            primitives[int(words[0])] = words[3]
        elif " is no longer a " in line:
            primitives.pop(int(line.split("object ", 1)[1].split()[0]), None)
    truth_l = {"box": 8.0, "sphere": 4.19, "cylinder": 4.58}
    for object_id, volume_l in volumes_l.items():
        body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, f"object-{object_id}")
        assert body >= 0, f"object {object_id} is not in the scene"
        kind = primitives.get(object_id)
        if kind is None:
            # The printed volume is rounded to 0.01 l.
            expected = 0.5 * volume_l
            assert model.body_mass[body] == pytest.approx(expected, abs=0.5 * 0.006), object_id
        else:
            ratio = model.body_mass[body] / (0.5 * truth_l[kind])
            assert 0.8 <= ratio <= 1.25, (object_id, kind, ratio)
    print(f"\nprimitives: {primitives}")
