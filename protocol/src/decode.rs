//! Byte stream → messages: frame splitting, then one parser per message kind.

use glam::Vec3;
use tacmesh_source::TriMesh;

use crate::encode::{
    check_number, PREFIX_BYTES, STAGE_FIXED_BYTES, TRIANGLE_BYTES, UPSERT_HEADER_BYTES,
    VERTEX_BYTES,
};
use crate::error::WireError;
use crate::message::{
    kind, Message, Sender, SimplifyStats, StageLatency, Stats, Upsert, MAX_FRAME_BYTES,
    MAX_NAME_BYTES, MAX_REASON_BYTES,
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
        kind::UPSERT => Message::Upsert(read_upsert(&mut r)?),
        kind::REMOVE => Message::Remove {
            object_id: r.u64("object_id")?,
        },
        kind::SNAPSHOT_DONE => Message::SnapshotDone,
        kind::STATS => Message::Stats(read_stats(&mut r)?),
        kind::GOODBYE => Message::Goodbye {
            reason: r.text("reason", MAX_REASON_BYTES)?,
        },
        kind::SUBSCRIBE => Message::Subscribe,
        _ => return Err(WireError::UnknownKind { kind }),
    };
    r.finish()?;
    Ok(message)
}

fn read_upsert(r: &mut Reader<'_>) -> Result<Upsert, WireError> {
    let available_at_start = r.bytes.len();
    let object_id = r.u64("object_id")?;
    let version = r.u64("version")?;
    let capture_time_ns = r.u64("capture_time_ns")?;
    let faces_in = r.u32("faces_in")?;
    let faces_out = r.u32("faces_out")?;
    let max_residual_m = r.f32("max_residual_m")?;
    check_number("max_residual_m", max_residual_m)?;
    let vertex_count = r.u32("vertex_count")? as usize;
    let triangle_count = r.u32("triangle_count")? as usize;
    debug_assert_eq!(available_at_start - r.bytes.len(), UPSERT_HEADER_BYTES);

    // Check the counts against the frame before allocating anything they size.
    let needed =
        vertex_count as u64 * VERTEX_BYTES as u64 + triangle_count as u64 * TRIANGLE_BYTES as u64;
    if needed > r.bytes.len() as u64 {
        return Err(WireError::Truncated {
            message: r.message,
            field: "vertices and triangles",
            needed,
            available: r.bytes.len(),
        });
    }

    let mut vertices = Vec::with_capacity(vertex_count);
    for vertex in 0..vertex_count {
        let xyz = [r.f32("vertices")?, r.f32("vertices")?, r.f32("vertices")?];
        if let Some(&value) = xyz.iter().find(|v| !v.is_finite()) {
            return Err(WireError::NonFiniteVertex { vertex, value });
        }
        vertices.push(Vec3::from_array(xyz));
    }
    let mut triangles = Vec::with_capacity(triangle_count);
    for triangle in 0..triangle_count {
        let corners = [
            r.u32("triangles")?,
            r.u32("triangles")?,
            r.u32("triangles")?,
        ];
        if let Some(&index) = corners.iter().find(|&&i| i as usize >= vertex_count) {
            return Err(WireError::IndexOutOfRange {
                triangle,
                index,
                vertex_count,
            });
        }
        triangles.push(corners);
    }
    Ok(Upsert {
        object_id,
        version,
        capture_time_ns,
        mesh: TriMesh::new(vertices, triangles),
        report: SimplifyStats {
            faces_in,
            faces_out,
            max_residual_m,
        },
    })
}

fn read_stats(r: &mut Reader<'_>) -> Result<Stats, WireError> {
    let frames_in = r.u64("frames_in")?;
    let frames_dropped = r.u64("frames_dropped")?;
    let invalid_pixels = r.u64("invalid_pixels")?;
    let objects_tracked = r.u64("objects_tracked")?;
    let meshing_runs = r.u64("meshing_runs")?;
    let meshes_published = r.u64("meshes_published")?;
    let bytes_sent = r.u64("bytes_sent")?;
    let frame_to_publish_p50_ms = r.f32("frame_to_publish_p50_ms")?;
    check_number("frame_to_publish_p50_ms", frame_to_publish_p50_ms)?;
    let frame_to_publish_p99_ms = r.f32("frame_to_publish_p99_ms")?;
    check_number("frame_to_publish_p99_ms", frame_to_publish_p99_ms)?;
    let stage_count = r.u32("stage_count")? as usize;
    // Every stage takes at least STAGE_FIXED_BYTES, which bounds a believable count.
    let mut stage_latencies =
        Vec::with_capacity(stage_count.min(r.bytes.len() / STAGE_FIXED_BYTES));
    for _ in 0..stage_count {
        let stage = r.text("stage", MAX_NAME_BYTES)?;
        let p50_ms = r.f32("p50_ms")?;
        check_number("p50_ms", p50_ms)?;
        let p99_ms = r.f32("p99_ms")?;
        check_number("p99_ms", p99_ms)?;
        stage_latencies.push(StageLatency {
            stage,
            p50_ms,
            p99_ms,
        });
    }
    Ok(Stats {
        frames_in,
        frames_dropped,
        invalid_pixels,
        objects_tracked,
        meshing_runs,
        meshes_published,
        bytes_sent,
        stage_latencies,
        frame_to_publish_p50_ms,
        frame_to_publish_p99_ms,
    })
}

/// A cursor over one payload; every read names the field it reads, for the error.
struct Reader<'a> {
    bytes: &'a [u8],
    message: &'static str,
}

impl<'a> Reader<'a> {
    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], WireError> {
        match self.bytes.split_first_chunk::<N>() {
            Some((head, rest)) => {
                self.bytes = rest;
                Ok(*head)
            }
            None => Err(self.truncated(field, N as u64)),
        }
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
