"""What a client reads of the demo scene, by the options it asks for: the daemon runs the
simulated demo for a while, four Python clients subscribe at once (one per row of
python/README.md's table), and each counts the bytes of every frame it reads (its first
snapshot included) by kind of message, over the time to the daemon's Goodbye.

    python3 benches/client_bytes.py [SECONDS]    # default 20

Needs a release build (cargo build --release; TACMESH_BIN names another) and the Python client
installed (pip install ./python, as .ci/run does in ~/.cache/tacmesh/py-venv). Prints a Markdown
table for python/README.md and the load average beside it.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any

from bench_daemon import SPECS, start_daemon
from tacmesh import Body, Pose, Shape, Subscriber

ROWS: list[tuple[str, dict[str, Any]]] = [
    ("the defaults (full encoding, bodies)", {}),
    ("`extrapolate=True`", {"extrapolate": True}),
    (
        '`extrapolate=True, encoding="compact"`',
        {"extrapolate": True, "encoding": "compact"},
    ),
    (
        '`extrapolate=True, encoding="compact", kinds=("objects", "supports")`',
        {"extrapolate": True, "encoding": "compact", "kinds": ("objects", "supports")},
    ),
]


class Reading:
    """One client's count: bytes by kind of message, Poses, and how long it read."""

    def __init__(self) -> None:
        self.bytes: Counter[str] = Counter()
        self.poses = 0
        self.bodies = 0
        self.seconds = 0.0
        self.error: str | None = None


def read(socket: Path, options: dict[str, Any], seconds: float, out: Reading) -> None:
    """Subscribe with `options` and count until the daemon says Goodbye."""
    try:
        started = time.monotonic()
        subscriber = Subscriber(
            socket, reconnect=False, timeout_s=seconds + 30, **options
        )
        for message in subscriber:
            size = subscriber.last_frame_bytes
            if isinstance(message, Shape):
                out.bytes["shapes"] += size
            elif isinstance(message, Body):
                out.bytes["bodies"] += size
                out.bodies += 1
            elif isinstance(message, Pose):
                out.bytes["poses"] += size
                out.poses += 1
            else:
                out.bytes["other"] += size
        out.seconds = time.monotonic() - started
    # Any failure is reported in the table, not raised from a thread.
    except Exception as err:  # noqa: BLE001
        out.error = f"{type(err).__name__}: {err}"


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    with tempfile.TemporaryDirectory() as tmp:
        socket = Path(tmp) / "tacmesh.sock"
        daemon = start_daemon(SPECS["demo"], socket, seconds)
        try:
            readings = [Reading() for _ in ROWS]
            threads = [
                threading.Thread(target=read, args=(socket, options, seconds, out))
                for (_, options), out in zip(ROWS, readings)
            ]
            for t in threads:
                t.start()
            for t in threads:
                t.join()
        finally:
            daemon.wait(timeout=60)
    print(
        "| options | bytes a second | of which shapes / bodies / poses | Bodies | Poses |"
    )
    print("|---|---|---|---|---|")
    for (name, _), r in zip(ROWS, readings):
        if r.error is not None or r.seconds <= 0:
            print(f"| {name} | failed: {r.error} | | | |")
            continue
        rate = sum(r.bytes.values()) / r.seconds / 1e3
        share = " / ".join(
            f"{r.bytes[k] / r.seconds / 1e3:.1f}" for k in ("shapes", "bodies", "poses")
        )
        print(f"| {name} | {rate:.1f} kB/s | {share} kB/s | {r.bodies} | {r.poses} |")
    print(f"\nload average at the end: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
