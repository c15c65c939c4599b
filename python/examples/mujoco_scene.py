"""Keep a MuJoCo model in step with the daemon's scene, and drop a probe onto an object.

    python python/examples/mujoco_scene.py --socket /tmp/tacmesh.sock [--seconds 3]

Reads the daemon's scene (the snapshot, then updates for ``--seconds``), builds an MJCF model of
it (each object a mesh geom, which MuJoCo collides as its convex hull; the support plane a
plane geom through the published fan, gravity along its normal toward it), and drops a 2 cm
sphere from 30 cm above the top of the largest object. It prints where the sphere comes to rest
against the object's highest point. Each time the scene changes the model is rebuilt
(``model_of``): MuJoCo compiles a model of a few objects in milliseconds.

Needs the ``mujoco`` package (``pip install mujoco``) and the client (``pip install ./python``).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import mujoco  # type: ignore[import-untyped]  # ships no type information
import numpy as np
import numpy.typing as npt

from tacmesh import Scene, SceneObject, Subscriber

PROBE_RADIUS_M = 0.02
DROP_HEIGHT_M = 0.3


@dataclass
class Support:
    """A support plane: a point on it and its unit normal, pointing to where objects stand."""

    point: npt.NDArray[np.float64]
    normal: npt.NDArray[np.float64]


def support_of(scene: Scene) -> Support:
    """The largest published support plane, its normal turned toward the objects."""
    planes = [o for o in scene.objects.values() if o.is_plane and len(o.triangles)]
    if not planes:
        raise ValueError("the daemon has published no support plane yet")
    plane = max(planes, key=lambda p: len(p.vertices))
    v = plane.vertices.astype(np.float64)
    a, b, c = (v[i] for i in plane.triangles[0])
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    point = v.mean(axis=0)
    objects = [o.vertices.mean(axis=0) for o in scene.objects.values() if not o.is_plane]
    if objects and float(np.mean([np.dot(c - point, normal) for c in objects])) < 0:
        normal = -normal
    return Support(point, normal)


def _numbers(values: npt.NDArray[np.generic]) -> str:
    return " ".join(f"{x:.6g}" for x in values.ravel())


def mjcf_of(scene: Scene, support: Support, probe_at: npt.NDArray[np.float64] | None) -> str:
    """The scene as MJCF: objects as static mesh geoms, the support as a plane, and a probe."""
    objects = [o for o in scene.objects.values() if not o.is_plane and len(o.triangles) >= 4]
    assets = "\n".join(
        f'    <mesh name="object{o.object_id}" vertex="{_numbers(o.vertices)}" '
        f'face="{_numbers(o.triangles)}"/>'
        for o in objects
    )
    geoms = "\n".join(
        f'    <geom name="object{o.object_id}" type="mesh" mesh="object{o.object_id}"/>'
        for o in objects
    )
    # MuJoCo's plane is z = 0 of its frame: rotate z onto the support's normal.
    quat = np.zeros(4)
    mujoco.mju_quatZ2Vec(quat, support.normal)
    gravity = -9.81 * support.normal
    probe = ""
    if probe_at is not None:
        probe = (
            f'    <body name="probe" pos="{_numbers(probe_at)}">\n'
            f"      <freejoint/>\n"
            f'      <geom type="sphere" size="{PROBE_RADIUS_M}" mass="0.05"/>\n'
            f"    </body>"
        )
    return f"""<mujoco model="tacmesh scene">
  <option gravity="{_numbers(gravity)}" timestep="0.002"/>
  <asset>
{assets}
  </asset>
  <worldbody>
    <geom name="support" type="plane" size="0 0 0.01" pos="{_numbers(support.point)}"
          quat="{_numbers(quat)}"/>
{geoms}
{probe}
  </worldbody>
</mujoco>
"""


def largest_object(scene: Scene) -> SceneObject:
    objects = [o for o in scene.objects.values() if not o.is_plane and len(o.triangles) >= 4]
    if not objects:
        raise ValueError("the daemon has published no object yet")
    return max(objects, key=lambda o: float(np.ptp(o.vertices, axis=0).prod()))


def model_of(scene: Scene, probe_at: npt.NDArray[np.float64] | None = None) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(mjcf_of(scene, support_of(scene), probe_at))


def drop_probe(scene: Scene, seconds: float = 1.5) -> tuple[float, float]:
    """Drops the probe over the middle of the largest object's upper part; returns (the probe's
    resting height above the support, the object's highest point above it), metres."""
    support = support_of(scene)
    target = largest_object(scene)
    heights = (target.vertices.astype(np.float64) - support.point) @ support.normal
    top = float(heights.max())
    # Over the middle of its upper part (a hull's highest vertex is a peak it would roll off).
    upper = target.vertices.astype(np.float64)[heights >= top - 0.25 * (top - heights.min())]
    middle = upper.mean(axis=0)
    start = middle + (top + DROP_HEIGHT_M - float((middle - support.point) @ support.normal)) * (
        support.normal
    )
    model = model_of(scene, start)
    data = mujoco.MjData(model)
    for _ in range(int(seconds / model.opt.timestep)):
        mujoco.mj_step(model, data)
    rest = float((data.qpos[:3] - support.point) @ support.normal)
    return rest, top


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--socket", required=True, help="the daemon's socket path")
    parser.add_argument("--seconds", type=float, default=3.0, help="how long to follow updates")
    args = parser.parse_args()
    scene = Scene()
    rebuilt = 0
    deadline = time.monotonic() + args.seconds
    with Subscriber(args.socket, reconnect=False, timeout_s=10) as subscriber:
        for message in subscriber:
            before = {i: o.version for i, o in scene.objects.items()}
            scene.apply(message)
            changed = {i: o.version for i, o in scene.objects.items()} != before
            if scene.complete and changed and support_or_none(scene) is not None:
                model_of(scene)
                rebuilt += 1
            if scene.complete and time.monotonic() > deadline:
                break
    rest, top = drop_probe(scene)
    objects = sum(not o.is_plane for o in scene.objects.values())
    print(
        f"{objects} objects; the model was rebuilt {rebuilt} times; the probe came to rest "
        f"{rest:.3f} m above the support, the object's top is at {top:.3f} m"
    )


def support_or_none(scene: Scene) -> Support | None:
    try:
        return support_of(scene)
    except ValueError:
        return None


if __name__ == "__main__":
    main()
