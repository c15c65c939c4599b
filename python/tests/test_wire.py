"""The codec against the examples of docs/protocol.md byte for byte, round trips of every
message, the compact encoding's bound, every refusal of the document's list, and the scene
rules."""

from __future__ import annotations

import math
import re
import struct
from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pytest

from tacmesh import Scene
from tacmesh.wire import (
    DEFAULT_OPTIONS,
    FIRST_SUPPORT_ID,
    MAX_FRAME_BYTES,
    SHAPE_CLOSED,
    SHAPE_SUPPORT,
    AnyMessage,
    BadBox,
    CountOverCap,
    EmptyFrame,
    Encoding,
    FrameDecoder,
    FrameTooLarge,
    Goodbye,
    Hello,
    IndexOutOfRange,
    InvalidEnum,
    InvalidFlags,
    InvalidNumber,
    InvalidText,
    Kinds,
    NonFinite,
    NotUnitQuaternion,
    Pose,
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
    quantisation_bound_m,
)

STATS_COUNTERS = [f.name for f in fields(Stats) if f.type == "int"][:19]
DOC = Path(__file__).resolve().parents[2] / "docs" / "protocol.md"


def frame(kind: int, payload: bytes) -> bytes:
    return struct.pack("<IB", 1 + len(payload), kind) + payload


def one(data: bytes, sender: Sender = "server") -> AnyMessage:
    (message,) = decode_all(data, sender)
    return message


# ---- the document's examples -----------------------------------------------------------------


def test_the_documents_hello() -> None:
    data = bytes.fromhex("0c000000 01 0200 0700 7461636d657368")
    assert len(data) == 16
    assert one(data) == Hello(2, "tacmesh")
    assert encode(Hello(2, "tacmesh")) == data


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
    data = bytes.fromhex("0c000000 81 01 01 00002041 03 00000000")
    options = Subscribe(Encoding.COMPACT, resend=True, max_rate_hz=10.0, kinds=Kinds.ALL)
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
    # Hello, Shape (full and compact), Pose, Remove, SnapshotDone, Goodbye, Subscribe.
    assert len(examples) >= 8, examples
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
    assert {Hello, Remove, SnapshotDone, Goodbye, Subscribe, Pose, Shape} <= kinds


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


# ---- round trips -----------------------------------------------------------------------------


def f32(value: float) -> float:
    """The value as the wire carries it."""
    return float(np.float32(value))


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
            stages=(StageLatency("segment", 1.5, 3.0), StageLatency("é" * 32, 0.0, 0.0)),
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
        SubscribeV1(),
    ],
    ids=["default", "everything", "v1"],
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
        encode(Hello(2, "tacmesh"))
        + encode(Session(1, 2))
        + encode(a_shape(Encoding.COMPACT, n=20))
        + encode(a_pose())
        + encode(SnapshotDone())
    )
    decoder = FrameDecoder()
    out = []
    for byte in stream:
        decoder.push(bytes([byte]))
        while (message := decoder.next_message()) is not None:
            out.append(type(message))
    assert out == [Hello, Session, Shape, Pose, SnapshotDone]
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
    ("a compact Shape longer than its counts", longer(COMPACT, bytes(6)), TrailingBytes),
    ("a short Stats", shorter(encode(Stats())), Truncated),
    (
        "a Stats with more stages than bytes",
        patched(encode(Stats()), 5 + 164, struct.pack("<I", 10**9)),
        Truncated,
    ),
    ("a long Session", longer(encode(Session(1, 2))), TrailingBytes),
    ("a server name that is not UTF-8", frame(0x01, b"\x02\x00\x02\x00\xff\xfe"), InvalidText),
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
    ("a Shape flag not defined", patched(SHAPE, FLAGS, b"\x04"), InvalidFlags),
    ("a Shape encoding not defined", patched(SHAPE, ENCODING, b"\x02"), InvalidEnum),
    (
        "a Session encoding not defined",
        patched(encode(Session(0, 0)), 5 + 16, b"\x02"),
        InvalidEnum,
    ),
    ("a Session flag not defined", patched(encode(Session(0, 0)), 5 + 17, b"\x04"), InvalidFlags),
    ("a Session of no kinds", patched(encode(Session(0, 0)), 5 + 22, b"\x00"), InvalidFlags),
    ("a Session kind not defined", patched(encode(Session(0, 0)), 5 + 22, b"\x07"), InvalidFlags),
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
    ("a NaN rotation", unchecked(replace(a_pose(), rotation=(NAN, 0, 0, 1))), NonFinite),
    ("an infinite translation", unchecked(replace(a_pose(), translation=(0, INF, 0))), NonFinite),
    ("a NaN velocity", unchecked(replace(a_pose(), linear_velocity=(0, 0, NAN))), NonFinite),
    ("an infinite spin", unchecked(replace(a_pose(), angular_velocity=(-INF, 0, 0))), NonFinite),
    (
        "a Shape's NaN pose",
        unchecked(replace(a_shape(n=10), pose=replace(a_pose(), translation=(NAN, 0, 0)))),
        NonFinite,
    ),
    ("a NaN box", patched(COMPACT, BOX, struct.pack("<f", NAN)), NonFinite),
    ("an infinite box", patched(COMPACT, BOX + 12 + 8, struct.pack("<f", INF)), NonFinite),
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
            replace(a_shape(Encoding.COMPACT, n=10), triangles=np.array([[9, 10, 0]], np.uint32))
        ),
        IndexOutOfRange,
    ),
    (
        "a compact box whose maximum is below its minimum",
        patched(COMPACT, BOX + 12 + 4, struct.pack("<f", -1e6)),
        BadBox,
    ),
    ("a negative residual", unchecked(replace(a_shape(n=10), max_residual_m=-1.0)), InvalidNumber),
    ("a NaN residual", patched(SHAPE, RESIDUAL, struct.pack("<f", NAN)), InvalidNumber),
    (
        "a negative rate",
        unchecked(Session(0, 0, Subscribe(max_rate_hz=-1.0))),
        InvalidNumber,
    ),
    ("an infinite rate", unchecked(Session(0, 0, Subscribe(max_rate_hz=INF))), InvalidNumber),
    ("a NaN latency", unchecked(Stats(frame_to_publish_p99_ms=NAN)), InvalidNumber),
    ("a negative latency", unchecked(Stats(frame_to_publish_p50_ms=-1.0)), InvalidNumber),
    (
        "an infinite stage latency",
        unchecked(Stats(stages=(StageLatency("mesh", 1.0, INF),))),
        InvalidNumber,
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
    ("a Subscribe over its length", longer(encode(DEFAULT_OPTIONS)), TrailingBytes),
    ("a short Subscribe", shorter(encode(DEFAULT_OPTIONS)), Truncated),
    ("a version 1 Subscribe with a payload", frame(0x80, b"\x00"), TrailingBytes),
    (
        "1025 ids",
        unchecked(Subscribe(object_ids=tuple(range(1025)))),
        CountOverCap,
    ),
    ("an encoding not defined", patched(encode(DEFAULT_OPTIONS), 5, b"\x02"), InvalidEnum),
    ("a flag not defined", patched(encode(DEFAULT_OPTIONS), 6, b"\x05"), InvalidFlags),
    ("no kinds", unchecked(Subscribe(kinds=Kinds(0))), InvalidFlags),
    ("a NaN rate", unchecked(Subscribe(max_rate_hz=NAN)), InvalidNumber),
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
        (replace(a_shape(n=10), triangles=np.array([[0, 1, 10]], np.uint32)), IndexOutOfRange),
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
        (Subscribe(kinds=Kinds(0)), InvalidFlags),
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
