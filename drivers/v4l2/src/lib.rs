//! V4L2 depth cameras (Intel RealSense and other UVC depth cameras streaming `Z16 ` or `Y16 `)
//! as a tacmesh depth source.
//!
//! Entry points:
//! - [`decode_z16`] / [`decode_y16`]: a 16-bit little-endian frame buffer with its row stride
//!   (`bytesperline`) → row-major depth units; pure, always compiled, no `v4l` dependency.
//! - [`DepthDecoder`]: one negotiated stream's buffers → [`tacmesh_source::DepthFrame`]s in
//!   metres, with the configured [`tacmesh_source::Intrinsics`], depth scale and pose.
//! - [`V4l2Config`]: device node, resolution (from the intrinsics), fps, format preference,
//!   depth scale, pose, buffers and read timeout.
//! - `V4l2Source` (feature `device`): a [`tacmesh_source::DepthSource`] streaming a
//!   `/dev/videoN` node through memory-mapped buffers, one
//!   [`tacmesh_source::Observation::Depth`] per frame stamped with
//!   [`tacmesh_source::monotonic_now`] when it was dequeued.
//! - [`V4l2Error`]: why a frame could not be decoded or a device not opened.
//!
//! Without the `device` feature only the decoding compiles, so the default build needs no
//! libclang (the `v4l` crate generates its kernel bindings with bindgen).

#![forbid(unsafe_code)]

mod config;
pub mod decode;
#[cfg(feature = "device")]
pub mod device;
mod error;

pub use config::V4l2Config;
pub use decode::{decode_y16, decode_z16, units_to_metres, DepthDecoder, PixelFormat};
#[cfg(feature = "device")]
pub use device::{Negotiated, V4l2Source};
pub use error::V4l2Error;
