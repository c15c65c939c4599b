"""The convex-decomposition peer for BENCHMARKS.md ("Convex parts (issue 13)"): CoACD (Wei et
al., "Approximate convex decomposition for 3D meshes with collision-aware concavity and tree
search", SIGGRAPH 2022) on the meshes `benches/convex.rs` writes, with the same bounds as
tacmesh's `convex_parts` (at most 8 hulls of at most 64 vertices).

    python3 benches/convex_peer.py MESH_DIR OUT_DIR    # needs numpy and coacd (pip install coacd==1.0.14)

For each `MESH_DIR/NAME.obj` it writes `OUT_DIR/NAME_hullK.obj` (K = 0, 1, …) and records
the seconds CoACD took in `OUT_DIR/timings.json`; `benches/convex.rs` runs it and judges both
decompositions with one metric. Run alone, it prints the time and hull count per mesh.
"""

from __future__ import annotations

import argparse
import importlib
import json
import pathlib
import time
from typing import Any

import numpy as np
import numpy.typing as npt

try:
    # Imported by name: coacd ships no type information, so it is typed `Any` on purpose.
    coacd: Any = importlib.import_module("coacd")
except ModuleNotFoundError as missing:
    raise SystemExit(
        "convex_peer.py needs coacd: pip install coacd==1.0.14"
    ) from missing

Vertices = npt.NDArray[np.float64]
Faces = npt.NDArray[np.int32]


def read_obj(path: pathlib.Path) -> tuple[Vertices, Faces]:
    """The `v` and triangular `f` lines of an OBJ file (as tacmesh writes it: 1-based, no
    slashes)."""
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    for line in path.read_text().splitlines():
        fields = line.split()
        if not fields:
            continue
        if fields[0] == "v":
            vertices.append([float(x) for x in fields[1:4]])
        elif fields[0] == "f":
            corners = [int(c.split("/")[0]) - 1 for c in fields[1:]]
            faces.extend([corners[0], a, b] for a, b in zip(corners[1:], corners[2:]))
    return np.array(vertices, dtype=np.float64), np.array(faces, dtype=np.int32)


def write_obj(path: pathlib.Path, vertices: Vertices, faces: Faces) -> None:
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices.tolist()]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces.tolist()]
    path.write_text("\n".join(lines) + "\n")


def decompose(
    vertices: Vertices,
    faces: Faces,
    max_hulls: int,
    max_hull_vertices: int,
    threshold: float,
) -> list[tuple[Vertices, Faces]]:
    """CoACD with its defaults but for the bounds: at most `max_hulls` hulls, each decimated
    to at most `max_hull_vertices` vertices."""
    parts = coacd.run_coacd(
        coacd.Mesh(vertices, faces),
        threshold=threshold,
        max_convex_hull=max_hulls,
        decimate=True,
        max_ch_vertex=max_hull_vertices,
        seed=1,
    )
    return [
        (np.asarray(v, dtype=np.float64), np.asarray(f, dtype=np.int32))
        for v, f in parts
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("mesh_dir", type=pathlib.Path)
    parser.add_argument("out_dir", type=pathlib.Path)
    parser.add_argument("--max-hulls", type=int, default=8)
    parser.add_argument("--max-hull-vertices", type=int, default=64)
    parser.add_argument(
        "--threshold", type=float, default=0.05, help="CoACD's concavity bound"
    )
    args = parser.parse_args()
    coacd.set_log_level("error")
    args.out_dir.mkdir(parents=True, exist_ok=True)
    timings: dict[str, float] = {}
    for path in sorted(args.mesh_dir.glob("*.obj")):
        vertices, faces = read_obj(path)
        started = time.perf_counter()
        hulls = decompose(
            vertices, faces, args.max_hulls, args.max_hull_vertices, args.threshold
        )
        seconds = time.perf_counter() - started
        timings[path.stem] = seconds
        for k, (hull_vertices, hull_faces) in enumerate(hulls):
            write_obj(
                args.out_dir / f"{path.stem}_hull{k}.obj", hull_vertices, hull_faces
            )
        print(
            f"coacd {path.stem:10} faces {len(faces):5} hulls {len(hulls):2} "
            f"max vertices {max(len(v) for v, _ in hulls):3} {seconds * 1e3:8.1f} ms"
        )
    (args.out_dir / "timings.json").write_text(json.dumps(timings, indent=1) + "\n")


if __name__ == "__main__":
    main()
