//! Golden bytes pin the layout of `docs/protocol.md`; the rest pins how bad input is refused.

use glam::Vec3;
use tacmesh_source::TriMesh;

use crate::*;

fn encoded(message: &Message) -> Vec<u8> {
    let mut out = Vec::new();
    encode(message, &mut out).expect("test messages are valid");
    out
}

/// Decodes one complete buffer, expecting exactly one message and nothing left over.
fn decode_one(bytes: &[u8], from: Sender) -> Result<Message, WireError> {
    let mut decoder = FrameDecoder::new(from);
    decoder.push(bytes);
    let message = decoder.next_message()?.expect("a whole frame was pushed");
    assert_eq!(decoder.buffered_len(), 0);
    Ok(message)
}

fn decode_err(bytes: &[u8], from: Sender) -> WireError {
    decode_one(bytes, from).expect_err("the frame is invalid")
}

fn one_triangle_upsert() -> Message {
    Message::Upsert(Upsert {
        object_id: 7,
        version: 2,
        capture_time_ns: 1_000_000_000,
        mesh: TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, -2.0)],
            vec![[0, 1, 2]],
        ),
        report: SimplifyStats {
            faces_in: 4,
            faces_out: 1,
            max_residual_m: 0.25,
        },
    })
}

#[rustfmt::skip]
const ONE_TRIANGLE_UPSERT_BYTES: [u8; 97] = [
    0x5d, 0x00, 0x00, 0x00,                         // length 93
    0x02,                                           // kind Upsert
    0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // object_id 7
    0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // version 2
    0x00, 0xca, 0x9a, 0x3b, 0x00, 0x00, 0x00, 0x00, // capture_time_ns 1e9
    0x04, 0x00, 0x00, 0x00,                         // faces_in 4
    0x01, 0x00, 0x00, 0x00,                         // faces_out 1
    0x00, 0x00, 0x80, 0x3e,                         // max_residual_m 0.25
    0x03, 0x00, 0x00, 0x00,                         // vertex_count 3
    0x01, 0x00, 0x00, 0x00,                         // triangle_count 1
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // (0, 0, 0)
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // (1, 0, 0)
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, // (0, 1, -2)
    0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, // [0, 1, 2]
];

fn sample_stats() -> Message {
    Message::Stats(Stats {
        frames_in: 1,
        frames_dropped: 2,
        invalid_pixels: 3,
        objects_tracked: 4,
        meshing_runs: 5,
        meshes_published: 6,
        bytes_sent: 7,
        stage_latencies: vec![StageLatency {
            stage: "mesh".into(),
            p50_ms: 0.5,
            p99_ms: 1.0,
        }],
        frame_to_publish_p50_ms: 2.0,
        frame_to_publish_p99_ms: 8.0,
    })
}

/// One message of every kind the server sends, with non-trivial content.
fn server_messages() -> Vec<Message> {
    let mut stats = sample_stats();
    if let Message::Stats(s) = &mut stats {
        for (i, stage) in ["deproject", "segment", "integrate", "simplify", "publish"]
            .into_iter()
            .enumerate()
        {
            s.stage_latencies.push(StageLatency {
                stage: stage.into(),
                p50_ms: i as f32 * 1.5,
                p99_ms: i as f32 * 7.25,
            });
        }
    }
    vec![
        Message::hello("tacmesh 0.1.0 — ünïcode"),
        one_triangle_upsert(),
        Message::Upsert(Upsert {
            object_id: u64::MAX,
            version: 1,
            capture_time_ns: 123_456_789_012,
            mesh: TriMesh::new(
                vec![
                    Vec3::new(0.1, 0.2, 0.3),
                    Vec3::new(-1.5, 2.0, 1e-7),
                    Vec3::new(3.0e3, -0.0, 0.5),
                    Vec3::new(0.0, 0.0, 1.0),
                ],
                vec![[0, 1, 2], [0, 2, 3], [1, 3, 2], [0, 3, 1]],
            ),
            report: SimplifyStats {
                faces_in: 10_000,
                faces_out: 4,
                max_residual_m: 0.004,
            },
        }),
        Message::Upsert(Upsert {
            object_id: 3,
            version: 9,
            capture_time_ns: 0,
            mesh: TriMesh::default(),
            report: SimplifyStats {
                faces_in: 0,
                faces_out: 0,
                max_residual_m: 0.0,
            },
        }),
        Message::Remove { object_id: 42 },
        Message::SnapshotDone,
        stats,
        Message::Stats(Stats::default()),
        Message::Goodbye {
            reason: "SIGTERM received".into(),
        },
        Message::Goodbye {
            reason: String::new(),
        },
    ]
}

fn stream_of(messages: &[Message]) -> Vec<u8> {
    let mut out = Vec::new();
    for message in messages {
        encode(message, &mut out).expect("test messages are valid");
    }
    out
}

// ---- golden bytes ------------------------------------------------------------------------------

#[test]
fn hello_golden_bytes() {
    #[rustfmt::skip]
    let expected: [u8; 16] = [
        0x0c, 0x00, 0x00, 0x00,                   // length 12
        0x01,                                     // kind Hello
        0x01, 0x00,                               // protocol_version 1
        0x07, 0x00,                               // server: 7 bytes
        b't', b'a', b'c', b'm', b'e', b's', b'h', // "tacmesh"
    ];
    let message = Message::Hello {
        protocol_version: 1,
        server: "tacmesh".into(),
    };
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
}

#[test]
fn remove_golden_bytes() {
    #[rustfmt::skip]
    let expected: [u8; 13] = [
        0x09, 0x00, 0x00, 0x00,                         // length 9
        0x03,                                           // kind Remove
        0x08, 0x07, 0x06, 0x05, 0x04, 0x03, 0x02, 0x01, // object_id 0x0102030405060708
    ];
    let message = Message::Remove {
        object_id: 0x0102_0304_0506_0708,
    };
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
}

#[test]
fn upsert_golden_bytes_one_triangle() {
    assert_eq!(encoded(&one_triangle_upsert()), ONE_TRIANGLE_UPSERT_BYTES);
    assert_eq!(
        decode_one(&ONE_TRIANGLE_UPSERT_BYTES, Sender::Server),
        Ok(one_triangle_upsert())
    );
}

#[test]
fn stats_golden_bytes_one_stage() {
    #[rustfmt::skip]
    let expected: [u8; 87] = [
        0x53, 0x00, 0x00, 0x00,                         // length 83
        0x05,                                           // kind Stats
        0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // frames_in 1
        0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // frames_dropped 2
        0x03, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // invalid_pixels 3
        0x04, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // objects_tracked 4
        0x05, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // meshing_runs 5
        0x06, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // meshes_published 6
        0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // bytes_sent 7
        0x00, 0x00, 0x00, 0x40,                         // frame_to_publish_p50_ms 2.0
        0x00, 0x00, 0x00, 0x41,                         // frame_to_publish_p99_ms 8.0
        0x01, 0x00, 0x00, 0x00,                         // stage_count 1
        0x04, 0x00, b'm', b'e', b's', b'h',             // stage "mesh"
        0x00, 0x00, 0x00, 0x3f,                         // p50_ms 0.5
        0x00, 0x00, 0x80, 0x3f,                         // p99_ms 1.0
    ];
    assert_eq!(encoded(&sample_stats()), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(sample_stats()));
}

#[test]
fn payloadless_and_goodbye_golden_bytes() {
    assert_eq!(
        encoded(&Message::SnapshotDone),
        [0x01, 0x00, 0x00, 0x00, 0x04]
    );
    assert_eq!(encoded(&Message::Subscribe), [0x01, 0x00, 0x00, 0x00, 0x80]);
    let goodbye = Message::Goodbye {
        reason: "bye".into(),
    };
    #[rustfmt::skip]
    let expected = [0x06, 0x00, 0x00, 0x00, 0x06, 0x03, 0x00, b'b', b'y', b'e'];
    assert_eq!(encoded(&goodbye), expected);
}

// ---- round trips -------------------------------------------------------------------------------

#[test]
fn every_message_round_trips() {
    for message in server_messages() {
        assert_eq!(
            decode_one(&encoded(&message), Sender::Server).as_ref(),
            Ok(&message)
        );
    }
    assert_eq!(
        decode_one(&encoded(&Message::Subscribe), Sender::Client),
        Ok(Message::Subscribe)
    );
}

#[test]
fn decoder_fed_one_byte_at_a_time_yields_the_same_messages() {
    let messages = server_messages();
    let stream = stream_of(&messages);
    let mut decoder = FrameDecoder::new(Sender::Server);
    let mut decoded = Vec::new();
    for byte in &stream {
        decoder.push(std::slice::from_ref(byte));
        while let Some(message) = decoder.next_message().expect("stream is valid") {
            decoded.push(message);
        }
    }
    assert_eq!(decoded, messages);
    assert_eq!(decoder.buffered_len(), 0);
}

#[test]
fn decoder_reads_several_frames_from_one_push() {
    let messages = server_messages();
    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(&stream_of(&messages));
    let mut decoded = Vec::new();
    while let Some(message) = decoder.next_message().expect("stream is valid") {
        decoded.push(message);
    }
    assert_eq!(decoded, messages);
}

#[test]
fn decoder_waits_for_a_whole_frame() {
    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(&ONE_TRIANGLE_UPSERT_BYTES[..96]);
    assert_eq!(decoder.next_message(), Ok(None));
    assert_eq!(decoder.buffered_len(), 96);
    decoder.push(&ONE_TRIANGLE_UPSERT_BYTES[96..]);
    assert_eq!(decoder.next_message(), Ok(Some(one_triangle_upsert())));
    assert_eq!(decoder.next_message(), Ok(None));
}

#[test]
fn decoder_skips_a_bad_frame_and_reads_the_next() {
    let mut stream = vec![0x01, 0x00, 0x00, 0x00, 0x7f]; // unknown kind, complete frame
    stream.extend(encoded(&Message::SnapshotDone));
    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(&stream);
    assert_eq!(
        decoder.next_message(),
        Err(WireError::UnknownKind { kind: 0x7f })
    );
    assert_eq!(decoder.next_message(), Ok(Some(Message::SnapshotDone)));
}

#[test]
fn check_hello_accepts_our_version_only() {
    assert_eq!(check_hello(&Message::hello("tacmesh")), Ok(()));
    assert_eq!(
        check_hello(&Message::Hello {
            protocol_version: 2,
            server: "future".into()
        }),
        Err(WireError::VersionMismatch { ours: 1, theirs: 2 })
    );
    assert_eq!(
        check_hello(&Message::SnapshotDone),
        Err(WireError::NotHello {
            got: "SnapshotDone"
        })
    );
}

// ---- size cap ----------------------------------------------------------------------------------

#[test]
fn wire_rejects_oversize_frame() {
    let mut decoder = FrameDecoder::new(Sender::Server);
    let length = MAX_FRAME_BYTES as u32 + 1;
    decoder.push(&length.to_le_bytes());
    // Refused on the prefix alone, before any of the body arrives.
    let err = decoder.next_message().expect_err("length over the cap");
    assert_eq!(
        err,
        WireError::FrameTooLarge {
            length: u64::from(length)
        }
    );
    assert!(err.to_string().contains("exceeds the cap"), "{err}");
    // And it does not resynchronise on later bytes.
    decoder.push(&encoded(&Message::SnapshotDone));
    assert!(decoder.next_message().is_err());

    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(&u32::MAX.to_le_bytes());
    assert!(matches!(
        decoder.next_message(),
        Err(WireError::FrameTooLarge { .. })
    ));
}

#[test]
fn wire_accepts_a_prefix_at_the_cap_and_waits_for_the_body() {
    let mut decoder = FrameDecoder::new(Sender::Server);
    decoder.push(&(MAX_FRAME_BYTES as u32).to_le_bytes());
    decoder.push(&[0x02]);
    assert_eq!(decoder.next_message(), Ok(None));
}

#[test]
fn encode_rejects_message_over_the_cap_before_writing() {
    let vertex_count = MAX_FRAME_BYTES / 12 + 1;
    let message = Message::Upsert(Upsert {
        object_id: 1,
        version: 1,
        capture_time_ns: 0,
        mesh: TriMesh::new(vec![Vec3::ZERO; vertex_count], Vec::new()),
        report: SimplifyStats {
            faces_in: 0,
            faces_out: 0,
            max_residual_m: 0.0,
        },
    });
    let mut out = vec![0xaa];
    assert!(matches!(
        encode(&message, &mut out),
        Err(WireError::FrameTooLarge { .. })
    ));
    assert_eq!(out, [0xaa]);
}

// ---- bad input -----------------------------------------------------------------------------------

/// A frame from its kind and payload.
fn frame(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = (payload.len() as u32 + 1).to_le_bytes().to_vec();
    out.push(kind);
    out.extend_from_slice(payload);
    out
}

#[test]
fn wire_rejects_empty_frame() {
    assert_eq!(
        decode_err(&[0, 0, 0, 0], Sender::Server),
        WireError::EmptyFrame
    );
}

#[test]
fn wire_rejects_garbage_kinds() {
    for kind in [0x00, 0x07, 0x7f, 0x81, 0xff] {
        let err = decode_err(&frame(kind, &[]), Sender::Server);
        assert_eq!(err, WireError::UnknownKind { kind });
        assert!(err.to_string().contains("unknown message kind"), "{err}");
        assert_eq!(
            decode_err(&frame(kind, &[1, 2, 3]), Sender::Client),
            WireError::UnknownKind { kind }
        );
    }
}

#[test]
fn wire_rejects_messages_of_the_other_direction() {
    // A client that sends server messages is refused by the daemon's decoder…
    let err = decode_err(&encoded(&Message::hello("x")), Sender::Client);
    assert_eq!(
        err,
        WireError::WrongSender {
            message: "Hello",
            sender: Sender::Server,
            expected: Sender::Client
        }
    );
    assert!(
        err.to_string().contains("Hello is sent by a server"),
        "{err}"
    );
    // …and a client's decoder refuses a Subscribe.
    assert!(matches!(
        decode_err(&encoded(&Message::Subscribe), Sender::Server),
        WireError::WrongSender { .. }
    ));
}

#[test]
fn wire_rejects_truncated_payload_inside_a_complete_frame() {
    let err = decode_err(&frame(0x03, &[1, 2, 3, 4, 5, 6, 7]), Sender::Server);
    assert_eq!(
        err,
        WireError::Truncated {
            message: "Remove",
            field: "object_id",
            needed: 8,
            available: 7
        }
    );
    assert!(err.to_string().contains("ends inside `object_id`"), "{err}");

    // An Upsert frame cut after its second vertex, length prefix fixed up to match.
    let mut bytes = ONE_TRIANGLE_UPSERT_BYTES[..4 + 1 + 44 + 24].to_vec();
    bytes[..4].copy_from_slice(&(1u32 + 44 + 24).to_le_bytes());
    assert!(matches!(
        decode_err(&bytes, Sender::Server),
        WireError::Truncated {
            field: "vertices and triangles",
            ..
        }
    ));

    // A Hello whose name runs past the frame.
    assert!(matches!(
        decode_err(&frame(0x01, &[1, 0, 9, 0, b'a']), Sender::Server),
        WireError::Truncated {
            field: "server",
            ..
        }
    ));
}

#[test]
fn wire_rejects_huge_counts_without_allocating() {
    let mut bytes = ONE_TRIANGLE_UPSERT_BYTES.to_vec();
    bytes[41..45].copy_from_slice(&u32::MAX.to_le_bytes()); // vertex_count
    bytes[45..49].copy_from_slice(&u32::MAX.to_le_bytes()); // triangle_count
    assert!(matches!(
        decode_err(&bytes, Sender::Server),
        WireError::Truncated { .. }
    ));

    let mut stats = encoded(&sample_stats());
    stats[69..73].copy_from_slice(&u32::MAX.to_le_bytes()); // stage_count
    assert!(matches!(
        decode_err(&stats, Sender::Server),
        WireError::Truncated { .. }
    ));
}

#[test]
fn wire_rejects_trailing_bytes_inside_a_frame() {
    let err = decode_err(&frame(0x03, &[0; 9]), Sender::Server);
    assert_eq!(
        err,
        WireError::TrailingBytes {
            message: "Remove",
            extra: 1
        }
    );
    assert!(
        err.to_string().contains("1 bytes after its last field"),
        "{err}"
    );
    assert!(matches!(
        decode_err(&frame(0x04, &[0]), Sender::Server),
        WireError::TrailingBytes { .. }
    ));
    assert!(matches!(
        decode_err(&frame(0x80, &[0]), Sender::Client),
        WireError::TrailingBytes { .. }
    ));

    let mut bytes = ONE_TRIANGLE_UPSERT_BYTES.to_vec();
    bytes.extend_from_slice(&[0; 4]);
    bytes[..4].copy_from_slice(&(93u32 + 4).to_le_bytes());
    assert_eq!(
        decode_err(&bytes, Sender::Server),
        WireError::TrailingBytes {
            message: "Upsert",
            extra: 4
        }
    );
}

#[test]
fn wire_rejects_out_of_range_triangle_index() {
    let mut bytes = ONE_TRIANGLE_UPSERT_BYTES.to_vec();
    bytes[93] = 3; // the last corner of the triangle
    let err = decode_err(&bytes, Sender::Server);
    assert_eq!(
        err,
        WireError::IndexOutOfRange {
            triangle: 0,
            index: 3,
            vertex_count: 3
        }
    );
    assert!(err.to_string().contains("only 3 vertices"), "{err}");
}

#[test]
fn wire_rejects_non_finite_vertices() {
    for (value, offset) in [
        (f32::NAN, 49),
        (f32::INFINITY, 61 + 8),
        (f32::NEG_INFINITY, 73),
    ] {
        let mut bytes = ONE_TRIANGLE_UPSERT_BYTES.to_vec();
        bytes[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
        let err = decode_err(&bytes, Sender::Server);
        assert!(
            matches!(err, WireError::NonFiniteVertex { vertex, .. } if vertex == (offset - 49) / 12),
            "{err:?}"
        );
        assert!(err.to_string().contains("non-finite"), "{err}");
    }
}

#[test]
fn wire_rejects_nan_residual_and_latency() {
    let mut bytes = ONE_TRIANGLE_UPSERT_BYTES.to_vec();
    bytes[37..41].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(matches!(
        decode_err(&bytes, Sender::Server),
        WireError::InvalidNumber {
            field: "max_residual_m",
            ..
        }
    ));
    let mut stats = encoded(&sample_stats());
    stats[79..83].copy_from_slice(&(-1.0f32).to_le_bytes()); // the stage's p50_ms
    assert_eq!(
        decode_err(&stats, Sender::Server),
        WireError::InvalidNumber {
            field: "p50_ms",
            value: -1.0
        }
    );
}

#[test]
fn wire_rejects_invalid_utf8() {
    let err = decode_err(
        &frame(0x01, &[1, 0, 3, 0, b'a', 0xff, b'b']),
        Sender::Server,
    );
    assert_eq!(
        err,
        WireError::InvalidUtf8 {
            message: "Hello",
            field: "server",
            valid_up_to: 1
        }
    );
    assert!(err.to_string().contains("not UTF-8"), "{err}");
}

#[test]
fn wire_rejects_text_over_its_cap() {
    let mut payload = vec![1, 0];
    payload.extend_from_slice(&(MAX_NAME_BYTES as u16 + 1).to_le_bytes());
    payload.extend(std::iter::repeat_n(b'a', MAX_NAME_BYTES + 1));
    assert!(matches!(
        decode_err(&frame(0x01, &payload), Sender::Server),
        WireError::TextTooLong {
            field: "server",
            ..
        }
    ));
}

#[test]
fn encode_refuses_what_decode_would_refuse_and_leaves_out_untouched() {
    let bad_mesh = |mesh: TriMesh| {
        Message::Upsert(Upsert {
            object_id: 1,
            version: 1,
            capture_time_ns: 0,
            mesh,
            report: SimplifyStats {
                faces_in: 1,
                faces_out: 1,
                max_residual_m: 0.0,
            },
        })
    };
    let triangle = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
    let cases = [
        (
            bad_mesh(TriMesh::new(triangle.clone(), vec![[0, 1, 3]])),
            WireError::IndexOutOfRange {
                triangle: 0,
                index: 3,
                vertex_count: 3,
            },
        ),
        (
            bad_mesh(TriMesh::new(
                vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::INFINITY, 0.0)],
                vec![[0, 1, 2]],
            )),
            WireError::NonFiniteVertex {
                vertex: 2,
                value: f32::INFINITY,
            },
        ),
        (
            Message::hello("x".repeat(MAX_NAME_BYTES + 1)),
            WireError::TextTooLong {
                message: "Hello",
                field: "server",
                len: MAX_NAME_BYTES + 1,
                max: MAX_NAME_BYTES,
            },
        ),
        (
            Message::Goodbye {
                reason: "x".repeat(MAX_REASON_BYTES + 1),
            },
            WireError::TextTooLong {
                message: "Goodbye",
                field: "reason",
                len: MAX_REASON_BYTES + 1,
                max: MAX_REASON_BYTES,
            },
        ),
        (
            Message::Stats(Stats {
                frame_to_publish_p99_ms: -0.5,
                ..Stats::default()
            }),
            WireError::InvalidNumber {
                field: "frame_to_publish_p99_ms",
                value: -0.5,
            },
        ),
    ];
    for (message, expected) in cases {
        let mut out = vec![0xaa, 0xbb];
        assert_eq!(encode(&message, &mut out), Err(expected));
        assert_eq!(out, [0xaa, 0xbb]);
    }
}

// ---- mangling ----------------------------------------------------------------------------------

/// Knuth's MMIX LCG; the high bits are good enough to pick corruptions.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> u32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 33) as u32
    }

    fn below(&mut self, n: usize) -> usize {
        (self.next() as usize) % n.max(1)
    }
}

/// Random corruptions of valid frames: whatever comes out, the decoder does not panic, and every
/// message it does accept re-encodes to exactly the bytes it was read from.
#[test]
fn mangled_frames_never_panic() {
    let mut rng = Lcg(0x7ac3_e5ed);
    let mut messages = server_messages();
    messages.push(Message::Subscribe);
    let mut accepted = 0;
    let mut refused = 0;
    for round in 0..20_000 {
        let first = rng.below(messages.len());
        let count = 1 + rng.below(3);
        let mut bytes = stream_of(
            &(0..count)
                .map(|i| messages[(first + i) % messages.len()].clone())
                .collect::<Vec<_>>(),
        );
        for _ in 0..1 + rng.below(4) {
            mangle(&mut bytes, &mut rng);
        }
        let from = if round % 2 == 0 {
            Sender::Server
        } else {
            Sender::Client
        };
        let mut decoder = FrameDecoder::new(from);
        let mut fed = 0;
        let mut offset = 0;
        'feed: while fed < bytes.len() {
            let chunk = 1 + rng.below(64);
            let end = (fed + chunk).min(bytes.len());
            decoder.push(&bytes[fed..end]);
            fed = end;
            loop {
                match decoder.next_message() {
                    Ok(Some(message)) => {
                        let again = encoded(&message);
                        assert_eq!(again[..], bytes[offset..offset + again.len()]);
                        offset += again.len();
                        accepted += 1;
                    }
                    Ok(None) => break,
                    Err(err) => {
                        assert!(!err.to_string().is_empty());
                        refused += 1;
                        break 'feed;
                    }
                }
            }
        }
    }
    // Both outcomes happen, so the corruptions reach past the framing.
    assert!(accepted > 1000 && refused > 1000, "{accepted} {refused}");
}

fn mangle(bytes: &mut Vec<u8>, rng: &mut Lcg) {
    if bytes.is_empty() {
        bytes.push(rng.next() as u8);
        return;
    }
    let at = rng.below(bytes.len());
    match rng.below(7) {
        0 => bytes[at] ^= 1 << rng.below(8),
        1 => bytes[at] = rng.next() as u8,
        2 => bytes.truncate(at),
        3 => bytes.insert(at, rng.next() as u8),
        4 => {
            bytes.remove(at);
        }
        // Write a random small or huge value over four bytes: lengths and counts.
        5 => {
            let value = if rng.below(2) == 0 {
                rng.below(200) as u32
            } else {
                rng.next().rotate_left(1)
            };
            let end = (at + 4).min(bytes.len());
            let le = value.to_le_bytes();
            bytes[at..end].copy_from_slice(&le[..end - at]);
        }
        // Plant a NaN or infinity over four bytes.
        _ => {
            let value = [f32::NAN, f32::INFINITY, -1.0][rng.below(3)];
            let end = (at + 4).min(bytes.len());
            bytes[at..end].copy_from_slice(&value.to_le_bytes()[..end - at]);
        }
    }
}
