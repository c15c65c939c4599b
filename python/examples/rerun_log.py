"""Log the daemon's stream to Rerun, to look at what it publishes.

    python python/examples/rerun_log.py --socket /tmp/tacmesh.sock --seconds 10 --save scene.rrd
    rerun scene.rrd                     # or --spawn to open a live viewer instead of saving

Each object's shape is logged as a ``Mesh3D`` in its own frame at ``objects/<id>`` (support
planes at ``supports/<n>``, n = id − 2^32), and its pose as a ``Transform3D`` of that entity
(translation and rotation quaternion: ``world_from_object``), logged again on every Pose, so
the viewer shows the object moving without the mesh being sent again. Times are on the
``capture`` timeline (the shape's or pose's capture time, seconds on the daemon host's
monotonic clock). A Remove clears the entity; the daemon's Stats are logged as scalars under
``stats/``.

Needs ``rerun-sdk`` (``pip install rerun-sdk``) and the client (``pip install ./python``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import rerun as rr

from tacmesh import FIRST_SUPPORT_ID, Pose, Remove, Shape, Stats, Subscriber


def entity(object_id: int) -> str:
    if object_id >= FIRST_SUPPORT_ID:
        return f"supports/{object_id - FIRST_SUPPORT_ID}"
    return f"objects/{object_id}"


def log_pose(pose: Pose) -> None:
    rr.set_time("capture", duration=pose.pose_time_ns * 1e-9)
    rr.log(
        entity(pose.object_id),
        rr.Transform3D(
            translation=pose.translation,
            quaternion=rr.Quaternion(xyzw=pose.rotation),
        ),
    )


def log_shape(shape: Shape) -> None:
    rr.set_time("capture", duration=shape.shape_time_ns * 1e-9)
    colour = (150, 150, 150) if shape.is_support else _colour(shape.object_id)
    rr.log(
        entity(shape.object_id),
        rr.Mesh3D(
            vertex_positions=shape.vertices,
            triangle_indices=shape.triangles,
            albedo_factor=colour,
        ),
    )
    log_pose(shape.pose)


def log_stream(
    socket: Path, seconds: float, *, encoding: str = "full", max_rate_hz: float = 0.0
) -> dict[str, int]:
    """Logs the stream for `seconds` (after the snapshot) to the current recording; returns how
    many of each message were logged."""
    counts = {"shapes": 0, "poses": 0, "removes": 0, "stats": 0}
    deadline: float | None = None
    last_s = 0.0
    with Subscriber(
        socket,
        encoding=encoding,
        max_rate_hz=max_rate_hz,
        reconnect=False,
        timeout_s=10,
    ) as subscriber:
        for message in subscriber:
            if isinstance(message, Shape):
                log_shape(message)
                last_s = max(last_s, message.pose.pose_time_ns * 1e-9)
                counts["shapes"] += 1
            elif isinstance(message, Pose):
                log_pose(message)
                last_s = max(last_s, message.pose_time_ns * 1e-9)
                counts["poses"] += 1
            elif isinstance(message, Remove):
                rr.set_time("capture", duration=last_s)
                rr.log(entity(message.object_id), rr.Clear(recursive=True))
                counts["removes"] += 1
            elif isinstance(message, Stats):
                rr.set_time("capture", duration=message.monotonic_ns * 1e-9)
                rr.log("stats/frames_in", rr.Scalars(float(message.frames_in)))
                rr.log(
                    "stats/frame_to_publish_p99_ms",
                    rr.Scalars(message.frame_to_publish_p99_ms),
                )
                rr.log("stats/bytes_sent", rr.Scalars(float(message.bytes_sent)))
                counts["stats"] += 1
            if deadline is None and subscriber.scene.complete and counts["stats"]:
                deadline = time.monotonic() + seconds
            if deadline is not None and time.monotonic() > deadline:
                break
    return counts


def _colour(object_id: int) -> tuple[int, int, int]:
    hue = (object_id * 0.618034) % 1.0
    r, g, b = (np.clip(np.abs((hue * 6 + k) % 6 - 3) - 1, 0, 1) for k in (0, 4, 2))
    return int(60 + 180 * r), int(60 + 180 * g), int(60 + 180 * b)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--socket", required=True, help="the daemon's socket path")
    parser.add_argument("--seconds", type=float, default=10.0, help="how long to log")
    parser.add_argument(
        "--compact", action="store_true", help="ask for the compact encoding of shapes"
    )
    parser.add_argument("--max-rate-hz", type=float, default=0.0, help="updates per object cap")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--save", type=Path, help="write a .rrd recording here")
    where.add_argument("--spawn", action="store_true", help="open a live Rerun viewer")
    args = parser.parse_args()
    rr.init("tacmesh", spawn=args.spawn)
    if args.save is not None:
        rr.save(args.save)
    counts = log_stream(
        Path(args.socket),
        args.seconds,
        encoding="compact" if args.compact else "full",
        max_rate_hz=args.max_rate_hz,
    )
    print(", ".join(f"{n} {what}" for what, n in counts.items()), "logged")


if __name__ == "__main__":
    main()
