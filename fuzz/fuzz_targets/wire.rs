//! The wire decoder, both directions: what a client reads from the daemon
//! (`FrameDecoder::new(Sender::Server)`) and what the daemon's publisher reads
//! from a client (`FrameDecoder::new(Sender::Client)`, as in `tacmesh-publish`'s `client.rs`).
//!
//! The input is split into chunks the way a socket might return it (the first byte picks the
//! chunk size), so frame reassembly across pushes is exercised too. Properties checked beyond
//! "no panic":
//! - every message decoded re-encodes to exactly the bytes of its frame (the decoder accepts
//!   nothing the encoder would not write, and loses nothing) — except a Shape in the compact
//!   encoding, which cannot: the encoder recomputes the box from the (dequantised) vertices and
//!   adds the quantisation bound to the residual again. For one of those:
//!   - re-encoded in the full encoding it decodes to the very same shape (nothing was lost on
//!     the way in), unless the full frame would exceed the size cap;
//!   - re-encoded compactly it decodes to the same shape but for its vertices and a residual
//!     no smaller, unless the box spans more than an `f32` holds or the residual plus the
//!     bound overflows (both only for coordinates near `f32::MAX`);
//! - a Body whose solid is compact likewise: in the full encoding it decodes to the same body,
//!   and compactly to the same body but for its solid's vertices;
//! - the decoder never buffers more than one frame beyond what was taken out;
//! - a decoded Subscribe's rate cap, as the interval the daemon makes of it, fits both
//!   `Duration` and `Instant` (a rate of 1e-45 Hz once aborted the daemon there).

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_protocol::{
    encode, Body, Encoding, FrameDecoder, Message, Sender, Shape, WireError, MAX_FRAME_BYTES,
};

/// Bytes of the length prefix.
const PREFIX_BYTES: usize = 4;

fuzz_target!(|data: &[u8]| {
    let Some((&chunk_seed, stream)) = data.split_first() else {
        return;
    };
    let chunk_len = usize::from(chunk_seed).max(1);
    for from in [Sender::Server, Sender::Client] {
        decode_stream(stream, from, chunk_len);
    }
});

fn decode_stream(stream: &[u8], from: Sender, chunk_len: usize) {
    let mut decoder = FrameDecoder::new(from);
    // Where the next frame starts in `stream`, to compare re-encoded messages against.
    let mut frame_start = 0;
    for chunk in stream.chunks(chunk_len) {
        decoder.push(chunk);
        loop {
            match decoder.next_message() {
                Ok(Some(message)) => {
                    let frame_len = frame_length(&stream[frame_start..]);
                    let frame = &stream[frame_start..frame_start + PREFIX_BYTES + frame_len];
                    match &message {
                        Message::Subscribe(options) => {
                            check_rate_interval(options.max_rate_hz);
                            let mut encoded = Vec::new();
                            encode(&message, &mut encoded).expect("a decoded message encodes");
                            assert_eq!(encoded, frame, "{message:?} does not round-trip");
                        }
                        Message::Shape(shape) if shape.encoding == Encoding::Compact => {
                            check_compact_shape(shape, from);
                        }
                        Message::Body(body) if body.encoding == Encoding::Compact => {
                            check_compact_body(body, from);
                        }
                        _ => {
                            let mut encoded = Vec::new();
                            encode(&message, &mut encoded).expect("a decoded message encodes");
                            assert_eq!(encoded, frame, "{message:?} does not round-trip");
                        }
                    }
                    frame_start += frame.len();
                }
                Ok(None) => break,
                // The daemon drops the connection here; nothing more to read.
                Err(_) => return,
            }
        }
        assert!(
            decoder.buffered_len() <= PREFIX_BYTES + MAX_FRAME_BYTES + chunk_len,
            "the decoder holds {} bytes",
            decoder.buffered_len()
        );
    }
}

/// A rate the decoder let through becomes an interval that fits the clocks, as the
/// publisher's rate cap computes it.
fn check_rate_interval(rate_hz: f32) {
    if rate_hz == 0.0 {
        return;
    }
    let interval = std::time::Duration::try_from_secs_f32(1.0 / rate_hz)
        .unwrap_or_else(|err| panic!("rate {rate_hz}: {err}"));
    assert!(
        std::time::Instant::now().checked_add(interval).is_some(),
        "rate {rate_hz}: an interval of {interval:?} overflows Instant"
    );
}

/// The round trips a decoded compact shape must survive (see the top of the file).
fn check_compact_shape(shape: &Shape, from: Sender) {
    let full = Message::Shape(Shape {
        encoding: Encoding::Full,
        ..shape.clone()
    });
    match round_trip(&full, from) {
        Ok(again) => assert_eq!(again, full, "a compact shape changed in the full encoding"),
        Err(WireError::FrameTooLarge { .. }) => {
            // The full encoding takes 12 bytes a vertex where compact took 6.
            let full_len = 1 + 130 + 12 * (shape.mesh.vertices.len() + shape.mesh.triangles.len());
            assert!(full_len > MAX_FRAME_BYTES, "{full_len} bytes refused");
        }
        Err(err) => panic!("a decoded compact shape does not encode in full: {err}"),
    }

    match round_trip(&Message::Shape(shape.clone()), from) {
        Ok(Message::Shape(again)) => {
            assert_eq!(again.encoding, Encoding::Compact);
            assert!(again.report.max_residual_m >= shape.report.max_residual_m);
            assert_eq!(again.mesh.triangles, shape.mesh.triangles);
            assert_eq!(again.mesh.vertices.len(), shape.mesh.vertices.len());
            let same_but_geometry = Shape {
                mesh: again.mesh.clone(),
                report: again.report,
                ..shape.clone()
            };
            assert_eq!(again, same_but_geometry);
        }
        Ok(other) => panic!("a Shape came back as {other:?}"),
        Err(WireError::CompactBoxTooLarge { .. }) => {}
        Err(WireError::InvalidNumber {
            field: "max_residual_m",
            value,
        }) if value.is_infinite() => {}
        Err(err) => panic!("a decoded compact shape does not encode again: {err}"),
    }
}

/// The round trips a decoded body with a compact solid must survive (see the top of the file).
fn check_compact_body(body: &Body, from: Sender) {
    let full = Message::Body(Body {
        encoding: Encoding::Full,
        ..body.clone()
    });
    match round_trip(&full, from) {
        Ok(again) => assert_eq!(again, full, "a compact body changed in the full encoding"),
        Err(WireError::FrameTooLarge { .. }) => {}
        Err(err) => panic!("a decoded compact body does not encode in full: {err}"),
    }
    match round_trip(&Message::Body(body.clone()), from) {
        Ok(Message::Body(again)) => {
            assert_eq!(again.mesh.triangles, body.mesh.triangles);
            assert_eq!(again.mesh.vertices.len(), body.mesh.vertices.len());
            let same_but_geometry = Body {
                mesh: again.mesh.clone(),
                ..body.clone()
            };
            assert_eq!(again, same_but_geometry);
        }
        Ok(other) => panic!("a Body came back as {other:?}"),
        Err(WireError::CompactBoxTooLarge { .. }) => {}
        Err(err) => panic!("a decoded compact body does not encode again: {err}"),
    }
}

/// `message` encoded, then decoded again: an encoding error is returned, a decoding error is a
/// bug (the encoder wrote what the decoder refuses).
fn round_trip(message: &Message, from: Sender) -> Result<Message, WireError> {
    let mut bytes = Vec::new();
    encode(message, &mut bytes)?;
    let mut decoder = FrameDecoder::new(from);
    decoder.push(&bytes);
    let again = decoder
        .next_message()
        .expect("what encode writes decodes")
        .expect("a whole frame was pushed");
    assert_eq!(decoder.buffered_len(), 0);
    Ok(again)
}

fn frame_length(at: &[u8]) -> usize {
    let prefix: [u8; PREFIX_BYTES] = at[..PREFIX_BYTES].try_into().expect("a whole prefix");
    u32::from_le_bytes(prefix) as usize
}
