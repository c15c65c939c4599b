//! The tacmesh wire protocol: the messages the daemon publishes on its Unix socket and the few a
//! subscriber may send back, as bytes. No I/O here: the daemon and clients own their sockets and
//! hand bytes to [`encode`] and a [`FrameDecoder`]. The byte layout is specified in
//! `docs/protocol.md`; the golden-byte tests in this crate pin it down.
//!
//! Entry points:
//! - [`Message`]: every message, with [`Upsert`], [`Stats`] and their parts.
//! - [`encode`]: one message to one frame, appended to a buffer.
//! - [`FrameDecoder`]: bytes from a stream in, whole messages out.
//! - [`check_hello`]: what a client does with the first message it receives.
//! - [`WireError`]: everything that can be wrong with a frame, said plainly.
//!
//! Framing: every frame is a little-endian `u32` length (of what follows), a `u8` message kind,
//! then the payload. A length above [`MAX_FRAME_BYTES`] is refused on both sides.

mod decode;
mod encode;
mod error;
mod message;

#[cfg(test)]
mod tests;

pub use decode::FrameDecoder;
pub use encode::encode;
pub use error::WireError;
pub use message::{
    check_hello, Message, Sender, SimplifyStats, StageLatency, Stats, Upsert, MAX_FRAME_BYTES,
    MAX_NAME_BYTES, MAX_REASON_BYTES, PROTOCOL_VERSION,
};
