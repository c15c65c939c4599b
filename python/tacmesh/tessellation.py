"""A closed triangle mesh of a Body's primitive, for what needs a surface rather than the
primitive's sizes (drawing it, or an engine without that primitive).

Entry point: :func:`tessellate`. A box is its 8 corners; a cylinder, a sphere and a capsule are
surfaces of revolution about the primitive's z: a profile of (radius, z) points from the bottom
pole to the top one, each point off the axis turned into a ring. Every mesh is closed (each
edge used once in each direction) and wound counter-clockwise seen from outside; its vertices
lie on the primitive's surface, so a round primitive's mesh is slightly inside it.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from .wire import Primitive, PrimitiveKind

#: A box's corners in its own frame: corner k has bit 0 for x, bit 1 for y, bit 2 for z (set
#: for +, clear for −).
BOX_CORNERS = np.array(
    [[1 if k & 1 else -1, 1 if k & 2 else -1, 1 if k & 4 else -1] for k in range(8)],
    np.float64,
)
#: Its faces, counter-clockwise seen from outside: −x, +x, −y, +y, −z, +z (as the box of
#: docs/protocol.md's second Body example).
BOX_TRIANGLES = np.array(
    [
        [0, 4, 6],
        [0, 6, 2],
        [1, 3, 7],
        [1, 7, 5],
        [0, 1, 5],
        [0, 5, 4],
        [2, 6, 7],
        [2, 7, 3],
        [0, 2, 3],
        [0, 3, 1],
        [4, 5, 7],
        [4, 7, 6],
    ],
    np.uint32,
)


def _profile(primitive: Primitive, rings: int) -> list[tuple[float, float]]:
    """The (radius, z) profile of a round primitive, bottom pole to top pole: a cylinder's
    rims, a sphere's ``rings`` bands of latitude, a capsule's two hemispheres of ``rings // 2``
    bands each with its cylinder between them."""
    radius, half = float(primitive.sizes[0]), float(primitive.sizes[1])
    if primitive.kind == PrimitiveKind.CYLINDER:
        return [(0.0, -half), (radius, -half), (radius, half), (0.0, half)]
    if primitive.kind == PrimitiveKind.SPHERE:
        bands = [math.pi * i / rings for i in range(1, rings)]
        latitudes = [(radius * math.sin(a), -radius * math.cos(a)) for a in bands]
        return [(0.0, -radius), *latitudes, (0.0, radius)]
    # A capsule: the lower hemisphere below −half, the upper above +half.
    n = max(rings // 2, 1)
    quarter = [0.5 * math.pi * i / n for i in range(1, n + 1)]
    lower = [(radius * math.sin(a), -half - radius * math.cos(a)) for a in quarter]
    upper = [(radius * math.sin(a), half + radius * math.cos(a)) for a in reversed(quarter)]
    return [(0.0, -half - radius), *lower, *upper, (0.0, half + radius)]


def _lathe(
    profile: list[tuple[float, float]], around: int
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.uint32]]:
    """The surface of revolution about z of ``profile`` (its first and last points on the
    axis, the others off it), ``around`` vertices to a ring."""
    angles = 2 * np.pi * np.arange(around) / around
    rings = [
        np.column_stack([r * np.cos(angles), r * np.sin(angles), np.full(around, z)])
        for r, z in profile[1:-1]
    ]
    bottom, top = profile[0][1], profile[-1][1]
    vertices = np.vstack([[0.0, 0.0, bottom], *rings, [0.0, 0.0, top]])
    j = np.arange(around)
    k = (j + 1) % around
    last = len(vertices) - 1

    def ring(i: int) -> npt.NDArray[np.int64]:
        return 1 + i * around + j

    def ring_next(i: int) -> npt.NDArray[np.int64]:
        return 1 + i * around + k

    triangles = [np.column_stack([np.zeros(around, np.int64), ring_next(0), ring(0)])]
    for i in range(len(rings) - 1):
        a, b, c, d = ring(i), ring_next(i), ring_next(i + 1), ring(i + 1)
        triangles += [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
    n = len(rings) - 1
    triangles.append(np.column_stack([np.full(around, last), ring(n), ring_next(n)]))
    return vertices, np.vstack(triangles).astype(np.uint32)


def tessellate(
    primitive: Primitive, around: int = 24, rings: int = 8
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    """A closed mesh of ``primitive`` in the object's frame (placed by its rotation and
    centre), counter-clockwise seen from outside: vertices ``float32 (V, 3)`` and triangles
    ``uint32 (T, 3)``. A box is its 8 corners and 12 triangles; a cylinder, a sphere and a
    capsule have ``around`` vertices to a ring, a sphere ``rings`` bands of latitude and a
    capsule ``rings // 2`` to each end."""
    if around < 3 or rings < 2:
        raise ValueError(f"around {around} and rings {rings}: at least 3 and 2 are needed")
    kind = PrimitiveKind(primitive.kind)
    if kind == PrimitiveKind.BOX:
        vertices = BOX_CORNERS * np.asarray(primitive.sizes, dtype=np.float64)
        triangles = BOX_TRIANGLES.copy()
    else:
        vertices, triangles = _lathe(_profile(primitive, rings), around)
    return primitive.to_object(vertices), triangles
