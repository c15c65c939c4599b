"""The tessellation of a Body's primitive: closed, counter-clockwise seen from outside, its
vertices on the primitive's surface, placed by the primitive's rotation and centre, and of
about the primitive's volume (a little less: the mesh is inscribed)."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import numpy.typing as npt
import pytest

from tacmesh import Primitive, PrimitiveKind, tessellate

#: A quarter turn about the horizontal axis 0.3 rad from x: the primitive lies on its side.
ROTATION = (
    math.sin(math.pi / 4) * math.cos(0.3),
    math.sin(math.pi / 4) * math.sin(0.3),
    0.0,
    math.cos(math.pi / 4),
)
CENTRE = (0.3, -0.2, 0.15)

PRIMITIVES = [
    Primitive(PrimitiveKind.BOX, (0.1, 0.05, 0.15), ROTATION, CENTRE),
    Primitive(PrimitiveKind.CYLINDER, (0.04, 0.09, 0.0), ROTATION, CENTRE),
    Primitive(PrimitiveKind.SPHERE, (0.1, 0.0, 0.0), ROTATION, CENTRE),
    Primitive(PrimitiveKind.CAPSULE, (0.03, 0.05, 0.0), ROTATION, CENTRE),
]


def volume_of(primitive: Primitive) -> float:
    a, b, c = primitive.sizes
    if primitive.kind == PrimitiveKind.BOX:
        return 8 * a * b * c
    if primitive.kind == PrimitiveKind.CYLINDER:
        return math.pi * a * a * 2 * b
    if primitive.kind == PrimitiveKind.SPHERE:
        return 4 / 3 * math.pi * a**3
    return math.pi * a * a * 2 * b + 4 / 3 * math.pi * a**3


def surface_distances(primitive: Primitive, points: npt.ArrayLike) -> npt.NDArray[np.float64]:
    """The distance of each of ``points`` (object frame) from the primitive's surface."""
    own = (np.asarray(points, np.float64) - primitive.centre) @ primitive.rotation_matrix()
    a, b, c = primitive.sizes
    if primitive.kind == PrimitiveKind.BOX:
        q = np.abs(own) - [a, b, c]
    elif primitive.kind == PrimitiveKind.CYLINDER:
        q = np.column_stack([np.linalg.norm(own[:, :2], axis=1) - a, np.abs(own[:, 2]) - b])
    else:
        # A sphere is a capsule whose axis is a point.
        axis = np.zeros_like(own)
        axis[:, 2] = own[:, 2].clip(-b, b)
        q = (np.linalg.norm(own - axis, axis=1) - a)[:, None]
    outside = np.linalg.norm(np.maximum(q, 0), axis=1)
    distances: npt.NDArray[np.float64] = np.abs(outside + np.minimum(q.max(axis=1), 0))
    return distances


@pytest.mark.parametrize("primitive", PRIMITIVES, ids=lambda p: p.kind.name.lower())
@pytest.mark.parametrize(("around", "rings"), [(3, 2), (8, 4), (24, 8), (128, 64)])
def test_a_primitives_mesh_is_closed_outward_and_on_its_surface(
    primitive: Primitive, around: int, rings: int
) -> None:
    vertices, triangles = tessellate(primitive, around, rings)
    assert vertices.dtype == np.float32 and vertices.shape[1] == 3
    assert triangles.dtype == np.uint32 and triangles.shape[1] == 3
    assert int(triangles.max()) < len(vertices) and len(np.unique(triangles)) == len(vertices)
    # Closed: each edge once in each direction; no triangle repeats a vertex.
    directed = Counter(
        (int(t[i]), int(t[(i + 1) % 3])) for t in triangles.tolist() for i in range(3)
    )
    assert all(n == 1 and directed[b, a] == 1 for (a, b), n in directed.items())
    assert all(len(set(t)) == 3 for t in triangles.tolist())
    # A closed surface of genus 0: 2 V − 4 triangles.
    assert len(triangles) == 2 * len(vertices) - 4
    # Counter-clockwise seen from outside: each face's normal points away from the centre
    # (every primitive is convex), and the volume is positive, a little under the primitive's.
    v = vertices.astype(np.float64)
    a, b, c = (v[triangles[:, i]] for i in range(3))
    normals = np.cross(b - a, c - a)
    assert np.all(np.einsum("ij,ij->i", normals, (a + b + c) / 3 - CENTRE) > 0)
    volume = float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum()) / 6
    truth = volume_of(primitive)
    assert volume <= truth * (1 + 1e-5)
    if primitive.kind == PrimitiveKind.BOX:
        assert volume == pytest.approx(truth, rel=1e-5)
    elif around >= 128:
        assert volume > 0.998 * truth
    elif around >= 24:
        assert volume > 0.95 * truth
    else:
        assert volume > 0.1 * truth
    # On the surface, placed by the rotation and centre.
    assert float(surface_distances(primitive, v).max()) < 1e-6


def test_a_box_is_its_corners_and_a_primitive_without_a_turn_stays_put() -> None:
    box = Primitive(PrimitiveKind.BOX, (0.1, 0.2, 0.3))
    vertices, triangles = tessellate(box)
    assert len(vertices) == 8 and len(triangles) == 12
    corners = {tuple(np.round(x, 6)) for x in vertices.tolist()}
    assert corners == {(x, y, z) for x in (-0.1, 0.1) for y in (-0.2, 0.2) for z in (-0.3, 0.3)}
    sphere = Primitive(PrimitiveKind.SPHERE, (0.5, 0.0, 0.0), centre=(1.0, 2.0, 3.0))
    vertices, _ = tessellate(sphere, around=16, rings=8)
    np.testing.assert_allclose(vertices.min(axis=0), [0.5, 1.5, 2.5], atol=0.02)
    np.testing.assert_allclose(vertices.max(axis=0), [1.5, 2.5, 3.5], atol=0.02)
    # The poles are on the primitive's z.
    np.testing.assert_allclose(vertices[0], [1.0, 2.0, 2.5], atol=1e-6)
    np.testing.assert_allclose(vertices[-1], [1.0, 2.0, 3.5], atol=1e-6)


def test_a_capsule_is_as_long_as_its_axis_and_two_radii() -> None:
    capsule = Primitive(PrimitiveKind.CAPSULE, (0.03, 0.05, 0.0))
    vertices, _ = tessellate(capsule)
    assert float(vertices[:, 2].min()) == pytest.approx(-0.08, abs=1e-7)
    assert float(vertices[:, 2].max()) == pytest.approx(0.08, abs=1e-7)
    assert float(np.linalg.norm(vertices[:, :2], axis=1).max()) == pytest.approx(0.03, abs=1e-7)
    # The distances the tests measure with: 10 cm beyond an end, 2 cm inside the side.
    np.testing.assert_allclose(
        surface_distances(capsule, [[0, 0, 0.18], [0.01, 0, 0.02]]), [0.1, 0.02], atol=1e-9
    )


def test_too_few_sides_are_refused() -> None:
    with pytest.raises(ValueError, match="at least"):
        tessellate(PRIMITIVES[1], around=2)
    with pytest.raises(ValueError, match="at least"):
        tessellate(PRIMITIVES[2], rings=1)
