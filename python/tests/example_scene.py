"""The demo scene of `physics/examples/write_mjcf.rs`, written for the tests that load it in a
simulator: as MJCF for MuJoCo (test_mjcf.py) or as an SDF world for PyBullet (test_sdf.py).

The example is named by TACMESH_MJCF_EXAMPLE (`cargo build -p tacmesh-physics --example
write_mjcf`, then `TACMESH_MJCF_EXAMPLE=$CARGO_TARGET_DIR/debug/examples/write_mjcf`); a test
that needs it is skipped, with the reason, when it is not named. No simulator is imported
here, so neither test is skipped for want of the other's.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest


def example_binary() -> Path:
    named = os.environ.get("TACMESH_MJCF_EXAMPLE")
    if not named:
        pytest.skip(
            "TACMESH_MJCF_EXAMPLE names no build of the write_mjcf example "
            "(cargo build -p tacmesh-physics --example write_mjcf)"
        )
    binary = Path(named)
    if not binary.is_file():
        pytest.skip(f"TACMESH_MJCF_EXAMPLE={named} is not a file")
    return binary


def write_example_scene(folder: Path, up: str, sdf: bool = False) -> Path:
    """Writes the scene with ``up`` ("z" or "y") as the world's up into ``folder``: its
    scene.xml, or with ``sdf`` its scene.sdf, whose path it returns."""
    done = subprocess.run(
        [str(example_binary()), str(folder), "--up", up, *(["--sdf"] if sdf else [])],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    scene = Path(done.stdout.strip())
    assert scene == folder / ("scene.sdf" if sdf else "scene.xml")
    return scene
