"""Whether the objects of a static recording keep their identities: the daemon plays each
recording in testdata looped for a while, and this prints per recording the births after the
first second (from the daemon's log), the objects removed, the ids that were replaced (a birth
within 10 cm of where an object was removed), the bursts of resets (an object's fused state
restarted from one frame), and how often the objects and the support planes
were re-meshed in the second half of the run (Shapes received, by object).

    python3 benches/identities.py [NAME...]   # names: oni bag tum slambook pcl_kinect milk

Needs a release build (cargo build --release; TACMESH_BIN names another) and the Python client
installed (pip install ./python, as .ci/run does in ~/.cache/tacmesh/py-venv). SECONDS_PER_RECORDING (default
30) sets the length of each run. Prints a Markdown table for BENCHMARKS.md.
"""

from __future__ import annotations

import os
import re
import sys
import tempfile
import time
from datetime import datetime
from pathlib import Path

import numpy as np

from bench_daemon import SPECS, start_daemon
from tacmesh import FIRST_SUPPORT_ID, Shape, Subscriber

SECONDS = float(os.environ.get("SECONDS_PER_RECORDING", "30"))
#: A birth this close to where an object was removed replaces it.
REPLACED_WITHIN_M = 0.10

APPEARED = re.compile(r"^(\S+Z) .*object appeared id=(\d+) .*centroid=\[([^\]]+)\]")
#: Any log line with its time and an object's id.
LOGGED_ID = re.compile(r"^(\S+Z) .*\bid=(\d+)")


def stamp(text: str) -> float:
    """Seconds of a log timestamp (RFC 3339, UTC)."""
    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


def measure(name: str, spec: str) -> str:
    """One Markdown row for `spec` played looped for SECONDS."""
    with tempfile.TemporaryDirectory() as tmp:
        socket = Path(tmp) / "tacmesh.sock"
        log_path = Path(tmp) / "daemon.log"
        with open(log_path, "wb") as log:
            daemon = start_daemon(spec, socket, SECONDS, log)
            started = time.monotonic()
            shapes_late: dict[int, int] = {}
            planes_late = 0
            try:
                subscriber = Subscriber(socket, reconnect=False, timeout_s=SECONDS + 30)
                for message in subscriber:
                    late = time.monotonic() - started > SECONDS / 2
                    if isinstance(message, Shape) and late:
                        if message.pose.object_id >= FIRST_SUPPORT_ID:
                            planes_late += 1
                        else:
                            shapes_late[message.pose.object_id] = (
                                shapes_late.get(message.pose.object_id, 0) + 1
                            )
                scene = subscriber.scene
            finally:
                daemon.wait(timeout=60)
        text = log_path.read_text(errors="replace")
    births: list[tuple[float, int, np.ndarray]] = []
    removals: list[tuple[float, int]] = []
    reset_at: list[tuple[float, int]] = []
    for line in text.splitlines():
        if m := APPEARED.match(line):
            centroid = np.array([float(v) for v in m.group(3).split(",")])
            births.append((stamp(m.group(1)), int(m.group(2)), centroid))
        elif m := LOGGED_ID.match(line):
            event = (stamp(m.group(1)), int(m.group(2)))
            if "object gone" in line or "object left" in line:
                removals.append(event)
            elif "object reset" in line:
                reset_at.append(event)
    if not births:
        return f"| {name} | nothing born | | | | | | | |"
    t0 = births[0][0]
    late_resets: dict[int, int] = {}
    for t, i in reset_at:
        if t - t0 > SECONDS / 2:
            late_resets[i] = late_resets.get(i, 0) + 1
    resets = f"{len(reset_at)} / {sum(late_resets.values())}" + (
        " ("
        + ", ".join(
            f"{i}: {n}"
            for i, n in sorted(late_resets.items(), key=lambda kv: -kv[1])[:3]
        )
        + ")"
        if late_resets
        else ""
    )
    where = {i: c for _, i, c in births}
    late_births = [(t, i, c) for t, i, c in births if t - t0 > 1.0]
    replaced = 0
    for t_removed, i in removals:
        if i not in where:
            continue
        if any(
            t > t_removed and np.linalg.norm(c - where[i]) < REPLACED_WITHIN_M
            for t, _, c in births
        ):
            replaced += 1
    objects = [o for o in scene.objects.values() if o.object_id < FIRST_SUPPORT_ID]
    busiest = sorted(shapes_late.items(), key=lambda kv: -kv[1])[:3]
    half = SECONDS / 2
    return (
        f"| {name} | {len(births)} | {len(late_births)} | {len(removals)} | {replaced} "
        f"| {resets} | {len(objects)} | {sum(shapes_late.values())} "
        f"({', '.join(f'{i}: {n}' for i, n in busiest) or '-'}) | {planes_late} |"
        f" <!-- {half:.0f} s -->"
    )


def main() -> None:
    names = sys.argv[1:] or ["oni", "bag", "tum", "slambook", "pcl_kinect", "milk"]
    print(
        f"| recording ({SECONDS:.0f} s looped) | births | after 1 s | removed | ids replaced "
        "| reset bursts / in the second half (busiest ids) | objects at the end | object shapes in the second half (busiest ids) "
        "| plane shapes in the second half |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name in names:
        print(measure(name, SPECS[name]), flush=True)


if __name__ == "__main__":
    main()
