"""Keep a MuJoCo model in step with the daemon's scene, and drop a probe onto an object.

    python python/examples/mujoco_scene.py --socket /tmp/tacmesh.sock [--seconds 3]

Reads the daemon's scene (the snapshot, then updates for ``--seconds``) and keeps an MJCF model
of it. Each object is a mocap body placed by the object's pose, holding, in the object's frame,
what its collision body says to collide: an object whose Body is a primitive
(``BodySolid.PRIMITIVE``) is MuJoCo's native geom of it (a box, a cylinder, a sphere or a
capsule, at the primitive's centre and rotation), an object with any other Body is its convex
hulls (a mesh geom each), and an object with no Body yet (or one of no hulls) is its shape (a
mesh geom, which MuJoCo collides as its convex hull). The support plane is a plane geom through the published fan,
gravity along its normal toward it. A new shape or body (or an object coming or going) rebuilds
the model (MuJoCo compiles a model of a few objects in milliseconds); a Pose only moves its
body (``data.mocap_pos`` / ``data.mocap_quat``), without a rebuild. At the end it drops a 2 cm
sphere from 30 cm above the top of the largest object and prints where it comes to rest
against the highest point of what the object is collided as.

Needs the ``mujoco`` package (``pip install mujoco``) and the client (``pip install ./python``).
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import mujoco  # type: ignore[import-untyped]  # ships no type information
import numpy as np
import numpy.typing as npt

from tacmesh import (
    Body,
    BodySolid,
    Hull,
    Mesh,
    Pose,
    Primitive,
    PrimitiveKind,
    Remove,
    Scene,
    SceneObject,
    Shape,
    Subscriber,
)

PROBE_RADIUS_M = 0.02
DROP_HEIGHT_M = 0.3
#: MuJoCo's geom of each primitive kind; its ``size`` is the primitive's sizes the kind uses
#: (a box's half sides; a cylinder's or capsule's radius and half height; a sphere's radius).
MUJOCO_GEOM = {
    PrimitiveKind.BOX: "box",
    PrimitiveKind.CYLINDER: "cylinder",
    PrimitiveKind.SPHERE: "sphere",
    PrimitiveKind.CAPSULE: "capsule",
}


@dataclass
class Support:
    """A support plane in the world: a point on it and its unit normal, pointing to where the
    objects stand."""

    point: npt.NDArray[np.float64]
    normal: npt.NDArray[np.float64]


def primitive_of(o: SceneObject) -> Primitive | None:
    """The primitive the object is, if its Body says it is one."""
    if o.body is not None and o.body.solid is BodySolid.PRIMITIVE:
        return o.body.primitive
    return None


def hulls_of(o: SceneObject) -> tuple[Hull, ...]:
    """The convex hulls the object is collided as: its Body's, unless that is a primitive."""
    if o.body is None or primitive_of(o) is not None:
        return ()
    return o.body.hulls


def modelled(scene: Scene) -> list[SceneObject]:
    """The objects the model holds (supports aside): those with a primitive or hulls, and the
    others (no Body yet, or one of no hulls) whose shape MuJoCo can make a hull of."""
    return [
        o
        for o in scene.non_supports
        if primitive_of(o) is not None or hulls_of(o) or len(o.triangles) >= 4
    ]


def collided_as(o: SceneObject) -> list[Mesh]:
    """What the model collides the object as, in the world: its primitive's tessellation, its
    hulls, or its shape."""
    if primitive_of(o) is not None and o.world_solid is not None:
        return [o.world_solid]
    if hulls_of(o):
        return list(o.world_hulls)
    return [o.mesh]


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


def mujoco_quat(rotation: tuple[float, float, float, float]) -> npt.NDArray[np.float64]:
    """MuJoCo's (w, x, y, z) of the wire's (x, y, z, w)."""
    x, y, z, w = rotation
    return np.array([w, x, y, z])


def _mesh(name: str, vertices: npt.ArrayLike, triangles: npt.ArrayLike) -> str:
    return f'    <mesh name="{name}" vertex="{_numbers(vertices)}" face="{_numbers(triangles)}"/>'


def assets_of(o: SceneObject) -> list[str]:
    """The mesh assets of an object's geoms (none for a primitive), object frame."""
    if primitive_of(o) is not None:
        return []
    hulls = hulls_of(o)
    if hulls:
        return [
            _mesh(f"object{o.object_id}_hull{k}", hull.vertices, hull.triangles)
            for k, hull in enumerate(hulls)
        ]
    return [_mesh(f"object{o.object_id}", o.vertices, o.triangles)]


def geoms_of(o: SceneObject) -> list[str]:
    """An object's geoms in its frame: its primitive, its hulls or its shape."""
    primitive = primitive_of(o)
    if primitive is not None:
        size = primitive.sizes[: primitive.kind.used_sizes]
        return [
            f'      <geom name="object{o.object_id}" type="{MUJOCO_GEOM[primitive.kind]}" '
            f'size="{_numbers(size)}" pos="{_numbers(primitive.centre)}" '
            f'quat="{_numbers(mujoco_quat(primitive.rotation))}"/>'
        ]
    hulls = hulls_of(o)
    if hulls:
        return [
            f'      <geom name="object{o.object_id}_hull{k}" type="mesh" '
            f'mesh="object{o.object_id}_hull{k}"/>'
            for k in range(len(hulls))
        ]
    return [f'      <geom name="object{o.object_id}" type="mesh" mesh="object{o.object_id}"/>']


def mjcf_of(scene: Scene, support: Support, probe_at: npt.NDArray[np.float64] | None) -> str:
    """The scene as MJCF: each object a mocap body at its pose holding its geoms (its
    primitive, its hulls or its shape, object frame), the support as a plane, and a probe."""
    objects = modelled(scene)
    assets = "\n".join(asset for o in objects for asset in assets_of(o))
    bodies = "\n".join(
        f'    <body name="object{o.object_id}" mocap="true" pos="{_numbers(o.pose.translation)}" '
        f'quat="{_numbers(mujoco_quat(o.pose.rotation))}">\n'
        + "\n".join(geoms_of(o))
        + "\n    </body>"
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


def body_version(body: Body | None) -> int | None:
    """The shape version a Body was made from, None without one."""
    return None if body is None else body.shape_version


class LiveModel:
    """A MuJoCo model and data kept in step with a scene: rebuilt when the shapes or bodies
    change (an object's new shape version or new Body, an object coming or going, another
    support), the mocap bodies moved when only poses change."""

    def __init__(self) -> None:
        self.model: mujoco.MjModel | None = None
        self.data: mujoco.MjData | None = None
        self.rebuilds = 0
        self.moves = 0
        #: Per object, its shape's version and its Body's (None without one).
        self._versions: dict[int, tuple[int, int | None]] = {}
        self._mocap: dict[int, int] = {}

    def update(self, scene: Scene) -> bool:
        """Brings the model up to date with ``scene``; True when that took a rebuild."""
        versions = {
            o.object_id: (o.shape_version, body_version(o.body)) for o in scene.objects.values()
        }
        if self.model is None or versions != self._versions:
            self.model = model_of(scene)
            self.data = mujoco.MjData(self.model)
            self._versions = versions
            self._mocap = {}
            for o in modelled(scene):
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
            self.data.mocap_quat[mocap] = mujoco_quat(pose.rotation)
        mujoco.mj_forward(self.model, self.data)
        self.moves += 1
        return False

    def body_pose(self, object_id: int) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
        """Where the model has the object's body now: position and (w, x, y, z)."""
        assert self.data is not None
        mocap = self._mocap[object_id]
        return np.array(self.data.mocap_pos[mocap]), np.array(self.data.mocap_quat[mocap])


def largest_object(scene: Scene) -> SceneObject:
    objects = modelled(scene)
    if not objects:
        raise ValueError("the daemon has published no object yet")
    return max(objects, key=lambda o: float(np.ptp(o.vertices, axis=0).prod()))


def drop_probe(scene: Scene, seconds: float = 1.5) -> tuple[float, float]:
    """Drops the probe over the middle of the largest object's upper part; returns (the probe's
    resting height above the support, the highest point of what the object is collided as
    above it), metres."""
    support = support_of(scene)
    target = np.vstack([m.vertices for m in collided_as(largest_object(scene))]).astype(np.float64)
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
                if isinstance(message, (Shape, Body, Pose, Remove)) or live.model is None:
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
