"""The segmentation peer for BENCHMARKS.md: Open3D's plane RANSAC and DBSCAN on the eight
labelled mOSD scans, scored as `segment/tests/real_data.rs` scores tacmesh (per labelled
object, the IoU of its points with the best-matching predicted segment).

    python3 benches/segment_peer.py            # needs numpy and open3d

The peer is the textbook tabletop pipeline: one `segment_plane` (1 cm, 1000 iterations) for
the table, then `cluster_dbscan` on the rest with tacmesh's cluster tolerance (1.5 cm) and
segments under 300 points dropped, as tacmesh drops them.
"""

from __future__ import annotations

import pathlib
import time

import numpy as np
import numpy.typing as npt
import open3d as o3d

SCANS = [
    ("osd_test0", "boxes"),
    ("osd_test35", "cylinders, stacked"),
    ("osd_test17", "stacked"),
    ("osd_test20", "stacked"),
    ("osd_test26", "occluded"),
    ("osd_test38", "cylinders"),
    ("osd_test45", "mixed"),
    ("osd_test57", "cluttered"),
]
ROOT = (
    pathlib.Path(__file__).resolve().parent.parent / "testdata" / "pointclouds" / "mosd"
)


def best_ious(
    truth: npt.NDArray[np.int64], predicted: npt.NDArray[np.int64]
) -> list[float]:
    """For each labelled object (labels of 20 and up, object = label // 10), the IoU with the
    best-matching predicted segment (1 and up; 0 is no segment)."""
    out = []
    objects = truth >= 20
    for obj in sorted(set((truth[objects] // 10).tolist())):
        mine = objects & (truth // 10 == obj)
        best = 0.0
        for seg in set(predicted[mine].tolist()) - {0}:
            theirs = predicted == seg
            inter = np.count_nonzero(mine & theirs)
            union = np.count_nonzero(mine | theirs)
            best = max(best, inter / union)
        out.append(best)
    return out


def segment(points: npt.NDArray[np.float64]) -> npt.NDArray[np.int64]:
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    _, inliers = cloud.segment_plane(
        distance_threshold=0.01, ransac_n=3, num_iterations=1000
    )
    rest = np.setdiff1d(np.arange(len(points)), inliers)
    labels = np.asarray(
        cloud.select_by_index(rest).cluster_dbscan(eps=0.015, min_points=10)
    )
    out = np.zeros(len(points), dtype=np.int64)
    for k in set(labels.tolist()) - {-1}:
        members = rest[labels == k]
        if len(members) >= 300:
            out[members] = k + 1
    return out


def main() -> None:
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    everything: list[float] = []
    for name, kind in SCANS:
        scan = o3d.t.io.read_point_cloud(str(ROOT / f"{name}.pcd"))
        points = scan.point.positions.numpy().astype(np.float64)
        labels = scan.point.label.numpy().reshape(-1).astype(np.int64)
        finite = np.isfinite(points).all(axis=1)
        points, labels = points[finite], labels[finite]
        started = time.perf_counter()
        predicted = segment(points)
        seconds = time.perf_counter() - started
        ious = best_ious(labels, predicted)
        everything += ious
        print(
            f"open3d {name:10} {kind:18} objects {len(ious):2} predicted "
            f"{len(set(predicted.tolist()) - {0}):2} mean IoU {np.mean(ious):.3f} "
            f"({seconds * 1e3:.0f} ms) per object {[round(float(v), 2) for v in ious]}"
        )
    print(f"open3d: mean IoU over {len(everything)} objects {np.mean(everything):.3f}")


if __name__ == "__main__":
    main()
