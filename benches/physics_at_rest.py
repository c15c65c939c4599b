"""Whether what tacmesh publishes stands still in a physics engine: the daemon plays each
recording in testdata (and the simulated demo) for a while, `tacmesh subscribe --out DIR --mjcf
--sdf` keeps the scene, and MuJoCo and PyBullet load it and step it for 2 s. A body that moves
more than 1 cm was thrown, sank or toppled: the scene is not at rest.

    python3 benches/physics_at_rest.py [NAME...]   # names: demo oni bag tum slambook pcl_kinect milk

Needs a release build (cargo build --release) and a Python with numpy, mujoco and pybullet
(the venv .ci/run makes: ~/.cache/tacmesh/py-venv). Prints a Markdown table for BENCHMARKS.md.
"""

from __future__ import annotations

import contextlib
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from bench_daemon import SPECS, TACMESH, start_daemon

SECONDS = 20
SIMULATED_S = 2.0


def keep_scene(spec: str, out: Path) -> str:
    """Plays `spec` for SECONDS with a subscriber keeping the physics scene in `out`; returns
    what the subscriber logged."""
    socket = out / "tacmesh.sock"
    daemon = start_daemon(spec, socket, SECONDS)
    try:
        done = subprocess.run(
            [
                str(TACMESH),
                "subscribe",
                "--socket",
                str(socket),
                "--out",
                str(out / "scene"),
            ]
            + ["--mjcf", "--sdf"],
            capture_output=True,
            text=True,
            timeout=SECONDS + 60,
            check=False,
        )
    finally:
        daemon.wait(timeout=60)
    return done.stderr


def mujoco_moves(scene: Path) -> dict[str, float]:
    import mujoco  # type: ignore[import-untyped]

    model: Any = mujoco.MjModel.from_xml_path(str(scene / "scene.xml"))
    data: Any = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    start = np.array(data.xpos)
    for _ in range(round(SIMULATED_S / model.opt.timestep)):
        mujoco.mj_step(model, data)
    moved = np.linalg.norm(np.array(data.xpos) - start, axis=1)
    return {
        model.body(b).name: float(moved[b])
        for b in range(1, model.nbody)
        if model.body_dofnum[b] > 0
    }


@contextlib.contextmanager
def quiet_stdout() -> Any:
    """Bullet's C++ importer prints its warnings to file descriptor 1; they are not the table."""
    sys.stdout.flush()
    saved = os.dup(1)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(null)
        os.close(saved)


def pybullet_moves(scene: Path) -> dict[str, float]:
    import pybullet  # type: ignore[import-not-found]

    path = scene / "scene.sdf"
    client = pybullet.connect(pybullet.DIRECT)
    try:
        with quiet_stdout():
            ids = pybullet.loadSDF(str(path), physicsClientId=client)
        names = {
            pybullet.getBodyInfo(b, physicsClientId=client)[1].decode(): b for b in ids
        }
        text = path.read_text()
        gravity = re.search(r"<gravity>([^<]+)</gravity>", text)
        assert gravity is not None
        pybullet.setGravity(
            *map(float, gravity.group(1).split()), physicsClientId=client
        )
        comment = text[text.index("<!--") : text.index("-->")]
        for a, b in re.findall(
            r"^\s+(\S+) and (\S+) \(\d+ mm\)\s*$", comment, flags=re.MULTILINE
        ):
            pybullet.setCollisionFilterPair(
                names[a], names[b], -1, -1, 0, physicsClientId=client
            )
        moving = {
            n: b
            for n, b in names.items()
            if pybullet.getDynamicsInfo(b, -1, physicsClientId=client)[0] > 0
        }
        start = {
            n: np.array(
                pybullet.getBasePositionAndOrientation(b, physicsClientId=client)[0]
            )
            for n, b in moving.items()
        }
        for _ in range(round(SIMULATED_S * 240)):
            pybullet.stepSimulation(physicsClientId=client)
        return {
            n: float(
                np.linalg.norm(
                    np.array(
                        pybullet.getBasePositionAndOrientation(
                            b, physicsClientId=client
                        )[0]
                    )
                    - start[n]
                )
            )
            for n, b in moving.items()
        }
    finally:
        pybullet.disconnect(client)


def summary(moves: dict[str, float]) -> str:
    if not moves:
        return "no free body"
    worst = max(moves, key=lambda n: moves[n])
    over = sum(m > 0.01 for m in moves.values())
    return (
        f"{over} of {len(moves)} over 1 cm; most {1e3 * moves[worst]:.1f} mm ({worst})"
    )


def main(names: list[str]) -> None:
    print(
        f"| recording | supports | overlaps excluded | MuJoCo, {SIMULATED_S:.0f} s | PyBullet, {SIMULATED_S:.0f} s |"
    )
    print("|---|---|---|---|---|")
    for name in names or list(SPECS):
        with tempfile.TemporaryDirectory() as work:
            out = Path(work)
            log = keep_scene(SPECS[name], out)
            scene = out / "scene"
            xml = (scene / "scene.xml").read_text()
            supports = xml.count('class="support" type="box"')
            overlaps = xml.count("<exclude ")
            print(
                f"| {name} | {supports} | {overlaps} | {summary(mujoco_moves(scene))} | "
                f"{summary(pybullet_moves(scene))} |",
                flush=True,
            )
            if "--log" in sys.argv:
                print(log, file=sys.stderr)


if __name__ == "__main__":
    main([a for a in sys.argv[1:] if not a.startswith("--")])
