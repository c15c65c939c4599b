"""Log the daemon's stream to Rerun, to look at what it publishes.

    python python/examples/rerun_log.py --socket /tmp/tacmesh.sock --seconds 10 --save scene.rrd
    rerun scene.rrd                     # or --spawn to open a live viewer instead of saving

Each object's mesh is logged as a ``Mesh3D`` at ``objects/<id>`` (support planes at
``planes/<id>``) on the ``capture`` timeline (the mesh's capture time, seconds on the host's
monotonic clock), a Remove clears its entity, and the daemon's Stats are logged as scalars
under ``stats/``.

Needs ``rerun-sdk`` (``pip install rerun-sdk``) and the client (``pip install ./python``).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import rerun as rr

from tacmesh import Remove, Stats, Subscriber, Upsert
from tacmesh.wire import FIRST_PLANE_ID


def entity(object_id: int) -> str:
    if object_id >= FIRST_PLANE_ID:
        return f"planes/{object_id - FIRST_PLANE_ID}"
    return f"objects/{object_id}"


def log_stream(socket: Path, seconds: float) -> dict[str, int]:
    """Logs the stream for `seconds` (after the snapshot) to the current recording; returns how
    many of each message were logged."""
    counts = {"upserts": 0, "removes": 0, "stats": 0}
    deadline: float | None = None
    last_capture_s = 0.0
    with Subscriber(socket, reconnect=False, timeout_s=10) as subscriber:
        for message in subscriber:
            if isinstance(message, Upsert):
                last_capture_s = message.capture_time_ns * 1e-9
                rr.set_time("capture", duration=last_capture_s)
                colour = (150, 150, 150) if message.is_plane else _colour(message.object_id)
                rr.log(
                    entity(message.object_id),
                    rr.Mesh3D(
                        vertex_positions=message.vertices,
                        triangle_indices=message.triangles,
                        albedo_factor=colour,
                    ),
                )
                counts["upserts"] += 1
            elif isinstance(message, Remove):
                rr.set_time("capture", duration=last_capture_s)
                rr.log(entity(message.object_id), rr.Clear(recursive=True))
                counts["removes"] += 1
            elif isinstance(message, Stats):
                rr.set_time("capture", duration=last_capture_s)
                rr.log("stats/frames_in", rr.Scalars(float(message.frames_in)))
                rr.log("stats/frame_to_publish_p99_ms", rr.Scalars(message.frame_to_publish_p99_ms))
                counts["stats"] += 1
            if deadline is None and counts["upserts"] and counts["stats"]:
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
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--save", type=Path, help="write a .rrd recording here")
    where.add_argument("--spawn", action="store_true", help="open a live Rerun viewer")
    args = parser.parse_args()
    rr.init("tacmesh", spawn=args.spawn)
    if args.save is not None:
        rr.save(args.save)
    counts = log_stream(Path(args.socket), args.seconds)
    print(", ".join(f"{n} {what}" for what, n in counts.items()), "logged")


if __name__ == "__main__":
    main()
