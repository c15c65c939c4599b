use crate::message::{Sender, MAX_FRAME_BYTES, MAX_RATE_HZ, MIN_RATE_HZ};

/// Everything that can be wrong with a frame, on either side. After any decode error the peer is
/// not speaking this protocol correctly: drop the connection (see [`crate::FrameDecoder`]). The
/// encoder returns the same errors for a message it would not be allowed to send, so that what
/// [`crate::encode`] writes always decodes.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum WireError {
    #[error(
        "frame length {length} exceeds the cap of {MAX_FRAME_BYTES} bytes: \
         the peer is not speaking the tacmesh protocol, or the message is too big to send"
    )]
    FrameTooLarge { length: u64 },

    #[error("frame length 0: every frame holds at least its message kind byte")]
    EmptyFrame,

    #[error(
        "unknown message kind 0x{kind:02x}: the peer speaks another protocol version \
         or is not a tacmesh peer"
    )]
    UnknownKind { kind: u8 },

    #[error("{message} is sent by a {sender}, but this decoder reads what a {expected} sends")]
    WrongSender {
        message: &'static str,
        sender: Sender,
        expected: Sender,
    },

    #[error(
        "{message} frame ends inside `{field}`: it needs {needed} more bytes, {available} are left"
    )]
    Truncated {
        message: &'static str,
        field: &'static str,
        needed: u64,
        available: usize,
    },

    #[error("{message} frame has {extra} bytes after its last field")]
    TrailingBytes { message: &'static str, extra: usize },

    #[error(
        "triangle {triangle} uses vertex {index}, but the mesh has only {vertex_count} vertices"
    )]
    IndexOutOfRange {
        triangle: usize,
        index: u32,
        vertex_count: usize,
    },

    #[error(
        "vertex {vertex} has a non-finite coordinate ({value}): coordinates are finite metres"
    )]
    NonFiniteVertex { vertex: usize, value: f32 },

    #[error("`{field}` of {message} has a non-finite component ({value}): it must be finite")]
    NonFinite {
        message: &'static str,
        field: &'static str,
        value: f32,
    },

    #[error("`{field}` is {value}, but it must be finite and not negative")]
    InvalidNumber { field: &'static str, value: f32 },

    #[error(
        "`max_rate_hz` is {value}, but it must be 0 (no cap) or from {MIN_RATE_HZ} to \
         {MAX_RATE_HZ} updates a second"
    )]
    InvalidRate { value: f32 },

    #[error(
        "`{field}` of {message} is 0x{value:02x}, but only the bits 0x{defined:02x} are defined"
    )]
    InvalidFlags {
        message: &'static str,
        field: &'static str,
        value: u8,
        defined: u8,
    },

    #[error(
        "`kinds` of {message} asks for neither objects (bit 0) nor support planes (bit 1): it \
         must ask for one of them or both (bit 2, bodies, comes with the objects)"
    )]
    NoKinds { message: &'static str },

    #[error("`{field}` of {message} is {value}, which is not a defined value ({defined})")]
    InvalidEnum {
        message: &'static str,
        field: &'static str,
        value: u8,
        /// The values the field may have, for a human.
        defined: &'static str,
    },

    #[error(
        "the body of object {object_id} has volume {volume_m3} m³: it must be finite and positive"
    )]
    BodyVolume { object_id: u64, volume_m3: f32 },

    #[error(
        "the body of object {object_id} is a {solid}, yet carries a mesh of {vertex_count} \
         vertices and {triangle_count} triangles (it must carry none)"
    )]
    SolidMeshNotEmpty {
        object_id: u64,
        solid: &'static str,
        vertex_count: usize,
        triangle_count: usize,
    },

    #[error(
        "the body of object {object_id} is a {solid}, yet {}",
        if *has_primitive { "carries a primitive (only a primitive solid does)" }
        else { "carries no primitive (kind 0)" }
    )]
    PrimitiveMismatch {
        object_id: u64,
        solid: &'static str,
        has_primitive: bool,
    },

    #[error(
        "the {kind} primitive of object {object_id}'s body has sizes {sizes:?}: the sizes its \
         kind uses must be finite and positive, the others 0"
    )]
    BadPrimitiveSize {
        object_id: u64,
        kind: &'static str,
        sizes: [f32; 3],
    },

    #[error("the body of object {object_id} has {count} hulls, more than the cap of {max}")]
    TooManyHulls {
        object_id: u64,
        count: usize,
        max: usize,
    },

    #[error(
        "hull {hull} of object {object_id}'s body has {vertex_count} vertices and \
         {triangle_count} triangles: a hull has 4 to 255 vertices and at most twice as many \
         triangles"
    )]
    BadHull {
        object_id: u64,
        hull: usize,
        vertex_count: usize,
        triangle_count: usize,
    },

    #[error(
        "the rotation of object {object_id} has norm {norm}: it must be a unit quaternion \
         (norm within 1e-3 of 1)"
    )]
    NotUnitQuaternion { object_id: u64, norm: f32 },

    #[error(
        "object {object_id} was last seen at {last_seen_ns} ns, before its pose time \
         {pose_time_ns} ns: last seen is never earlier than the pose time"
    )]
    TimesOutOfOrder {
        object_id: u64,
        pose_time_ns: u64,
        last_seen_ns: u64,
    },

    #[error("{message} lists {count} object ids, more than the cap of {max}")]
    TooManyIds {
        message: &'static str,
        count: u64,
        max: usize,
    },

    #[error("the compact box's {axis} maximum {max} is below its minimum {min}")]
    BadBox {
        axis: &'static str,
        min: f32,
        max: f32,
    },

    #[error(
        "the shape's vertices span {min} to {max} on {axis}, more than the compact \
         encoding's box can hold in f32: send it in the full encoding"
    )]
    CompactBoxTooLarge {
        axis: &'static str,
        min: f32,
        max: f32,
    },

    #[error("`{field}` of {message} is not UTF-8 (valid up to byte {valid_up_to})")]
    InvalidUtf8 {
        message: &'static str,
        field: &'static str,
        valid_up_to: usize,
    },

    #[error("`{field}` of {message} is {len} bytes, more than the cap of {max}")]
    TextTooLong {
        message: &'static str,
        field: &'static str,
        len: usize,
        max: usize,
    },

    #[error(
        "the server speaks protocol version {theirs}, this client speaks only version {ours}: \
         use a client and daemon from the same release"
    )]
    VersionMismatch { ours: u16, theirs: u16 },

    #[error("expected Hello as the first message of the connection, got {got}")]
    NotHello { got: &'static str },
}
