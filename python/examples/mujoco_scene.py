"""Keep a MuJoCo model in step with the daemon's scene, and drop a probe onto an object.

    python python/examples/mujoco_scene.py --socket /tmp/tacmesh.sock [--seconds 3]

Reads the daemon's scene (the snapshot, then updates for ``--seconds``) and keeps an MJCF model
of it: each object a mesh geom (which MuJoCo collides as its convex hull) in its own frame, on
a mocap body placed by the object's pose; the support plane a plane geom through the published
fan, gravity along its normal toward it. A new shape (or an object coming or going) rebuilds the
model (MuJoCo compiles a model of a few objects in milliseconds); a Pose only moves its body
(``data.mocap_pos`` / ``data.mocap_quat``), without a rebuild. At the end it drops a 2 cm
sphere from 30 cm above the top of the largest object and prints where it comes to rest
against the object's highest point.

Needs the ``mujoco`` package (``pip install mujoco``) and the client (``pip install ./python``).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import mujoco  # type: ignore[import-untyped]  # ships no type information
import numpy as np
import numpy.typing as npt

from tacmesh import Pose, Scene, SceneObject, Shape, Subscriber

PROBE_RADIUS_M = 0.02
DROP_HEIGHT_M = 0.3


@dataclass
class Support:
    """A support plane in the world: a point on it and its unit normal, pointing to where the
    objects stand."""

    point: npt.NDArray[np.float64]
    normal: npt.NDArray[np.float64]


def meshed(scene: Scene) -> list[SceneObject]:
    """The objects MuJoCo can make a hull of (supports aside)."""
    return [o for o in scene.non_supports if len(o.triangles) >= 4]


def support_of(scene: Scene) -> Support:
    """The largest published support plane, in the world, its normal turned toward the
    objects."""
    planes = [o for o in scene.supports if len(o.triangles)]
    if not planes:
        raise ValueError("the daemon has published no support plane yet")
    plane = max(planes, key=lambda p: len(p.vertices))
    v = plane.mesh.vertices.astype(np.float64)
    a, b, c = (v[i] for i in plane.triangles[0])
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    point = v.mean(axis=0)
    centres = [o.mesh.vertices.mean(axis=0) for o in scene.non_supports if len(o.vertices)]
    if centres and float(np.mean([np.dot(c - point, normal) for c in centres])) < 0:
        normal = -normal
    return Support(point, normal)


def _numbers(values: npt.ArrayLike) -> str:
    return " ".join(f"{x:.9g}" for x in np.asarray(values, dtype=np.float64).ravel())


def mujoco_quat(pose: Pose) -> npt.NDArray[np.float64]:
    """MuJoCo's (w, x, y, z) of the wire's (x, y, z, w)."""
    x, y, z, w = pose.rotation
    return np.array([w, x, y, z])


def mjcf_of(scene: Scene, support: Support, probe_at: npt.NDArray[np.float64] | None) -> str:
    """The scene as MJCF: each object's shape (object frame) as a mesh on a mocap body at its
    pose, the support as a plane, and a probe."""
    objects = meshed(scene)
    assets = "\n".join(
        f'    <mesh name="object{o.object_id}" vertex="{_numbers(o.vertices)}" '
        f'face="{_numbers(o.triangles)}"/>'
        for o in objects
    )
    bodies = "\n".join(
        f'    <body name="object{o.object_id}" mocap="true" pos="{_numbers(o.pose.translation)}" '
        f'quat="{_numbers(mujoco_quat(o.pose))}">\n'
        f'      <geom name="object{o.object_id}" type="mesh" mesh="object{o.object_id}"/>\n'
        f"    </body>"
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
{bodies}
{probe}
  </worldbody>
</mujoco>
"""


def model_of(scene: Scene, probe_at: npt.NDArray[np.float64] | None = None) -> mujoco.MjModel:
    return mujoco.MjModel.from_xml_string(mjcf_of(scene, support_of(scene), probe_at))


class LiveModel:
    """A MuJoCo model and data kept in step with a scene: rebuilt when the shapes change (an
    object's new shape version, an object coming or going, another support), the mocap bodies
    moved when only poses change."""

    def __init__(self) -> None:
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.rebuilds = 0
        self.moves = 0
        self._shapes: dict[int, int] = {}
        self._mocap: dict[int, int] = {}

    def update(self, scene: Scene) -> bool:
        """Brings the model up to date with ``scene``; True when that took a rebuild."""
        shapes = {o.object_id: o.shape_version for o in scene.objects.values()}
        if self.model is None or shapes != self._shapes:
            self.model = model_of(scene)
            self.data = mujoco.MjData(self.model)
            self._shapes = shapes
            self._mocap = {}
            for o in meshed(scene):
                body = mujoco.mj_name2id(
                    self.model, mujoco.mjtObj.mjOBJ_BODY, f"object{o.object_id}"
                )
                self._mocap[o.object_id] = int(self.model.body_mocapid[body])
            mujoco.mj_forward(self.model, self.data)
            self.rebuilds += 1
            return True
        assert self.data is not None
        for object_id, mocap in self._mocap.items():
            pose = scene.objects[object_id].pose
            self.data.mocap_pos[mocap] = pose.translation
            self.data.mocap_quat[mocap] = mujoco_quat(pose)
        mujoco.mj_forward(self.model, self.data)
        self.moves += 1
        return False

    def body_pose(self, object_id: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Where the model has the object's body now: position and (w, x, y, z)."""
        assert self.data is not None
        mocap = self._mocap[object_id]
        return np.array(self.data.mocap_pos[mocap]), np.array(self.data.mocap_quat[mocap])


def largest_object(scene: Scene) -> SceneObject:
    objects = meshed(scene)
    if not objects:
        raise ValueError("the daemon has published no object yet")
    return max(objects, key=lambda o: float(np.ptp(o.vertices, axis=0).prod()))


def drop_probe(scene: Scene, seconds: float = 1.5) -> tuple[float, float]:
    """Drops the probe over the middle of the largest object's upper part; returns (the probe's
    resting height above the support, the object's highest point above it), metres."""
    support = support_of(scene)
    target = largest_object(scene).mesh.vertices.astype(np.float64)
    heights = (target - support.point) @ support.normal
    top = float(heights.max())
    # Over the middle of its upper part (a hull's highest vertex is a peak it would roll off).
    upper = target[heights >= top - 0.25 * (top - heights.min())]
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


def follow(socket: str, seconds: float) -> tuple[Scene, LiveModel]:
    """Keeps a live model of the daemon's scene for ``seconds`` after its snapshot."""
    live = LiveModel()
    deadline: float | None = None
    with Subscriber(socket, reconnect=False, timeout_s=10) as subscriber:
        scene = subscriber.scene
        for message in subscriber:
            if scene.complete and support_or_none(scene) is not None:
                if deadline is None:
                    deadline = time.monotonic() + seconds
                if isinstance(message, (Shape, Pose)) or live.model is None:
                    live.update(scene)
            if deadline is not None and time.monotonic() > deadline:
                break
    return scene, live


def support_or_none(scene: Scene) -> Support | None:
    try:
        return support_of(scene)
    except ValueError:
        return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--socket", required=True, help="the daemon's socket path")
    parser.add_argument("--seconds", type=float, default=3.0, help="how long to follow updates")
    args = parser.parse_args()
    scene, live = follow(args.socket, args.seconds)
    rest, top = drop_probe(scene)
    print(
        f"{len(scene.non_supports)} objects; the model was rebuilt {live.rebuilds} times and "
        f"its bodies moved by poses {live.moves} times; the probe came to rest {rest:.3f} m "
        f"above the support, the object's top is at {top:.3f} m"
    )


if __name__ == "__main__":
    main()
