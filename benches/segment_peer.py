"""The segmentation peer for BENCHMARKS.md: Open3D's plane RANSAC and DBSCAN on labelled mOSD
scans, scored as `tacmesh_segment::labelled` scores tacmesh (per labelled object, the IoU of
its points with the best-matching predicted segment; an object's pieces count as one), per
scan and per kind of scene, as the `labelled_iou` example prints tacmesh's.

    python3 benches/segment_peer.py            # the eight scans in testdata; numpy, open3d
    python3 benches/segment_peer.py ../shared/data/pointclouds/mosd_learn testdata/pointclouds/mosd

The peer is the textbook tabletop pipeline: one `segment_plane` (1 cm, 1000 iterations) for
the table, then `cluster_dbscan` on the rest with tacmesh's cluster tolerance (1.5 cm) and
segments under 300 points dropped, as tacmesh drops them.
"""

from __future__ import annotations

import pathlib
import re
import sys
import time

import numpy as np
import numpy.typing as npt
import open3d as o3d

ROOT = (
    pathlib.Path(__file__).resolve().parent.parent / "testdata" / "pointclouds" / "mosd"
)

# The kinds of scene by scan number, from the dataset's README.
LEARN_KINDS = [(16, "boxes"), (24, "stacked"), (32, "occluded"), (44, "cylinders")]
TEST_KINDS = [
    (15, "boxes"),
    (23, "stacked"),
    (30, "occluded"),
    (42, "cylinders"),
    (54, "mixed"),
    (65, "complex"),
]
KINDS = ["boxes", "stacked", "occluded", "cylinders", "mixed", "complex"]


def kind_of(name: str) -> str | None:
    """The kind of the scan `learnN` or `[osd_]testN`, or None."""
    match = re.fullmatch(r"(.*?)(\d+)", name)
    if match is None:
        return None
    stem, number = match.group(1), int(match.group(2))
    table = (
        LEARN_KINDS
        if stem.endswith("learn")
        else TEST_KINDS if stem.endswith("test") else []
    )
    for last, kind in table:
        if number <= last:
            return kind
    return None


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


def scans(arguments: list[str]) -> list[pathlib.Path]:
    """The PCD files named or in the folders named (the eight in testdata by default), by
    kind and number."""
    files: list[pathlib.Path] = []
    for argument in arguments or [str(ROOT)]:
        path = pathlib.Path(argument)
        files += sorted(path.glob("*.pcd")) if path.is_dir() else [path]

    def order(file: pathlib.Path) -> tuple[int, int]:
        kind = kind_of(file.stem)
        number = int(re.sub(r"\D", "", file.stem) or 0)
        return (KINDS.index(kind) if kind else len(KINDS), number)

    return sorted(files, key=order)


def main() -> None:
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    by_kind: dict[str, list[float]] = {}
    for file in scans(sys.argv[1:]):
        scan = o3d.t.io.read_point_cloud(str(file))
        points = scan.point.positions.numpy().astype(np.float64)
        labels = scan.point.label.numpy().reshape(-1).astype(np.int64)
        finite = np.isfinite(points).all(axis=1)
        points, labels = points[finite], labels[finite]
        started = time.perf_counter()
        predicted = segment(points)
        seconds = time.perf_counter() - started
        ious = best_ious(labels, predicted)
        kind = kind_of(file.stem) or "other"
        by_kind.setdefault(kind, []).extend(ious)
        print(
            f"open3d {file.stem:12} {kind:9} objects {len(ious):2} predicted "
            f"{len(set(predicted.tolist()) - {0}):2} mean IoU {np.mean(ious):.3f} "
            f"({seconds * 1e3:.0f} ms) per object {[round(float(v), 2) for v in ious]}"
        )
    print()
    print("| kind | objects | mean IoU | >= 0.8 |")
    print("|---|---|---|---|")
    everything: list[float] = []
    for kind in [k for k in KINDS + ["other"] if k in by_kind]:
        ious = by_kind[kind]
        everything += ious
        good = sum(v >= 0.8 for v in ious) / len(ious)
        print(f"| {kind} | {len(ious)} | {np.mean(ious):.3f} | {good * 100:.0f} % |")
    good = sum(v >= 0.8 for v in everything) / max(len(everything), 1)
    print(
        f"| all | {len(everything)} | {np.mean(everything):.3f} | {good * 100:.0f} % |"
    )


if __name__ == "__main__":
    main()
