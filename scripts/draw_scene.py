"""Draw what the daemon published over the depth cloud it came from, and list the objects.

Usage (see BENCHMARKS.md, "What is published on the room recordings"):

    tacmesh capture --sensor SPEC --out CLOUD_DIR            # frame-0.ply, the depth cloud
    tacmesh run --sensor SPEC --loop --duration-s 20 &       # the daemon on the recording
    tacmesh subscribe --out MESH_DIR                         # object-ID.ply, plane-N.ply
    python3 scripts/draw_scene.py CLOUD_DIR/frame-0.ply MESH_DIR --title NAME -o NAME.png

The picture is the camera's view (x/z and y/z of the world frame, which is the camera's for a
recording with no pose): the cloud in grey, each object's mesh in its own colour and labelled
with its id, support planes outlined. The listing (standard output, Markdown) gives each
object's faces, size (the longest side of its bounding box), area and range.

Needs numpy and matplotlib.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]


def read_ply(path: pathlib.Path) -> tuple[Array, npt.NDArray[np.int64]]:
    """Vertices and triangles of a PLY file (ASCII or binary little-endian, float vertices,
    uchar/int face lists), as tacmesh writes them."""
    data = path.read_bytes()
    end = data.index(b"end_header") + len(b"end_header")
    end = data.index(b"\n", end) + 1
    header = data[:end].decode("ascii").splitlines()
    fmt = "ascii"
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for line in header:
        words = line.split()
        if not words:
            continue
        if words[0] == "format":
            fmt = words[1]
        elif words[0] == "element":
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property":
            elements[-1][2].append((words[1], words[-1]))
    if fmt not in ("ascii", "binary_little_endian"):
        raise ValueError(f"{path}: PLY format {fmt} is not supported here")
    sizes = {"float": 4, "float32": 4, "double": 8, "float64": 8, "uchar": 1, "uint8": 1,
             "char": 1, "int8": 1, "short": 2, "int16": 2, "ushort": 2, "uint16": 2,
             "int": 4, "int32": 4, "uint": 4, "uint32": 4}
    codes = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8", "uchar": "u1",
             "uint8": "u1", "char": "i1", "int8": "i1", "short": "i2", "int16": "i2",
             "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4",
             "uint32": "u4"}
    vertices: Array = np.zeros((0, 3))
    faces: list[list[int]] = []
    if fmt == "ascii":
        rows = data[end:].decode("ascii").split("\n")
        at = 0
        for name, count, props in elements:
            block = rows[at:at + count]
            at += count
            if name == "vertex":
                names = [p[1] for p in props]
                table = np.array([[float(x) for x in r.split()] for r in block if r.strip()])
                vertices = table[:, [names.index(a) for a in ("x", "y", "z")]]
            elif name == "face":
                faces = [[int(x) for x in r.split()[1:4]] for r in block if r.strip()]
        return vertices, np.array(faces, dtype=np.int64).reshape(-1, 3)
    at = end
    for name, count, props in elements:
        if name == "face":
            # A face is "property list COUNT_TYPE INDEX_TYPE vertex_indices".
            line = next(h for h in header if h.startswith("property list"))
            _, _, count_t, index_t, _ = line.split()
            for _ in range(count):
                n = int(np.frombuffer(data, codes[count_t], 1, at)[0])
                at += sizes[count_t]
                idx = np.frombuffer(data, codes[index_t], n, at)
                at += n * sizes[index_t]
                faces.append([int(i) for i in idx[:3]])
        else:
            dtype = np.dtype([(p[1], "<" + codes[p[0]]) for p in props])
            table = np.frombuffer(data, dtype, count, at)
            at += count * dtype.itemsize
            if name == "vertex":
                vertices = np.stack([table[a].astype(np.float64) for a in ("x", "y", "z")], 1)
    return vertices, np.array(faces, dtype=np.int64).reshape(-1, 3)


@dataclass
class Published:
    """One published object or support plane."""

    name: str
    vertices: Array
    faces: npt.NDArray[np.int64]

    @property
    def size_m(self) -> float:
        return float((self.vertices.max(0) - self.vertices.min(0)).max())

    @property
    def area_m2(self) -> float:
        v = self.vertices[self.faces]
        return float(0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1).sum())

    @property
    def range_m(self) -> float:
        return float(np.linalg.norm(self.vertices.mean(0)))


def load_published(folder: pathlib.Path) -> list[Published]:
    out = []
    for path in sorted(folder.glob("*.ply"), key=lambda p: (p.stem.split("-")[0], int(p.stem.split("-")[1]))):
        vertices, faces = read_ply(path)
        if len(faces):
            out.append(Published(path.stem, vertices, faces))
    return out


def draw(cloud: Array, published: list[Published], title: str, out: pathlib.Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    def view(p: Array) -> Array:
        z = np.maximum(p[:, 2], 1e-3)
        return np.stack([p[:, 0] / z, -p[:, 1] / z], 1)

    fig, ax = plt.subplots(figsize=(9, 7))
    # The cloud as a depth image (nearest point per cell; nearer is darker), drawn under the
    # meshes.
    uv = view(cloud)
    lo, hi = uv.min(0), uv.max(0)
    width = 320
    height = max(1, int(width * (hi[1] - lo[1]) / max(hi[0] - lo[0], 1e-6)))
    cols = np.clip(((uv[:, 0] - lo[0]) / (hi[0] - lo[0] + 1e-9) * width).astype(int), 0, width - 1)
    rows = np.clip(((hi[1] - uv[:, 1]) / (hi[1] - lo[1] + 1e-9) * height).astype(int), 0, height - 1)
    image = np.full((height, width), np.nan)
    order = np.argsort(-np.linalg.norm(cloud, axis=1))  # nearest written last
    image[rows[order], cols[order]] = np.linalg.norm(cloud[order], axis=1)
    ax.imshow(image, cmap="Greys_r", extent=(lo[0], hi[0], lo[1], hi[1]), vmin=0.0,
              vmax=1.5 * float(np.nanpercentile(image, 95)), interpolation="nearest")
    colours = plt.get_cmap("tab20")
    for k, obj in enumerate(published):
        tri = view(obj.vertices)[obj.faces]
        if obj.name.startswith("plane"):
            ax.add_collection(PolyCollection(list(tri), facecolors="none", edgecolors="tab:blue",
                                             linewidths=0.6, alpha=0.7))
            continue
        colour = colours(k % 20)
        ax.add_collection(PolyCollection(list(tri), facecolors=colour, edgecolors="k",
                                         linewidths=0.2, alpha=0.75))
        centre = view(obj.vertices).mean(0)
        ax.annotate(obj.name.split("-")[1], centre, fontsize=8, ha="center", va="center",
                    bbox={"boxstyle": "round,pad=0.1", "fc": "white", "alpha": 0.7, "lw": 0})
    ax.set_aspect("equal")
    ax.set_title(title)
    ax.set_xlabel("x / z")
    ax.set_ylabel("-y / z")
    ax.autoscale()
    fig.tight_layout()
    fig.savefig(out, dpi=90)


def listing(published: list[Published]) -> str:
    rows = ["| published | faces | size (m) | area (m²) | range (m) |", "|---|---|---|---|---|"]
    for obj in published:
        rows.append(f"| {obj.name} | {len(obj.faces)} | {obj.size_m:.2f} | {obj.area_m2:.3f} | {obj.range_m:.2f} |")
    return "\n".join(rows)


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cloud", type=pathlib.Path, help="a depth cloud from tacmesh capture")
    parser.add_argument("meshes", type=pathlib.Path, help="the folder tacmesh subscribe --out wrote")
    parser.add_argument("--title", default="", help="the picture's title")
    parser.add_argument("-o", "--out", type=pathlib.Path, required=True, help="the PNG to write")
    args = parser.parse_args(argv)
    cloud, _ = read_ply(args.cloud)
    published = load_published(args.meshes)
    draw(cloud, published, args.title, args.out)
    print(listing(published))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
