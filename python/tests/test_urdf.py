"""The URDF files `tacmesh subscribe --out DIR --urdf` keeps of the daemon's demo scene load in
PyBullet, one robot per object and support placed as `urdf/scene.json` says, weigh what the
MuJoCo scene written beside them says, and rest on the table.

Skipped, with the reason, when pybullet is not installed.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from typing import Any

import pytest

from test_daemon import Daemon, daemon, daemon_binary  # noqa: F401  (the fixture)
from test_sdf import assert_at_rest, assert_weighs_as_its_mjcf, client  # noqa: F401  (the fixture)

pybullet = pytest.importorskip("pybullet", reason="the pybullet package is not installed")


def load_scene(index_path: Path, client: int) -> dict[str, int]:  # noqa: F811
    """Loads every robot `scene.json` names at its pose; returns body ids by name."""
    index: dict[str, Any] = json.loads(index_path.read_text())
    bodies: dict[str, int] = {}
    for entry in index["bodies"]:
        bodies[entry["name"]] = pybullet.loadURDF(
            str(index_path.parent / entry["file"]),
            basePosition=entry["position"],
            baseOrientation=entry["orientation_xyzw"],
            useFixedBase=entry["static"],
            physicsClientId=client,
        )
    pybullet.setGravity(*index["gravity_m_s2"], physicsClientId=client)
    for a, b in index["no_collision"]:
        pybullet.setCollisionFilterPair(bodies[a], bodies[b], -1, -1, 0, physicsClientId=client)
    return bodies


def test_the_subscribers_urdf_of_the_demo_rests_and_weighs_as_its_mjcf(
    daemon: Daemon, tmp_path: Path, client: int  # noqa: F811  (the fixtures)
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
            "--urdf",
            "--count",
            "40",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    bodies = load_scene(tmp_path / "urdf" / "scene.json", client)
    objects = {name: body for name, body in bodies.items() if name.startswith("object-")}
    assert len(objects) >= 3, done.stdout
    assert [name for name in bodies if name.startswith("plane-")], sorted(bodies)

    assert_weighs_as_its_mjcf(objects, tmp_path / "scene.xml", client)
    assert_at_rest(objects, client, 2.0)
