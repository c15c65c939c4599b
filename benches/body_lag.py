"""How long each object waits for its body: the daemon plays each recording in testdata (and
the simulated demo) for a while, this client notes when each Shape and each Body arrives, and
prints, per recording, the lag from a shape to the body made from it (p50, p99, max), how many
objects hold a body at the end and what those bodies are (primitive kinds, fallbacks).

    python3 benches/body_lag.py [NAME...]   # names: demo oni bag tum slambook pcl_kinect milk

Needs a release build (cargo build --release; TACMESH_BIN names another) and the Python client installed
(pip install ./python, as .ci/run does in ~/.cache/tacmesh/py-venv). Prints a Markdown table for
BENCHMARKS.md. A shape whose body never comes (a newer shape replaced it first) is not a lag.
"""

from __future__ import annotations

import os
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np

from bench_daemon import SPECS, start_daemon
from tacmesh import FIRST_SUPPORT_ID, Body, BodySolid, Shape, Subscriber

SECONDS = 20


def measure(spec: str) -> str:
    """One Markdown row: the lags and the bodies of `spec` played for SECONDS."""
    with tempfile.TemporaryDirectory() as tmp:
        socket = Path(tmp) / "tacmesh.sock"
        daemon = start_daemon(spec, socket, SECONDS)
        shaped: dict[tuple[int, int], float] = {}
        lags: list[float] = []
        try:
            subscriber = Subscriber(socket, reconnect=False, timeout_s=SECONDS + 30)
            for message in subscriber:
                now = time.monotonic()
                if isinstance(message, Shape):
                    shaped.setdefault((message.object_id, message.shape_version), now)
                elif isinstance(message, Body):
                    made = shaped.get((message.object_id, message.shape_version))
                    if made is not None:
                        lags.append(now - made)
            scene = subscriber.scene
        finally:
            daemon.wait(timeout=60)
    objects = [o for o in scene.objects.values() if o.object_id < FIRST_SUPPORT_ID]
    kinds: Counter[str] = Counter()
    for o in objects:
        if o.body is None:
            kinds["none"] += 1
        elif o.body.solid is BodySolid.PRIMITIVE and o.body.primitive is not None:
            kinds[o.body.primitive.kind.name.lower()] += 1
        else:
            kinds[o.body.solid.name.lower().replace("_", " ")] += 1
    with_body = sum(1 for o in objects if o.body is not None)
    ms = np.array(lags) * 1e3
    timing = (
        f"{np.percentile(ms, 50):.0f} / {np.percentile(ms, 99):.0f} / {ms.max():.0f}"
        if len(ms)
        else "—"
    )
    what = ", ".join(f"{n} {k}" for k, n in kinds.most_common())
    return f"| {len(lags)} | {timing} | {with_body} of {len(objects)} | {what} |"


def main() -> None:
    names = sys.argv[1:] or list(SPECS)
    print(
        "| recording | bodies | lag after its shape, ms: p50 / p99 / max | objects with a body at the end | what they are |"
    )
    print("|---|---|---|---|---|")
    for name in names:
        print(f"| {name} {measure(SPECS[name])}", flush=True)
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
