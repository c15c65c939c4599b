//! Golden bytes pin the layout of `docs/protocol.md` (its examples are these tests' bytes); the
//! rest pins the round trips, the compact encoding's error bound, and how bad input is refused:
//! one test per item of the document's "A receiver refuses…" list.

use glam::{Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::*;

mod body;

// ---- helpers -------------------------------------------------------------------------------------

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

/// A frame from its kind and payload.
fn frame(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut out = (payload.len() as u32 + 1).to_le_bytes().to_vec();
    out.push(kind);
    out.extend_from_slice(payload);
    out
}

/// A copy of `bytes` with `value` written at `offset` (a frame offset: payload offset + 5).
fn patched(bytes: &[u8], offset: usize, value: &[u8]) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out[offset..offset + value.len()].copy_from_slice(value);
    out
}

/// A copy of a frame with `extra` bytes more or fewer at its end, the length prefix fixed up.
fn resized(bytes: &[u8], new_len: usize) -> Vec<u8> {
    let mut out = bytes.to_vec();
    out.resize(new_len, 0);
    let length = (new_len - 4) as u32;
    out[..4].copy_from_slice(&length.to_le_bytes());
    out
}

fn stream_of(messages: &[Message]) -> Vec<u8> {
    let mut out = Vec::new();
    for message in messages {
        encode(message, &mut out).expect("test messages are valid");
    }
    out
}

fn from_of(message: &Message) -> Sender {
    message.sender()
}

/// Frame offsets of the fields the refusal tests corrupt (payload offset + 5).
mod at {
    pub const POSE_TIME: usize = 5 + 16;
    pub const LAST_SEEN: usize = 5 + 32;
    pub const ROTATION: usize = 5 + 40;
    pub const TRANSLATION: usize = 5 + 56;
    pub const LINEAR_VELOCITY: usize = 5 + 68;
    pub const ANGULAR_VELOCITY: usize = 5 + 80;
    pub const SHAPE_FLAGS: usize = 5 + 108;
    pub const RESIDUAL: usize = 5 + 117;
    pub const ENCODING: usize = 5 + 121;
    pub const VERTEX_COUNT: usize = 5 + 122;
    pub const TRIANGLE_COUNT: usize = 5 + 126;
    pub const GEOMETRY: usize = 5 + 130;
    pub const BOX_MAX: usize = 5 + 142;
    pub const COMPACT_VERTICES: usize = 5 + 154;
    pub const SUBSCRIBE_ENCODING: usize = 5;
    pub const SUBSCRIBE_FLAGS: usize = 5 + 1;
    pub const RATE: usize = 5 + 2;
    pub const KINDS: usize = 5 + 6;
    pub const ID_COUNT: usize = 5 + 7;
    pub const SESSION_OPTIONS: usize = 16;
    pub const FRAME_TO_PUBLISH_P99: usize = 5 + 160;
    pub const STAGE_COUNT: usize = 5 + 164;
    pub const STAGES: usize = 5 + 168;
}

const SECOND_NS: u64 = 1_000_000_000;
const REALTIME_NS: u64 = 1_700_000_000_000_000_000;

/// The Pose example of `docs/protocol.md`.
fn example_pose() -> Pose {
    Pose {
        object_id: 7,
        shape_version: 2,
        pose_time_ns: SECOND_NS,
        pose_time_realtime_ns: REALTIME_NS,
        last_seen_ns: 2 * SECOND_NS,
        rotation: Quat::IDENTITY,
        translation: Vec3::new(1.0, 0.0, -2.0),
        linear_velocity: Vec3::new(0.5, 0.0, 0.0),
        angular_velocity: Vec3::new(0.0, 0.0, 0.25),
    }
}

/// The Shape examples of `docs/protocol.md`: one triangle placed by the example pose.
fn example_shape(encoding: Encoding) -> Shape {
    Shape {
        pose: example_pose(),
        shape_time_ns: SECOND_NS,
        shape_time_realtime_ns: REALTIME_NS,
        flags: 0,
        mesh: TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, 1.0, -2.0)],
            vec![[0, 1, 2]],
        ),
        report: SimplifyStats {
            faces_in: 4,
            faces_out: 1,
            max_residual_m: 0.25,
        },
        encoding,
    }
}

#[rustfmt::skip]
const EXAMPLE_POSE_PAYLOAD: [u8; 92] = [
    0x07, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // object_id 7
    0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // shape_version 2
    0x00, 0xca, 0x9a, 0x3b, 0x00, 0x00, 0x00, 0x00, // pose_time_ns 1 s
    0x00, 0x00, 0x2a, 0x36, 0xfe, 0x9c, 0x97, 0x17, // pose_time_realtime_ns 1.7e18
    0x00, 0x94, 0x35, 0x77, 0x00, 0x00, 0x00, 0x00, // last_seen_ns 2 s
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // rotation x 0, y 0
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, //          z 0, w 1
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xc0, // translation (1, 0, -2)
    0x00, 0x00, 0x00, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // linear (0.5, 0, 0)
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3e, // angular (0, 0, 0.25)
];

/// A Shape frame: prefix, kind, the example pose, then `rest`.
fn shape_frame(rest: &[u8]) -> Vec<u8> {
    let mut payload = EXAMPLE_POSE_PAYLOAD.to_vec();
    payload.extend_from_slice(rest);
    frame(0x08, &payload)
}

#[rustfmt::skip]
const FULL_SHAPE_TAIL: [u8; 86] = [
    0x00, 0xca, 0x9a, 0x3b, 0x00, 0x00, 0x00, 0x00, // shape_time_ns 1 s
    0x00, 0x00, 0x2a, 0x36, 0xfe, 0x9c, 0x97, 0x17, // shape_time_realtime_ns 1.7e18
    0x00,                                           // flags: open, not a support
    0x04, 0x00, 0x00, 0x00,                         // faces_in 4
    0x01, 0x00, 0x00, 0x00,                         // faces_out 1
    0x00, 0x00, 0x80, 0x3e,                         // max_residual_m 0.25
    0x00,                                           // encoding full
    0x03, 0x00, 0x00, 0x00,                         // vertex_count 3
    0x01, 0x00, 0x00, 0x00,                         // triangle_count 1
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // (0, 0, 0)
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, // (1, 0, 0)
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0xc0, // (0, 1, -2)
    0x00, 0x00, 0x00, 0x00, 0x01, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00, 0x00, // [0, 1, 2]
];

#[rustfmt::skip]
const COMPACT_SHAPE_TAIL: [u8; 86] = [
    0x00, 0xca, 0x9a, 0x3b, 0x00, 0x00, 0x00, 0x00, // shape_time_ns 1 s
    0x00, 0x00, 0x2a, 0x36, 0xfe, 0x9c, 0x97, 0x17, // shape_time_realtime_ns 1.7e18
    0x00,                                           // flags: open, not a support
    0x04, 0x00, 0x00, 0x00,                         // faces_in 4
    0x01, 0x00, 0x00, 0x00,                         // faces_out 1
    0x87, 0x02, 0x80, 0x3e,                         // max_residual_m 0.25 + 1.93e-5
    0x01,                                           // encoding compact
    0x03, 0x00, 0x00, 0x00,                         // vertex_count 3
    0x01, 0x00, 0x00, 0x00,                         // triangle_count 1
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0xc0, // box_min (0, 0, -2)
    0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x80, 0x3f, 0x00, 0x00, 0x00, 0x00, // box_max (1, 1, 0)
    0x00, 0x00, 0x00, 0x00, 0xff, 0xff,             // q (0, 0, 65535): (0, 0, 0)
    0xff, 0xff, 0x00, 0x00, 0xff, 0xff,             // q (65535, 0, 65535): (1, 0, 0)
    0x00, 0x00, 0xff, 0xff, 0x00, 0x00,             // q (0, 65535, 0): (0, 1, -2)
    0x00, 0x00, 0x01, 0x00, 0x02, 0x00,             // [0, 1, 2] as u16
];

/// A closed UV sphere of radius `radius_m` with 10 rings of 10 vertices between its poles:
/// 102 vertices, 200 triangles, counter-clockwise seen from outside.
fn uv_sphere(radius_m: f32) -> TriMesh {
    const RINGS: u32 = 10;
    const SEGMENTS: u32 = 10;
    let mut vertices = vec![Vec3::new(0.0, 0.0, radius_m)];
    for ring in 1..=RINGS {
        let polar = ring as f32 * std::f32::consts::PI / (RINGS + 1) as f32;
        for segment in 0..SEGMENTS {
            let azimuth = segment as f32 * std::f32::consts::TAU / SEGMENTS as f32;
            vertices.push(
                radius_m
                    * Vec3::new(
                        polar.sin() * azimuth.cos(),
                        polar.sin() * azimuth.sin(),
                        polar.cos(),
                    ),
            );
        }
    }
    let south = vertices.len() as u32;
    vertices.push(Vec3::new(0.0, 0.0, -radius_m));
    let at = |ring: u32, segment: u32| 1 + (ring - 1) * SEGMENTS + segment % SEGMENTS;
    let mut triangles = Vec::new();
    for s in 0..SEGMENTS {
        triangles.push([0, at(1, s), at(1, s + 1)]);
        for ring in 1..RINGS {
            let (upper, lower) = (ring, ring + 1);
            triangles.push([at(upper, s), at(lower, s), at(lower, s + 1)]);
            triangles.push([at(upper, s), at(lower, s + 1), at(upper, s + 1)]);
        }
        triangles.push([south, at(RINGS, s + 1), at(RINGS, s)]);
    }
    TriMesh::new(vertices, triangles)
}

/// A shape of `mesh` with the example pose, in `encoding`.
fn shape_of(mesh: TriMesh, encoding: Encoding) -> Shape {
    Shape {
        mesh,
        flags: SHAPE_CLOSED,
        report: SimplifyStats {
            faces_in: 10_000,
            faces_out: 200,
            max_residual_m: 0.002,
        },
        ..example_shape(encoding)
    }
}

fn sample_stats() -> Stats {
    Stats {
        monotonic_ns: 5 * SECOND_NS,
        realtime_ns: REALTIME_NS + 5 * SECOND_NS,
        frames_in: 150,
        frames_dropped: 2,
        invalid_pixels: 3,
        malformed_frames: 4,
        source_errors: 5,
        source_restarts: 6,
        objects_tracked: 7,
        objects_born: 8,
        objects_removed: 9,
        meshing_runs: 10,
        meshing_failures: 11,
        shapes_published: 12,
        poses_published: 13,
        bytes_sent: 14,
        clients_connected: 15,
        clients_dropped: 16,
        clients_refused: 17,
        latency_window: 2048,
        frame_to_publish_p50_ms: 2.0,
        frame_to_publish_p99_ms: 8.0,
        stage_latencies: vec![StageLatency {
            stage: "mesh".into(),
            p50_ms: 0.5,
            p99_ms: 1.0,
        }],
    }
}

fn sample_subscribe() -> Subscribe {
    Subscribe {
        encoding: Encoding::Compact,
        resend: true,
        extrapolate: false,
        max_rate_hz: 10.0,
        kinds: Kinds::ALL,
        object_ids: Vec::new(),
    }
}

/// One message of every kind the server sends, full-encoding shapes only (they round-trip
/// exactly), with non-trivial content.
fn server_messages() -> Vec<Message> {
    let mut stats = sample_stats();
    for (i, stage) in ["deproject", "segment", "integrate", "simplify", "publish"]
        .into_iter()
        .enumerate()
    {
        stats.stage_latencies.push(StageLatency {
            stage: stage.into(),
            p50_ms: i as f32 * 1.5,
            p99_ms: i as f32 * 7.25,
        });
    }
    let mut support = shape_of(
        TriMesh::new(
            vec![
                Vec3::new(0.1, 0.2, 0.3),
                Vec3::new(-1.5, 2.0, 1e-7),
                Vec3::new(3.0e3, -0.0, 0.5),
                Vec3::new(0.0, 0.0, 1.0),
            ],
            vec![[0, 1, 2], [0, 2, 3], [1, 3, 2], [0, 3, 1]],
        ),
        Encoding::Full,
    );
    support.flags = SHAPE_SUPPORT;
    support.pose.object_id = FIRST_SUPPORT_ID + 1;
    support.pose.rotation = Quat::from_rotation_x(1.0);
    let mut empty = shape_of(TriMesh::default(), Encoding::Full);
    empty.report = SimplifyStats {
        faces_in: 0,
        faces_out: 0,
        max_residual_m: 0.0,
    };
    let mut far_pose = example_pose();
    far_pose.object_id = u64::MAX;
    far_pose.shape_version = u64::MAX;
    far_pose.pose_time_ns = u64::MAX;
    far_pose.last_seen_ns = u64::MAX;
    far_pose.rotation = Quat::from_xyzw(0.5, -0.5, 0.5, 0.5);
    vec![
        Message::hello("tacmesh 0.1.0 — ünïcode"),
        Message::Session(Session {
            monotonic_ns: 5 * SECOND_NS,
            realtime_ns: REALTIME_NS + 5 * SECOND_NS,
            options: Subscribe::default(),
        }),
        Message::Session(Session {
            monotonic_ns: 1,
            realtime_ns: 2,
            options: Subscribe {
                object_ids: vec![1, FIRST_SUPPORT_ID, u64::MAX],
                kinds: Kinds::SUPPORTS,
                ..sample_subscribe()
            },
        }),
        Message::Shape(example_shape(Encoding::Full)),
        Message::Shape(shape_of(uv_sphere(0.05), Encoding::Full)),
        Message::Shape(support),
        Message::Shape(empty),
        Message::Pose(example_pose()),
        Message::Pose(far_pose),
        Message::Body(body::example_body(Encoding::Full)),
        Message::Body(body::shape_body()),
        Message::Remove { object_id: 42 },
        Message::SnapshotDone,
        Message::Stats(stats),
        Message::Stats(Stats::default()),
        Message::Goodbye {
            reason: "SIGTERM received".into(),
        },
        Message::Goodbye {
            reason: String::new(),
        },
    ]
}

fn client_messages() -> Vec<Message> {
    vec![
        Message::Subscribe(Subscribe::default()),
        Message::Subscribe(sample_subscribe()),
        Message::Subscribe(Subscribe {
            encoding: Encoding::Full,
            resend: false,
            extrapolate: true,
            max_rate_hz: 0.5,
            kinds: Kinds::OBJECTS,
            object_ids: (1..=MAX_SUBSCRIBE_IDS as u64).collect(),
        }),
        Message::SubscribeV1,
    ]
}

/// Compact shapes: the example, a sphere, one flat on an axis, an empty one.
fn compact_shapes() -> Vec<Shape> {
    let flat = TriMesh::new(
        vec![
            Vec3::new(-0.3, 0.25, 0.0),
            Vec3::new(0.3, 0.25, 0.1),
            Vec3::new(0.0, 0.25, -0.4),
        ],
        vec![[0, 1, 2]],
    );
    vec![
        example_shape(Encoding::Compact),
        shape_of(uv_sphere(0.05), Encoding::Compact),
        shape_of(flat, Encoding::Compact),
        shape_of(TriMesh::default(), Encoding::Compact),
    ]
}

/// How far a compact vertex may read back from where it was: [`quantisation_bound_m`] (half a
/// step per axis, exact in real arithmetic) plus what the receiver's f32 arithmetic adds to it:
/// per axis about 3 roundings of the step times up to 65,535 (3 · 2⁻²⁴ · extent) and one of the
/// coordinate itself (2⁻²⁴ · |coordinate|). The second term matters only for a box far from
/// the origin for its size; an object's frame has its origin near the object.
fn compact_tolerance_m(min: Vec3, max: Vec3) -> f32 {
    quantisation_bound_m(min, max)
}

/// `decoded` is what `sent` (compact) should read as: the same but for vertices moved by at
/// most [`compact_tolerance_m`], and the residual increased by the quantisation bound.
fn assert_compact_round_trip(sent: &Shape, decoded: &Shape) {
    let (min, max) = sent.mesh.bounds().unwrap_or((Vec3::ZERO, Vec3::ZERO));
    let bound = quantisation_bound_m(min, max);
    let tolerance = compact_tolerance_m(min, max);
    assert_eq!(decoded.encoding, Encoding::Compact);
    assert_eq!(
        decoded.report.max_residual_m,
        sent.report.max_residual_m + bound
    );
    assert_eq!(decoded.mesh.triangles, sent.mesh.triangles);
    assert_eq!(decoded.mesh.vertices.len(), sent.mesh.vertices.len());
    for (got, want) in decoded.mesh.vertices.iter().zip(&sent.mesh.vertices) {
        assert!(
            got.distance(*want) <= tolerance,
            "{got} is {} from {want}, more than {tolerance}",
            got.distance(*want)
        );
    }
    let same_but_geometry = Shape {
        mesh: decoded.mesh.clone(),
        report: decoded.report,
        encoding: Encoding::Compact,
        ..sent.clone()
    };
    assert_eq!(&same_but_geometry, decoded);
}

// ---- golden bytes ------------------------------------------------------------------------------

#[test]
fn hello_golden_bytes() {
    #[rustfmt::skip]
    let expected: [u8; 16] = [
        0x0c, 0x00, 0x00, 0x00,                   // length 12
        0x01,                                     // kind Hello
        0x04, 0x00,                               // protocol_version 4
        0x07, 0x00,                               // server: 7 bytes
        b't', b'a', b'c', b'm', b'e', b's', b'h', // "tacmesh"
    ];
    let message = Message::hello("tacmesh");
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
fn payloadless_and_goodbye_golden_bytes() {
    let done = [0x01, 0x00, 0x00, 0x00, 0x04];
    assert_eq!(encoded(&Message::SnapshotDone), done);
    assert_eq!(decode_one(&done, Sender::Server), Ok(Message::SnapshotDone));
    let v1 = [0x01, 0x00, 0x00, 0x00, 0x80];
    assert_eq!(encoded(&Message::SubscribeV1), v1);
    assert_eq!(decode_one(&v1, Sender::Client), Ok(Message::SubscribeV1));
    let goodbye = Message::Goodbye {
        reason: "bye".into(),
    };
    #[rustfmt::skip]
    let expected = [0x06, 0x00, 0x00, 0x00, 0x06, 0x03, 0x00, b'b', b'y', b'e'];
    assert_eq!(encoded(&goodbye), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(goodbye));
}

#[test]
fn subscribe_golden_bytes() {
    #[rustfmt::skip]
    let expected: [u8; 16] = [
        0x0c, 0x00, 0x00, 0x00, // length 12
        0x81,                   // kind Subscribe
        0x01,                   // encoding compact
        0x01,                   // flags: resend
        0x00, 0x00, 0x20, 0x41, // max_rate_hz 10
        0x07,                   // kinds: objects, supports and bodies
        0x00, 0x00, 0x00, 0x00, // id_count 0: all objects
    ];
    let message = Message::Subscribe(sample_subscribe());
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Client), Ok(message));
}

#[test]
fn pose_golden_bytes() {
    let expected = frame(0x09, &EXAMPLE_POSE_PAYLOAD);
    assert_eq!(expected[..5], [0x5d, 0x00, 0x00, 0x00, 0x09]); // length 93, kind Pose
    let message = Message::Pose(example_pose());
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
}

#[test]
fn full_shape_golden_bytes() {
    let expected = shape_frame(&FULL_SHAPE_TAIL);
    assert_eq!(expected[..5], [0xb3, 0x00, 0x00, 0x00, 0x08]); // length 179, kind Shape
    let message = Message::Shape(example_shape(Encoding::Full));
    assert_eq!(encoded(&message), expected);
    assert_eq!(decode_one(&expected, Sender::Server), Ok(message));
}

#[test]
fn compact_shape_golden_bytes() {
    let expected = shape_frame(&COMPACT_SHAPE_TAIL);
    // The box costs 24 bytes: one triangle is no smaller than in the full encoding.
    assert_eq!(expected[..5], [0xb3, 0x00, 0x00, 0x00, 0x08]); // length 179, kind Shape
    let sent = example_shape(Encoding::Compact);
    assert_eq!(encoded(&Message::Shape(sent.clone())), expected);
    // These vertices sit on the box's corners, so they read back exactly; the residual grows.
    let read = Shape {
        report: SimplifyStats {
            max_residual_m: 0.25
                + quantisation_bound_m(Vec3::new(0.0, 0.0, -2.0), Vec3::new(1.0, 1.0, 0.0)),
            ..sent.report
        },
        ..sent
    };
    assert_eq!(
        read.report.max_residual_m.to_le_bytes(),
        [0x87, 0x02, 0x80, 0x3e]
    );
    assert_eq!(
        decode_one(&expected, Sender::Server),
        Ok(Message::Shape(read))
    );
}

#[test]
fn pose_frame_is_97_bytes() {
    assert_eq!(encoded(&Message::Pose(example_pose())).len(), 97);
}

/// Session and Stats have no example in the document: this pins each field at its offset.
#[test]
fn session_and_stats_fields_sit_at_their_documented_offsets() {
    let session = encoded(&Message::Session(Session {
        monotonic_ns: 0x1111,
        realtime_ns: 0x2222,
        options: Subscribe {
            object_ids: vec![0x3333],
            ..sample_subscribe()
        },
    }));
    assert_eq!(session.len(), 5 + 16 + 11 + 8);
    assert_eq!(session[4], 0x07);
    assert_eq!(session[5..7], [0x11, 0x11]);
    assert_eq!(session[13..15], [0x22, 0x22]);
    let options = 5 + at::SESSION_OPTIONS;
    assert_eq!(
        session[options..options + 11],
        [0x01, 0x01, 0x00, 0x00, 0x20, 0x41, 0x07, 0x01, 0x00, 0x00, 0x00]
    );
    assert_eq!(session[options + 11..options + 13], [0x33, 0x33]);

    let stats = encoded(&Message::Stats(sample_stats()));
    assert_eq!(stats.len(), 5 + 168 + 2 + 4 + 8);
    assert_eq!(stats[4], 0x0a);
    let counters = [
        5 * SECOND_NS,
        REALTIME_NS + 5 * SECOND_NS,
        150,
        2,
        3,
        4,
        5,
        6,
        7,
        8,
        9,
        10,
        11,
        12,
        13,
        14,
        15,
        16,
        17,
    ];
    for (i, counter) in counters.into_iter().enumerate() {
        let offset = 5 + 8 * i;
        assert_eq!(stats[offset..offset + 8], counter.to_le_bytes(), "u64 #{i}");
    }
    assert_eq!(stats[5 + 152..5 + 156], 2048u32.to_le_bytes());
    assert_eq!(stats[5 + 156..5 + 160], 2.0f32.to_le_bytes());
    assert_eq!(stats[at::FRAME_TO_PUBLISH_P99..][..4], 8.0f32.to_le_bytes());
    assert_eq!(stats[at::STAGE_COUNT..][..4], 1u32.to_le_bytes());
    assert_eq!(
        stats[at::STAGES..],
        [4, 0, b'm', b'e', b's', b'h', 0, 0, 0, 0x3f, 0, 0, 0x80, 0x3f]
    );
}

// ---- round trips -------------------------------------------------------------------------------

#[test]
fn every_message_round_trips() {
    for message in server_messages().into_iter().chain(client_messages()) {
        assert_eq!(
            decode_one(&encoded(&message), from_of(&message)).as_ref(),
            Ok(&message)
        );
    }
}

#[test]
fn compact_shapes_round_trip_within_the_quantisation_bound() {
    for sent in compact_shapes() {
        let Ok(Message::Shape(decoded)) =
            decode_one(&encoded(&Message::Shape(sent.clone())), Sender::Server)
        else {
            panic!("a compact shape decodes as a Shape");
        };
        assert_compact_round_trip(&sent, &decoded);
    }
}

#[test]
fn compact_indices_widen_above_65536_vertices() {
    for (vertex_count, index_bytes) in [(65_536u32, 2), (65_537, 4)] {
        let vertices = (0..vertex_count)
            .map(|i| Vec3::new(i as f32 * 1e-4, (i % 7) as f32 * 0.01, 0.0))
            .collect();
        let last = vertex_count - 1;
        let mesh = TriMesh::new(vertices, vec![[0, last / 2, last], [last, 1, 0]]);
        let sent = shape_of(mesh, Encoding::Compact);
        let bytes = encoded(&Message::Shape(sent.clone()));
        assert_eq!(
            bytes.len(),
            5 + 154 + 6 * vertex_count as usize + 2 * 3 * index_bytes
        );
        let Ok(Message::Shape(decoded)) = decode_one(&bytes, Sender::Server) else {
            panic!("a compact shape decodes as a Shape");
        };
        assert_compact_round_trip(&sent, &decoded);
    }
}

#[test]
fn two_hundred_face_compact_shape_fits_in_2000_bytes() {
    let sphere = uv_sphere(0.05);
    assert_eq!((sphere.vertices.len(), sphere.triangles.len()), (102, 200));
    // Closed and consistently wound: every directed edge once, and its reverse once.
    let mut edges = std::collections::HashSet::new();
    for &[a, b, c] in &sphere.triangles {
        for edge in [(a, b), (b, c), (c, a)] {
            assert!(edges.insert(edge), "edge {edge:?} twice");
        }
    }
    assert!(edges.iter().all(|&(a, b)| edges.contains(&(b, a))));

    let compact = encoded(&Message::Shape(shape_of(sphere.clone(), Encoding::Compact)));
    let full = encoded(&Message::Shape(shape_of(sphere, Encoding::Full)));
    println!(
        "200-face shape: {} bytes compact, {} bytes full",
        compact.len(),
        full.len()
    );
    assert_eq!(compact.len(), 5 + 154 + 6 * 102 + 6 * 200);
    assert_eq!(full.len(), 5 + 130 + 12 * 102 + 12 * 200);
    assert!(compact.len() <= 2000, "{} bytes", compact.len());
}

/// Knuth's MMIX LCG; the high bits are good enough for test data and corruptions.
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

    /// Uniform in `[-1, 1]`.
    fn signed_unit(&mut self) -> f32 {
        self.next() as f32 / (u32::MAX >> 1) as f32 * 2.0 - 1.0
    }
}

/// Over objects from 1 mm to 2 m, their frame's origin anywhere within them, every vertex reads
/// back within `quantisation_bound_m` of where it was (as `docs/protocol.md` promises), give or
/// take the receiver's f32 rounding ([`compact_tolerance_m`]).
#[test]
fn compact_bound_holds_over_random_vertices() {
    let mut rng = Lcg(0x5eed_0fc0_ffee);
    let mut worst_ratio = 0.0f32;
    let mut over_bound = 0;
    let mut vertex_count = 0;
    for round in 0..400 {
        let size_m = [0.001, 0.05, 0.3, 2.0][round % 4];
        let half_extent = Vec3::new(
            size_m * (0.1 + rng.signed_unit().abs()),
            size_m * (0.1 + rng.signed_unit().abs()),
            size_m * (0.1 + rng.signed_unit().abs()),
        );
        let centre =
            half_extent * Vec3::new(rng.signed_unit(), rng.signed_unit(), rng.signed_unit());
        let vertices: Vec<Vec3> = (0..500)
            .map(|_| {
                centre
                    + half_extent
                        * Vec3::new(rng.signed_unit(), rng.signed_unit(), rng.signed_unit())
            })
            .collect();
        let triangles = (0..498u32).map(|i| [i, i + 1, i + 2]).collect();
        let sent = shape_of(TriMesh::new(vertices, triangles), Encoding::Compact);
        let Ok(Message::Shape(decoded)) =
            decode_one(&encoded(&Message::Shape(sent.clone())), Sender::Server)
        else {
            panic!("a compact shape decodes as a Shape");
        };
        // Within the tolerance, vertex by vertex.
        assert_compact_round_trip(&sent, &decoded);
        let (min, max) = sent.mesh.bounds().expect("not empty");
        let bound = quantisation_bound_m(min, max);
        for (got, want) in decoded.mesh.vertices.iter().zip(&sent.mesh.vertices) {
            let ratio = got.distance(*want) / bound;
            worst_ratio = worst_ratio.max(ratio);
            over_bound += usize::from(ratio > 1.0);
            vertex_count += 1;
        }
    }
    println!(
        "worst compact error: {worst_ratio:.4} of the bound; \
         {over_bound} of {vertex_count} vertices over it by rounding"
    );
    assert!(worst_ratio <= 1.01, "{worst_ratio}");
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
    let messages = client_messages();
    let mut decoder = FrameDecoder::new(Sender::Client);
    decoder.push(&stream_of(&messages));
    let mut decoded = Vec::new();
    while let Some(message) = decoder.next_message().expect("stream is valid") {
        decoded.push(message);
    }
    assert_eq!(decoded, messages);
}

/// A frame cut anywhere gives nothing and no error; the rest of it then gives the message.
#[test]
fn decoder_waits_for_a_whole_frame_cut_at_every_byte() {
    let compact = compact_shapes().into_iter().map(Message::Shape);
    for message in server_messages()
        .into_iter()
        .chain(client_messages())
        .chain(compact)
    {
        let bytes = encoded(&message);
        let whole = decode_one(&bytes, from_of(&message)).expect("valid");
        for cut in 0..bytes.len() {
            let mut decoder = FrameDecoder::new(from_of(&message));
            decoder.push(&bytes[..cut]);
            assert_eq!(
                decoder.next_message(),
                Ok(None),
                "{} cut at {cut}",
                message.name()
            );
            assert_eq!(decoder.buffered_len(), cut);
            decoder.push(&bytes[cut..]);
            assert_eq!(decoder.next_message(), Ok(Some(whole.clone())));
            assert_eq!(decoder.next_message(), Ok(None));
        }
    }
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
fn check_hello_accepts_version_4_only() {
    assert_eq!(check_hello(&Message::hello("tacmesh")), Ok(()));
    for theirs in [1, 2, 3, 5] {
        let err = check_hello(&Message::Hello {
            protocol_version: theirs,
            server: "other".into(),
        })
        .expect_err("another version");
        assert_eq!(err, WireError::VersionMismatch { ours: 4, theirs });
        assert!(err.to_string().contains("speaks only version 4"), "{err}");
    }
    assert_eq!(
        check_hello(&Message::SnapshotDone),
        Err(WireError::NotHello {
            got: "SnapshotDone"
        })
    );
}

// ---- size cap ----------------------------------------------------------------------------------

#[test]
fn wire_rejects_oversize_frame_on_its_prefix_alone() {
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

    let mut decoder = FrameDecoder::new(Sender::Client);
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
    decoder.push(&[0x08]);
    assert_eq!(decoder.next_message(), Ok(None));
}

#[test]
fn encode_rejects_message_over_the_cap_before_writing() {
    let vertex_count = MAX_FRAME_BYTES / 12 + 1;
    let message = Message::Shape(shape_of(
        TriMesh::new(vec![Vec3::ZERO; vertex_count], Vec::new()),
        Encoding::Full,
    ));
    let mut out = vec![0xaa];
    assert!(matches!(
        encode(&message, &mut out),
        Err(WireError::FrameTooLarge { .. })
    ));
    assert_eq!(out, [0xaa]);
}

// ---- refusals: one test per item of "A receiver refuses…" ---------------------------------------

#[test]
fn wire_rejects_empty_frame() {
    assert_eq!(
        decode_err(&[0, 0, 0, 0], Sender::Server),
        WireError::EmptyFrame
    );
}

#[test]
fn wire_rejects_unknown_and_retired_kinds() {
    // 0x02 and 0x05 are version 1's Upsert and Stats, 0x0b version 3's Body: retired.
    for kind in [0x00, 0x02, 0x05, 0x0b, 0x0d, 0x7f, 0x82, 0xff] {
        for from in [Sender::Server, Sender::Client] {
            let err = decode_err(&frame(kind, &[1, 2, 3]), from);
            assert_eq!(err, WireError::UnknownKind { kind });
            assert!(err.to_string().contains("unknown message kind"), "{err}");
        }
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
    for message in server_messages() {
        assert!(matches!(
            decode_err(&encoded(&message), Sender::Client),
            WireError::WrongSender { .. }
        ));
    }
    // …and a client's decoder refuses a Subscribe of either version.
    for message in client_messages() {
        assert!(matches!(
            decode_err(&encoded(&message), Sender::Server),
            WireError::WrongSender {
                sender: Sender::Client,
                ..
            }
        ));
    }
}

#[test]
fn wire_rejects_a_payload_shorter_than_its_layout() {
    let compact = compact_shapes().into_iter().map(Message::Shape);
    for message in server_messages()
        .into_iter()
        .chain(client_messages())
        .chain(compact)
    {
        let bytes = encoded(&message);
        if bytes.len() == 5 {
            continue; // nothing to cut
        }
        let err = decode_err(&resized(&bytes, bytes.len() - 1), from_of(&message));
        assert!(
            matches!(err, WireError::Truncated { message: name, .. } if name == message.name()),
            "{message:?}: {err:?}"
        );
    }
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
    // A Hello whose name runs past the frame.
    assert!(matches!(
        decode_err(&frame(0x01, &[2, 0, 9, 0, b'a']), Sender::Server),
        WireError::Truncated {
            field: "server",
            ..
        }
    ));
}

#[test]
fn wire_rejects_a_payload_longer_than_its_layout() {
    for message in server_messages().into_iter().chain(client_messages()) {
        let bytes = encoded(&message);
        let err = decode_err(&resized(&bytes, bytes.len() + 1), from_of(&message));
        assert_eq!(
            err,
            WireError::TrailingBytes {
                message: message.name(),
                extra: 1
            }
        );
    }
    let err = decode_err(&frame(0x03, &[0; 9]), Sender::Server);
    assert!(
        err.to_string().contains("1 bytes after its last field"),
        "{err}"
    );
}

#[test]
fn wire_rejects_invalid_utf8() {
    let err = decode_err(
        &frame(0x01, &[2, 0, 3, 0, b'a', 0xff, b'b']),
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
    assert!(matches!(
        decode_err(&frame(0x06, &[2, 0, 0xc3, 0x28]), Sender::Server),
        WireError::InvalidUtf8 {
            field: "reason",
            ..
        }
    ));
    let stats = encoded(&Message::Stats(sample_stats()));
    assert!(matches!(
        decode_err(&patched(&stats, at::STAGES + 2, &[0xfe]), Sender::Server),
        WireError::InvalidUtf8 { field: "stage", .. }
    ));
}

#[test]
fn wire_rejects_text_over_its_cap() {
    let text = |len: usize| {
        let mut out = (len as u16).to_le_bytes().to_vec();
        out.extend(std::iter::repeat_n(b'a', len));
        out
    };
    let mut hello = vec![2, 0];
    hello.extend(text(MAX_NAME_BYTES + 1));
    assert_eq!(
        decode_err(&frame(0x01, &hello), Sender::Server),
        WireError::TextTooLong {
            message: "Hello",
            field: "server",
            len: MAX_NAME_BYTES + 1,
            max: MAX_NAME_BYTES
        }
    );
    assert!(matches!(
        decode_err(&frame(0x06, &text(MAX_REASON_BYTES + 1)), Sender::Server),
        WireError::TextTooLong {
            field: "reason",
            ..
        }
    ));
    // At the cap is fine.
    assert!(decode_one(&frame(0x06, &text(MAX_REASON_BYTES)), Sender::Server).is_ok());
    let mut stats = encoded(&Message::Stats(sample_stats()));
    stats.truncate(at::STAGES);
    stats.extend(text(MAX_NAME_BYTES + 1));
    stats.extend([0; 8]);
    let stats = resized(&stats, stats.len());
    assert!(matches!(
        decode_err(&stats, Sender::Server),
        WireError::TextTooLong { field: "stage", .. }
    ));
}

#[test]
fn wire_rejects_too_many_ids() {
    let too_many = MAX_SUBSCRIBE_IDS as u32 + 1;
    let mut subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    subscribe[at::ID_COUNT..at::ID_COUNT + 4].copy_from_slice(&too_many.to_le_bytes());
    // The ids are there, so the count is what is refused.
    subscribe.extend(vec![0; 8 * too_many as usize]);
    let subscribe = resized(&subscribe, subscribe.len());
    let err = decode_err(&subscribe, Sender::Client);
    assert_eq!(
        err,
        WireError::TooManyIds {
            message: "Subscribe",
            count: u64::from(too_many),
            max: MAX_SUBSCRIBE_IDS
        }
    );
    assert!(
        err.to_string().contains("more than the cap of 1024"),
        "{err}"
    );

    let session = encoded(&Message::Session(Session::default()));
    let session = patched(
        &session,
        at::ID_COUNT + at::SESSION_OPTIONS,
        &u32::MAX.to_le_bytes(),
    );
    assert!(matches!(
        decode_err(&session, Sender::Server),
        WireError::TooManyIds {
            message: "Session",
            ..
        }
    ));
}

#[test]
fn wire_rejects_undefined_flags() {
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    assert_eq!(
        decode_err(&patched(&shape, at::SHAPE_FLAGS, &[0x08]), Sender::Server),
        WireError::InvalidFlags {
            message: "Shape",
            field: "flags",
            value: 0x08,
            defined: 0x07
        }
    );
    // The three defined bits together are fine.
    assert!(decode_one(&patched(&shape, at::SHAPE_FLAGS, &[0x07]), Sender::Server).is_ok());

    let subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    let err = decode_err(
        &patched(&subscribe, at::SUBSCRIBE_FLAGS, &[0x05]),
        Sender::Client,
    );
    assert_eq!(
        err,
        WireError::InvalidFlags {
            message: "Subscribe",
            field: "flags",
            value: 0x05,
            defined: 0x03
        }
    );
    assert!(err.to_string().contains("only the bits 0x03"), "{err}");
    // resend and extrapolate together are fine.
    assert!(decode_one(
        &patched(&subscribe, at::SUBSCRIBE_FLAGS, &[0x03]),
        Sender::Client
    )
    .is_ok());
    assert!(matches!(
        decode_err(&patched(&subscribe, at::KINDS, &[0x0b]), Sender::Client),
        WireError::InvalidFlags { field: "kinds", .. }
    ));
    // Bodies alone ask for no object: refused like no kind at all.
    assert_eq!(
        decode_err(&patched(&subscribe, at::KINDS, &[0x04]), Sender::Client),
        WireError::NoKinds {
            message: "Subscribe"
        }
    );
    assert!(decode_one(&patched(&subscribe, at::KINDS, &[0x05]), Sender::Client).is_ok());
    assert_eq!(
        decode_err(&patched(&subscribe, at::KINDS, &[0x00]), Sender::Client),
        WireError::NoKinds {
            message: "Subscribe"
        }
    );
    let session = encoded(&Message::Session(Session::default()));
    assert_eq!(
        decode_err(
            &patched(&session, at::KINDS + at::SESSION_OPTIONS, &[0x00]),
            Sender::Server
        ),
        WireError::NoKinds { message: "Session" }
    );
}

#[test]
fn wire_rejects_undefined_encoding() {
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    assert_eq!(
        decode_err(&patched(&shape, at::ENCODING, &[2]), Sender::Server),
        WireError::InvalidEnum {
            message: "Shape",
            field: "encoding",
            value: 2,
            defined: "0 full, 1 compact",
        }
    );
    let subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    assert_eq!(
        decode_err(
            &patched(&subscribe, at::SUBSCRIBE_ENCODING, &[0xff]),
            Sender::Client
        ),
        WireError::InvalidEnum {
            message: "Subscribe",
            field: "encoding",
            value: 0xff,
            defined: "0 full, 1 compact",
        }
    );
}

#[test]
fn wire_rejects_non_finite_vertices() {
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    for (value, vertex, axis) in [
        (f32::NAN, 0, 0),
        (f32::INFINITY, 1, 2),
        (f32::NEG_INFINITY, 2, 1),
    ] {
        let offset = at::GEOMETRY + 12 * vertex + 4 * axis;
        let err = decode_err(
            &patched(&shape, offset, &value.to_le_bytes()),
            Sender::Server,
        );
        assert!(
            matches!(err, WireError::NonFiniteVertex { vertex: v, .. } if v == vertex),
            "{err:?}"
        );
        assert!(err.to_string().contains("non-finite"), "{err}");
    }
    // A compact box so wide that its vertices overflow f32 when read.
    let compact = encoded(&Message::Shape(example_shape(Encoding::Compact)));
    let wide = patched(&compact, at::GEOMETRY, &(-3e38f32).to_le_bytes());
    let wide = patched(&wide, at::BOX_MAX, &3e38f32.to_le_bytes());
    assert!(matches!(
        decode_err(&wide, Sender::Server),
        WireError::NonFiniteVertex { vertex: 0, .. }
    ));
}

#[test]
fn wire_rejects_non_finite_pose_velocity_and_box() {
    let pose = encoded(&Message::Pose(example_pose()));
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    for (field, offset) in [
        ("rotation", at::ROTATION + 12),
        ("translation", at::TRANSLATION + 4),
        ("linear_velocity", at::LINEAR_VELOCITY),
        ("angular_velocity", at::ANGULAR_VELOCITY + 8),
    ] {
        for (bytes, message) in [(&pose, "Pose"), (&shape, "Shape")] {
            let err = decode_err(
                &patched(bytes, offset, &f32::INFINITY.to_le_bytes()),
                Sender::Server,
            );
            assert_eq!(
                err,
                WireError::NonFinite {
                    message,
                    field,
                    value: f32::INFINITY
                }
            );
        }
    }
    let compact = encoded(&Message::Shape(example_shape(Encoding::Compact)));
    for (field, offset) in [("box_min", at::GEOMETRY + 4), ("box_max", at::BOX_MAX + 8)] {
        let err = decode_err(
            &patched(&compact, offset, &f32::NAN.to_le_bytes()),
            Sender::Server,
        );
        assert!(
            matches!(err, WireError::NonFinite { field: f, .. } if f == field),
            "{err:?}"
        );
    }
}

#[test]
fn wire_rejects_a_rotation_that_is_not_a_unit_quaternion() {
    let pose = encoded(&Message::Pose(example_pose()));
    let w = at::ROTATION + 12;
    for w_value in [1.002f32, 0.998, 0.0, -3.0] {
        let err = decode_err(&patched(&pose, w, &w_value.to_le_bytes()), Sender::Server);
        assert_eq!(
            err,
            WireError::NotUnitQuaternion {
                object_id: 7,
                norm: w_value.abs()
            }
        );
    }
    // Within 1e-3 of a unit norm is accepted (the sender's rounding), and so is -q.
    for w_value in [1.000_9f32, 0.999_1, -1.0] {
        assert!(decode_one(&patched(&pose, w, &w_value.to_le_bytes()), Sender::Server).is_ok());
    }
    let shape = encoded(&Message::Shape(example_shape(Encoding::Compact)));
    assert!(matches!(
        decode_err(&patched(&shape, w, &2.0f32.to_le_bytes()), Sender::Server),
        WireError::NotUnitQuaternion { .. }
    ));
    let err = decode_err(&patched(&pose, w, &0.5f32.to_le_bytes()), Sender::Server);
    assert!(err.to_string().contains("unit quaternion"), "{err}");
}

#[test]
fn wire_rejects_last_seen_before_pose_time() {
    let pose = encoded(&Message::Pose(example_pose()));
    let early = patched(&pose, at::LAST_SEEN, &(SECOND_NS - 1).to_le_bytes());
    let err = decode_err(&early, Sender::Server);
    assert_eq!(
        err,
        WireError::TimesOutOfOrder {
            object_id: 7,
            pose_time_ns: SECOND_NS,
            last_seen_ns: SECOND_NS - 1
        }
    );
    assert!(err.to_string().contains("before its pose time"), "{err}");
    // Equal is fine: seen only in the frame the pose came from.
    let equal = patched(&pose, at::LAST_SEEN, &SECOND_NS.to_le_bytes());
    assert!(decode_one(&equal, Sender::Server).is_ok());
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    let late_pose = patched(&shape, at::POSE_TIME, &u64::MAX.to_le_bytes());
    assert!(matches!(
        decode_err(&late_pose, Sender::Server),
        WireError::TimesOutOfOrder { .. }
    ));
}

#[test]
fn wire_rejects_out_of_range_triangle_index() {
    let full = encoded(&Message::Shape(example_shape(Encoding::Full)));
    let last_corner = at::GEOMETRY + 3 * 12 + 8;
    let err = decode_err(&patched(&full, last_corner, &[3]), Sender::Server);
    assert_eq!(
        err,
        WireError::IndexOutOfRange {
            triangle: 0,
            index: 3,
            vertex_count: 3
        }
    );
    assert!(err.to_string().contains("only 3 vertices"), "{err}");

    let compact = encoded(&Message::Shape(example_shape(Encoding::Compact)));
    let first_corner = at::COMPACT_VERTICES + 3 * 6;
    assert_eq!(
        decode_err(
            &patched(&compact, first_corner, &[0xff, 0xff]),
            Sender::Server
        ),
        WireError::IndexOutOfRange {
            triangle: 0,
            index: 0xffff,
            vertex_count: 3
        }
    );
}

#[test]
fn wire_rejects_a_compact_box_whose_maximum_is_below_its_minimum() {
    let compact = encoded(&Message::Shape(example_shape(Encoding::Compact)));
    // box_max.y from 1 to -1, below box_min.y = 0.
    let err = decode_err(
        &patched(&compact, at::BOX_MAX + 4, &(-1.0f32).to_le_bytes()),
        Sender::Server,
    );
    assert_eq!(
        err,
        WireError::BadBox {
            axis: "y",
            min: 0.0,
            max: -1.0
        }
    );
    assert!(err.to_string().contains("below its minimum"), "{err}");
    // A flat box (max = min) is fine.
    let flat = patched(&compact, at::BOX_MAX + 4, &0.0f32.to_le_bytes());
    assert!(decode_one(&flat, Sender::Server).is_ok());
}

#[test]
fn wire_rejects_invalid_residual_rate_and_latency() {
    let shape = encoded(&Message::Shape(example_shape(Encoding::Full)));
    let subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    let stats = encoded(&Message::Stats(sample_stats()));
    for value in [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        -f32::MIN_POSITIVE,
    ] {
        let bytes = value.to_le_bytes();
        for (frame, offset, from, field) in [
            (&shape, at::RESIDUAL, Sender::Server, "max_residual_m"),
            (
                &stats,
                at::FRAME_TO_PUBLISH_P99,
                Sender::Server,
                "frame_to_publish_p99_ms",
            ),
            (&stats, at::STAGES + 6 + 4, Sender::Server, "p99_ms"),
        ] {
            let err = decode_err(&patched(frame, offset, &bytes), from);
            assert!(
                matches!(err, WireError::InvalidNumber { field: f, value: v }
                    if f == field && v.to_bits() == value.to_bits()),
                "{field} = {value}: {err:?}"
            );
        }
    }
    // Zero is fine: no rate cap, an exact mesh, a stage with no samples.
    assert!(decode_one(&patched(&subscribe, at::RATE, &[0; 4]), Sender::Client).is_ok());
    assert!(decode_one(&patched(&shape, at::RESIDUAL, &[0; 4]), Sender::Server).is_ok());
}

/// A property over many Subscribe payloads, every field random (xorshift, fixed seed): each
/// decodes to options whose rate cap, as the interval a server makes of it, fits `Duration`
/// and `Instant`, or is refused with an error; and what decodes encodes to the same bytes.
#[test]
fn every_subscribe_that_decodes_has_a_rate_interval_the_clocks_hold() {
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    let (mut decoded, mut refused) = (0, 0);
    for round in 0..200_000u32 {
        let bits = next();
        // Half of the rates are any f32 bits, half near the edges of the range.
        let rate = if round % 2 == 0 {
            f32::from_bits(bits as u32)
        } else {
            let edges = [0.0, MIN_RATE_HZ, MAX_RATE_HZ, 1e-45, f32::MIN_POSITIVE];
            let edge = edges[(bits >> 40) as usize % edges.len()];
            f32::from_bits(
                edge.to_bits()
                    .wrapping_add((bits >> 32) as u32 % 5)
                    .wrapping_sub(2),
            )
        };
        let mut payload = vec![(bits >> 8) as u8 & 1, (bits >> 16) as u8 & 3];
        payload.extend_from_slice(&rate.to_le_bytes());
        payload.push((bits >> 24) as u8 & 7);
        payload.extend_from_slice(&0u32.to_le_bytes());
        let mut frame = ((payload.len() + 1) as u32).to_le_bytes().to_vec();
        frame.push(0x81);
        frame.extend_from_slice(&payload);
        let mut decoder = FrameDecoder::new(Sender::Client);
        decoder.push(&frame);
        match decoder.next_message() {
            Ok(Some(Message::Subscribe(options))) => {
                decoded += 1;
                if options.max_rate_hz != 0.0 {
                    let interval =
                        std::time::Duration::try_from_secs_f32(1.0 / options.max_rate_hz)
                            .expect("the interval fits a Duration");
                    assert!(std::time::Instant::now().checked_add(interval).is_some());
                }
                let mut again = Vec::new();
                encode(&Message::Subscribe(options), &mut again).expect("encodes again");
                assert_eq!(again, frame);
            }
            Ok(other) => panic!("{other:?}"),
            Err(_) => refused += 1,
        }
    }
    assert!(
        decoded > 1_000 && refused > 1_000,
        "{decoded} decoded, {refused} refused"
    );
}

/// A rate the server would turn into an interval no clock can hold (1e-45 Hz once aborted the
/// daemon in `Duration::from_secs_f32`), or one that is no cap at all, is refused on both sides.
#[test]
fn wire_rejects_rates_outside_the_documented_range() {
    let subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    for value in [
        f32::NAN,
        f32::INFINITY,
        f32::NEG_INFINITY,
        -1.0,
        -f32::MIN_POSITIVE,
        1e-45,
        f32::MIN_POSITIVE,
        1.1e-19,
        MIN_RATE_HZ * 0.99,
        MAX_RATE_HZ * 1.01,
        f32::MAX,
    ] {
        let frame = patched(&subscribe, at::RATE, &value.to_le_bytes());
        let err = decode_err(&frame, Sender::Client);
        assert!(
            matches!(err, WireError::InvalidRate { value: v } if v.to_bits() == value.to_bits()),
            "{value}: {err:?}"
        );
        assert!(err.to_string().contains("0 (no cap)"), "{err}");
        let mut options = sample_subscribe();
        options.max_rate_hz = value;
        let mut out = Vec::new();
        assert!(
            encode(&Message::Subscribe(options), &mut out).is_err(),
            "{value} was encoded"
        );
    }
    for value in [0.0, MIN_RATE_HZ, 1.0, 30.0, MAX_RATE_HZ] {
        let frame = patched(&subscribe, at::RATE, &value.to_le_bytes());
        assert!(decode_one(&frame, Sender::Client).is_ok(), "{value}");
    }
}

#[test]
fn wire_rejects_huge_counts_without_allocating() {
    for encoding in [Encoding::Full, Encoding::Compact] {
        let shape = encoded(&Message::Shape(example_shape(encoding)));
        let shape = patched(&shape, at::VERTEX_COUNT, &u32::MAX.to_le_bytes());
        let shape = patched(&shape, at::TRIANGLE_COUNT, &u32::MAX.to_le_bytes());
        assert!(matches!(
            decode_err(&shape, Sender::Server),
            WireError::Truncated {
                field: "vertices and triangles",
                ..
            }
        ));
    }
    let stats = encoded(&Message::Stats(sample_stats()));
    assert!(matches!(
        decode_err(
            &patched(&stats, at::STAGE_COUNT, &u32::MAX.to_le_bytes()),
            Sender::Server
        ),
        WireError::Truncated {
            field: "stages",
            ..
        }
    ));
    // Within the id cap but past the frame's end.
    let subscribe = encoded(&Message::Subscribe(sample_subscribe()));
    let subscribe = patched(&subscribe, at::ID_COUNT, &1024u32.to_le_bytes());
    assert!(matches!(
        decode_err(&subscribe, Sender::Client),
        WireError::Truncated {
            field: "object_ids",
            ..
        }
    ));
}

// ---- the encoder refuses the same ----------------------------------------------------------------

#[test]
fn encode_refuses_what_decode_would_refuse_and_leaves_out_untouched() {
    let shape = |f: &dyn Fn(&mut Shape)| {
        let mut shape = example_shape(Encoding::Full);
        f(&mut shape);
        Message::Shape(shape)
    };
    let pose = |f: &dyn Fn(&mut Pose)| {
        let mut pose = example_pose();
        f(&mut pose);
        Message::Pose(pose)
    };
    let subscribe = |f: &dyn Fn(&mut Subscribe)| {
        let mut subscribe = sample_subscribe();
        f(&mut subscribe);
        Message::Subscribe(subscribe)
    };
    let cases = [
        (
            shape(&|s| s.mesh.triangles[0][2] = 3),
            WireError::IndexOutOfRange {
                triangle: 0,
                index: 3,
                vertex_count: 3,
            },
        ),
        (
            shape(&|s| {
                s.encoding = Encoding::Compact;
                s.mesh.triangles[0][0] = 7;
            }),
            WireError::IndexOutOfRange {
                triangle: 0,
                index: 7,
                vertex_count: 3,
            },
        ),
        (
            shape(&|s| s.mesh.vertices[2].y = f32::INFINITY),
            WireError::NonFiniteVertex {
                vertex: 2,
                value: f32::INFINITY,
            },
        ),
        (
            shape(&|s| s.flags = 0x84),
            WireError::InvalidFlags {
                message: "Shape",
                field: "flags",
                value: 0x84,
                defined: 0x07,
            },
        ),
        (
            shape(&|s| s.report.max_residual_m = -0.5),
            WireError::InvalidNumber {
                field: "max_residual_m",
                value: -0.5,
            },
        ),
        (
            // Finite, but not once the compact bound (7.6e31 m for this box) is added.
            shape(&|s| {
                s.encoding = Encoding::Compact;
                s.mesh.vertices[1].x = 1e37;
                s.report.max_residual_m = f32::MAX;
            }),
            WireError::InvalidNumber {
                field: "max_residual_m",
                value: f32::INFINITY,
            },
        ),
        (
            shape(&|s| {
                s.encoding = Encoding::Compact;
                s.mesh.vertices[0].x = -3e38;
                s.mesh.vertices[1].x = 3e38;
            }),
            WireError::CompactBoxTooLarge {
                axis: "x",
                min: -3e38,
                max: 3e38,
            },
        ),
        (
            shape(&|s| s.pose.rotation = Quat::from_xyzw(0.0, 0.0, 0.0, 0.5)),
            WireError::NotUnitQuaternion {
                object_id: 7,
                norm: 0.5,
            },
        ),
        (
            pose(&|p| p.rotation = Quat::from_xyzw(f32::NAN, 0.0, 0.0, 1.0)),
            WireError::NonFinite {
                message: "Pose",
                field: "rotation",
                value: f32::NAN,
            },
        ),
        (
            pose(&|p| p.linear_velocity.z = f32::NEG_INFINITY),
            WireError::NonFinite {
                message: "Pose",
                field: "linear_velocity",
                value: f32::NEG_INFINITY,
            },
        ),
        (
            pose(&|p| p.last_seen_ns = 0),
            WireError::TimesOutOfOrder {
                object_id: 7,
                pose_time_ns: SECOND_NS,
                last_seen_ns: 0,
            },
        ),
        (
            subscribe(&|s| s.max_rate_hz = -1.0),
            WireError::InvalidRate { value: -1.0 },
        ),
        (
            subscribe(&|s| s.kinds = Kinds(0)),
            WireError::NoKinds {
                message: "Subscribe",
            },
        ),
        (
            subscribe(&|s| s.kinds = Kinds(0x0b)),
            WireError::InvalidFlags {
                message: "Subscribe",
                field: "kinds",
                value: 0x0b,
                defined: 0x07,
            },
        ),
        (
            subscribe(&|s| s.object_ids = vec![1; MAX_SUBSCRIBE_IDS + 1]),
            WireError::TooManyIds {
                message: "Subscribe",
                count: MAX_SUBSCRIBE_IDS as u64 + 1,
                max: MAX_SUBSCRIBE_IDS,
            },
        ),
        (
            Message::Session(Session {
                options: Subscribe {
                    object_ids: vec![1; MAX_SUBSCRIBE_IDS + 1],
                    ..Subscribe::default()
                },
                ..Session::default()
            }),
            WireError::TooManyIds {
                message: "Session",
                count: MAX_SUBSCRIBE_IDS as u64 + 1,
                max: MAX_SUBSCRIBE_IDS,
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
                stage_latencies: vec![StageLatency {
                    stage: "s".repeat(MAX_NAME_BYTES + 1),
                    p50_ms: 0.0,
                    p99_ms: 0.0,
                }],
                ..Stats::default()
            }),
            WireError::TextTooLong {
                message: "Stats",
                field: "stage",
                len: MAX_NAME_BYTES + 1,
                max: MAX_NAME_BYTES,
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
        let result = encode(&message, &mut out);
        // NaN != NaN: compare the errors by their text.
        assert_eq!(
            result.map_err(|e| e.to_string()),
            Err(expected.to_string()),
            "{message:?}"
        );
        assert_eq!(out, [0xaa, 0xbb]);
    }
}

// ---- mangling ----------------------------------------------------------------------------------

/// Random corruptions of valid frames: whatever comes out, the decoder does not panic, and every
/// message it does accept re-encodes: to exactly the bytes it was read from, or (a compact
/// shape, whose re-encoding adds the quantisation bound again) in the full encoding to the same
/// message.
#[test]
fn mangled_frames_never_panic() {
    let mut rng = Lcg(0x7ac3_e5ed);
    let mut messages = server_messages();
    messages.extend(compact_shapes().into_iter().map(Message::Shape));
    messages.extend(client_messages());
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
                        let frame_len = 4 + u32::from_le_bytes(
                            bytes[offset..offset + 4].try_into().expect("a prefix"),
                        ) as usize;
                        match message {
                            Message::Shape(ref shape) if shape.encoding == Encoding::Compact => {
                                let full = Message::Shape(Shape {
                                    encoding: Encoding::Full,
                                    ..shape.clone()
                                });
                                assert_eq!(decode_one(&encoded(&full), from), Ok(full));
                            }
                            _ => assert_eq!(encoded(&message), bytes[offset..offset + frame_len]),
                        }
                        offset += frame_len;
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
        // Plant a NaN, an infinity or a negative over four bytes.
        _ => {
            let value = [f32::NAN, f32::INFINITY, -1.0][rng.below(3)];
            let end = (at + 4).min(bytes.len());
            bytes[at..end].copy_from_slice(&value.to_le_bytes()[..end - at]);
        }
    }
}

/// A pose extrapolated by its velocities: the translation along the linear velocity, the
/// rotation about the angular velocity's axis; a newer pose on that path needs no sending, one
/// off it by more than the tolerance does, and so does one a second newer.
#[test]
fn a_pose_extrapolates_by_its_velocity_and_says_when_a_newer_one_must_go() {
    let pose = Pose {
        object_id: 3,
        shape_version: 2,
        pose_time_ns: 1_000_000_000,
        pose_time_realtime_ns: 0,
        last_seen_ns: 1_000_000_000,
        rotation: Quat::IDENTITY,
        translation: Vec3::new(1.0, 0.0, 0.0),
        linear_velocity: Vec3::new(0.1, 0.0, 0.0),
        angular_velocity: Vec3::new(0.0, 0.0, 0.5),
    };
    let (rotation, translation) = pose.extrapolated_parts(1_500_000_000);
    assert!(translation.distance(Vec3::new(1.05, 0.0, 0.0)) < 1e-6);
    assert!((rotation.angle_between(Quat::from_rotation_z(0.25))).abs() < 1e-5);
    let on_path = |ms: u64, off_m: f32| Pose {
        pose_time_ns: 1_000_000_000 + ms * 1_000_000,
        last_seen_ns: 1_000_000_000 + ms * 1_000_000,
        rotation: pose.extrapolated_parts(1_000_000_000 + ms * 1_000_000).0,
        translation: pose.extrapolated_parts(1_000_000_000 + ms * 1_000_000).1
            + Vec3::new(0.0, off_m, 0.0),
        ..pose
    };
    assert!(!pose.extrapolation_misses(&on_path(500, 0.0)));
    assert!(!pose.extrapolation_misses(&on_path(500, 0.0019)));
    assert!(pose.extrapolation_misses(&on_path(500, 0.0021)));
    assert!(
        pose.extrapolation_misses(&on_path(1000, 0.0)),
        "a second old"
    );
    let turned = Pose {
        rotation: Quat::from_rotation_x(0.02) * on_path(100, 0.0).rotation,
        ..on_path(100, 0.0)
    };
    assert!(pose.extrapolation_misses(&turned), "turned 1.1° off");
    let reshaped = Pose {
        shape_version: 3,
        ..on_path(100, 0.0)
    };
    assert!(pose.extrapolation_misses(&reshaped));
}
