"""What the Python benchmarks share: the executable, the recordings in testdata (and the
simulated demo) as sensor specs, and a daemon started on one of them.

Imported by the scripts beside it (`python3 benches/NAME.py` puts this folder on the path).
"""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parents[1]
#: The release build, or what TACMESH_BIN names.
TACMESH = Path(os.environ.get("TACMESH_BIN", ROOT / "target/release/tacmesh"))

#: Each recording in testdata, and the simulated demo, as `tacmesh run --sensor` takes it.
SPECS = {
    "demo": "sim:demo",
    "oni": "replay:testdata/recordings/openni1_primesense_12frames_640x480.oni",
    "bag": "replay:testdata/recordings/realsense_d435_single_depth_color_640x480.bag",
    "tum": "replay:testdata/depth/tum_fr1?fx=520.9&fy=521.0&cx=325.1&cy=249.7&depth_scale_m=0.0002",
    "slambook": "replay:testdata/depth/slambook_kinect?fx=518&fy=519&cx=325.5&cy=253.5",
    "pcl_kinect": "replay:testdata/depth/pcl_kinect_grabber?fx=525&fy=525&cx=320&cy=240",
    "milk": "replay:testdata/pointclouds/pcl/milk_cartoon_all_small_clorox.pcd",
}


def start_daemon(
    spec: str, socket: Path, seconds: float, log: IO[bytes] | None = None
) -> subprocess.Popen[bytes]:
    """`tacmesh run` on `spec` (a recording looped) for `seconds`, serving `socket`; returns
    once the socket is there. Its log (at `info`) goes to `log`, or nowhere. The caller waits
    for the daemon to end."""
    loop = [] if spec.startswith("sim:") else ["--loop"]
    daemon = subprocess.Popen(
        [str(TACMESH), "run", "--sensor", spec, *loop, "--socket", str(socket)]
        + ["--duration-s", str(seconds)],
        cwd=ROOT,
        stderr=subprocess.DEVNULL if log is None else log,
        env=os.environ if log is None else {**os.environ, "RUST_LOG": "info"},
    )
    deadline = time.monotonic() + 60
    while not socket.exists():
        if time.monotonic() > deadline or daemon.poll() is not None:
            daemon.kill()
            daemon.wait(timeout=60)
            raise RuntimeError(f"the daemon on {spec} did not start")
        time.sleep(0.02)
    return daemon
