"""Tests of draw_scene.py: `python3 -m pytest scripts/` (needs numpy and matplotlib)."""

from __future__ import annotations

import pathlib
import struct

import numpy as np
import pytest

import draw_scene

TRIANGLE = np.array([[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.0, 0.2, 1.0]])


def write_ascii(path: pathlib.Path) -> None:
    path.write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
        "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
        + "".join(f"{x} {y} {z}\n" for x, y, z in TRIANGLE)
        + "3 0 1 2\n"
    )


def write_binary(path: pathlib.Path) -> None:
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\n"
        "property float y\nproperty float z\nelement face 1\n"
        "property list uchar uint vertex_indices\nend_header\n"
    ).encode()
    body = b"".join(struct.pack("<3f", *v) for v in TRIANGLE)
    body += struct.pack("<B3I", 3, 0, 1, 2)
    path.write_bytes(header + body)


@pytest.mark.parametrize("write", [write_ascii, write_binary])
def test_reads_what_tacmesh_writes(tmp_path: pathlib.Path, write: object) -> None:
    path = tmp_path / "object-7.ply"
    assert callable(write)
    write(path)
    vertices, faces = draw_scene.read_ply(path)
    np.testing.assert_allclose(vertices, TRIANGLE, atol=1e-6)
    assert faces.tolist() == [[0, 1, 2]]


def test_lists_and_draws_published_objects(tmp_path: pathlib.Path) -> None:
    meshes = tmp_path / "meshes"
    meshes.mkdir()
    write_binary(meshes / "object-7.ply")
    write_ascii(meshes / "plane-1.ply")
    published = draw_scene.load_published(meshes)
    assert [p.name for p in published] == ["object-7", "plane-1"]
    obj = published[0]
    assert obj.area_m2 == pytest.approx(0.01, rel=1e-5)
    assert obj.size_m == pytest.approx(0.2, rel=1e-5)
    table = draw_scene.listing(published)
    assert "| object-7 | 1 | 0.20 | 0.010 | 1.00 |" in table
    cloud = np.random.default_rng(0).uniform([-0.5, -0.5, 0.8], [0.5, 0.5, 2.0], (500, 3))
    out = tmp_path / "scene.png"
    draw_scene.draw(cloud, published, "test", out)
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
