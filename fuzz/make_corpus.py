#!/usr/bin/env python3
"""Builds the seed corpora of the fuzz targets, one directory per target, from the real files in
the repository's test data (testdata/, see its SOURCES.md) and from small hand-built inputs.

    python3 fuzz/make_corpus.py [--data testdata] [--out fuzz/corpus]

Real files over a few hundred kilobytes are not copied whole (libFuzzer would then mutate
megabyte inputs at a few executions a second); they are cut down to a valid file of the same
format: the first depth frame of the ONI recording, the first points of the bunny scans and PCD
clouds, the small messages of the RealSense bag with its depth image cropped, the first
revolutions of the serial capture. Seeds are rewritten on every run (same bytes each time), and
files libFuzzer added beside them are kept. Only the standard library is needed.
"""

import argparse
import math
import random
import struct
from pathlib import Path

HERE = Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parent / "testdata"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", type=Path, default=DEFAULT_DATA)
    parser.add_argument("--out", type=Path, default=HERE / "corpus")
    args = parser.parse_args()
    data = args.data
    if not (data / "SOURCES.md").is_file():
        raise SystemExit(f"{data} is not the test data (no SOURCES.md); pass --data")
    seeds = {
        "wire": wire_seeds(),
        "ply": ply_seeds(data),
        "pcd": pcd_seeds(data),
        "obj_xyz": obj_xyz_seeds(data),
        "oni": oni_seeds(data),
        "oni_16zt": oni_16zt_seeds(data),
        "rosbag": rosbag_seeds(data),
        "camsense": camsense_seeds(data),
        "rplidar": rplidar_seeds(),
        "simplify": simplify_seeds(data),
    }
    for target, files in seeds.items():
        directory = args.out / target
        directory.mkdir(parents=True, exist_ok=True)
        for name, content in files.items():
            (directory / f"seed-{name}").write_bytes(content)
        total = sum(len(c) for c in files.values())
        print(f"{target}: {len(files)} seeds, {total} bytes")


# ---------------------------------------------------------------------------------------------
# wire: frames of docs/protocol.md. The first byte of every input is the fuzz target's chunk size.


def text(s):
    b = s.encode()
    return struct.pack("<H", len(b)) + b


def frame(kind, payload=b""):
    return struct.pack("<IB", 1 + len(payload), kind) + payload


def pose(object_id, shape_version, time_ns=1_000_000_000):
    # object, shape version, pose time, its wall-clock time, last seen; identity rotation
    # (x, y, z, w), a translation, linear and angular velocity: 92 bytes.
    return struct.pack("<QQQQQ4f3f3f3f", object_id, shape_version, time_ns,
                       1_700_000_000_000_000_000 + time_ns, time_ns + 33_000_000,
                       0, 0, 0, 1, 0.1, -0.2, 1.0, 0.05, 0, 0, 0, 0, 0.3)


def geometry(vertices, triangles, compact):
    # A Shape's (and a Body proxy's) vertices and triangles: full, or the compact box, 16-bit
    # steps and u16 indices.
    if not compact:
        return (b"".join(struct.pack("<3f", *v) for v in vertices)
                + b"".join(struct.pack("<3I", *t) for t in triangles))
    lo = [min((v[k] for v in vertices), default=0.0) for k in range(3)]
    hi = [max((v[k] for v in vertices), default=0.0) for k in range(3)]
    step = [(h - l) / 65535 if h > l else 1.0 for l, h in zip(lo, hi)]
    return (struct.pack("<6f", *lo, *hi)
            + b"".join(struct.pack("<3H", *(round((v[k] - lo[k]) / step[k]) for k in range(3)))
                       for v in vertices)
            + b"".join(struct.pack("<3H", *t) for t in triangles))


def shape(object_id, version, vertices, triangles, compact=False):
    payload = pose(object_id, version) + struct.pack(
        "<QQBIIfBII", 900_000_000, 1_700_000_000_900_000_000, 0, 2 * len(triangles),
        len(triangles), 0.002, 1 if compact else 0, len(vertices), len(triangles))
    payload += geometry(vertices, triangles, compact)
    return frame(0x08, payload)


def body(object_id, version, vertices, triangles, compact=False):
    # A shadow-volume body (docs/protocol.md, Body): no primitive (its 45 bytes zero), the
    # solid in either encoding, then one hull of the same vertices, full precision with byte
    # indices.
    payload = struct.pack("<QQBff3f6f", object_id, version, 3, 0.004, 1e-4,
                          0.03, 0.03, 0.03, 1e-6, 1e-6, 1e-6, 0, 0, 0)
    payload += bytes(45)
    payload += struct.pack("<BII", 1 if compact else 0, len(vertices), len(triangles))
    payload += geometry(vertices, triangles, compact)
    payload += struct.pack("<BBH", 1, len(vertices), len(triangles))
    payload += b"".join(struct.pack("<3f", *v) for v in vertices)
    payload += b"".join(struct.pack("<3B", *t) for t in triangles)
    return frame(0x0C, payload)


def primitive_body(object_id, version):
    # A box like docs/protocol.md's second Body example, not turned: its primitive, no mesh,
    # one hull of its eight corners.
    half = (0.1, 0.05, 0.15)
    corners = [(sx * half[0], sy * half[1], 0.15 + sz * half[2])
               for sz in (-1, 1) for sy in (-1, 1) for sx in (-1, 1)]
    faces = [(0, 4, 6), (0, 6, 2), (1, 3, 7), (1, 7, 5), (0, 1, 5), (0, 5, 4),
             (2, 6, 7), (2, 7, 3), (0, 2, 3), (0, 3, 1), (4, 5, 7), (4, 7, 6)]
    payload = struct.pack("<QQBff3f6f", object_id, version, 1, 0.0, 0.006,
                          0.0, 0.0, 0.15, 5e-5, 6.5e-5, 2.5e-5, 0, 0, 0)
    payload += struct.pack("<B3f4f3ff", 1, *half, 0, 0, 0, 1, 0, 0, 0.15, 0.002)
    payload += struct.pack("<BII", 0, 0, 0)
    payload += struct.pack("<BBH", 1, len(corners), len(faces))
    payload += b"".join(struct.pack("<3f", *v) for v in corners)
    payload += b"".join(struct.pack("<3B", *t) for t in faces)
    return frame(0x0C, payload)


def subscribe(encoding=0, resend=0, rate_hz=0.0, kinds=7, ids=()):
    payload = struct.pack("<BBfBI", encoding, resend, rate_hz, kinds, len(ids))
    payload += b"".join(struct.pack("<Q", i) for i in ids)
    return frame(0x81, payload)


def wire_seeds():
    tetrahedron = ([(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1)],
                   [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)])
    hello = frame(0x01, struct.pack("<H", 4) + text("tacmesh 0.1.0"))
    options = subscribe()[5:]
    session = frame(0x07, struct.pack("<QQ", 5_000_000_000, 1_700_000_005_000_000_000) + options)
    stats = frame(0x0A, struct.pack("<19QIffI", 2_000_000_000, 1_700_000_002_000_000_000, 900,
                                    3, 12_000, 1, 0, 0, 2, 5, 3, 40, 1, 38, 300, 65_536, 1, 0, 0,
                                    2048, 12.5, 31.0, 2)
                  + text("reconstruct") + struct.pack("<2f", 4.0, 9.5)
                  + text("simplify") + struct.pack("<2f", 1.5, 3.25))
    goodbye = frame(0x06, text("shutting down"))
    server = (hello + session + shape(7, 1, *tetrahedron) + body(7, 1, *tetrahedron)
              + body(7, 1, *tetrahedron, compact=True) + primitive_body(7, 1)
              + frame(0x09, pose(7, 1))
              + frame(0x04) + shape(7, 2, *tetrahedron, compact=True)
              + frame(0x09, pose(7, 2, 2_000_000_000)) + frame(0x03, struct.pack("<Q", 7))
              + stats + goodbye)
    seeds = {
        "server-stream-whole": b"\xff" + server,
        "server-stream-bytewise": b"\x01" + server,
        "server-stream-chunks-7": b"\x07" + server,
        "hello": b"\xff" + hello,
        "session": b"\xff" + session,
        "shape": b"\xff" + shape(1, 1, *tetrahedron),
        "shape-compact": b"\xff" + shape(1, 1, *tetrahedron, compact=True),
        "shape-empty": b"\xff" + shape(2, 1, [], []),
        "pose": b"\xff" + frame(0x09, pose(3, 4)),
        "body": b"\xff" + body(1, 1, *tetrahedron),
        "body-compact": b"\xff" + body(1, 1, *tetrahedron, compact=True),
        "body-primitive": b"\xff" + primitive_body(1, 1),
        "stats": b"\xff" + stats,
        "goodbye": b"\xff" + goodbye,
        "client-subscribe": b"\x03" + subscribe() + subscribe(1, 1, 10.0, 1, (4, 5)),
        "client-subscribe-v1": b"\x03" + frame(0x80),
        "client-subscribe-tiny-rate": b"\x10" + subscribe(0, 0, 1e-45, 3),
        "oversize-prefix": b"\xff" + struct.pack("<IB", 0x7FFF_FFFF, 0x08),
    }
    return seeds


# ---------------------------------------------------------------------------------------------
# PLY: the bunny cut to a few hundred vertices, in all three encodings.


def ply_header(fmt, comments, elements):
    lines = ["ply", f"format {fmt} 1.0"] + comments
    for name, count, properties in elements:
        lines.append(f"element {name} {count}")
        lines.extend(f"property {p}" for p in properties)
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode()


def ply_seeds(data):
    bunny = (data / "pointclouds/stanford_bunny/bun_zipper_res2.ply").read_text().splitlines()
    end = bunny.index("end_header")
    vertex_count = int(next(l for l in bunny if l.startswith("element vertex")).split()[2])
    body = bunny[end + 1:]
    vertices = [tuple(map(float, l.split())) for l in body[:300]]
    faces = []
    for line in body[vertex_count:]:
        corners = tuple(map(int, line.split()[1:]))
        if max(corners) < len(vertices):
            faces.append(corners)
    faces = faces[:400]
    vertex_props = ["float x", "float y", "float z", "float confidence", "float intensity"]
    elements = [("vertex", len(vertices), vertex_props),
                ("face", len(faces), ["list uchar int vertex_indices"])]
    seeds = {}
    ascii_body = "".join(" ".join(f"{x:g}" for x in v) + "\n" for v in vertices)
    ascii_body += "".join(f"{len(f)} " + " ".join(map(str, f)) + "\n" for f in faces)
    seeds["bunny-res2-head-ascii"] = (ply_header("ascii", ["comment zipper output"], elements)
                                      + ascii_body.encode())
    for fmt, order in [("binary_little_endian", "<"), ("binary_big_endian", ">")]:
        out = ply_header(fmt, [], elements)
        out += b"".join(struct.pack(f"{order}5f", *v) for v in vertices)
        out += b"".join(struct.pack(f"{order}B{len(f)}i", len(f), *f) for f in faces)
        seeds[f"bunny-res2-head-{fmt}"] = out

    # A range scan: vertices plus the scanner's range_grid element, which readers skip.
    scan = (data / "pointclouds/stanford_bunny/bun000.ply").read_text().splitlines()
    end = scan.index("end_header")
    header = [l for l in scan[:end] if not l.startswith(("ply", "format", "element", "property"))]
    scan_vertices = scan[end + 1:end + 1 + 200]
    grid = ["0"] * 50 + ["1 3", "1 7", "0", "1 11"]
    elements = [("vertex", len(scan_vertices), ["float x", "float y", "float z"]),
                ("range_grid", len(grid), ["list uchar int vertex_indices"])]
    seeds["bun000-head-range-grid"] = (ply_header("ascii", header, elements)
                                       + "\n".join(scan_vertices + grid).encode() + b"\n")

    # A cube with normals and doubles, faces as quads with uint indices.
    cube = [(x, y, z) for x in (0, 1) for y in (0, 1) for z in (0, 1)]
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    elements = [("vertex", 8, ["double x", "double y", "double z",
                               "float nx", "float ny", "float nz", "uchar red"]),
                ("face", 6, ["list uchar uint vertex_index"])]
    out = ply_header("binary_little_endian", [], elements)
    for v in cube:
        n = [c - 0.5 for c in v]
        out += struct.pack("<3d3fB", *v, *n, 200)
    out += b"".join(struct.pack("<B4I", 4, *q) for q in quads)
    seeds["cube-normals-double-quads"] = out
    return seeds


# ---------------------------------------------------------------------------------------------
# PCD: the real milk model as is (93 kB), and crops of real clouds in every DATA kind.


def lzf_decompress(src, size):
    out = bytearray()
    i = 0
    while i < len(src) and len(out) < size:
        ctrl = src[i]
        i += 1
        if ctrl < 32:
            out += src[i:i + ctrl + 1]
            i += ctrl + 1
        else:
            length = ctrl >> 5
            if length == 7:
                length += src[i]
                i += 1
            ref = len(out) - ((ctrl & 0x1F) << 8) - src[i] - 1
            i += 1
            for _ in range(length + 2):
                out.append(out[ref])
                ref += 1
    return bytes(out)


def lzf_compress(data):
    """A small greedy LZF compressor (back-references found through a hash of 3 bytes)."""
    out = bytearray()
    literals = bytearray()
    table = {}
    i = 0

    def flush():
        for start in range(0, len(literals), 32):
            chunk = literals[start:start + 32]
            out.append(len(chunk) - 1)
            out.extend(chunk)
        literals.clear()

    while i < len(data):
        key = data[i:i + 3]
        ref = table.get(key) if len(key) == 3 else None
        table[key] = i
        if ref is not None and i - ref - 1 < 8192:
            length = 3
            while i + length < len(data) and length < 264 and data[ref + length] == data[i + length]:
                length += 1
            flush()
            off = i - ref - 1
            if length - 2 < 7:
                out.append(((length - 2) << 5) | (off >> 8))
            else:
                out.append((7 << 5) | (off >> 8))
                out.append(length - 2 - 7)
            out.append(off & 0xFF)
            i += length
        else:
            literals.append(data[i])
            i += 1
    flush()
    return bytes(out)


def read_pcd(path):
    """Header lines and the decompressed column-major data of a binary_compressed PCD."""
    raw = path.read_bytes()
    end = raw.index(b"DATA binary_compressed\n") + len(b"DATA binary_compressed\n")
    header = raw[:end].decode().splitlines()
    compressed, size = struct.unpack_from("<II", raw, end)
    return header, lzf_decompress(raw[end + 8:end + 8 + compressed], size)


def pcd_header(fields, sizes, types, width, height, data):
    return ("# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
            f"FIELDS {' '.join(fields)}\nSIZE {' '.join(map(str, sizes))}\n"
            f"TYPE {' '.join(types)}\nCOUNT {' '.join('1' for _ in fields)}\n"
            f"WIDTH {width}\nHEIGHT {height}\nVIEWPOINT 0 0 0 1 0 0 0\n"
            f"POINTS {width * height}\nDATA {data}\n").encode()


def pcd_all_kinds(name, fields, sizes, types, width, height, rows):
    """One cloud (rows of per-field values, floats may be NaN) in ascii, binary and compressed."""
    codes = {("F", 4): "f", ("F", 8): "d", ("U", 4): "I", ("U", 1): "B", ("I", 2): "h"}
    packers = [codes[(t, s)] for t, s in zip(types, sizes)]
    seeds = {}
    lines = []
    for row in rows:
        lines.append(" ".join("nan" if isinstance(v, float) and math.isnan(v) else
                              (f"{v:g}" if isinstance(v, float) else str(v)) for v in row))
    seeds[f"{name}-ascii"] = (pcd_header(fields, sizes, types, width, height, "ascii")
                              + ("\n".join(lines) + "\n").encode())
    binary = b"".join(struct.pack("<" + "".join(packers), *row) for row in rows)
    seeds[f"{name}-binary"] = pcd_header(fields, sizes, types, width, height, "binary") + binary
    columns = b"".join(struct.pack(f"<{len(rows)}{p}", *(row[k] for row in rows))
                       for k, p in enumerate(packers))
    packed = lzf_compress(columns)
    seeds[f"{name}-binary_compressed"] = (
        pcd_header(fields, sizes, types, width, height, "binary_compressed")
        + struct.pack("<II", len(packed), len(columns)) + packed)
    return seeds


def pcd_seeds(data):
    seeds = {"milk-real": (data / "pointclouds/pcl/milk.pcd").read_bytes()}

    # A 16x8 crop of the labelled mOSD scene (label x y z rgba), NaN points included.
    header, columns = read_pcd(data / "pointclouds/mosd/osd_test0.pcd")
    width, n = 640, 640 * 480
    labels = struct.unpack_from(f"<{n}I", columns, 0)
    xyz = [struct.unpack_from(f"<{n}f", columns, 4 * n * k) for k in (1, 2, 3)]
    rgba = struct.unpack_from(f"<{n}I", columns, 16 * n)
    rows = []
    for y in range(236, 244):
        for x in range(300, 316):
            i = y * width + x
            rows.append((labels[i], xyz[0][i], xyz[1][i], xyz[2][i], rgba[i]))
    rows[0] = (0, math.nan, math.nan, math.nan, 0)
    seeds.update(pcd_all_kinds("osd-crop-16x8", ["label", "x", "y", "z", "rgba"],
                               [4, 4, 4, 4, 4], ["U", "F", "F", "F", "U"], 16, 8, rows))

    # Normals, doubles, small integers and padding-free odd sizes, from the milk points.
    header, columns = read_pcd(data / "pointclouds/pcl/milk.pcd")
    n = 13704
    xyz = [struct.unpack_from(f"<{n}f", columns, 4 * n * k) for k in range(3)]
    rows = []
    for i in range(0, 40 * 97, 97):
        p = (xyz[0][i], xyz[1][i], xyz[2][i])
        length = math.sqrt(sum(c * c for c in p)) or 1.0
        rows.append((*p, *(c / length for c in p), i % 7, i % 300 - 150))
    seeds.update(pcd_all_kinds("milk-normals-40",
                               ["x", "y", "z", "normal_x", "normal_y", "normal_z", "label", "intensity"],
                               [4, 4, 4, 8, 8, 8, 1, 2], ["F", "F", "F", "F", "F", "F", "U", "I"],
                               40, 1, rows))
    return seeds


# ---------------------------------------------------------------------------------------------
# OBJ and XYZ text: the small Blender meshes as they are, and milk points as XYZ.


def obj_xyz_seeds(data):
    seeds = {}
    for name in ["cube", "plane", "ico_sphere", "cone", "cylinder", "grid",
                 "suzanne_blender283_with_uv_normals"]:
        seeds[f"obj-{name}"] = (data / f"meshes/{name}.obj").read_bytes()
    header, columns = read_pcd(data / "pointclouds/pcl/milk.pcd")
    n = 13704
    xyz = [struct.unpack_from(f"<{n}f", columns, 4 * n * k) for k in range(3)]
    points = [(xyz[0][i], xyz[1][i], xyz[2][i]) for i in range(0, n, 271)]
    seeds["xyz-milk"] = "".join(f"{x:g} {y:g} {z:g}\n" for x, y, z in points).encode()
    lines = ["# x, y, z, nx, ny, nz", ""]
    for p in points:
        length = math.sqrt(sum(c * c for c in p)) or 1.0
        lines.append(", ".join(f"{c:g}" for c in (*p, *(c / length for c in p))))
    seeds["xyz-milk-normals-commas"] = ("\n".join(lines) + "\n").encode()
    return seeds


# ---------------------------------------------------------------------------------------------
# ONI: the real recording cut to its first depth frame, and a tiny hand-built one.


def oni_records(raw):
    """(offset, type, node, bytes) of every record up to and including End."""
    offset = 24
    while offset < len(raw):
        _, kind, node, fields, payload = struct.unpack_from("<IIIII", raw, offset)
        yield offset, kind, node, raw[offset:offset + fields + payload]
        if kind == 11:
            return
        offset += fields + payload


NEW_DATA, SEEK_TABLE, NODE_ADDED, END = 10, 14, 13, 11


def oni_real_first_frame(data):
    raw = (data / "recordings/openni1_primesense_12frames_640x480.oni").read_bytes()
    depth_node = None
    out = bytearray(raw[:24])
    depth_frames = 0
    payloads = []
    for _, kind, node, record in oni_records(raw):
        if kind == NODE_ADDED and record[32:39] == b"Depth1\x00":
            depth_node = node
        if kind == NEW_DATA:
            if node != depth_node or depth_frames == 1:
                continue
            depth_frames += 1
            fields = struct.unpack_from("<I", record, 12)[0]
            payloads.append(record[fields:])
        if kind == SEEK_TABLE:
            continue
        out += record
    return bytes(out), payloads


def oni_record(kind, node, fields, payload=b""):
    return struct.pack("<IIIIIQ", int.from_bytes(b"NIR\0", "little"), kind, node,
                       28 + len(fields), len(payload), 0) + fields + payload


def oni_string(s):
    b = s.encode() + b"\0"
    return struct.pack("<I", len(b)) + b


def encode_16zt(depth_mm):
    """A valid 16zT payload: the value table, then every pixel as an escaped absolute index."""
    table = sorted(set(depth_mm))
    index = [table.index(d) for d in depth_mm]
    out = struct.pack(f"<H{len(table)}HH", len(table), *table, index[0])
    return out + b"".join(bytes([0xFF, i >> 8, i & 0xFF]) for i in index[1:])


# Table [0, 700], first pixel index 0, then (nibble d: index -= d - 6): 66 two pixels at 0;
# 56 up one, two at 700; E1 a run of 2; 6D one and padding; FF 00 00 an absolute index 0;
# 6D one; 6F C0 one, then an escaped delta of 0, one more. 12 pixels.
NIBBLES_AND_RUNS = struct.pack("<HHHH", 2, 0, 700, 0) + bytes(
    [0x66, 0x56, 0xE1, 0x6D, 0xFF, 0x00, 0x00, 0x6D, 0x6F, 0xC0])


def oni_tiny():
    width, height = 4, 3
    depth = [0, 500, 500, 510, 520, 520, 520, 0, 800, 801, 802, 0]
    out = bytearray(b"NI10" + struct.pack("<BBHIQI", 1, 0, 1, 0, 66_000, 1))
    out += oni_record(NODE_ADDED, 1, oni_string("Depth1") + struct.pack("<I", 2) + b"16zT"
                      + struct.pack("<IQQQ", 2, 0, 66_000, 0))
    mode = struct.pack("<III", width, height, 30)
    out += oni_record(6, 1, oni_string("xnMapOutputMode") + struct.pack("<I", 12) + mode)
    fov = struct.pack("<2d", 1.01447, 0.78981)
    out += oni_record(6, 1, oni_string("xnFOV") + struct.pack("<I", 16) + fov)
    out += oni_record(3, 1, oni_string("ZPD") + struct.pack("<IQ", 8, 120))
    out += oni_record(4, 1, oni_string("ZPPS") + struct.pack("<Id", 8, 0.1042))
    payload = encode_16zt(depth)
    out += oni_record(NEW_DATA, 1, struct.pack("<QI", 0, 1), payload)
    out += oni_record(NEW_DATA, 1, struct.pack("<QI", 33_000, 2), NIBBLES_AND_RUNS)
    out += oni_record(END, 0xFFFF_FFFF, b"")
    return bytes(out)


def oni_seeds(data):
    real, _ = oni_real_first_frame(data)
    return {"primesense-first-depth-frame": real, "tiny-4x3-two-frames": oni_tiny()}


def oni_16zt_seeds(data):
    """Each input is a u32 pixel count, then the payload."""
    _, payloads = oni_real_first_frame(data)
    depth = [0, 500, 500, 510, 520, 520, 520, 0, 800, 801, 802, 0]
    return {
        "primesense-frame-1": struct.pack("<I", 640 * 480) + payloads[0],
        "tiny-escapes": struct.pack("<I", 12) + encode_16zt(depth),
        "tiny-nibbles-runs": struct.pack("<I", 12) + NIBBLES_AND_RUNS,
    }


# ---------------------------------------------------------------------------------------------
# ROS bag: the RealSense recording's small messages with its depth image cropped to 8x6,
# re-chunked as `none` and as `lz4` (frames of stored blocks, checksummed with xxHash32).


def xxh32(data, seed=0):
    p1, p2, p3, p4, p5 = 2654435761, 2246822519, 3266489917, 668265263, 374761393
    mask = 0xFFFFFFFF

    def rotl(x, r):
        return ((x << r) | (x >> (32 - r))) & mask

    def round_(acc, lane):
        return (rotl((acc + lane * p2) & mask, 13) * p1) & mask

    n, i = len(data), 0
    if n >= 16:
        v = [(seed + p1 + p2) & mask, (seed + p2) & mask, seed, (seed - p1) & mask]
        while i + 16 <= n:
            lanes = struct.unpack_from("<4I", data, i)
            v = [round_(a, l) for a, l in zip(v, lanes)]
            i += 16
        h = (rotl(v[0], 1) + rotl(v[1], 7) + rotl(v[2], 12) + rotl(v[3], 18)) & mask
    else:
        h = (seed + p5) & mask
    h = (h + n) & mask
    while i + 4 <= n:
        h = (rotl((h + struct.unpack_from("<I", data, i)[0] * p3) & mask, 17) * p4) & mask
        i += 4
    while i < n:
        h = (rotl((h + data[i] * p5) & mask, 11) * p1) & mask
        i += 1
    h ^= h >> 15
    h = (h * p2) & mask
    h ^= h >> 13
    h = (h * p3) & mask
    return h ^ (h >> 16)


def lz4_stored_frame(content):
    descriptor = bytes([0x64, 0x40])  # version 1, independent blocks, content checksum; 64 KiB
    out = bytearray(b"\x04\x22\x4d\x18" + descriptor + bytes([(xxh32(descriptor) >> 8) & 0xFF]))
    for start in range(0, len(content), 65536):
        block = content[start:start + 65536]
        out += struct.pack("<I", len(block) | 0x8000_0000) + block
    out += struct.pack("<II", 0, xxh32(content))
    return bytes(out)


def lz4_block_decompress(src, out):
    i = 0
    while i < len(src):
        token = src[i]
        i += 1
        length = token >> 4
        if length == 15:
            while True:
                b = src[i]
                i += 1
                length += b
                if b != 255:
                    break
        out += src[i:i + length]
        i += length
        if i >= len(src):
            break
        offset = src[i] | src[i + 1] << 8
        i += 2
        length = token & 15
        if length == 15:
            while True:
                b = src[i]
                i += 1
                length += b
                if b != 255:
                    break
        start = len(out) - offset
        for k in range(length + 4):
            out.append(out[start + k])


def lz4_frame_decompress(src):
    flg = src[4]
    i = 7 + (8 if flg & 0x08 else 0)
    out = bytearray()
    while True:
        size = struct.unpack_from("<I", src, i)[0]
        i += 4
        if size == 0:
            return bytes(out)
        if size & 0x8000_0000:
            out += src[i:i + (size & 0x7FFF_FFFF)]
        else:
            # Blocks are dependent in ROS's roslz4 frames: decode into the running output.
            lz4_block_decompress(src[i:i + size], out)
        i += size & 0x7FFF_FFFF
        if flg & 0x10:
            i += 4


def bag_fields(raw):
    fields, i = {}, 0
    while i < len(raw):
        n = struct.unpack_from("<I", raw, i)[0]
        name, value = raw[i + 4:i + 4 + n].split(b"=", 1)
        fields[name.decode()] = value
        i += 4 + n
    return fields


def bag_records(raw, offset=0):
    """(header fields, raw header, data) of every record from offset on."""
    while offset + 4 <= len(raw):
        header_len = struct.unpack_from("<I", raw, offset)[0]
        header = raw[offset + 4:offset + 4 + header_len]
        data_len = struct.unpack_from("<I", raw, offset + 4 + header_len)[0]
        data = raw[offset + 8 + header_len:offset + 8 + header_len + data_len]
        yield bag_fields(header), header, data
        offset += 8 + header_len + data_len


def bag_field(name, value):
    return struct.pack("<I", len(name) + 1 + len(value)) + name.encode() + b"=" + value


def bag_record(fields, data):
    header = b"".join(bag_field(n, v) for n, v in fields)
    return struct.pack("<I", len(header)) + header + struct.pack("<I", len(data)) + data


def crop_image(message, width, height):
    """A sensor_msgs/Image cut to its top-left width x height pixels."""
    i = 12
    frame_id_len = struct.unpack_from("<I", message, i)[0]
    i += 4 + frame_id_len
    rows, cols = struct.unpack_from("<II", message, i)
    encoding_len = struct.unpack_from("<I", message, i + 8)[0]
    j = i + 12 + encoding_len
    bigendian, step, data_len = struct.unpack_from("<BII", message, j)
    pixels = message[j + 9:j + 9 + data_len]
    bpp = step // cols
    # Rows from the middle, where the depth is valid.
    top, left = rows // 2, cols // 2
    cropped = b"".join(pixels[(top + r) * step + left * bpp:(top + r) * step + (left + width) * bpp]
                       for r in range(height))
    return (message[:i] + struct.pack("<II", height, width) + message[i + 8:j]
            + struct.pack("<BII", bigendian, width * bpp, len(cropped)) + cropped)


def rosbag_seeds(data):
    raw = (data / "recordings/realsense_d435_single_depth_color_640x480.bag").read_bytes()
    magic = b"#ROSBAG V2.0\n"
    records = list(bag_records(raw, len(magic)))
    inner = bytearray()
    kept = {"/device_0/sensor_0/Depth_0/image/data", "/device_0/sensor_0/Depth_0/info/camera_info",
            "/device_0/sensor_0/option/Depth Units/value", "/device_0/sensor_1/Color_0/image/data"}
    conn_topics = {}
    seen_images = set()
    for fields, header, chunk in records:
        if fields["op"] != b"\x05":
            continue
        content = lz4_frame_decompress(chunk)
        for f, h, d in bag_records(content):
            op = f["op"][0]
            if op == 7:
                conn_topics[f["conn"]] = f["topic"].decode()
                if conn_topics[f["conn"]] in kept:
                    inner += bag_record([(n, v) for n, v in field_pairs(h)], d)
            elif op == 2 and conn_topics.get(f["conn"]) in kept:
                topic = conn_topics[f["conn"]]
                if topic.endswith("image/data"):
                    if topic in seen_images:
                        continue
                    seen_images.add(topic)
                    d = crop_image(d, 8, 6)
                inner += bag_record(list(field_pairs(h)), d)
    inner = bytes(inner)
    connections = [bag_record(list(field_pairs(h)), d) for f, h, d in records
                   if f["op"] == b"\x07" and f["topic"].decode() in kept]

    # The connections first, then the messages: the record boundary nearest the middle.
    boundaries = [0]
    for f, h, d in bag_records(inner):
        boundaries.append(boundaries[-1] + 8 + len(h) + len(d))
    half = min(boundaries, key=lambda b: abs(b - len(inner) // 2))

    def bag(chunks, indexed):
        header_len_guess = 4096
        body = bytearray()
        for compression, content in chunks:
            stored = lz4_stored_frame(content) if compression == "lz4" else content
            body += bag_record([("op", b"\x05"), ("compression", compression.encode()),
                                ("size", struct.pack("<I", len(content)))], stored)
        index = b""
        if indexed:
            index = b"".join(connections)
            index += b"".join(bag_record([("op", b"\x06"), ("ver", struct.pack("<I", 1)),
                                          ("chunk_pos", struct.pack("<Q", 0)),
                                          ("start_time", bytes(8)), ("end_time", bytes(8)),
                                          ("count", struct.pack("<I", 0))], b"")
                              for _ in chunks)
        fields = [("op", b"\x03"), ("index_pos", struct.pack("<Q", 0)),
                  ("conn_count", struct.pack("<I", len(connections) if indexed else 0)),
                  ("chunk_count", struct.pack("<I", len(chunks)))]
        probe = bag_record(fields, b"")
        padding = b" " * (header_len_guess - len(probe))
        index_pos = len(magic) + len(probe) + len(padding) + len(body) if indexed else 0
        fields[1] = ("index_pos", struct.pack("<Q", index_pos))
        return magic + bag_record(fields, padding) + bytes(body) + index

    return {
        "d435-cropped-indexed-none": bag([("none", inner)], True),
        "d435-cropped-indexed-lz4": bag([("lz4", inner)], True),
        "d435-cropped-unindexed-two-chunks": bag([("none", inner[:half]), ("lz4", inner[half:])],
                                                 False),
    }


def field_pairs(header):
    i = 0
    while i < len(header):
        n = struct.unpack_from("<I", header, i)[0]
        name, value = header[i + 4:i + 4 + n].split(b"=", 1)
        yield name.decode(), value
        i += 4 + n


# ---------------------------------------------------------------------------------------------
# Serial: the real Camsense capture in slices, and an RPLIDAR stream built from its protocol.


def camsense_seeds(data):
    capture = (data / "serial/camsense_x1_protocol_uart_capture.bin").read_bytes()
    # About 50 packets of 36 bytes make a revolution; 4 kB hold two, plus the leading partial.
    return {
        "capture-start-whole": b"\xff" + capture[:4096],
        "capture-start-uart-reads-of-32": b"\x20" + capture[:4096],
        "capture-middle-bytewise": b"\x01" + capture[300_000:302_048],
    }


def rplidar_node(start, quality, angle_deg, distance_mm):
    s = 1 if start else 0
    angle_q6 = int(angle_deg * 64) & 0x7FFF
    return struct.pack("<BHH", (quality << 2) | ((1 - s) << 1) | s, (angle_q6 << 1) | 1,
                       int(distance_mm * 4) & 0xFFFF)


def rplidar_seeds():
    rng = random.Random(5)
    nodes = bytearray()
    for _ in range(2):
        for k in range(90):
            angle = k * 4 + rng.random()
            distance = 0 if rng.random() < 0.1 else 1000 + 500 * math.sin(math.radians(angle))
            nodes += rplidar_node(k == 0, rng.randrange(64), angle, distance)
    descriptor = bytes([0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81])
    info = bytes([0xA5, 0x5A, 0x14, 0, 0, 0, 0x04, 0x18, 0x1D, 0x01, 0x07]) + bytes(range(16))
    health = bytes([0xA5, 0x5A, 0x03, 0, 0, 0, 0x06, 0x00, 0x00, 0x00])
    noisy = bytearray(nodes)
    for at in (17, 300, 301, 302, 611):
        noisy[at] ^= 0x5A
    return {
        "scan-descriptor-then-nodes": b"\xff" + descriptor + bytes(nodes),
        "scan-nodes-reads-of-13": b"\x0d" + bytes(nodes),
        "scan-nodes-corrupted": b"\xff" + bytes(noisy),
        "info-answer": b"\xff" + info,
        "health-answer": b"\xff" + health,
    }


# ---------------------------------------------------------------------------------------------
# Simplify: byte 0 mode (0 OBJ, 1 height field, else soup), byte 1 residual (mm), byte 2
# min_faces; see fuzz_targets/simplify.rs.


def simplify_seeds(data):
    seeds = {}
    meshes = ["cube", "plane", "ico_sphere", "cylinder", "cone", "grid", "suzanne", "torus",
              "uv_sphere"]
    for k, name in enumerate(meshes):
        obj = (data / f"meshes/{name}.obj").read_bytes()
        residual = [1, 10, 50, 250, 255][k % 5]
        seeds[f"obj-{name}"] = bytes([0, residual, 4]) + obj
    rng = random.Random(7)
    bumps = bytes((int(20 * math.sin(x / 3) * math.cos(y / 4)) & 0xFF)
                  for y in range(16) for x in range(16))
    seeds["height-field-16x16-bumps"] = bytes([1, 3, 1, 14]) + bumps
    seeds["height-field-flat-10x10"] = bytes([1, 0, 1, 8]) + bytes(100)
    seeds["height-field-noise"] = bytes([1, 30, 2, 11]) + bytes(rng.randrange(256)
                                                                for _ in range(144))
    seeds["soup-random"] = bytes([2, 20, 1]) + bytes(rng.randrange(256) for _ in range(400))
    # The soup is read with `arbitrary`: each element of a Vec follows an odd "one more" byte,
    # an even byte ends it; then an Option (a flag byte, a u64 position and a u32 index).
    vertices = [(0, 0, 0), (0.01, 0, 0), (0, 0.01, 0), (0.01, 0.01, 0.001)]
    soup = b"".join(b"\x01" + struct.pack("<3f", *v) for v in vertices) + b"\x00"
    soup += b"".join(b"\x01" + bytes(t) for t in [(0, 1, 2), (1, 3, 2)]) + b"\x00"
    seeds["soup-two-triangles"] = bytes([2, 10, 1]) + soup + b"\x00"
    seeds["soup-index-out-of-range"] = (bytes([2, 10, 1]) + soup + b"\x01"
                                        + struct.pack("<QI", 4, 0x7FFF_FFFF))
    seeds["soup-one-past-the-end"] = (bytes([2, 10, 1]) + soup + b"\x01"
                                      + struct.pack("<QI", 2, 4))
    return seeds


if __name__ == "__main__":
    main()
