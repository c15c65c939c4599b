"""Whether the demo's static shapes stay where their own primitive bodies say they are, over
minutes: the daemon runs on the demo for SECONDS (default 300), and for every new shape of an
object whose body is a primitive made from that shape, this prints when it came, how far the
shape is from the primitive over its surface (p50 and p95 of 20,000 area-weighted samples)
and over its vertices (median), and how many shapes the object has had.

    python3 benches/shape_drift.py        # SECONDS=120 for a shorter run

A shape that grows where the camera never looks (flying pixels fused on its hidden faces)
drifts off its primitive, which is fitted to the bulk of the fused points: on the cube, the
vertex median went 0.6 -> 10.9 mm in five minutes before flying pixels were kept out of
fusion (BENCHMARKS.md, "Flying pixels and hidden faces").

Needs a release build (cargo build --release; TACMESH_BIN names another) and the Python client
installed (pip install ./python) with numpy.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench_daemon import SPECS, start_daemon
from tacmesh import BodySolid, Subscriber

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "python" / "tests"))
from test_daemon import surface_samples  # noqa: E402
from test_tessellation import surface_distances  # noqa: E402

SECONDS = float(os.environ.get("SECONDS", "300"))


def main() -> None:
    with tempfile.TemporaryDirectory() as work:
        socket = Path(work) / "tacmesh.sock"
        daemon = start_daemon(SPECS["demo"], socket, SECONDS)
        started = time.monotonic()
        seen: set[tuple[int, int]] = set()
        print(
            "| s | object | primitive | shape | surface p50 / p95 mm | vertex median mm |"
        )
        print("|---|---|---|---|---|---|")
        try:
            with Subscriber(socket, reconnect=False, timeout_s=10) as sub:
                for _ in sub:
                    if not sub.scene.complete:
                        continue
                    for o in sub.scene.non_supports:
                        body = o.body
                        if (
                            body is None
                            or body.primitive is None
                            or body.solid is not BodySolid.PRIMITIVE
                            or body.shape_version != o.shape_version
                            or (o.object_id, o.shape_version) in seen
                        ):
                            continue
                        seen.add((o.object_id, o.shape_version))
                        over_surface = surface_distances(
                            body.primitive, surface_samples(o.vertices, o.triangles)
                        )
                        at_vertices = surface_distances(body.primitive, o.vertices)
                        p50, p95 = np.percentile(over_surface, [50, 95]) * 1000
                        print(
                            f"| {time.monotonic() - started:.0f} | {o.object_id} "
                            f"| {body.primitive.kind.name.lower()} | {o.shape_version} "
                            f"| {p50:.1f} / {p95:.1f} | {np.median(at_vertices) * 1000:.1f} |",
                            flush=True,
                        )
        except OSError:
            pass  # the daemon ended its run
        daemon.wait(timeout=60)


if __name__ == "__main__":
    main()
