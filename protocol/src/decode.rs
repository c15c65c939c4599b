//! Byte stream → messages: frame splitting, then one parser per message kind. The checks on
//! what a frame holds are the encoder's (`encode.rs`), so both sides refuse the same things:
//! the list in `docs/protocol.md`, "A receiver refuses…".

use glam::{Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::encode::{
    check_body_solid, check_finite, check_flags, check_hull_count, check_hull_size, check_id_count,
    check_kinds, check_number, check_pose, check_primitive, check_rate, check_triangle,
    check_vertex, compact_index_bytes, CompactBox, COMPACT_VERTEX_BYTES, HULL_TRIANGLE_BYTES,
    ID_BYTES, PREFIX_BYTES, SHAPE_FLAGS, STAGE_FIXED_BYTES, SUBSCRIBE_EXTRAPOLATE,
    SUBSCRIBE_RESEND, TRIANGLE_BYTES, VERTEX_BYTES,
};
use crate::error::WireError;
use crate::message::{
    kind, Body, BodyPrimitive, BodySolid, Encoding, Hull, Message, Pose, PrimitiveShape, Sender,
    Session, Shape, SimplifyStats, StageLatency, Stats, Subscribe, MAX_FRAME_BYTES, MAX_NAME_BYTES,
    MAX_REASON_BYTES,
};

/// Splits a byte stream into frames and decodes them, for one direction of a connection.
///
/// Feed it whatever the socket returned with [`push`](Self::push), then call
/// [`next_message`](Self::next_message) until it returns `Ok(None)`. It buffers at most one
/// frame beyond what has been taken out, and a length prefix over [`MAX_FRAME_BYTES`] is refused
/// as soon as its four bytes arrive, before any of the body is buffered.
///
/// After an error, drop the connection. (A frame with bad content is discarded, so the next call
/// goes on with the following frame; a bad length prefix stays in place and gives the same error
/// again, since there is no way to find the next frame.)
#[derive(Debug)]
pub struct FrameDecoder {
    from: Sender,
    buffer: Vec<u8>,
    /// Bytes of `buffer` already decoded; dropped on the next push.
    consumed: usize,
}

impl FrameDecoder {
    /// A decoder for what `from` sends: a client uses `FrameDecoder::new(Sender::Server)`, the
    /// daemon `FrameDecoder::new(Sender::Client)`. A message kind of the other direction is a
    /// [`WireError::WrongSender`].
    pub fn new(from: Sender) -> Self {
        Self {
            from,
            buffer: Vec::new(),
            consumed: 0,
        }
    }

    /// Appends bytes received from the stream.
    pub fn push(&mut self, bytes: &[u8]) {
        if self.consumed > 0 {
            self.buffer.drain(..self.consumed);
            self.consumed = 0;
        }
        self.buffer.extend_from_slice(bytes);
    }

    /// Bytes pushed but not yet returned as messages (a partial frame, or several frames).
    pub fn buffered_len(&self) -> usize {
        self.buffer.len() - self.consumed
    }

    /// The next whole message, `Ok(None)` until one is fully buffered.
    ///
    /// A [`Shape`] in the compact encoding comes back with the vertices the receiver reads
    /// (dequantised), its `max_residual_m` as sent (the quantisation bound included) and
    /// `encoding` [`Encoding::Compact`].
    pub fn next_message(&mut self) -> Result<Option<Message>, WireError> {
        let pending = &self.buffer[self.consumed..];
        let Some((prefix, rest)) = pending.split_first_chunk::<PREFIX_BYTES>() else {
            return Ok(None);
        };
        let length = u32::from_le_bytes(*prefix) as usize;
        if length > MAX_FRAME_BYTES {
            return Err(WireError::FrameTooLarge {
                length: length as u64,
            });
        }
        let Some(frame) = rest.get(..length) else {
            return Ok(None);
        };
        let decoded = decode_frame(frame, self.from);
        self.consumed += PREFIX_BYTES + length;
        decoded.map(Some)
    }
}

/// One frame without its length prefix: the kind byte and the payload.
fn decode_frame(frame: &[u8], from: Sender) -> Result<Message, WireError> {
    let Some((&kind, payload)) = frame.split_first() else {
        return Err(WireError::EmptyFrame);
    };
    // The retired kinds (0x02, 0x05) have no name, so they are unknown like any other.
    let name = kind::name(kind).ok_or(WireError::UnknownKind { kind })?;
    let sender = if kind & 0x80 == 0 {
        Sender::Server
    } else {
        Sender::Client
    };
    if sender != from {
        return Err(WireError::WrongSender {
            message: name,
            sender,
            expected: from,
        });
    }
    let mut r = Reader {
        bytes: payload,
        message: name,
    };
    let message = match kind {
        kind::HELLO => Message::Hello {
            protocol_version: r.u16("protocol_version")?,
            server: r.text("server", MAX_NAME_BYTES)?,
        },
        kind::SESSION => Message::Session(Session {
            monotonic_ns: r.u64("monotonic_ns")?,
            realtime_ns: r.u64("realtime_ns")?,
            options: read_options(&mut r)?,
        }),
        kind::SHAPE => Message::Shape(read_shape(&mut r)?),
        kind::POSE => Message::Pose(read_pose(&mut r)?),
        kind::BODY => Message::Body(read_body(&mut r)?),
        kind::REMOVE => Message::Remove {
            object_id: r.u64("object_id")?,
        },
        kind::SNAPSHOT_DONE => Message::SnapshotDone,
        kind::STATS => Message::Stats(read_stats(&mut r)?),
        kind::GOODBYE => Message::Goodbye {
            reason: r.text("reason", MAX_REASON_BYTES)?,
        },
        kind::SUBSCRIBE => Message::Subscribe(read_options(&mut r)?),
        kind::SUBSCRIBE_V1 => Message::SubscribeV1,
        _ => return Err(WireError::UnknownKind { kind }),
    };
    r.finish()?;
    Ok(message)
}

/// A Subscribe payload, or the options at the end of a Session.
fn read_options(r: &mut Reader<'_>) -> Result<Subscribe, WireError> {
    let encoding = r.encoding()?;
    let flags = r.u8("flags")?;
    check_flags(
        r.message,
        "flags",
        flags,
        SUBSCRIBE_RESEND | SUBSCRIBE_EXTRAPOLATE,
    )?;
    let max_rate_hz = r.f32("max_rate_hz")?;
    check_rate(max_rate_hz)?;
    let kinds = check_kinds(r.message, r.u8("kinds")?)?;
    let id_count = r.u32("id_count")?;
    check_id_count(r.message, u64::from(id_count))?;
    r.ensure("object_ids", u64::from(id_count) * ID_BYTES as u64)?;
    let object_ids = (0..id_count)
        .map(|_| r.u64("object_ids"))
        .collect::<Result<_, _>>()?;
    Ok(Subscribe {
        encoding,
        resend: flags & SUBSCRIBE_RESEND != 0,
        extrapolate: flags & SUBSCRIBE_EXTRAPOLATE != 0,
        max_rate_hz,
        kinds,
        object_ids,
    })
}

/// A Pose payload, or the start of a Shape's.
fn read_pose(r: &mut Reader<'_>) -> Result<Pose, WireError> {
    let pose = Pose {
        object_id: r.u64("object_id")?,
        shape_version: r.u64("shape_version")?,
        pose_time_ns: r.u64("pose_time_ns")?,
        pose_time_realtime_ns: r.u64("pose_time_realtime_ns")?,
        last_seen_ns: r.u64("last_seen_ns")?,
        rotation: Quat::from_array([
            r.f32("rotation")?,
            r.f32("rotation")?,
            r.f32("rotation")?,
            r.f32("rotation")?,
        ]),
        translation: r.vec3("translation")?,
        linear_velocity: r.vec3("linear_velocity")?,
        angular_velocity: r.vec3("angular_velocity")?,
    };
    // Finite, unit rotation, last seen not before the pose time.
    check_pose(&pose, r.message)?;
    Ok(pose)
}

fn read_shape(r: &mut Reader<'_>) -> Result<Shape, WireError> {
    let pose = read_pose(r)?;
    let shape_time_ns = r.u64("shape_time_ns")?;
    let shape_time_realtime_ns = r.u64("shape_time_realtime_ns")?;
    let flags = r.u8("flags")?;
    check_flags(r.message, "flags", flags, SHAPE_FLAGS)?;
    let faces_in = r.u32("faces_in")?;
    let faces_out = r.u32("faces_out")?;
    let max_residual_m = r.f32("max_residual_m")?;
    check_number("max_residual_m", max_residual_m)?;
    let (encoding, mesh) = read_geometry(r, |_, _| Ok(()))?;
    Ok(Shape {
        pose,
        shape_time_ns,
        shape_time_realtime_ns,
        flags,
        mesh,
        report: SimplifyStats {
            faces_in,
            faces_out,
            max_residual_m,
        },
        encoding,
    })
}

/// The encoding byte, the two counts and the geometry (Shape's layout, also a Body's proxy's);
/// `check_counts` sees the counts before anything is read by them.
fn read_geometry(
    r: &mut Reader<'_>,
    check_counts: impl FnOnce(usize, usize) -> Result<(), WireError>,
) -> Result<(Encoding, TriMesh), WireError> {
    let encoding = r.encoding()?;
    let vertex_count = r.u32("vertex_count")? as usize;
    let triangle_count = r.u32("triangle_count")? as usize;
    check_counts(vertex_count, triangle_count)?;
    let mesh = match encoding {
        Encoding::Full => read_full_geometry(r, vertex_count, triangle_count)?,
        Encoding::Compact => read_compact_geometry(r, vertex_count, triangle_count)?,
    };
    Ok((encoding, mesh))
}

fn read_body(r: &mut Reader<'_>) -> Result<Body, WireError> {
    let object_id = r.u64("object_id")?;
    let shape_version = r.u64("shape_version")?;
    let solid_byte = r.u8("solid")?;
    let solid = BodySolid::from_byte(solid_byte).ok_or(WireError::InvalidEnum {
        message: r.message,
        field: "solid",
        value: solid_byte,
        defined: "0 shape, 1 primitive, 2 completed solid, 3 shadow volume, 4 extrusion",
    })?;
    let margin_m = r.f32("margin_m")?;
    check_number("margin_m", margin_m)?;
    let volume_m3 = r.f32("volume_m3")?;
    let centre_of_mass = r.vec3("centre_of_mass")?;
    check_finite(r.message, "centre_of_mass", &centre_of_mass.to_array())?;
    let mut entries = [0.0f32; 6];
    for entry in &mut entries {
        *entry = r.f32("inertia")?;
    }
    check_finite(r.message, "inertia", &entries)?;
    let [xx, yy, zz, xy, xz, yz] = entries;
    let inertia = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]];
    let primitive = read_primitive(r, object_id)?;
    let (encoding, mesh) = read_geometry(r, |vertices, triangles| {
        check_body_solid(
            object_id,
            solid,
            volume_m3,
            primitive.is_some(),
            vertices,
            triangles,
        )
    })?;
    let hull_count = usize::from(r.u8("hull_count")?);
    check_hull_count(object_id, hull_count)?;
    let mut hulls = Vec::with_capacity(hull_count);
    for hull in 0..hull_count {
        let vertex_count = usize::from(r.u8("hull vertex_count")?);
        let triangle_count = usize::from(r.u16("hull triangle_count")?);
        check_hull_size(object_id, hull, vertex_count, triangle_count)?;
        let mut vertices = Vec::with_capacity(vertex_count);
        for vertex in 0..vertex_count {
            let p = r.vec3("hull vertices")?;
            check_vertex(vertex, p)?;
            vertices.push(p);
        }
        r.ensure(
            "hull triangles",
            (triangle_count * HULL_TRIANGLE_BYTES) as u64,
        )?;
        let mut triangles = Vec::with_capacity(triangle_count);
        for triangle in 0..triangle_count {
            let corners: [u8; 3] = r.array("hull triangles")?;
            check_triangle(triangle, corners.map(u32::from), vertex_count)?;
            triangles.push(corners);
        }
        hulls.push(Hull {
            vertices,
            triangles,
        });
    }
    Ok(Body {
        object_id,
        shape_version,
        solid,
        margin_m,
        volume_m3,
        centre_of_mass,
        inertia,
        primitive,
        mesh,
        encoding,
        hulls,
    })
}

/// A Body's primitive block: `None` for kind 0 (whose other bytes must be 0).
fn read_primitive(r: &mut Reader<'_>, object_id: u64) -> Result<Option<BodyPrimitive>, WireError> {
    let kind = r.u8("primitive kind")?;
    let sizes = [
        r.f32("primitive sizes")?,
        r.f32("primitive sizes")?,
        r.f32("primitive sizes")?,
    ];
    let rotation: [f32; 4] = [
        r.f32("primitive rotation")?,
        r.f32("primitive rotation")?,
        r.f32("primitive rotation")?,
        r.f32("primitive rotation")?,
    ];
    let centre = r.vec3("primitive centre")?;
    let residual_m = r.f32("primitive residual_m")?;
    if kind == 0 {
        let unused = sizes
            .iter()
            .chain(&rotation)
            .chain(&centre.to_array())
            .chain(std::iter::once(&residual_m))
            .all(|v| v.to_bits() == 0);
        return if unused {
            Ok(None)
        } else {
            Err(WireError::BadPrimitiveSize {
                object_id,
                kind: "absent (kind 0)",
                sizes,
            })
        };
    }
    let shape = PrimitiveShape::from_wire(kind, sizes).ok_or(WireError::InvalidEnum {
        message: r.message,
        field: "primitive kind",
        value: kind,
        defined: "0 none, 1 box, 2 cylinder, 3 sphere, 4 capsule",
    })?;
    // Every size field the kind does not use is 0: garbage is refused, not ignored.
    if shape.sizes().map(f32::to_bits) != sizes.map(f32::to_bits) {
        return Err(WireError::BadPrimitiveSize {
            object_id,
            kind: shape.name(),
            sizes,
        });
    }
    let primitive = BodyPrimitive {
        shape,
        rotation: glam::Quat::from_array(rotation),
        centre,
        residual_m,
    };
    check_primitive(object_id, &primitive)?;
    Ok(Some(primitive))
}

/// V × 3 f32 vertices, then T × 3 u32 indices.
fn read_full_geometry(
    r: &mut Reader<'_>,
    vertex_count: usize,
    triangle_count: usize,
) -> Result<TriMesh, WireError> {
    // Check the counts against the frame before allocating anything they size.
    r.ensure(
        "vertices and triangles",
        vertex_count as u64 * VERTEX_BYTES as u64 + triangle_count as u64 * TRIANGLE_BYTES as u64,
    )?;
    let mut vertices = Vec::with_capacity(vertex_count);
    for vertex in 0..vertex_count {
        let p = r.vec3("vertices")?;
        check_vertex(vertex, p)?;
        vertices.push(p);
    }
    let mut triangles = Vec::with_capacity(triangle_count);
    for triangle in 0..triangle_count {
        let corners = [
            r.u32("triangles")?,
            r.u32("triangles")?,
            r.u32("triangles")?,
        ];
        check_triangle(triangle, corners, vertex_count)?;
        triangles.push(corners);
    }
    Ok(TriMesh::new(vertices, triangles))
}

/// The box, V × 3 u16 steps, then T × 3 indices of u16 (V ≤ 65,536) or u32.
fn read_compact_geometry(
    r: &mut Reader<'_>,
    vertex_count: usize,
    triangle_count: usize,
) -> Result<TriMesh, WireError> {
    let compact_box = CompactBox {
        min: r.vec3("box_min")?,
        max: r.vec3("box_max")?,
    };
    compact_box.check(r.message)?;
    let index_bytes = compact_index_bytes(vertex_count);
    r.ensure(
        "vertices and triangles",
        vertex_count as u64 * COMPACT_VERTEX_BYTES as u64
            + triangle_count as u64 * 3 * index_bytes as u64,
    )?;
    let mut vertices = Vec::with_capacity(vertex_count);
    for vertex in 0..vertex_count {
        let q = [r.u16("vertices")?, r.u16("vertices")?, r.u16("vertices")?];
        // Finite for any box the encoder writes; a hostile box can still overflow.
        let p = compact_box.dequantise(q);
        check_vertex(vertex, p)?;
        vertices.push(p);
    }
    let mut triangles = Vec::with_capacity(triangle_count);
    for triangle in 0..triangle_count {
        let mut corners = [0; 3];
        for corner in &mut corners {
            *corner = if index_bytes == 2 {
                u32::from(r.u16("triangles")?)
            } else {
                r.u32("triangles")?
            };
        }
        check_triangle(triangle, corners, vertex_count)?;
        triangles.push(corners);
    }
    Ok(TriMesh::new(vertices, triangles))
}

fn read_stats(r: &mut Reader<'_>) -> Result<Stats, WireError> {
    let mut stats = Stats {
        monotonic_ns: r.u64("monotonic_ns")?,
        realtime_ns: r.u64("realtime_ns")?,
        frames_in: r.u64("frames_in")?,
        frames_dropped: r.u64("frames_dropped")?,
        invalid_pixels: r.u64("invalid_pixels")?,
        malformed_frames: r.u64("malformed_frames")?,
        source_errors: r.u64("source_errors")?,
        source_restarts: r.u64("source_restarts")?,
        objects_tracked: r.u64("objects_tracked")?,
        objects_born: r.u64("objects_born")?,
        objects_removed: r.u64("objects_removed")?,
        meshing_runs: r.u64("meshing_runs")?,
        meshing_failures: r.u64("meshing_failures")?,
        shapes_published: r.u64("shapes_published")?,
        poses_published: r.u64("poses_published")?,
        bytes_sent: r.u64("bytes_sent")?,
        clients_connected: r.u64("clients_connected")?,
        clients_dropped: r.u64("clients_dropped")?,
        clients_refused: r.u64("clients_refused")?,
        latency_window: r.u32("latency_window")?,
        frame_to_publish_p50_ms: r.f32("frame_to_publish_p50_ms")?,
        frame_to_publish_p99_ms: r.f32("frame_to_publish_p99_ms")?,
        stage_latencies: Vec::new(),
    };
    check_number("frame_to_publish_p50_ms", stats.frame_to_publish_p50_ms)?;
    check_number("frame_to_publish_p99_ms", stats.frame_to_publish_p99_ms)?;
    let stage_count = r.u32("stage_count")?;
    // Every stage takes at least STAGE_FIXED_BYTES, which bounds a believable count.
    r.ensure("stages", u64::from(stage_count) * STAGE_FIXED_BYTES as u64)?;
    stats.stage_latencies.reserve(stage_count as usize);
    for _ in 0..stage_count {
        let stage = r.text("stage", MAX_NAME_BYTES)?;
        let p50_ms = r.f32("p50_ms")?;
        check_number("p50_ms", p50_ms)?;
        let p99_ms = r.f32("p99_ms")?;
        check_number("p99_ms", p99_ms)?;
        stats.stage_latencies.push(StageLatency {
            stage,
            p50_ms,
            p99_ms,
        });
    }
    Ok(stats)
}

/// A cursor over one payload; every read names the field it reads, for the error.
struct Reader<'a> {
    bytes: &'a [u8],
    message: &'static str,
}

impl Reader<'_> {
    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], WireError> {
        match self.bytes.split_first_chunk::<N>() {
            Some((head, rest)) => {
                self.bytes = rest;
                Ok(*head)
            }
            None => Err(self.truncated(field, N as u64)),
        }
    }

    fn u8(&mut self, field: &'static str) -> Result<u8, WireError> {
        self.array::<1>(field).map(|[byte]| byte)
    }

    fn u16(&mut self, field: &'static str) -> Result<u16, WireError> {
        self.array(field).map(u16::from_le_bytes)
    }

    fn u32(&mut self, field: &'static str) -> Result<u32, WireError> {
        self.array(field).map(u32::from_le_bytes)
    }

    fn u64(&mut self, field: &'static str) -> Result<u64, WireError> {
        self.array(field).map(u64::from_le_bytes)
    }

    fn f32(&mut self, field: &'static str) -> Result<f32, WireError> {
        self.array(field).map(f32::from_le_bytes)
    }

    /// Three f32, as they are: the caller checks them.
    fn vec3(&mut self, field: &'static str) -> Result<Vec3, WireError> {
        Ok(Vec3::new(
            self.f32(field)?,
            self.f32(field)?,
            self.f32(field)?,
        ))
    }

    /// An `encoding` byte: 0 full, 1 compact.
    fn encoding(&mut self) -> Result<Encoding, WireError> {
        let value = self.u8("encoding")?;
        Encoding::from_byte(value).ok_or(WireError::InvalidEnum {
            message: self.message,
            field: "encoding",
            value,
            defined: "0 full, 1 compact",
        })
    }

    /// A u16 byte length, then that many bytes of UTF-8.
    fn text(&mut self, field: &'static str, max: usize) -> Result<String, WireError> {
        let len = self.u16(field)? as usize;
        if len > max {
            return Err(WireError::TextTooLong {
                message: self.message,
                field,
                len,
                max,
            });
        }
        let Some((bytes, rest)) = self.bytes.split_at_checked(len) else {
            return Err(self.truncated(field, len as u64));
        };
        self.bytes = rest;
        match std::str::from_utf8(bytes) {
            Ok(text) => Ok(text.to_owned()),
            Err(e) => Err(WireError::InvalidUtf8 {
                message: self.message,
                field,
                valid_up_to: e.valid_up_to(),
            }),
        }
    }

    /// At least `needed` bytes are left: checked before allocating for a count read from the
    /// wire, so that a hostile count costs nothing.
    fn ensure(&self, field: &'static str, needed: u64) -> Result<(), WireError> {
        if needed <= self.bytes.len() as u64 {
            Ok(())
        } else {
            Err(self.truncated(field, needed))
        }
    }

    fn truncated(&self, field: &'static str, needed: u64) -> WireError {
        WireError::Truncated {
            message: self.message,
            field,
            needed,
            available: self.bytes.len(),
        }
    }

    /// Every byte of the payload must have been read.
    fn finish(&self) -> Result<(), WireError> {
        if self.bytes.is_empty() {
            Ok(())
        } else {
            Err(WireError::TrailingBytes {
                message: self.message,
                extra: self.bytes.len(),
            })
        }
    }
}
