"""The decoder against the examples of docs/protocol.md, byte for byte, and against frames that
break its rules."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tacmesh.wire import (
    MAX_FRAME_BYTES,
    FrameDecoder,
    Goodbye,
    Hello,
    ProtocolError,
    Remove,
    SnapshotDone,
    Stats,
    Upsert,
    encode_subscribe,
)


def decode_all(data: bytes) -> list[object]:
    decoder = FrameDecoder()
    decoder.push(data)
    messages: list[object] = []
    while (message := decoder.next_message()) is not None:
        messages.append(message)
    assert decoder.buffered == 0
    return messages


def frame(kind: int, payload: bytes) -> bytes:
    return struct.pack("<IB", 1 + len(payload), kind) + payload


def test_the_documents_hello() -> None:
    data = bytes.fromhex("0c000000 01 0100 0700 7461636d657368")
    assert decode_all(data) == [Hello(1, "tacmesh")]


def test_the_documents_upsert() -> None:
    data = bytes.fromhex(
        "5d000000 02"
        "0700000000000000 0200000000000000 00ca9a3b00000000"
        "04000000 01000000 0000803e 03000000 01000000"
        "000000000000000000000000"
        "0000803f0000000000000000"
        "000000000000803f000000c0"
        "000000000100000002000000"
    )
    (upsert,) = decode_all(data)
    assert isinstance(upsert, Upsert)
    assert (upsert.object_id, upsert.version, upsert.capture_time_ns) == (7, 2, 1_000_000_000)
    assert (upsert.faces_in, upsert.faces_out, upsert.max_residual_m) == (4, 1, 0.25)
    assert upsert.vertices.dtype == np.float32 and upsert.vertices.shape == (3, 3)
    np.testing.assert_array_equal(upsert.vertices, [[0, 0, 0], [1, 0, 0], [0, 1, -2]])
    assert upsert.triangles.dtype == np.uint32
    np.testing.assert_array_equal(upsert.triangles, [[0, 1, 2]])
    assert not upsert.is_plane


def test_the_documents_remove_snapshot_done_and_subscribe() -> None:
    data = bytes.fromhex("09000000 03 0807060504030201") + bytes.fromhex("01000000 04")
    assert decode_all(data) == [Remove(0x0102030405060708), SnapshotDone()]
    assert encode_subscribe() == bytes.fromhex("01000000 80")


def test_stats_and_goodbye() -> None:
    counters = struct.pack("<7Q", 1, 2, 3, 4, 5, 6, 7) + struct.pack("<2f", 30.0, 90.0)
    stage = struct.pack("<H", 7) + b"segment" + struct.pack("<2f", 9.5, 17.0)
    stats_payload = counters + struct.pack("<I", 1) + stage
    data = frame(0x05, stats_payload) + bytes.fromhex("06000000 06 0300 627965")
    stats, goodbye = decode_all(data)
    assert isinstance(stats, Stats)
    assert (stats.frames_in, stats.bytes_sent, stats.frame_to_publish_p99_ms) == (1, 7, 90.0)
    assert [(s.stage, s.p50_ms, s.p99_ms) for s in stats.stages] == [("segment", 9.5, 17.0)]
    assert goodbye == Goodbye("bye")


def test_a_message_split_anywhere_comes_out_whole() -> None:
    data = bytes.fromhex("0c000000 01 0100 0700 7461636d657368") * 3
    decoder = FrameDecoder()
    out = []
    for byte in data:
        decoder.push(bytes([byte]))
        while (message := decoder.next_message()) is not None:
            out.append(message)
    assert out == [Hello(1, "tacmesh")] * 3


def upsert_payload(vertices: list[float], triangles: list[int], residual: float = 0.0) -> bytes:
    v, t = len(vertices) // 3, len(triangles) // 3
    head = struct.pack("<QQQIIfII", 1, 1, 0, 0, t, residual, v, t)
    return (
        head
        + struct.pack(f"<{len(vertices)}f", *vertices)
        + struct.pack(f"<{len(triangles)}I", *triangles)
    )


@pytest.mark.parametrize(
    ("what", "data"),
    [
        ("an unknown kind", frame(0x42, b"")),
        ("kind 0", frame(0x00, b"")),
        ("a client's kind", frame(0x80, b"")),
        ("a zero length", struct.pack("<I", 0)),
        ("a length over the cap", struct.pack("<I", MAX_FRAME_BYTES + 1)),
        ("a short Remove", frame(0x03, b"\x01\x02")),
        ("a long Remove", frame(0x03, bytes(9))),
        ("SnapshotDone with a payload", frame(0x04, b"\x00")),
        ("a server name that is not UTF-8", frame(0x01, b"\x01\x00\x02\x00\xff\xfe")),
        ("a server name over 64 bytes", frame(0x01, b"\x01\x00\x41\x00" + b"a" * 65)),
        ("a NaN vertex", frame(0x02, upsert_payload([0, 0, float("nan")] * 3, [0, 1, 2]))),
        ("a triangle index out of range", frame(0x02, upsert_payload([0.0] * 9, [0, 1, 3]))),
        ("a negative residual", frame(0x02, upsert_payload([0.0] * 9, [0, 1, 2], -1.0))),
        (
            "counts that do not match the payload",
            frame(0x02, upsert_payload([0.0] * 9, [0, 1, 2])[:-4]),
        ),
    ],
)
def test_a_frame_that_breaks_the_rules_is_refused(what: str, data: bytes) -> None:
    decoder = FrameDecoder()
    decoder.push(data)
    with pytest.raises(ProtocolError):
        decoder.next_message()
