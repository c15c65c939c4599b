"""The SDF world the Rust writer produces (`tacmesh_physics::write_sdf`) loads in PyBullet and
behaves as its MuJoCo twin does (test_mjcf.py): a cube resting on the support plane stays, a
sphere dropped beside it lands, in a z-up world and in a y-up one; a static body stays put.
And the world `tacmesh subscribe --out DIR --sdf` keeps of the daemon's demo scene loads, gives
every object the mass its MuJoCo scene gives it, and its objects rest on the table.

PyBullet's `loadSDF` reads the models, poses, `<static>`, masses, mesh collisions and boxes;
it computes inertia from the collision shapes itself (Gazebo takes the file's) and does not
read `<gravity>`; the pairs that start inside each other, which the file's first comment
lists, are kept from colliding with `setCollisionFilterPair` as that comment says.

The example scene comes from `physics/examples/write_mjcf.rs --sdf`, named by
TACMESH_MJCF_EXAMPLE (see example_scene.py). Skipped, with the reason, when it is not named or
pybullet is not installed.
"""

from __future__ import annotations

import importlib
import importlib.util
import re
import subprocess
import xml.etree.ElementTree as ElementTree
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import numpy.typing as npt
import pytest

from example_scene import write_example_scene
from test_daemon import Daemon, daemon, daemon_binary  # noqa: F401  (the fixture)

pybullet = pytest.importorskip("pybullet", reason="the pybullet package is not installed")

STEP_S = 1.0 / 240.0  # PyBullet's default step
CUBE_HALF_M = 0.05
SPHERE_RADIUS_M = 0.05
# Bullet keeps convex shapes this far apart (its collision margin), so a resting body stands
# about a millimetre above where MuJoCo's would.
MARGIN_M = 0.0015


@pytest.fixture
def client() -> Iterator[int]:
    connection: int = pybullet.connect(pybullet.DIRECT)
    try:
        yield connection
    finally:
        pybullet.disconnect(connection)


def load_world(path: Path, client: int) -> dict[str, int]:
    """Loads the SDF world at ``path`` with the world's gravity; returns body ids by model
    name."""
    ids = pybullet.loadSDF(str(path), physicsClientId=client)
    gravity_text = ElementTree.parse(path).getroot().findtext("world/gravity")
    assert gravity_text is not None, "the world has no gravity"
    pybullet.setGravity(*[float(g) for g in gravity_text.split()], physicsClientId=client)
    names = {pybullet.getBodyInfo(body, physicsClientId=client)[1].decode(): body for body in ids}
    assert len(names) == len(ids), "two models share a name"
    return names


def excluded_pairs(path: Path) -> list[tuple[str, str]]:
    """The pairs the world's first comment says are not to collide with each other."""
    text = path.read_text()
    comment = text[text.index("<!--") : text.index("-->")]
    return re.findall(r"^\s+(\S+) and (\S+) \(\d+ mm\)\s*$", comment, flags=re.MULTILINE)


def position(body: int, client: int) -> npt.NDArray[np.float64]:
    where: npt.NDArray[np.float64] = np.array(
        pybullet.getBasePositionAndOrientation(body, physicsClientId=client)[0]
    )
    return where


def mass(body: int, client: int) -> float:
    value: float = pybullet.getDynamicsInfo(body, -1, physicsClientId=client)[0]
    return value


def assert_weighs_as_its_mjcf(objects: dict[str, int], scene_xml: Path, client: int) -> None:
    """Every object weighs what the MuJoCo scene written beside it says (the same parts, the
    same mass properties), when MuJoCo is here to read it."""
    if importlib.util.find_spec("mujoco") is None:
        return
    mujoco: Any = importlib.import_module("mujoco")
    model: Any = mujoco.MjModel.from_xml_path(str(scene_xml))
    for name, body in objects.items():
        mj_body = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        assert mj_body >= 0, f"{name} is not in the MuJoCo scene"
        assert mass(body, client) == pytest.approx(model.body_mass[mj_body], rel=1e-5), name


def assert_at_rest(objects: dict[str, int], client: int, seconds: float) -> None:
    """Stepped for `seconds`, no object moves 1 cm."""
    start = {name: position(body, client) for name, body in objects.items()}
    step(client, seconds)
    moved = {
        name: float(np.linalg.norm(position(body, client) - start[name]))
        for name, body in objects.items()
    }
    assert all(distance < 0.01 for distance in moved.values()), moved


def step(client: int, seconds: float) -> None:
    for _ in range(round(seconds / STEP_S)):
        pybullet.stepSimulation(physicsClientId=client)


@pytest.mark.parametrize(
    ("up_axis", "up"),
    [("z", np.array([0.0, 0.0, 1.0])), ("y", np.array([0.0, 1.0, 0.0]))],
)
def test_cube_rests_and_sphere_lands(
    tmp_path: Path, client: int, up_axis: str, up: npt.NDArray[np.float64]
) -> None:
    bodies = load_world(write_example_scene(tmp_path, up_axis, sdf=True), client)
    assert sorted(bodies) == [
        "cube",
        "desk",
        "drum",
        "on_desk",
        "sphere",
        "table",
        "under_desk",
        "wall",
    ]
    # 0.001 m³ at the writer's default 500 kg/m³; static models have no mass (fixed).
    assert mass(bodies["cube"], client) == pytest.approx(0.5, rel=1e-5)
    assert mass(bodies["wall"], client) == 0.0
    assert mass(bodies["table"], client) == 0.0
    cube_start = position(bodies["cube"], client)
    wall_start = position(bodies["wall"], client)
    assert np.dot(cube_start, up) == pytest.approx(CUBE_HALF_M, abs=1e-6)

    step(client, 0.4)

    cube = position(bodies["cube"], client)
    # Resting: neither sinking through the plane nor thrown off it, nor sliding away.
    assert CUBE_HALF_M - 0.002 < np.dot(cube, up) < CUBE_HALF_M + MARGIN_M
    assert np.linalg.norm(cube - cube_start) < 0.003
    sphere = position(bodies["sphere"], client)
    # Landed from 0.2 m on its hull (grown to cover the sphere's mesh: 3 mm beyond it), on
    # the plane, not through it.
    assert SPHERE_RADIUS_M - 0.001 < np.dot(sphere, up) < SPHERE_RADIUS_M + 0.005 + MARGIN_M
    assert np.array_equal(position(bodies["wall"], client), wall_start)
    # The desk top is a finite slab 0.4 m up, with a cube on it and one on the floor under it.
    on_desk = position(bodies["on_desk"], client)
    assert 0.4 + CUBE_HALF_M - 0.002 < np.dot(on_desk, up) < 0.4 + CUBE_HALF_M + MARGIN_M
    under_desk = position(bodies["under_desk"], client)
    assert CUBE_HALF_M - 0.002 < np.dot(under_desk, up) < CUBE_HALF_M + MARGIN_M
    # The drum is a primitive cylinder (SDFormat's own): 16 cm tall, standing.
    drum = position(bodies["drum"], client)
    assert 0.08 - 0.002 < np.dot(drum, up) < 0.08 + MARGIN_M


def test_the_subscribers_world_of_the_demo_rests_and_weighs_as_its_mjcf(
    daemon: Daemon, tmp_path: Path, client: int  # noqa: F811  (the fixture)
) -> None:
    done = subprocess.run(
        [
            str(daemon_binary()),
            "subscribe",
            "--socket",
            str(daemon.socket_path),
            "--out",
            str(tmp_path),
            "--mjcf",
            "--sdf",
            "--count",
            "40",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    bodies = load_world(tmp_path / "scene.sdf", client)
    objects = {name: body for name, body in bodies.items() if name.startswith("object-")}
    # The demo's objects and its table (a static plane).
    assert len(objects) >= 3, done.stdout
    assert [name for name in bodies if name.startswith("plane-")], sorted(bodies)

    assert_weighs_as_its_mjcf(objects, tmp_path / "scene.xml", client)

    # Bodies collide with each other and the table, but for the pairs the file's comment says
    # start inside each other (their proxies may overlap in the space no sensor saw).
    for first, second in excluded_pairs(tmp_path / "scene.sdf"):
        pybullet.setCollisionFilterPair(
            bodies[first], bodies[second], -1, -1, 0, physicsClientId=client
        )
    assert_at_rest(objects, client, 4.0)
    for body in objects.values():
        linear, _ = pybullet.getBaseVelocity(body, physicsClientId=client)
        assert np.linalg.norm(linear) < 0.1
