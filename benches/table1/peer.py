"""The peer of `cargo bench --bench table1`: Open3D's screened Poisson reconstruction and quadric
decimation on the same clouds as ours (the usual Python path from a point cloud to a small
mesh). Run by the bench, not by hand:

    python benches/table1/peer.py MANIFEST.json

MANIFEST.json: {"clouds": [{"name": str, "cloud": PLY path, "faces": [int, ...]}], "out": dir}.
For each cloud: normals from 30 neighbours, oriented consistently over a tangent-plane graph
(the cloud has no sensor to point them at), Poisson at depth 8, then the mesh decimated to
each face count asked for. Writes OUT/NAME-FACES.ply for each, OUT/NAME-poisson.ply, and
OUT/timings.json: {name: {"normals_s", "poisson_s", "poisson_faces", "decimate_s": {faces: s}}}.
One thread (OMP_NUM_THREADS=1, set by the bench), as ours is timed.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import open3d as o3d  # type: ignore[import-untyped]

NEIGHBOURS = 30
POISSON_DEPTH = 8


def run(entry: dict[str, Any], out: Path) -> dict[str, Any]:
    cloud = o3d.io.read_point_cloud(entry["cloud"])
    start = time.perf_counter()
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(NEIGHBOURS))
    cloud.orient_normals_consistent_tangent_plane(NEIGHBOURS)
    normals_s = time.perf_counter() - start
    start = time.perf_counter()
    mesh, _densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        cloud, depth=POISSON_DEPTH
    )
    poisson_s = time.perf_counter() - start
    o3d.io.write_triangle_mesh(str(out / f"{entry['name']}-poisson.ply"), mesh)
    decimate_s: dict[str, float] = {}
    for faces in entry["faces"]:
        start = time.perf_counter()
        small = mesh.simplify_quadric_decimation(target_number_of_triangles=int(faces))
        decimate_s[str(faces)] = time.perf_counter() - start
        o3d.io.write_triangle_mesh(str(out / f"{entry['name']}-{faces}.ply"), small)
    return {
        "normals_s": normals_s,
        "poisson_s": poisson_s,
        "poisson_faces": len(mesh.triangles),
        "decimate_s": decimate_s,
    }


def main() -> None:
    manifest = json.loads(Path(sys.argv[1]).read_text())
    out = Path(manifest["out"])
    timings = {}
    for entry in manifest["clouds"]:
        timings[entry["name"]] = run(entry, out)
        print(f"peer: {entry['name']} done", file=sys.stderr)
    (out / "timings.json").write_text(json.dumps(timings))


if __name__ == "__main__":
    main()
