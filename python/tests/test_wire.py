"""The codec against the examples of docs/protocol.md byte for byte (the Body examples against
golden bytes computed from its layout table), round trips of every message, the compact
encoding's bound, every refusal of the document's list, and the scene rules."""

from __future__ import annotations

import math
import re
import struct
from dataclasses import fields, replace
from pathlib import Path
from typing import Any, cast

import numpy as np
import numpy.typing as npt
import pytest

from tacmesh import Scene
from tacmesh.wire import (
    DEFAULT_OPTIONS,
    FIRST_SUPPORT_ID,
    MAX_FRAME_BYTES,
    MAX_HULLS,
    PROTOCOL_VERSION,
    SHAPE_CLOSED,
    SHAPE_NEW_FRAME,
    SHAPE_SUPPORT,
    AnyMessage,
    BadBody,
    BadBox,
    BadHull,
    Body,
    BodySolid,
    CountOverCap,
    EmptyFrame,
    Encoding,
    FrameDecoder,
    FrameTooLarge,
    Goodbye,
    Hello,
    Hull,
    IndexOutOfRange,
    InvalidEnum,
    InvalidFlags,
    InvalidNumber,
    InvalidText,
    Kinds,
    NonFinite,
    NotUnitQuaternion,
    Pose,
    Primitive,
    PrimitiveKind,
    Remove,
    Sender,
    Session,
    Shape,
    SnapshotDone,
    StageLatency,
    Stats,
    Subscribe,
    SubscribeV1,
    TextTooLong,
    TimesOutOfOrder,
    TrailingBytes,
    Truncated,
    UnknownKind,
    WireError,
    WrongDirection,
    decode_all,
    encode,
    encode_subscribe,
    encode_subscribe_v1,
    inertia_matrix,
    quantisation_bound_m,
)
from tacmesh.tessellation import tessellate

STATS_COUNTERS = [f.name for f in fields(Stats) if f.type == "int"][:19]
DOC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"


def frame(kind: int, payload: bytes) -> bytes:
    return struct.pack("<IB", 1 + len(payload), kind) + payload


def one(data: bytes, sender: Sender = "server") -> AnyMessage:
    (message,) = decode_all(data, sender)
    return message


def f32(value: float) -> float:
    """The value as the wire carries it."""
    return float(np.float32(value))


# ---- the document's examples -----------------------------------------------------------------


def test_the_documents_hello() -> None:
    data = bytes.fromhex("0c000000 01 0400 0700 7461636d657368")
    assert len(data) == 16
    assert one(data) == Hello(PROTOCOL_VERSION, "tacmesh") == Hello(4, "tacmesh")
    assert encode(Hello(4, "tacmesh")) == data


def test_the_documents_remove_snapshot_done_and_goodbye() -> None:
    remove = bytes.fromhex("09000000 03 0807060504030201")
    done = bytes.fromhex("01000000 04")
    goodbye = bytes.fromhex("06000000 06 0300 627965")
    assert decode_all(remove + done + goodbye) == [
        Remove(0x0102030405060708),
        SnapshotDone(),
        Goodbye("bye"),
    ]
    assert encode(Remove(0x0102030405060708)) == remove
    assert encode(SnapshotDone()) == done
    assert encode(Goodbye("bye")) == goodbye


def test_the_documents_subscribe() -> None:
    data = bytes.fromhex("0c000000 81 01 01 00002041 07 00000000")
    options = Subscribe(Encoding.COMPACT, resend=True, max_rate_hz=10.0, kinds=Kinds.ALL)
    assert Kinds.ALL == Kinds.OBJECTS | Kinds.SUPPORTS | Kinds.BODIES == 7
    assert encode_subscribe(options) == data
    assert one(data, "client") == options
    # Version 1's empty Subscribe, which this client never sends.
    assert encode_subscribe_v1() == bytes.fromhex("01000000 80")
    assert one(encode_subscribe_v1(), "client") == SubscribeV1()


HEX_BYTE = re.compile(r"^[0-9a-f]{2}$")
POSE_PLACEHOLDER = b"<the Pose example's payload>"


def leading_hex(line: str) -> bytes | None:
    """The bytes a line of a code block starts with (its annotation after them ignored), None
    for a line that starts with something else."""
    tokens = line.split()
    n = 0
    while n < len(tokens) and HEX_BYTE.match(tokens[n]):
        n += 1
    return bytes.fromhex("".join(tokens[:n])) if n else None


def hex_examples(text: str) -> list[bytes]:
    """Every frame the document shows in hex: inline code that is nothing but hex bytes, and
    code blocks whose lines start with hex bytes (annotations after them, or on lines of their
    own, are skipped). A "…" line standing for "the 92 payload bytes of the Pose example" is
    replaced by them."""
    found: list[bytes] = []
    block: bytes | None = None
    for line in text.splitlines():
        if line.startswith("```"):
            if block is None:
                block = b""
            else:
                if block:
                    found.append(block)
                block = None
            continue
        if block is not None:
            if line.lstrip().startswith("…") and "Pose example" in line:
                block += POSE_PLACEHOLDER
            elif (chunk := leading_hex(line)) is not None:
                block += chunk
            continue
        for code in re.findall(r"`([^`]+)`", line):
            chunk = leading_hex(code)
            if chunk is not None and len(code.split()) == len(chunk) and len(chunk) >= 5:
                found.append(chunk)
    poses = [f[5:] for f in found if len(f) == 97 and f[4] == 0x09]
    if any(POSE_PLACEHOLDER in f for f in found):
        assert len(poses) == 1, "a Shape example refers to the Pose example, and there is none"
        found = [f.replace(POSE_PLACEHOLDER, poses[0]) for f in found]
    return found


def test_every_byte_example_in_the_document_decodes_and_encodes_back() -> None:
    examples = hex_examples(DOC.read_text(encoding="utf-8"))
    # Hello, Shape (full and compact), Pose, Body, Remove, SnapshotDone, Goodbye, Subscribe.
    assert len(examples) >= 9, examples
    kinds = set()
    for data in examples:
        sender: Sender = "client" if data[4] >= 0x80 else "server"
        message = one(data, sender)
        kinds.add(type(message))
        if isinstance(message, Shape) and message.encoding is Encoding.COMPACT:
            # Encoding again adds the quantisation bound to the residual once more: all else
            # is the same, byte for byte.
            again = encode(message)
            residual = 5 + 117
            assert again[:residual] == data[:residual]
            assert again[residual + 4 :] == data[residual + 4 :]
        else:
            assert encode(message) == data, (message, data.hex(" "))
    assert {Hello, Remove, SnapshotDone, Goodbye, Subscribe, Pose, Shape, Body} <= kinds


DOC_POSE = Pose(
    object_id=7,
    shape_version=2,
    pose_time_ns=1_000_000_000,
    pose_time_realtime_ns=1_700_000_000_000_000_000,
    last_seen_ns=2_000_000_000,
    rotation=(0.0, 0.0, 0.0, 1.0),
    translation=(1.0, 0.0, -2.0),
    linear_velocity=(0.5, 0.0, 0.0),
    angular_velocity=(0.0, 0.0, 0.25),
)
DOC_SHAPE = Shape(
    pose=DOC_POSE,
    shape_time_ns=1_000_000_000,
    shape_time_realtime_ns=1_700_000_000_000_000_000,
    flags=0,
    faces_in=4,
    faces_out=1,
    max_residual_m=0.25,
    vertices=np.array([[0, 0, 0], [1, 0, 0], [0, 1, -2]], np.float32),
    triangles=np.array([[0, 1, 2]], np.uint32),
)


def test_the_documents_pose() -> None:
    (data,) = [f for f in hex_examples(DOC.read_text(encoding="utf-8")) if f[4] == 0x09]
    assert len(data) == 97
    assert one(data) == DOC_POSE
    assert encode(DOC_POSE) == data


def test_the_documents_shape_in_both_encodings() -> None:
    full, compact = [f for f in hex_examples(DOC.read_text(encoding="utf-8")) if f[4] == 0x08]
    assert len(full) == len(compact) == 183
    # Full: exactly the shape, both ways.
    assert encode(DOC_SHAPE) == full
    shape = one(full)
    assert isinstance(shape, Shape)
    same_shape_fields(shape, DOC_SHAPE)
    np.testing.assert_array_equal(shape.vertices, DOC_SHAPE.vertices)
    assert shape.max_residual_m == 0.25 and not shape.is_closed and not shape.is_support
    # Compact: the encoder writes the document's bytes (its bound added to the residual), and
    # these vertices, on the box's faces, read back exactly.
    assert encode(replace(DOC_SHAPE, encoding=Encoding.COMPACT)) == compact
    shape = one(compact)
    assert isinstance(shape, Shape) and shape.encoding is Encoding.COMPACT
    np.testing.assert_array_equal(shape.vertices, DOC_SHAPE.vertices)
    np.testing.assert_array_equal(shape.triangles, DOC_SHAPE.triangles)
    assert shape.max_residual_m == pytest.approx(0.25 + 1.93e-5, abs=1e-7)
    assert quantisation_bound_m((0, 0, -2), (1, 1, 0)) == pytest.approx(1.93e-5, abs=5e-8)
    # In the world, by the Pose example's pose (a translation by (1, 0, −2)).
    np.testing.assert_array_equal(shape.world_vertices(), [[1, 0, -2], [2, 0, -2], [1, 1, -4]])


# ---- the Body examples -----------------------------------------------------------------------

#: The first Body example of docs/protocol.md (object 7's shadow volume), 280 bytes, 16 a row,
#: computed by hand from the document's layout table. If the reference implementation's golden
#: bytes differ, paste its hex here (any spacing and line breaks): every test of the example
#: reads it from this constant.
BODY_EXAMPLE_HEX = """
14 01 00 00 0c 07 00 00 00 00 00 00 00 02 00 00
00 00 00 00 00 03 00 00 80 3e ab aa 2a 3e 00 00
80 3e 00 00 80 3e 00 00 80 3e cd cc 4c 3c cd cc
4c 3c cd cc 4c 3c 89 88 08 3b 89 88 08 3b 89 88
08 3b 00 00 00 00 00 00 00 00 00 00 00 00 00 00
00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00
00 00 00 00 00 00 00 00 00 00 00 00 00 00 00 00
04 00 00 00 04 00 00 00 00 00 00 00 00 00 00 00
00 00 00 00 00 00 80 3f 00 00 00 00 00 00 00 00
00 00 00 00 00 00 80 3f 00 00 00 00 00 00 00 00
00 00 00 00 00 00 80 3f 00 00 00 00 02 00 00 00
01 00 00 00 00 00 00 00 01 00 00 00 03 00 00 00
01 00 00 00 02 00 00 00 03 00 00 00 00 00 00 00
03 00 00 00 02 00 00 00 01 04 04 00 00 00 00 00
00 00 00 00 00 00 00 00 00 00 80 3f 00 00 00 00
00 00 00 00 00 00 00 00 00 00 80 3f 00 00 00 00
00 00 00 00 00 00 00 00 00 00 80 3f 00 02 01 00
01 03 01 02 03 00 03 02
"""
BODY_EXAMPLE = bytes.fromhex("".join(BODY_EXAMPLE_HEX.split()))

TETRAHEDRON = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32)
TETRAHEDRON_FACES = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]], np.uint32)
DOC_BODY = Body(
    object_id=7,
    shape_version=2,
    solid=BodySolid.SHADOW_VOLUME,
    margin_m=0.25,
    volume_m3=float(np.float32(1 / 6)),
    centre_of_mass=np.array([0.25, 0.25, 0.25], np.float32),
    inertia=inertia_matrix(1 / 80, 1 / 80, 1 / 80, 1 / 480, 1 / 480, 1 / 480),
    vertices=TETRAHEDRON,
    triangles=TETRAHEDRON_FACES,
    hulls=(Hull(TETRAHEDRON, TETRAHEDRON_FACES.astype(np.uint8)),),
)

#: The second Body example (object 9, a box primitive): a 0.2 × 0.1 × 0.3 m box standing on
#: the object frame's origin, turned a quarter about z.
BOX_HALF_SIDES = (f32(0.1), f32(0.05), f32(0.15))
QUARTER_TURN_ABOUT_Z = (0.0, 0.0, f32(math.sqrt(0.5)), f32(math.sqrt(0.5)))
BOX_PRIMITIVE = Primitive(
    kind=PrimitiveKind.BOX,
    sizes=BOX_HALF_SIDES,
    rotation=QUARTER_TURN_ABOUT_Z,
    centre=(0.0, 0.0, f32(0.15)),
    residual_m=f32(0.002),
)
#: Its hull: the box's corners, as the document lists them (the long side along the object's
#: y), and its faces, counter-clockwise seen from outside.
BOX_CORNERS = np.array(
    [[x, y, z] for z in (0.0, 0.3) for x in (0.05, -0.05) for y in (-0.1, 0.1)], np.float32
)
BOX_FACES = np.array(
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
    np.uint8,
)
DOC_BOX_BODY = Body(
    object_id=9,
    shape_version=4,
    solid=BodySolid.PRIMITIVE,
    margin_m=0.0,
    volume_m3=f32(0.006),
    centre_of_mass=np.array([0.0, 0.0, 0.15], np.float32),
    inertia=inertia_matrix(6.5e-5, 5e-5, 2.5e-5, 0.0, 0.0, 0.0),
    primitive=BOX_PRIMITIVE,
    hulls=(Hull(BOX_CORNERS, BOX_FACES),),
)


def document_example(caption: str) -> bytes:
    """The bytes of the document's code block after ``caption``: the hex pairs each of its
    lines starts with (the annotations after them skipped)."""
    text = DOC.read_text(encoding="utf-8")
    block = text[text.index(caption) :].split("```")[1]
    return b"".join(chunk for line in block.splitlines() if (chunk := leading_hex(line)))


BOX_BODY_EXAMPLE = document_example("Example, the body of object 9")


def same_body(a: Body, b: Body) -> None:
    """Every field of the two Bodies equal (the arrays element by element)."""
    assert (a.object_id, a.shape_version, a.solid, a.encoding) == (
        b.object_id,
        b.shape_version,
        b.solid,
        b.encoding,
    )
    assert (a.margin_m, a.volume_m3, a.primitive) == (b.margin_m, b.volume_m3, b.primitive)
    np.testing.assert_array_equal(a.centre_of_mass, b.centre_of_mass)
    np.testing.assert_array_equal(a.inertia, b.inertia)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    assert len(a.hulls) == len(b.hulls)
    for mine, theirs in zip(a.hulls, b.hulls):
        np.testing.assert_array_equal(mine.vertices, theirs.vertices)
        np.testing.assert_array_equal(mine.triangles, theirs.triangles)


def check_fields_in_order(frame_bytes: bytes, fields_in_order: list[tuple[str, bytes]]) -> None:
    """``frame_bytes`` are the fields, one after the other and nothing else: if not, says which
    field differs."""
    at = 0
    for name, expected in fields_in_order:
        got = frame_bytes[at : at + len(expected)]
        assert got == expected, f"`{name}` at frame offset {at}: {got.hex(' ')}"
        at += len(expected)
    assert at == len(frame_bytes)


def test_the_body_example_golden_bytes_follow_the_layout_table() -> None:
    """The golden bytes, rebuilt field by field from the document's table: if a pasted hex
    differs, this says which field."""
    f4 = struct.Struct("<f")
    check_fields_in_order(
        BODY_EXAMPLE,
        [
            ("length", struct.pack("<I", 276)),
            ("kind", b"\x0c"),
            ("object_id", struct.pack("<Q", 7)),
            ("shape_version", struct.pack("<Q", 2)),
            ("solid", b"\x03"),
            ("margin_m", f4.pack(0.25)),
            ("volume_m3", f4.pack(1 / 6)),
            ("centre_of_mass", struct.pack("<3f", 0.25, 0.25, 0.25)),
            ("inertia", struct.pack("<6f", *[1 / 80] * 3, *[1 / 480] * 3)),
            ("primitive kind", b"\x00"),
            ("primitive sizes, rotation, centre, residual_m", bytes(44)),
            ("encoding", b"\x00"),
            ("vertex_count", struct.pack("<I", 4)),
            ("triangle_count", struct.pack("<I", 4)),
            ("vertices", TETRAHEDRON.astype("<f4").tobytes()),
            ("triangles", TETRAHEDRON_FACES.astype("<u4").tobytes()),
            ("hull_count", b"\x01"),
            ("hull vertex_count", b"\x04"),
            ("hull triangle_count", struct.pack("<H", 4)),
            ("hull vertices", TETRAHEDRON.astype("<f4").tobytes()),
            ("hull triangles", TETRAHEDRON_FACES.astype(np.uint8).tobytes()),
        ],
    )
    assert len(BODY_EXAMPLE) == 280
    # The stored values, as the document gives them.
    assert f4.unpack(f4.pack(1 / 6))[0] == pytest.approx(1 / 6, rel=1e-7)
    assert BODY_EXAMPLE[26:30].hex(" ") == "ab aa 2a 3e"
    assert BODY_EXAMPLE[42:46].hex(" ") == "cd cc 4c 3c"  # 1/80
    assert BODY_EXAMPLE[54:58].hex(" ") == "89 88 08 3b"  # 1/480


def test_the_box_body_examples_bytes_follow_the_layout_table() -> None:
    """The document's second Body example, field by field from its table."""
    f4 = struct.Struct("<f")
    half = math.sqrt(0.5)
    check_fields_in_order(
        BOX_BODY_EXAMPLE,
        [
            ("length", struct.pack("<I", 252)),
            ("kind", b"\x0c"),
            ("object_id", struct.pack("<Q", 9)),
            ("shape_version", struct.pack("<Q", 4)),
            ("solid", b"\x01"),
            ("margin_m", f4.pack(0.0)),
            ("volume_m3", f4.pack(0.006)),
            ("centre_of_mass", struct.pack("<3f", 0.0, 0.0, 0.15)),
            ("inertia", struct.pack("<6f", 6.5e-5, 5e-5, 2.5e-5, 0.0, 0.0, 0.0)),
            ("primitive kind", b"\x01"),
            ("primitive sizes", struct.pack("<3f", 0.1, 0.05, 0.15)),
            ("primitive rotation", struct.pack("<4f", 0.0, 0.0, half, half)),
            ("primitive centre", struct.pack("<3f", 0.0, 0.0, 0.15)),
            ("primitive residual_m", f4.pack(0.002)),
            ("encoding", b"\x00"),
            ("vertex_count", struct.pack("<I", 0)),
            ("triangle_count", struct.pack("<I", 0)),
            ("hull_count", b"\x01"),
            ("hull vertex_count", b"\x08"),
            ("hull triangle_count", struct.pack("<H", 12)),
            ("hull vertices", BOX_CORNERS.astype("<f4").tobytes()),
            ("hull triangles", BOX_FACES.tobytes()),
        ],
    )
    assert len(BOX_BODY_EXAMPLE) == 256


def test_the_body_example_encodes_and_decodes() -> None:
    assert encode(DOC_BODY).hex(" ") == BODY_EXAMPLE.hex(" ")
    body = one(BODY_EXAMPLE)
    assert isinstance(body, Body)
    same_body(body, DOC_BODY)
    assert body.solid is BodySolid.SHADOW_VOLUME and body.encoding is Encoding.FULL
    assert body.solid.is_fallback and body.primitive is None
    assert body.centre_of_mass.dtype == np.float32 and body.centre_of_mass.shape == (3,)
    assert body.inertia.shape == (3, 3) and np.array_equal(body.inertia, body.inertia.T)
    assert body.inertia_terms == pytest.approx((1 / 80,) * 3 + (1 / 480,) * 3, rel=1e-6)
    assert body.triangles.dtype == np.uint32
    (hull,) = body.hulls
    assert hull.vertices.dtype == np.float32 and hull.triangles.dtype == np.uint8


def test_the_documents_box_body_decodes_and_encodes_back_byte_for_byte() -> None:
    body = one(BOX_BODY_EXAMPLE)
    assert isinstance(body, Body)
    same_body(body, DOC_BOX_BODY)
    assert body.solid is BodySolid.PRIMITIVE and not body.solid.is_fallback
    assert body.primitive == BOX_PRIMITIVE and body.primitive.kind is PrimitiveKind.BOX
    assert body.primitive.residual_m == pytest.approx(0.002, rel=1e-7)
    assert body.vertices.shape == (0, 3) and body.triangles.shape == (0, 3)
    assert encode(body).hex(" ") == BOX_BODY_EXAMPLE.hex(" ")
    assert encode(DOC_BOX_BODY).hex(" ") == BOX_BODY_EXAMPLE.hex(" ")


def test_the_documents_body_examples_are_the_golden_frames() -> None:
    bodies = [f for f in hex_examples(DOC.read_text(encoding="utf-8")) if f[4] == 0x0C]
    assert [b.hex(" ") for b in bodies] == [BODY_EXAMPLE.hex(" "), BOX_BODY_EXAMPLE.hex(" ")]
    assert not [f for f in hex_examples(DOC.read_text(encoding="utf-8")) if f[4] == 0x0B]


def mass_properties(
    vertices: npt.NDArray[np.float32], faces: npt.NDArray[np.unsignedinteger[Any]]
) -> tuple[float, npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Volume, centre of mass and inertia about it (``ixy`` = −∫ x y dV) of a closed mesh, by
    the divergence theorem over its faces."""
    volume, first, second = 0.0, np.zeros(3), np.zeros((3, 3))
    for face in faces:
        a, b, c = (vertices[i].astype(np.float64) for i in face)
        # The signed tetrahedron from the origin to the face.
        v = float(np.dot(a, np.cross(b, c))) / 6
        volume += v
        first += v * (a + b + c) / 4
        second += v / 20 * (np.outer(a + b + c, a + b + c) + sum(np.outer(p, p) for p in (a, b, c)))
    centre = first / volume
    about_centre = second - volume * np.outer(centre, centre)
    return volume, centre, np.trace(about_centre) * np.eye(3) - about_centre


def test_the_body_examples_mass_properties_are_the_tetrahedrons() -> None:
    volume, centre, inertia = mass_properties(TETRAHEDRON, TETRAHEDRON_FACES)
    assert volume == pytest.approx(DOC_BODY.volume_m3, rel=1e-6)
    np.testing.assert_allclose(centre, DOC_BODY.centre_of_mass, rtol=1e-6)
    np.testing.assert_allclose(inertia, DOC_BODY.inertia, rtol=1e-6)


def test_the_box_examples_mass_properties_hull_and_primitive_agree() -> None:
    """The box example's volume, centre and inertia are its primitive's (the quarter turn
    swaps the box's own x and y moments) and its hull's, and its hull is the primitive's
    tessellation: the box's corners, closed, counter-clockwise from outside."""
    a, b, c = (2 * s for s in BOX_HALF_SIDES)
    volume = a * b * c
    own = np.diag([b * b + c * c, a * a + c * c, a * a + b * b]) * volume / 12
    turn = BOX_PRIMITIVE.rotation_matrix()
    assert volume == pytest.approx(DOC_BOX_BODY.volume_m3, rel=1e-6)
    np.testing.assert_allclose(turn @ own @ turn.T, DOC_BOX_BODY.inertia, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(BOX_PRIMITIVE.centre, DOC_BOX_BODY.centre_of_mass)
    (hull,) = DOC_BOX_BODY.hulls
    hull_volume, hull_centre, hull_inertia = mass_properties(hull.vertices, hull.triangles)
    assert hull_volume == pytest.approx(volume, rel=1e-6)
    np.testing.assert_allclose(hull_centre, DOC_BOX_BODY.centre_of_mass, atol=1e-7)
    np.testing.assert_allclose(hull_inertia, DOC_BOX_BODY.inertia, rtol=1e-5, atol=1e-12)
    vertices, triangles = tessellate(BOX_PRIMITIVE)
    np.testing.assert_allclose(vertices, hull.vertices, atol=1e-7)
    np.testing.assert_array_equal(triangles, hull.triangles)


# ---- round trips -----------------------------------------------------------------------------


def a_pose(object_id: int = 7, version: int = 3) -> Pose:
    half = f32(math.sqrt(0.5))
    return Pose(
        object_id=object_id,
        shape_version=version,
        pose_time_ns=1_000_000_000,
        pose_time_realtime_ns=1_700_000_000_000_000_000,
        last_seen_ns=1_500_000_000,
        rotation=(0.0, 0.0, half, half),
        translation=(0.25, -0.5, 1.0),
        linear_velocity=(f32(0.1), 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.5),
    )


def a_mesh(n: int = 200, seed: int = 1) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint32]]:
    rng = np.random.default_rng(seed)
    vertices = (rng.random((n, 3)) * [0.2, 0.1, 0.3] - [0.1, 0.05, 0.0]).astype(np.float32)
    triangles = rng.integers(0, n, (2 * n, 3)).astype(np.uint32)
    return vertices, triangles


def a_shape(encoding: Encoding = Encoding.FULL, n: int = 200, flags: int = SHAPE_CLOSED) -> Shape:
    vertices, triangles = a_mesh(n)
    return Shape(
        pose=a_pose(),
        shape_time_ns=900_000_000,
        shape_time_realtime_ns=1_699_999_999_900_000_000,
        flags=flags,
        faces_in=5000,
        faces_out=len(triangles),
        max_residual_m=0.002,
        vertices=vertices,
        triangles=triangles,
        encoding=encoding,
    )


def same_shape_fields(a: Shape, b: Shape) -> None:
    assert a.pose == b.pose
    assert (a.shape_time_ns, a.shape_time_realtime_ns) == (
        b.shape_time_ns,
        b.shape_time_realtime_ns,
    )
    assert (a.flags, a.faces_in, a.faces_out, a.encoding) == (
        b.flags,
        b.faces_in,
        b.faces_out,
        b.encoding,
    )
    np.testing.assert_array_equal(a.triangles, b.triangles)


@pytest.mark.parametrize(
    "message",
    [
        Hello(2, "tacmesh 0.1.0"),
        Hello(1, ""),
        Session(123, 1_700_000_000_000_000_123),
        Session(5, 6, Subscribe(Encoding.COMPACT, False, 2.5, Kinds.SUPPORTS, (1 << 32, 9))),
        a_pose(),
        a_pose(FIRST_SUPPORT_ID + 3, 1),
        Remove(2**64 - 1),
        SnapshotDone(),
        Stats(
            **{name: n for n, name in enumerate(STATS_COUNTERS, 1)},
            latency_window=2048,
            frame_to_publish_p50_ms=12.5,
            frame_to_publish_p99_ms=40.0,
            stages=(
                StageLatency("segment", 1.5, 3.0),
                StageLatency("é" * 32, 0.0, 0.0),
            ),
        ),
        Goodbye("SIGTERM received"),
        Goodbye("x" * 1024),
    ],
    ids=lambda m: type(m).__name__,
)
def test_server_messages_round_trip(message: AnyMessage) -> None:
    assert one(encode(message)) == message


@pytest.mark.parametrize(
    "message",
    [
        DEFAULT_OPTIONS,
        Subscribe(Encoding.COMPACT, True, 10.0, Kinds.OBJECTS, tuple(range(1, 1025)), True),
        Subscribe(kinds=Kinds.OBJECTS | Kinds.BODIES),
        Subscribe(kinds=Kinds.SUPPORTS | Kinds.BODIES),
        Subscribe(kinds=Kinds.OBJECTS | Kinds.SUPPORTS),
        SubscribeV1(),
    ],
    ids=[
        "default",
        "everything",
        "objects and bodies",
        "supports and bodies",
        "no bodies",
        "v1",
    ],
)
def test_client_messages_round_trip(message: AnyMessage) -> None:
    assert one(encode(message), "client") == message


def test_the_layouts_have_the_documents_sizes() -> None:
    assert len(encode(a_pose())) == 97
    assert len(encode(Session(0, 0))) == 5 + 16 + 11
    assert len(encode(Session(0, 0, Subscribe(object_ids=(1, 2, 3))))) == 5 + 16 + 11 + 24
    assert len(encode(Stats())) == 5 + 168
    shape = a_shape()
    v, t = len(shape.vertices), len(shape.triangles)
    assert len(encode(shape)) == 5 + 130 + 12 * v + 12 * t
    assert len(encode(replace(shape, encoding=Encoding.COMPACT))) == 5 + 154 + 6 * v + 6 * t
    body = a_body()
    v, t = len(body.vertices), len(body.triangles)
    hulls = sum(3 + 12 * len(h.vertices) + 3 * len(h.triangles) for h in body.hulls)
    assert len(encode(body)) == 5 + 115 + 12 * v + 12 * t + 1 + hulls
    compact = replace(body, encoding=Encoding.COMPACT)
    assert len(encode(compact)) == 5 + 115 + 24 + 6 * v + 6 * t + 1 + hulls


def a_hull(n: int, seed: int) -> Hull:
    """A hull of ``n`` vertices and ``2n − 4`` triangles (the counts of a closed convex one; the
    faces themselves are made up)."""
    rng = np.random.default_rng(seed)
    vertices = (rng.random((n, 3)) * 0.1).astype(np.float32)
    triangles = rng.integers(0, n, (2 * n - 4, 3)).astype(np.uint8)
    return Hull(vertices, triangles)


def a_body(
    encoding: Encoding = Encoding.FULL,
    solid: BodySolid = BodySolid.EXTRUSION,
    object_id: int = 7,
    version: int = 3,
) -> Body:
    vertices, triangles = a_mesh(300, seed=2)
    return Body(
        object_id=object_id,
        shape_version=version,
        solid=solid,
        margin_m=f32(0.002),
        volume_m3=f32(1.5e-3),
        centre_of_mass=np.array([0.01, -0.02, 0.15], np.float32),
        inertia=inertia_matrix(2e-5, 3e-5, 1.5e-5, -1e-6, 2e-7, 0.0),
        vertices=vertices,
        triangles=triangles,
        hulls=(a_hull(4, 1), a_hull(40, 2), a_hull(255, 3)),
        encoding=encoding,
    )


def test_a_full_body_round_trips_exactly() -> None:
    body = a_body()
    back = one(encode(body))
    assert isinstance(back, Body)
    same_body(back, body)
    assert back.solid is BodySolid.EXTRUSION and back.solid.is_fallback
    assert back.inertia_terms == pytest.approx((2e-5, 3e-5, 1.5e-5, -1e-6, 2e-7, 0.0), rel=1e-6)


def test_a_compact_body_moves_its_solid_by_at_most_the_bound_and_its_hulls_not_at_all() -> None:
    body = a_body(Encoding.COMPACT)
    back = one(encode(body))
    assert isinstance(back, Body) and back.encoding is Encoding.COMPACT
    bound = quantisation_bound_m(body.vertices.min(axis=0), body.vertices.max(axis=0))
    moved = np.linalg.norm(back.vertices.astype(np.float64) - body.vertices, axis=1)
    assert 0 < float(moved.max()) <= bound
    # All the rest is exact: the fixed fields, the indices and the full-precision hulls.
    same_body(back, replace(body, vertices=back.vertices))


@pytest.mark.parametrize("encoding", list(Encoding), ids=lambda e: e.name.lower())
def test_a_body_whose_shape_is_its_solid_carries_no_mesh(encoding: Encoding) -> None:
    body = replace(
        a_body(encoding, BodySolid.SHAPE),
        margin_m=0.0,
        vertices=np.zeros((0, 3), np.float32),
        triangles=np.zeros((0, 3), np.uint32),
    )
    data = encode(body)
    hulls = sum(3 + 12 * len(h.vertices) + 3 * len(h.triangles) for h in body.hulls)
    assert len(data) == 5 + 115 + (24 if encoding is Encoding.COMPACT else 0) + 1 + hulls
    assert data[5 + 61 : 5 + 106] == bytes(45), "no primitive: its 45 bytes are 0"
    back = one(data)
    assert isinstance(back, Body) and back.solid is BodySolid.SHAPE
    assert back.vertices.shape == (0, 3) and back.triangles.shape == (0, 3)
    same_body(back, body)


#: A primitive of each kind: sizes the kind uses, then the unused ones 0.
PRIMITIVES = [
    Primitive(
        PrimitiveKind.BOX,
        (f32(0.1), f32(0.05), f32(0.15)),
        QUARTER_TURN_ABOUT_Z,
        (0.0, 0.0, f32(0.15)),
        f32(0.002),
    ),
    # A lying cylinder: its axis (its own z) turned onto the object's x.
    Primitive(
        PrimitiveKind.CYLINDER,
        (f32(0.04), f32(0.09), 0.0),
        (0.0, f32(math.sqrt(0.5)), 0.0, f32(math.sqrt(0.5))),
        (f32(0.01), f32(-0.02), f32(0.04)),
        f32(0.0015),
    ),
    Primitive(PrimitiveKind.SPHERE, (f32(0.1), 0.0, 0.0), centre=(0.0, 0.0, f32(0.1))),
    Primitive(
        PrimitiveKind.CAPSULE,
        (f32(0.03), f32(0.05), 0.0),
        centre=(0.0, 0.0, f32(0.08)),
        residual_m=f32(0.001),
    ),
]


def a_primitive_body(primitive: Primitive, encoding: Encoding = Encoding.FULL) -> Body:
    """A body that is ``primitive``, its one hull the primitive's tessellation."""
    vertices, triangles = tessellate(primitive, around=8, rings=4)
    return Body(
        object_id=5,
        shape_version=2,
        solid=BodySolid.PRIMITIVE,
        margin_m=0.0,
        volume_m3=f32(1e-3),
        centre_of_mass=np.asarray(primitive.centre, np.float32),
        inertia=inertia_matrix(1e-6, 2e-6, 3e-6, 0.0, 0.0, 0.0),
        primitive=primitive,
        hulls=(Hull(vertices, triangles.astype(np.uint8)),),
        encoding=encoding,
    )


@pytest.mark.parametrize("encoding", list(Encoding), ids=lambda e: e.name.lower())
@pytest.mark.parametrize("primitive", PRIMITIVES, ids=lambda p: p.kind.name.lower())
def test_a_primitive_body_of_each_kind_round_trips_exactly(
    primitive: Primitive, encoding: Encoding
) -> None:
    body = a_primitive_body(primitive, encoding)
    data = encode(body)
    (hull,) = body.hulls
    hull_bytes = 3 + 12 * len(hull.vertices) + 3 * len(hull.triangles)
    assert len(data) == 5 + 115 + (24 if encoding is Encoding.COMPACT else 0) + 1 + hull_bytes
    assert data[5 + 61] == int(primitive.kind)
    assert struct.unpack_from("<3f", data, 5 + 62) == primitive.sizes
    back = one(data)
    assert isinstance(back, Body)
    same_body(back, body)
    assert back.primitive == primitive and back.primitive is not None
    assert back.primitive.kind is primitive.kind


def test_a_body_at_its_caps_round_trips() -> None:
    """16 hulls of 255 vertices and 510 triangles each, the most a Body may carry."""
    hull = Hull(a_hull(255, 4).vertices, np.resize(a_hull(255, 4).triangles, (510, 3)))
    body = replace(a_body(), hulls=(hull,) * MAX_HULLS)
    back = one(encode(body))
    assert isinstance(back, Body)
    same_body(back, body)


def test_hull_triangles_may_be_given_as_any_unsigned_integers() -> None:
    wide = replace(
        DOC_BODY,
        hulls=tuple(Hull(h.vertices, h.triangles.astype(np.uint32)) for h in DOC_BODY.hulls),
    )
    assert encode(wide) == BODY_EXAMPLE


def test_a_shape_says_new_frame_in_its_flags() -> None:
    shape = a_shape(n=10, flags=SHAPE_CLOSED | SHAPE_NEW_FRAME)
    data = encode(shape)
    assert data[5 + 108] == 0x05
    back = one(data)
    assert isinstance(back, Shape)
    assert back.is_new_frame and back.is_closed and not back.is_support
    assert not a_shape(n=10).is_new_frame


def test_a_full_shape_round_trips_exactly() -> None:
    shape = a_shape()
    back = one(encode(shape))
    assert isinstance(back, Shape)
    same_shape_fields(back, shape)
    assert back.max_residual_m == pytest.approx(0.002, rel=1e-7)
    assert back.vertices.dtype == np.float32 and back.triangles.dtype == np.uint32
    np.testing.assert_array_equal(back.vertices, shape.vertices)
    assert back.is_closed and not back.is_support and back.object_id == 7
    assert back.shape_version == 3


def test_a_compact_shape_moves_each_vertex_by_at_most_the_bound_it_adds() -> None:
    shape = a_shape(Encoding.COMPACT, n=2000)
    data = encode(shape)
    back = one(data)
    assert isinstance(back, Shape)
    same_shape_fields(back, shape)
    box_min, box_max = shape.vertices.min(axis=0), shape.vertices.max(axis=0)
    # The box is on the wire as given: the smallest and largest coordinates.
    assert np.frombuffer(data[5 + 130 : 5 + 142], "<f4").tolist() == box_min.tolist()
    assert np.frombuffer(data[5 + 142 : 5 + 154], "<f4").tolist() == box_max.tolist()
    bound = quantisation_bound_m(box_min, box_max)
    half_steps = 0.5 * float(np.linalg.norm(box_max - box_min)) / 65535
    assert half_steps < bound < 1.1 * half_steps
    error = back.vertices.astype(np.float64) - shape.vertices
    # Half a step per axis plus the f32 rounding of decoding, and the bound in all, which
    # covers both.
    extent = (box_max - box_min).astype(np.float64)
    corner = np.maximum(np.abs(box_min), np.abs(box_max)).astype(np.float64)
    rounding = 2.0**-24 * (3 * np.linalg.norm(extent) + np.linalg.norm(corner))
    half_step = 0.5 * extent / 65535
    assert np.all(np.abs(error) <= half_step + rounding)
    assert float(np.linalg.norm(error, axis=1).max()) <= bound
    # Some vertex does move by about half a step: the quantisation is not finer than said.
    assert float(np.abs(error).max()) > 0.25 * float(half_step.max())
    # The encoder adds the bound to the residual it sends.
    assert back.max_residual_m == pytest.approx(0.002 + bound, rel=1e-6)
    assert back.max_residual_m >= 0.002


def test_compact_dequantisation_is_the_documents_f32_formula() -> None:
    box_min = np.array([-1.0, 0.5, 2.0], np.float32)
    box_max = np.array([1.0, 0.5, 7.0], np.float32)
    q = [(0, 0, 0), (65535, 65535, 65535), (12345, 7, 54321)]
    pose = struct.pack("<5Q4f3f3f3f", 1, 1, 0, 0, 0, 0, 0, 0, 1, *([0.0] * 9))
    payload = (
        pose
        + struct.pack("<QQBIIfBII", 0, 0, 0, 0, 0, 0.0, 1, 3, 1)
        + box_min.tobytes()
        + box_max.tobytes()
        + struct.pack("<9H", *(c for v in q for c in v))
        + struct.pack("<3H", 0, 1, 2)
    )
    shape = one(frame(0x08, payload))
    assert isinstance(shape, Shape) and shape.encoding is Encoding.COMPACT
    step = (box_max - box_min) / np.float32(65535)
    expected = box_min + np.array(q, np.float32) * step
    assert expected.dtype == np.float32
    np.testing.assert_array_equal(shape.vertices, expected)
    assert shape.vertices[1].tolist() == pytest.approx(box_max.tolist(), abs=1e-6)
    # A flat axis reads back exactly.
    assert set(shape.vertices[:, 1].tolist()) == {0.5}


def test_compact_indices_widen_past_65536_vertices() -> None:
    def compact_of(v: int) -> Shape:
        vertices = np.zeros((v, 3), np.float32)
        vertices[:, 0] = np.linspace(0, 1, v)
        return replace(
            a_shape(Encoding.COMPACT),
            vertices=vertices,
            triangles=np.array([[0, 1, v - 1]], np.uint32),
        )

    for v, index_bytes in [(65536, 2), (65537, 4)]:
        data = encode(compact_of(v))
        assert len(data) == 5 + 154 + 6 * v + 3 * index_bytes
        back = one(data)
        assert isinstance(back, Shape)
        assert back.triangles.tolist() == [[0, 1, v - 1]]


def test_an_empty_shape_is_valid_in_both_encodings() -> None:
    empty = replace(
        a_shape(),
        vertices=np.zeros((0, 3), np.float32),
        triangles=np.zeros((0, 3), np.uint32),
    )
    for encoding, size in [(Encoding.FULL, 130), (Encoding.COMPACT, 154)]:
        data = encode(replace(empty, encoding=encoding))
        assert len(data) == 5 + size
        if encoding is Encoding.COMPACT:
            assert data[5 + 130 :] == bytes(24)  # a box of zeros
        back = one(data)
        assert isinstance(back, Shape)
        assert back.vertices.shape == (0, 3) and back.triangles.shape == (0, 3)


def test_a_message_split_anywhere_comes_out_whole() -> None:
    stream = (
        encode(Hello(4, "tacmesh"))
        + encode(Session(1, 2))
        + encode(a_shape(Encoding.COMPACT, n=20))
        + encode(a_body(Encoding.COMPACT))
        + BOX_BODY_EXAMPLE
        + encode(a_pose())
        + encode(SnapshotDone())
    )
    decoder = FrameDecoder()
    out = []
    for byte in stream:
        decoder.push(bytes([byte]))
        while (message := decoder.next_message()) is not None:
            out.append(type(message))
    assert out == [Hello, Session, Shape, Body, Body, Pose, SnapshotDone]
    assert decoder.buffered == 0


def test_the_world_vertices_are_the_shape_placed_by_its_pose() -> None:
    shape = replace(
        a_shape(),
        vertices=np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32),
        triangles=np.array([[0, 1, 2]], np.uint32),
    )
    # A quarter turn about z, then the translation (0.25, -0.5, 1).
    np.testing.assert_allclose(
        shape.world_vertices(),
        [[0.25, 0.5, 1.0], [-0.75, -0.5, 1.0], [0.25, -0.5, 2.0]],
        atol=1e-6,
    )
    matrix = shape.pose.world_from_object()
    np.testing.assert_allclose(matrix[:3, :3] @ [1, 0, 0], [0, 1, 0], atol=1e-7)


# ---- refusals --------------------------------------------------------------------------------


def patched(data: bytes, frame_offset: int, new: bytes) -> bytes:
    return data[:frame_offset] + new + data[frame_offset + len(new) :]


def longer(data: bytes, extra: bytes = b"\x00") -> bytes:
    """The same frame with bytes appended and its length prefix grown to match."""
    (length,) = struct.unpack_from("<I", data)
    return struct.pack("<I", length + len(extra)) + data[4:] + extra


def shorter(data: bytes, n: int = 1) -> bytes:
    (length,) = struct.unpack_from("<I", data)
    return struct.pack("<I", length - n) + data[4:-n]


NAN = float("nan")
INF = float("inf")
SHAPE = encode(a_shape(n=10))
COMPACT = encode(a_shape(Encoding.COMPACT, n=10))
POSE = encode(a_pose())
# Frame offsets of Shape fields: 5 + the payload offset.
FLAGS, ENCODING, RESIDUAL, BOX = 5 + 108, 5 + 121, 5 + 117, 5 + 130
# Frame offsets in the Body examples (the first: 4 vertices, 4 triangles, full; one hull of 4
# and 4).
B_SOLID, B_MARGIN, B_VOLUME, B_CENTRE, B_INERTIA = (
    5 + 16,
    5 + 17,
    5 + 21,
    5 + 25,
    5 + 37,
)
# The primitive block: its kind, sizes, rotation, centre and residual.
B_PRIMITIVE, B_SIZES, B_ROTATION, B_PRIMITIVE_CENTRE, B_RESIDUAL = (
    5 + 61,
    5 + 62,
    5 + 74,
    5 + 90,
    5 + 102,
)
B_ENCODING, B_VERTEX_COUNT, B_VERTICES, B_TRIANGLES = 5 + 106, 5 + 107, 5 + 115, 5 + 163
B_HULL_COUNT, B_HULL = 5 + 211, 5 + 212
B_HULL_VERTICES, B_HULL_TRIANGLES = B_HULL + 3, B_HULL + 3 + 48
COMPACT_BODY = encode(replace(DOC_BODY, encoding=Encoding.COMPACT))
#: The box example, for short in the refusals below.
BOX_BODY = BOX_BODY_EXAMPLE
#: The first Body example as version 3 laid it out, kind 0x0B: no primitive block, and its
#: shadow volume was proxy 1.
VERSION_3_BODY = frame(
    0x0B, BODY_EXAMPLE[5:21] + b"\x01" + BODY_EXAMPLE[22:66] + BODY_EXAMPLE[111:]
)


def f32_bytes(value: float) -> bytes:
    return struct.pack("<f", value)


def unchecked(message: AnyMessage) -> bytes:
    return encode(message, validate=False)


REFUSALS: list[tuple[str, bytes, type[WireError]]] = [
    ("a zero length", struct.pack("<I", 0), EmptyFrame),
    ("a length over the cap", struct.pack("<I", MAX_FRAME_BYTES + 1), FrameTooLarge),
    ("kind 0", frame(0x00, b""), UnknownKind),
    ("an unknown kind", frame(0x42, b""), UnknownKind),
    ("an unknown client kind", frame(0x82, b""), UnknownKind),
    ("version 1's Upsert", frame(0x02, bytes(44)), UnknownKind),
    ("version 1's Stats", frame(0x05, bytes(68)), UnknownKind),
    ("version 3's Body", VERSION_3_BODY, UnknownKind),
    ("version 3's Body kind on a version 4 Body", frame(0x0B, BODY_EXAMPLE[5:]), UnknownKind),
    ("a client's Subscribe", encode(DEFAULT_OPTIONS), WrongDirection),
    ("a client's version 1 Subscribe", encode(SubscribeV1()), WrongDirection),
    ("a short Remove", frame(0x03, b"\x01\x02"), Truncated),
    ("a long Remove", frame(0x03, bytes(9)), TrailingBytes),
    ("SnapshotDone with a payload", frame(0x04, b"\x00"), TrailingBytes),
    ("a short Pose", shorter(POSE), Truncated),
    ("a long Pose", longer(POSE), TrailingBytes),
    ("a Shape shorter than its counts", shorter(SHAPE, 4), Truncated),
    ("a Shape longer than its counts", longer(SHAPE, bytes(12)), TrailingBytes),
    ("a compact Shape shorter than its counts", shorter(COMPACT, 2), Truncated),
    (
        "a compact Shape longer than its counts",
        longer(COMPACT, bytes(6)),
        TrailingBytes,
    ),
    ("a short Stats", shorter(encode(Stats())), Truncated),
    (
        "a Stats with more stages than bytes",
        patched(encode(Stats()), 5 + 164, struct.pack("<I", 10**9)),
        Truncated,
    ),
    ("a long Session", longer(encode(Session(1, 2))), TrailingBytes),
    (
        "a server name that is not UTF-8",
        frame(0x01, b"\x02\x00\x02\x00\xff\xfe"),
        InvalidText,
    ),
    ("a reason that is not UTF-8", frame(0x06, b"\x01\x00\xc3"), InvalidText),
    ("a server name over 64 bytes", unchecked(Hello(2, "a" * 65)), TextTooLong),
    ("a reason over 1024 bytes", unchecked(Goodbye("a" * 1025)), TextTooLong),
    (
        "a stage name over 64 bytes",
        unchecked(Stats(stages=(StageLatency("s" * 65, 0, 0),))),
        TextTooLong,
    ),
    (
        "a Session with more than 1024 ids",
        unchecked(Session(0, 0, Subscribe(object_ids=tuple(range(1025))))),
        CountOverCap,
    ),
    ("a Shape flag not defined", patched(SHAPE, FLAGS, b"\x08"), InvalidFlags),
    ("a Shape encoding not defined", patched(SHAPE, ENCODING, b"\x02"), InvalidEnum),
    (
        "a Session encoding not defined",
        patched(encode(Session(0, 0)), 5 + 16, b"\x02"),
        InvalidEnum,
    ),
    (
        "a Session flag not defined",
        patched(encode(Session(0, 0)), 5 + 17, b"\x04"),
        InvalidFlags,
    ),
    (
        "a Session of no kinds",
        patched(encode(Session(0, 0)), 5 + 22, b"\x00"),
        InvalidFlags,
    ),
    (
        "a Session kind not defined",
        patched(encode(Session(0, 0)), 5 + 22, b"\x0f"),
        InvalidFlags,
    ),
    (
        "a Session of bodies alone",
        patched(encode(Session(0, 0)), 5 + 22, b"\x04"),
        InvalidFlags,
    ),
    (
        "a NaN vertex",
        unchecked(replace(a_shape(n=10), vertices=np.full((10, 3), NAN, np.float32))),
        NonFinite,
    ),
    (
        "an infinite vertex",
        patched(SHAPE, 5 + 130 + 4, struct.pack("<f", INF)),
        NonFinite,
    ),
    (
        "a NaN rotation",
        unchecked(replace(a_pose(), rotation=(NAN, 0, 0, 1))),
        NonFinite,
    ),
    (
        "an infinite translation",
        unchecked(replace(a_pose(), translation=(0, INF, 0))),
        NonFinite,
    ),
    (
        "a NaN velocity",
        unchecked(replace(a_pose(), linear_velocity=(0, 0, NAN))),
        NonFinite,
    ),
    (
        "an infinite spin",
        unchecked(replace(a_pose(), angular_velocity=(-INF, 0, 0))),
        NonFinite,
    ),
    (
        "a Shape's NaN pose",
        unchecked(replace(a_shape(n=10), pose=replace(a_pose(), translation=(NAN, 0, 0)))),
        NonFinite,
    ),
    ("a NaN box", patched(COMPACT, BOX, struct.pack("<f", NAN)), NonFinite),
    (
        "an infinite box",
        patched(COMPACT, BOX + 12 + 8, struct.pack("<f", INF)),
        NonFinite,
    ),
    (
        "a rotation of norm 1.01",
        unchecked(replace(a_pose(), rotation=(0.0, 0.0, 0.0, 1.01))),
        NotUnitQuaternion,
    ),
    (
        "a zero rotation",
        unchecked(replace(a_pose(), rotation=(0.0, 0.0, 0.0, 0.0))),
        NotUnitQuaternion,
    ),
    (
        "last seen before the pose time",
        unchecked(replace(a_pose(), last_seen_ns=a_pose().pose_time_ns - 1)),
        TimesOutOfOrder,
    ),
    (
        "a triangle index out of range",
        unchecked(replace(a_shape(n=10), triangles=np.array([[0, 1, 10]], np.uint32))),
        IndexOutOfRange,
    ),
    (
        "a compact triangle index out of range",
        unchecked(
            replace(
                a_shape(Encoding.COMPACT, n=10),
                triangles=np.array([[9, 10, 0]], np.uint32),
            )
        ),
        IndexOutOfRange,
    ),
    (
        "a compact box whose maximum is below its minimum",
        patched(COMPACT, BOX + 12 + 4, struct.pack("<f", -1e6)),
        BadBox,
    ),
    (
        "a negative residual",
        unchecked(replace(a_shape(n=10), max_residual_m=-1.0)),
        InvalidNumber,
    ),
    ("a NaN residual", patched(SHAPE, RESIDUAL, struct.pack("<f", NAN)), InvalidNumber),
    (
        "a negative rate",
        unchecked(Session(0, 0, Subscribe(max_rate_hz=-1.0))),
        InvalidNumber,
    ),
    (
        "an infinite rate",
        unchecked(Session(0, 0, Subscribe(max_rate_hz=INF))),
        InvalidNumber,
    ),
    ("a NaN latency", unchecked(Stats(frame_to_publish_p99_ms=NAN)), InvalidNumber),
    (
        "a negative latency",
        unchecked(Stats(frame_to_publish_p50_ms=-1.0)),
        InvalidNumber,
    ),
    (
        "an infinite stage latency",
        unchecked(Stats(stages=(StageLatency("mesh", 1.0, INF),))),
        InvalidNumber,
    ),
    # The Body's rules.
    ("a short Body", frame(0x0C, BODY_EXAMPLE[5:60]), Truncated),
    ("a Body cut inside its primitive", frame(0x0C, BOX_BODY[5:90]), Truncated),
    ("a Body cut inside its hull", shorter(BODY_EXAMPLE), Truncated),
    ("a Body longer than its hulls", longer(BODY_EXAMPLE), TrailingBytes),
    (
        "a Body whose mesh counts exceed its payload",
        patched(BODY_EXAMPLE, B_VERTEX_COUNT, struct.pack("<I", 10**9)),
        Truncated,
    ),
    (
        "a Body with more hulls than it carries",
        patched(BODY_EXAMPLE, B_HULL_COUNT, b"\x02"),
        Truncated,
    ),
    ("a Body solid not defined", patched(BODY_EXAMPLE, B_SOLID, b"\x05"), InvalidEnum),
    (
        "a Body encoding not defined",
        patched(BODY_EXAMPLE, B_ENCODING, b"\x02"),
        InvalidEnum,
    ),
    (
        "a shape solid that carries a mesh",
        patched(BODY_EXAMPLE, B_SOLID, b"\x00"),
        BadBody,
    ),
    (
        "a primitive solid that carries a mesh",
        unchecked(replace(DOC_BOX_BODY, vertices=TETRAHEDRON, triangles=TETRAHEDRON_FACES)),
        BadBody,
    ),
    (
        "a primitive solid without a primitive",
        unchecked(replace(DOC_BOX_BODY, primitive=None)),
        BadBody,
    ),
    (
        "a primitive solid without a primitive, with a mesh",
        patched(BODY_EXAMPLE, B_SOLID, b"\x01"),
        BadBody,
    ),
    ("a primitive on a shape solid", patched(BOX_BODY, B_SOLID, b"\x00"), BadBody),
    ("a primitive on a completed solid", patched(BOX_BODY, B_SOLID, b"\x02"), BadBody),
    ("a primitive on a shadow volume", patched(BOX_BODY, B_SOLID, b"\x03"), BadBody),
    ("a primitive on an extrusion", patched(BOX_BODY, B_SOLID, b"\x04"), BadBody),
    ("primitive kind 5", patched(BOX_BODY, B_PRIMITIVE, b"\x05"), InvalidEnum),
    ("primitive kind 255", patched(BOX_BODY, B_PRIMITIVE, b"\xff"), InvalidEnum),
    ("no primitive, with a size", patched(BODY_EXAMPLE, B_SIZES, f32_bytes(0.1)), BadBody),
    ("no primitive, with a −0 size", patched(BODY_EXAMPLE, B_SIZES + 3, b"\x80"), BadBody),
    (
        "no primitive, with a rotation",
        patched(BODY_EXAMPLE, B_ROTATION + 12, f32_bytes(1.0)),
        BadBody,
    ),
    (
        "no primitive, with its last byte set",
        patched(BODY_EXAMPLE, B_RESIDUAL + 3, b"\x01"),
        BadBody,
    ),
    ("kind 0 on the box's primitive", patched(BOX_BODY, B_PRIMITIVE, b"\x00"), BadBody),
    ("a box with a 0 size", patched(BOX_BODY, B_SIZES + 4, f32_bytes(0.0)), BadBody),
    ("a box with a −0 size", patched(BOX_BODY, B_SIZES + 4, f32_bytes(-0.0)), BadBody),
    ("a box with a negative size", patched(BOX_BODY, B_SIZES + 8, f32_bytes(-0.1)), BadBody),
    ("a box with a NaN size", patched(BOX_BODY, B_SIZES, f32_bytes(NAN)), BadBody),
    ("a box with an infinite size", patched(BOX_BODY, B_SIZES, f32_bytes(INF)), BadBody),
    # The box's sizes are (0.1, 0.05, 0.15): as another kind, a size it does not use is not 0.
    ("a cylinder with a third size", patched(BOX_BODY, B_PRIMITIVE, b"\x02"), BadBody),
    ("a sphere with a second size", patched(BOX_BODY, B_PRIMITIVE, b"\x03"), BadBody),
    ("a capsule with a third size", patched(BOX_BODY, B_PRIMITIVE, b"\x04"), BadBody),
    (
        "a cylinder with a −0 third size",
        patched(patched(BOX_BODY, B_PRIMITIVE, b"\x02"), B_SIZES + 8, f32_bytes(-0.0)),
        BadBody,
    ),
    (
        "a primitive rotation of norm 0.87",
        patched(BOX_BODY, B_ROTATION + 12, f32_bytes(0.5)),
        NotUnitQuaternion,
    ),
    ("a zero primitive rotation", patched(BOX_BODY, B_ROTATION + 8, bytes(8)), NotUnitQuaternion),
    ("a NaN primitive rotation", patched(BOX_BODY, B_ROTATION, f32_bytes(NAN)), NonFinite),
    (
        "a NaN primitive centre",
        patched(BOX_BODY, B_PRIMITIVE_CENTRE + 8, f32_bytes(NAN)),
        NonFinite,
    ),
    (
        "an infinite primitive centre",
        patched(BOX_BODY, B_PRIMITIVE_CENTRE, f32_bytes(-INF)),
        NonFinite,
    ),
    (
        "a negative primitive residual",
        patched(BOX_BODY, B_RESIDUAL, f32_bytes(-0.001)),
        InvalidNumber,
    ),
    ("a NaN primitive residual", patched(BOX_BODY, B_RESIDUAL, f32_bytes(NAN)), InvalidNumber),
    (
        "an infinite primitive residual",
        patched(BOX_BODY, B_RESIDUAL, f32_bytes(INF)),
        InvalidNumber,
    ),
    ("a zero volume", patched(BODY_EXAMPLE, B_VOLUME, struct.pack("<f", 0.0)), BadBody),
    (
        "a negative volume",
        patched(BODY_EXAMPLE, B_VOLUME, struct.pack("<f", -1.0)),
        BadBody,
    ),
    ("a NaN volume", patched(BODY_EXAMPLE, B_VOLUME, struct.pack("<f", NAN)), BadBody),
    (
        "an infinite volume",
        patched(BODY_EXAMPLE, B_VOLUME, struct.pack("<f", INF)),
        BadBody,
    ),
    (
        "a negative margin",
        patched(BODY_EXAMPLE, B_MARGIN, struct.pack("<f", -0.1)),
        InvalidNumber,
    ),
    (
        "a NaN margin",
        patched(BODY_EXAMPLE, B_MARGIN, struct.pack("<f", NAN)),
        InvalidNumber,
    ),
    (
        "a NaN centre of mass",
        patched(BODY_EXAMPLE, B_CENTRE + 4, struct.pack("<f", NAN)),
        NonFinite,
    ),
    (
        "an infinite inertia",
        patched(BODY_EXAMPLE, B_INERTIA + 16, struct.pack("<f", -INF)),
        NonFinite,
    ),
    (
        "a NaN solid vertex",
        patched(BODY_EXAMPLE, B_VERTICES + 12 * 3 + 8, struct.pack("<f", NAN)),
        NonFinite,
    ),
    (
        "a solid triangle index out of range",
        patched(BODY_EXAMPLE, B_TRIANGLES + 4, struct.pack("<I", 4)),
        IndexOutOfRange,
    ),
    (
        "a compact solid box whose maximum is below its minimum",
        patched(COMPACT_BODY, B_VERTICES + 12 + 4, struct.pack("<f", -1.0)),
        BadBox,
    ),
    (
        "a compact solid's NaN box",
        patched(COMPACT_BODY, B_VERTICES, struct.pack("<f", NAN)),
        NonFinite,
    ),
    ("17 hulls", patched(BODY_EXAMPLE, B_HULL_COUNT, b"\x11"), CountOverCap),
    ("a hull of 3 vertices", patched(BODY_EXAMPLE, B_HULL, b"\x03"), BadHull),
    ("a hull of no vertices", patched(BODY_EXAMPLE, B_HULL, b"\x00"), BadHull),
    (
        "a hull of more triangles than twice its vertices",
        patched(BODY_EXAMPLE, B_HULL + 1, struct.pack("<H", 9)),
        BadHull,
    ),
    (
        "an infinite hull vertex",
        patched(BODY_EXAMPLE, B_HULL_VERTICES + 4, struct.pack("<f", INF)),
        NonFinite,
    ),
    (
        "a hull triangle index out of range",
        patched(BODY_EXAMPLE, B_HULL_TRIANGLES + 11, b"\x04"),
        IndexOutOfRange,
    ),
]


@pytest.mark.parametrize(("what", "data", "error"), REFUSALS, ids=[r[0] for r in REFUSALS])
def test_a_frame_that_breaks_the_rules_is_refused(
    what: str, data: bytes, error: type[WireError]
) -> None:
    decoder = FrameDecoder()
    decoder.push(data)
    with pytest.raises(error) as raised:
        decoder.next_message()
    assert str(raised.value), what


CLIENT_REFUSALS: list[tuple[str, bytes, type[WireError]]] = [
    ("a server's Hello", encode(Hello(2, "x")), WrongDirection),
    ("a server's Body", BODY_EXAMPLE, WrongDirection),
    ("a server's box Body", BOX_BODY, WrongDirection),
    ("a Subscribe over its length", longer(encode(DEFAULT_OPTIONS)), TrailingBytes),
    ("a short Subscribe", shorter(encode(DEFAULT_OPTIONS)), Truncated),
    ("a version 1 Subscribe with a payload", frame(0x80, b"\x00"), TrailingBytes),
    (
        "1025 ids",
        unchecked(Subscribe(object_ids=tuple(range(1025)))),
        CountOverCap,
    ),
    (
        "an encoding not defined",
        patched(encode(DEFAULT_OPTIONS), 5, b"\x02"),
        InvalidEnum,
    ),
    ("a flag not defined", patched(encode(DEFAULT_OPTIONS), 6, b"\x05"), InvalidFlags),
    ("no kinds", unchecked(Subscribe(kinds=Kinds(0))), InvalidFlags),
    ("bodies alone", unchecked(Subscribe(kinds=Kinds.BODIES)), InvalidFlags),
    ("a kind not defined", patched(encode(DEFAULT_OPTIONS), 11, b"\x0b"), InvalidFlags),
    ("a NaN rate", unchecked(Subscribe(max_rate_hz=NAN)), InvalidNumber),
    # A rate whose interval overflows the daemon's clock once aborted it.
    ("a rate of 1e-45 Hz", unchecked(Subscribe(max_rate_hz=1e-45)), InvalidNumber),
    ("a rate below 0.01 Hz", unchecked(Subscribe(max_rate_hz=0.0099)), InvalidNumber),
    ("a rate above 10 kHz", unchecked(Subscribe(max_rate_hz=10_001.0)), InvalidNumber),
]


@pytest.mark.parametrize(
    ("what", "data", "error"), CLIENT_REFUSALS, ids=[r[0] for r in CLIENT_REFUSALS]
)
def test_a_client_frame_that_breaks_the_rules_is_refused(
    what: str, data: bytes, error: type[WireError]
) -> None:
    decoder = FrameDecoder("client")
    decoder.push(data)
    with pytest.raises(error):
        decoder.next_message()


def test_a_length_over_the_cap_is_refused_from_its_four_bytes() -> None:
    decoder = FrameDecoder()
    decoder.push(struct.pack("<I", MAX_FRAME_BYTES + 1))
    with pytest.raises(FrameTooLarge, match="cap"):
        decoder.next_message()
    # The cap itself is a length a receiver waits for.
    decoder = FrameDecoder()
    decoder.push(struct.pack("<IB", MAX_FRAME_BYTES, 0x08))
    assert decoder.next_message() is None


def test_a_rotation_within_a_thousandth_of_unit_is_accepted() -> None:
    pose = replace(a_pose(), rotation=(0.0, 0.0, 0.0, f32(1.0009)))
    assert one(encode(pose)) == pose


def test_last_seen_may_equal_the_pose_time() -> None:
    pose = replace(a_pose(), last_seen_ns=a_pose().pose_time_ns)
    assert one(encode(pose)) == pose


@pytest.mark.parametrize(
    ("message", "error"),
    [
        (Hello(2, "a" * 65), TextTooLong),
        (replace(a_pose(), rotation=(0.0, 0.0, 0.0, 2.0)), NotUnitQuaternion),
        (replace(a_pose(), last_seen_ns=0), TimesOutOfOrder),
        (
            replace(a_shape(n=10), triangles=np.array([[0, 1, 10]], np.uint32)),
            IndexOutOfRange,
        ),
        (replace(a_shape(n=10), max_residual_m=NAN), InvalidNumber),
        (replace(a_shape(n=10), flags=8), InvalidFlags),
        (
            replace(
                a_shape(Encoding.COMPACT, n=2),
                vertices=np.array([[-3e38, 0, 0], [3e38, 0, 0]], np.float32),
            ),
            BadBox,
        ),
        (Subscribe(object_ids=tuple(range(1025))), CountOverCap),
        (Subscribe(max_rate_hz=-1.0), InvalidNumber),
        (Subscribe(max_rate_hz=1e-45), InvalidNumber),
        (Subscribe(max_rate_hz=1e30), InvalidNumber),
        (Subscribe(kinds=Kinds(0)), InvalidFlags),
        (Subscribe(kinds=Kinds.BODIES), InvalidFlags),
        (replace(DOC_BODY, volume_m3=0.0), BadBody),
        (replace(DOC_BODY, solid=BodySolid.SHAPE), BadBody),
        (replace(DOC_BODY, solid=cast(BodySolid, 5)), InvalidEnum),
        (replace(DOC_BODY, solid=BodySolid.PRIMITIVE), BadBody),
        (replace(DOC_BODY, primitive=BOX_PRIMITIVE), BadBody),
        (replace(DOC_BOX_BODY, primitive=None), BadBody),
        (replace(DOC_BOX_BODY, vertices=TETRAHEDRON, triangles=TETRAHEDRON_FACES), BadBody),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, kind=cast(PrimitiveKind, 0))),
            InvalidEnum,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, kind=cast(PrimitiveKind, 5))),
            InvalidEnum,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, sizes=(0.1, 0.0, 0.15))),
            BadBody,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, kind=PrimitiveKind.CYLINDER)),
            BadBody,
        ),
        (
            replace(
                DOC_BOX_BODY,
                primitive=Primitive(PrimitiveKind.SPHERE, (-1.0, 0.0, 0.0)),
            ),
            BadBody,
        ),
        (
            replace(
                DOC_BOX_BODY,
                primitive=Primitive(PrimitiveKind.SPHERE, (0.1, -0.0, 0.0)),
            ),
            BadBody,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, rotation=(0.0, 0.0, 0.0, 2.0))),
            NotUnitQuaternion,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, centre=(0.0, NAN, 0.0))),
            NonFinite,
        ),
        (
            replace(DOC_BOX_BODY, primitive=replace(BOX_PRIMITIVE, residual_m=-0.001)),
            InvalidNumber,
        ),
        (replace(DOC_BODY, margin_m=-0.25), InvalidNumber),
        (
            replace(DOC_BODY, centre_of_mass=np.array([0, NAN, 0], np.float32)),
            NonFinite,
        ),
        (
            replace(DOC_BODY, triangles=np.array([[0, 1, 4]], np.uint32)),
            IndexOutOfRange,
        ),
        (replace(DOC_BODY, hulls=DOC_BODY.hulls * (MAX_HULLS + 1)), CountOverCap),
        (
            replace(DOC_BODY, hulls=(Hull(TETRAHEDRON[:3], TETRAHEDRON_FACES[:1]),)),
            BadHull,
        ),
        (
            replace(DOC_BODY, hulls=(Hull(TETRAHEDRON, np.array([[0, 1, 4]], np.uint8)),)),
            IndexOutOfRange,
        ),
        (
            replace(DOC_BODY, inertia=np.arange(9, dtype=np.float32).reshape(3, 3)),
            ValueError,
        ),
    ],
    ids=lambda x: x.__name__ if isinstance(x, type) else type(x).__name__,
)
def test_the_encoder_refuses_what_a_receiver_would(message: AnyMessage, error: type) -> None:
    with pytest.raises(error):
        encode(message)


# ---- the scene rules -------------------------------------------------------------------------


def shape_of(object_id: int, version: int, pose_time_ns: int = 10, flags: int = 0) -> Shape:
    pose = replace(a_pose(object_id, version), pose_time_ns=pose_time_ns, last_seen_ns=pose_time_ns)
    return replace(a_shape(n=4, flags=flags), pose=pose)


def pose_of(object_id: int, version: int, pose_time_ns: int, last_seen_ns: int = 0) -> Pose:
    return replace(
        a_pose(object_id, version),
        pose_time_ns=pose_time_ns,
        last_seen_ns=max(pose_time_ns, last_seen_ns),
        translation=(float(pose_time_ns), 0.0, 0.0),
    )


def test_a_session_starts_the_scene_afresh() -> None:
    scene = Scene()
    scene.apply(Hello(2, "t"))
    scene.apply(Session(100, 1_000_100))
    scene.apply(shape_of(1, 1))
    scene.apply(shape_of(FIRST_SUPPORT_ID, 1, flags=SHAPE_SUPPORT))
    assert not scene.complete
    scene.apply(SnapshotDone())
    assert scene.complete and set(scene.objects) == {1, FIRST_SUPPORT_ID}
    assert [o.object_id for o in scene.supports] == [FIRST_SUPPORT_ID]
    assert [o.object_id for o in scene.non_supports] == [1]
    scene.apply(Session(200, 1_000_200))
    assert scene.objects == {} and not scene.complete
    scene.apply(shape_of(2, 1))
    scene.apply(SnapshotDone())
    assert set(scene.objects) == {2}
    # The Session's two clocks map stream times onto the daemon's wall clock.
    assert scene.realtime_ns(150) == 1_000_150


def test_the_highest_shape_version_is_kept() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 5))
    scene.apply(shape_of(1, 4))
    assert scene.objects[1].shape_version == 5 and scene.stale == 1
    scene.apply(shape_of(1, 9))
    assert scene.objects[1].shape_version == 9


def test_a_pose_applies_only_to_the_shape_version_it_names() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 2, pose_time_ns=10))
    scene.apply(pose_of(1, 1, pose_time_ns=20))  # an older shape's
    scene.apply(pose_of(1, 3, pose_time_ns=20))  # a shape this client does not have
    scene.apply(pose_of(9, 1, pose_time_ns=20))  # an object it does not have
    assert scene.objects[1].pose_time_ns == 10 and scene.stale == 3
    scene.apply(pose_of(1, 2, pose_time_ns=30))
    held = scene.objects[1]
    assert held.pose_time_ns == 30 and held.shape_version == 2
    assert held.world_vertices[:, 0] == pytest.approx(held.vertices[:, 1] * -1 + 30, abs=1e-4)


def test_a_pose_never_goes_backwards() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1, pose_time_ns=10))
    scene.apply(pose_of(1, 1, pose_time_ns=50, last_seen_ns=60))
    scene.apply(pose_of(1, 1, pose_time_ns=40, last_seen_ns=70))  # an older pose
    scene.apply(pose_of(1, 1, pose_time_ns=50, last_seen_ns=55))  # seen earlier
    assert (scene.objects[1].pose_time_ns, scene.objects[1].last_seen_ns) == (50, 60)
    # A static object: the same pose time, seen again later.
    scene.apply(pose_of(1, 1, pose_time_ns=50, last_seen_ns=90))
    assert (scene.objects[1].pose_time_ns, scene.objects[1].last_seen_ns) == (50, 90)
    # A new shape brings its own pose.
    scene.apply(shape_of(1, 2, pose_time_ns=95))
    assert scene.objects[1].pose_time_ns == 95


def test_a_remove_forgets_the_object() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1))
    scene.apply(shape_of(2, 1))
    scene.apply(Remove(1))
    scene.apply(Remove(77))
    assert set(scene.objects) == {2}
    scene.apply(pose_of(1, 1, pose_time_ns=20))
    assert set(scene.objects) == {2}


def test_a_narrower_filter_forgets_what_it_leaves_out() -> None:
    scene = Scene()
    for object_id in (1, 2, FIRST_SUPPORT_ID):
        scene.apply(shape_of(object_id, 1))
    scene.keep_only(Subscribe(kinds=Kinds.OBJECTS))
    assert set(scene.objects) == {1, 2}
    scene.keep_only(Subscribe(object_ids=(2, FIRST_SUPPORT_ID)))
    assert set(scene.objects) == {2}


def test_the_world_mesh_follows_the_pose() -> None:
    scene = Scene()
    shape = replace(
        shape_of(1, 1),
        vertices=np.array([[0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]], np.float32),
        triangles=np.array([[0, 1, 2]], np.uint32),
    )
    scene.apply(shape)
    moved = replace(
        pose_of(1, 1, pose_time_ns=20),
        rotation=(1.0, 0.0, 0.0, 0.0),  # half a turn about x
        translation=(1.0, 2.0, 3.0),
    )
    scene.apply(moved)
    mesh = scene.objects[1].mesh
    assert mesh.vertices.dtype == np.float32
    np.testing.assert_allclose(
        mesh.vertices, [[1.1, 2.0, 3.0], [1.0, 1.9, 3.0], [1.0, 2.0, 2.9]], atol=1e-6
    )
    np.testing.assert_array_equal(mesh.triangles, shape.triangles)
    # The object frame's vertices stay as sent.
    np.testing.assert_array_equal(scene.objects[1].vertices, shape.vertices)


def body_of(object_id: int, version: int, solid: BodySolid = BodySolid.SHADOW_VOLUME) -> Body:
    """The document's first Body example (its second for a primitive), of another object and
    shape version."""
    if solid is BodySolid.PRIMITIVE:
        return replace(DOC_BOX_BODY, object_id=object_id, shape_version=version)
    body = replace(DOC_BODY, object_id=object_id, shape_version=version, solid=solid)
    if solid is BodySolid.SHAPE:
        body = replace(
            body,
            vertices=np.zeros((0, 3), np.float32),
            triangles=np.zeros((0, 3), np.uint32),
        )
    return body


def test_a_body_is_kept_beside_its_shape_and_placed_by_the_current_pose() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1, pose_time_ns=10))
    assert scene.objects[1].body is None and scene.objects[1].world_solid is None
    assert scene.objects[1].world_hulls == () and scene.objects[1].world_centre_of_mass is None
    body = body_of(1, 1)
    scene.apply(body)
    assert scene.objects[1].body is body and scene.stale == 0
    # A Pose moves the body with the shape: half a turn about x, then (1, 2, 3).
    scene.apply(
        replace(
            pose_of(1, 1, 20),
            rotation=(1.0, 0.0, 0.0, 0.0),
            translation=(1.0, 2.0, 3.0),
        )
    )
    held = scene.objects[1]
    assert held.body is body and held.pose_time_ns == 20
    expected = TETRAHEDRON * [1, -1, -1] + [1, 2, 3]
    solid = held.world_solid
    assert solid is not None and solid.vertices.dtype == np.float32
    np.testing.assert_allclose(solid.vertices, expected, atol=1e-6)
    np.testing.assert_array_equal(solid.triangles, TETRAHEDRON_FACES)
    (hull,) = held.world_hulls
    np.testing.assert_allclose(hull.vertices, expected, atol=1e-6)
    assert hull.triangles.dtype == np.uint32
    np.testing.assert_array_equal(hull.triangles, TETRAHEDRON_FACES)
    centre = held.world_centre_of_mass
    assert centre is not None
    np.testing.assert_allclose(centre, [1.25, 1.75, 2.75], atol=1e-6)
    # The object frame's solid stays as sent.
    np.testing.assert_array_equal(body.vertices, TETRAHEDRON)


def test_a_body_whose_solid_is_its_shape_is_the_shape_in_the_world() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1, flags=SHAPE_CLOSED))
    scene.apply(body_of(1, 1, BodySolid.SHAPE))
    held = scene.objects[1]
    solid = held.world_solid
    assert solid is not None
    np.testing.assert_array_equal(solid.vertices, held.mesh.vertices)
    np.testing.assert_array_equal(solid.triangles, held.shape.triangles)


def test_a_primitive_body_is_its_primitives_tessellation_in_the_world() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1))
    scene.apply(body_of(1, 1, BodySolid.PRIMITIVE))
    # Half a turn about x, then (1, 2, 3).
    scene.apply(
        replace(pose_of(1, 1, 20), rotation=(1.0, 0.0, 0.0, 0.0), translation=(1.0, 2.0, 3.0))
    )
    held = scene.objects[1]
    solid = held.world_solid
    assert solid is not None and solid.vertices.dtype == np.float32
    # The box example's primitive is 8 corners, the same as its hull: both placed by the pose.
    expected = BOX_CORNERS * [1, -1, -1] + [1, 2, 3]
    np.testing.assert_allclose(solid.vertices, expected, atol=1e-6)
    np.testing.assert_array_equal(solid.triangles, BOX_FACES)
    (hull,) = held.world_hulls
    np.testing.assert_allclose(hull.vertices, expected, atol=1e-6)
    centre = held.world_centre_of_mass
    assert centre is not None
    np.testing.assert_allclose(centre, [1.0, 2.0, 2.85], atol=1e-6)


def test_a_round_primitive_body_is_a_closed_mesh_on_its_surface_in_the_world() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1))
    cylinder = PRIMITIVES[1]
    scene.apply(replace(a_primitive_body(cylinder), object_id=1, shape_version=1))
    held = scene.objects[1]
    solid = held.world_solid
    assert solid is not None
    vertices, triangles = tessellate(cylinder)
    np.testing.assert_allclose(solid.vertices, held.pose.to_world(vertices), atol=1e-7)
    np.testing.assert_array_equal(solid.triangles, triangles)
    # In the primitive's frame every vertex is on the cylinder: radius 4 cm, within 9 cm of
    # its middle along its axis.
    turn = cylinder.rotation_matrix()
    own = (vertices.astype(np.float64) - cylinder.centre) @ turn
    radial = np.linalg.norm(own[:, :2], axis=1)
    on_side = np.isclose(radial, 0.04, atol=1e-6)
    on_cap = np.isclose(np.abs(own[:, 2]), 0.09, atol=1e-6)
    assert np.all(on_side | on_cap) and np.all(radial <= 0.04 + 1e-6)


def test_only_the_shadow_volume_and_the_extrusion_are_fallbacks() -> None:
    assert [s.is_fallback for s in BodySolid] == [False, False, False, True, True]
    assert [s.carries_mesh for s in BodySolid] == [False, False, True, True, True]
    assert [int(s) for s in BodySolid] == [0, 1, 2, 3, 4]
    assert [int(k) for k in PrimitiveKind] == [1, 2, 3, 4]
    assert [k.used_sizes for k in PrimitiveKind] == [3, 2, 1, 2]


def test_a_body_of_an_object_not_held_is_stale() -> None:
    scene = Scene()
    scene.apply(body_of(1, 1))
    assert scene.objects == {} and scene.stale == 1
    scene.apply(shape_of(1, 1))
    assert scene.objects[1].body is None


def test_the_newest_body_is_kept_and_a_newer_shape_in_the_same_frame_keeps_it() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 2))
    scene.apply(body_of(1, 2))
    scene.apply(body_of(1, 1))  # older than the held body
    assert scene.objects[1].body is not None and scene.objects[1].body.shape_version == 2
    assert scene.stale == 1
    # A new shape without `new_frame` is in the same frame: the held body still fits.
    scene.apply(shape_of(1, 3))
    held = scene.objects[1]
    assert held.shape_version == 3 and held.body is not None and held.body.shape_version == 2
    # Its own body, when it comes, replaces the older one; the same one again is taken too.
    scene.apply(body_of(1, 3))
    scene.apply(body_of(1, 3))
    assert scene.objects[1].body is not None and scene.objects[1].body.shape_version == 3
    assert scene.stale == 1


def test_a_new_frame_shape_drops_an_older_body() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1))
    scene.apply(body_of(1, 1))
    scene.apply(shape_of(1, 2, flags=SHAPE_NEW_FRAME))
    held = scene.objects[1]
    assert held.shape_version == 2 and held.body is None and held.world_hulls == ()
    # A Body made in the frame before, arriving late, does not fit either ...
    scene.apply(body_of(1, 1))
    assert scene.objects[1].body is None and scene.stale == 1
    # ... not even after a later shape in the new frame.
    scene.apply(shape_of(1, 3))
    scene.apply(body_of(1, 1))
    assert scene.objects[1].body is None and scene.stale == 2
    scene.apply(body_of(1, 2))
    assert scene.objects[1].body is not None and scene.objects[1].body.shape_version == 2


def test_a_new_frame_shape_keeps_a_body_of_its_own_version() -> None:
    """Where Shapes and Bodies travel apart, a Body can come before its Shape."""
    scene = Scene()
    scene.apply(shape_of(1, 1))
    scene.apply(body_of(1, 2))
    scene.apply(shape_of(1, 2, flags=SHAPE_NEW_FRAME))
    held = scene.objects[1]
    assert held.body is not None and held.body.shape_version == 2


def test_a_remove_or_a_session_forgets_the_body_with_the_object() -> None:
    scene = Scene()
    scene.apply(shape_of(1, 1))
    scene.apply(body_of(1, 1))
    scene.apply(Remove(1))
    assert scene.objects == {}
    scene.apply(shape_of(1, 1))
    assert scene.objects[1].body is None
    scene.apply(body_of(1, 1))
    scene.apply(Session(1, 2))
    scene.apply(shape_of(1, 1))
    assert scene.objects[1].body is None


def test_a_filter_without_bodies_forgets_the_bodies() -> None:
    scene = Scene()
    for object_id in (1, 2):
        scene.apply(shape_of(object_id, 1))
        scene.apply(body_of(object_id, 1))
    scene.keep_only(Subscribe(kinds=Kinds.OBJECTS | Kinds.BODIES, object_ids=(1,)))
    assert set(scene.objects) == {1} and scene.objects[1].body is not None
    scene.keep_only(Subscribe(kinds=Kinds.OBJECTS))
    assert set(scene.objects) == {1} and scene.objects[1].body is None


def test_a_pose_extrapolates_by_its_velocities() -> None:
    pose = Pose(
        object_id=3,
        shape_version=2,
        pose_time_ns=1_000_000_000,
        pose_time_realtime_ns=0,
        last_seen_ns=1_000_000_000,
        rotation=(0.0, 0.0, 0.0, 1.0),
        translation=(1.0, 0.0, 0.0),
        linear_velocity=(0.1, 0.0, 0.0),
        angular_velocity=(0.0, 0.0, 0.5),
    )
    later = pose.extrapolated(1_500_000_000)
    assert np.allclose(later.translation, (1.05, 0.0, 0.0))
    # A quarter radian about z: (0, 0, sin 0.125, cos 0.125).
    assert np.allclose(later.rotation, (0.0, 0.0, np.sin(0.125), np.cos(0.125)))
    assert pose.extrapolated(1_000_000_000) == pose
