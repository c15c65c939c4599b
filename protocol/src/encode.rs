//! Message → frame. Encoding refuses anything decoding would refuse, so whatever [`encode`]
//! accepts round-trips.

use tacmesh_source::TriMesh;

use crate::error::WireError;
use crate::message::{
    Message, SimplifyStats, Stats, Upsert, MAX_FRAME_BYTES, MAX_NAME_BYTES, MAX_REASON_BYTES,
};

/// Bytes of the length prefix.
pub(crate) const PREFIX_BYTES: usize = 4;
/// Fixed part of an Upsert payload: ids and time (3 × u64), report (2 × u32 + f32), counts (2 × u32).
pub(crate) const UPSERT_HEADER_BYTES: usize = 3 * 8 + 3 * 4 + 2 * 4;
/// Bytes of one vertex (3 × f32) and of one triangle (3 × u32).
pub(crate) const VERTEX_BYTES: usize = 12;
pub(crate) const TRIANGLE_BYTES: usize = 12;
/// Fixed part of a Stats payload: 7 × u64 counters, 2 × f32 latencies, a u32 stage count.
pub(crate) const STATS_HEADER_BYTES: usize = 7 * 8 + 2 * 4 + 4;
/// Bytes of one stage besides its name: u16 name length, 2 × f32 latencies.
pub(crate) const STAGE_FIXED_BYTES: usize = 2 + 2 * 4;

/// Appends `message` to `out` as one frame. On error `out` is left as it was.
///
/// Errors: [`WireError::FrameTooLarge`] when the frame would exceed [`MAX_FRAME_BYTES`] (checked
/// before anything is written), [`WireError::TextTooLong`], [`WireError::NonFiniteVertex`],
/// [`WireError::IndexOutOfRange`] and [`WireError::InvalidNumber`] for content a decoder would
/// refuse.
pub fn encode(message: &Message, out: &mut Vec<u8>) -> Result<(), WireError> {
    let length = 1 + payload_len(message);
    if length > MAX_FRAME_BYTES as u64 {
        return Err(WireError::FrameTooLarge { length });
    }
    let start = out.len();
    out.reserve(PREFIX_BYTES + length as usize);
    // The cap check above guarantees the length and every count below fit in a u32.
    out.extend_from_slice(&(length as u32).to_le_bytes());
    out.push(message.kind());
    let written = write_payload(message, out);
    if written.is_err() {
        out.truncate(start);
    }
    debug_assert!(written.is_err() || out.len() - start == PREFIX_BYTES + length as usize);
    written
}

/// The payload size in bytes, computed without writing, in u64 so that no input overflows it.
fn payload_len(message: &Message) -> u64 {
    let text = |s: &str| 2 + s.len() as u64;
    match message {
        Message::Hello { server, .. } => 2 + text(server),
        Message::Upsert(upsert) => {
            UPSERT_HEADER_BYTES as u64
                + upsert.mesh.vertices.len() as u64 * VERTEX_BYTES as u64
                + upsert.mesh.triangles.len() as u64 * TRIANGLE_BYTES as u64
        }
        Message::Remove { .. } => 8,
        Message::SnapshotDone | Message::Subscribe => 0,
        Message::Stats(stats) => {
            STATS_HEADER_BYTES as u64
                + stats
                    .stage_latencies
                    .iter()
                    .map(|s| STAGE_FIXED_BYTES as u64 + s.stage.len() as u64)
                    .sum::<u64>()
        }
        Message::Goodbye { reason } => text(reason),
    }
}

fn write_payload(message: &Message, out: &mut Vec<u8>) -> Result<(), WireError> {
    match message {
        Message::Hello {
            protocol_version,
            server,
        } => {
            out.extend_from_slice(&protocol_version.to_le_bytes());
            write_text(out, server, "Hello", "server", MAX_NAME_BYTES)
        }
        Message::Upsert(upsert) => write_upsert(upsert, out),
        Message::Remove { object_id } => {
            out.extend_from_slice(&object_id.to_le_bytes());
            Ok(())
        }
        Message::SnapshotDone | Message::Subscribe => Ok(()),
        Message::Stats(stats) => write_stats(stats, out),
        Message::Goodbye { reason } => {
            write_text(out, reason, "Goodbye", "reason", MAX_REASON_BYTES)
        }
    }
}

fn write_upsert(upsert: &Upsert, out: &mut Vec<u8>) -> Result<(), WireError> {
    let SimplifyStats {
        faces_in,
        faces_out,
        max_residual_m,
    } = upsert.report;
    check_number("max_residual_m", max_residual_m)?;
    let TriMesh {
        vertices,
        triangles,
    } = &upsert.mesh;
    for field in [upsert.object_id, upsert.version, upsert.capture_time_ns] {
        out.extend_from_slice(&field.to_le_bytes());
    }
    out.extend_from_slice(&faces_in.to_le_bytes());
    out.extend_from_slice(&faces_out.to_le_bytes());
    out.extend_from_slice(&max_residual_m.to_le_bytes());
    out.extend_from_slice(&(vertices.len() as u32).to_le_bytes());
    out.extend_from_slice(&(triangles.len() as u32).to_le_bytes());
    for (vertex, p) in vertices.iter().enumerate() {
        for value in p.to_array() {
            if !value.is_finite() {
                return Err(WireError::NonFiniteVertex { vertex, value });
            }
            out.extend_from_slice(&value.to_le_bytes());
        }
    }
    for (triangle, corners) in triangles.iter().enumerate() {
        for &index in corners {
            if index as usize >= vertices.len() {
                return Err(WireError::IndexOutOfRange {
                    triangle,
                    index,
                    vertex_count: vertices.len(),
                });
            }
            out.extend_from_slice(&index.to_le_bytes());
        }
    }
    Ok(())
}

fn write_stats(stats: &Stats, out: &mut Vec<u8>) -> Result<(), WireError> {
    check_number("frame_to_publish_p50_ms", stats.frame_to_publish_p50_ms)?;
    check_number("frame_to_publish_p99_ms", stats.frame_to_publish_p99_ms)?;
    for counter in [
        stats.frames_in,
        stats.frames_dropped,
        stats.invalid_pixels,
        stats.objects_tracked,
        stats.meshing_runs,
        stats.meshes_published,
        stats.bytes_sent,
    ] {
        out.extend_from_slice(&counter.to_le_bytes());
    }
    out.extend_from_slice(&stats.frame_to_publish_p50_ms.to_le_bytes());
    out.extend_from_slice(&stats.frame_to_publish_p99_ms.to_le_bytes());
    out.extend_from_slice(&(stats.stage_latencies.len() as u32).to_le_bytes());
    for stage in &stats.stage_latencies {
        check_number("p50_ms", stage.p50_ms)?;
        check_number("p99_ms", stage.p99_ms)?;
        write_text(out, &stage.stage, "Stats", "stage", MAX_NAME_BYTES)?;
        out.extend_from_slice(&stage.p50_ms.to_le_bytes());
        out.extend_from_slice(&stage.p99_ms.to_le_bytes());
    }
    Ok(())
}

/// A string as a u16 byte length and its UTF-8 bytes.
fn write_text(
    out: &mut Vec<u8>,
    text: &str,
    message: &'static str,
    field: &'static str,
    max: usize,
) -> Result<(), WireError> {
    if text.len() > max {
        return Err(WireError::TextTooLong {
            message,
            field,
            len: text.len(),
            max,
        });
    }
    // max ≤ MAX_REASON_BYTES < u16::MAX.
    out.extend_from_slice(&(text.len() as u16).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    Ok(())
}

/// Residuals and latencies are finite and not negative.
pub(crate) fn check_number(field: &'static str, value: f32) -> Result<(), WireError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(WireError::InvalidNumber { field, value })
    }
}
