//! The tacmesh wire protocol, version 3: the messages the daemon publishes on its Unix socket
//! and the few a subscriber may send back, as bytes. No I/O here: the daemon and clients own
//! their sockets and hand bytes to [`encode`] and a [`FrameDecoder`]. The byte layout is
//! specified in `docs/protocol.md`; the golden-byte tests in this crate pin it down.
//!
//! Entry points:
//! - [`Message`]: every message, with [`Session`], [`Shape`], [`Pose`], [`Body`], [`Stats`],
//!   [`Subscribe`] and their parts.
//! - [`encode`]: one message to one frame, appended to a buffer; a [`Shape`] in the
//!   [`Encoding`] it names.
//! - [`FrameDecoder`]: bytes from a stream in, whole messages out.
//! - [`check_hello`]: what a client does with the first message it receives.
//! - [`Scene`]: what a client keeps of the stream (the latest shape and pose per object).
//! - [`WireError`]: everything that can be wrong with a frame, said plainly.
//!
//! Framing: every frame is a little-endian `u32` length (of what follows), a `u8` message kind,
//! then the payload. A length above [`MAX_FRAME_BYTES`] is refused on both sides.

mod decode;
mod encode;
mod error;
mod message;
mod scene;

#[cfg(test)]
mod tests;

pub use decode::FrameDecoder;
pub use encode::check_rate;
pub use encode::encode;
pub use error::WireError;
pub use message::{
    check_hello, quantisation_bound_m, Body, BodyPrimitive, BodySolid, Encoding, Hull, Kinds,
    Message, Pose, PrimitiveShape, Sender, Session, Shape, SimplifyStats, StageLatency, Stats,
    Subscribe, EXTRAPOLATION_REFRESH, EXTRAPOLATION_TOLERANCE_M, EXTRAPOLATION_TOLERANCE_RAD,
    FIRST_SUPPORT_ID, MAX_FRAME_BYTES, MAX_HULLS, MAX_HULL_VERTICES, MAX_NAME_BYTES, MAX_RATE_HZ,
    MAX_REASON_BYTES, MAX_SUBSCRIBE_IDS, MIN_HULL_VERTICES, MIN_RATE_HZ, PROTOCOL_VERSION,
    SHAPE_CLOSED, SHAPE_NEW_FRAME, SHAPE_SUPPORT,
};
pub use scene::{Scene, SceneChange, SceneObject};
