//! Pure-Rust reader of OpenNI `.oni` recordings and a replay [`DepthSource`] over them.
//!
//! Reads the NI10 container written by OpenNI 1.x (and read by OpenNI2), finds the depth node,
//! and decodes its `16zT` frames ("16Z with an embedded value table") into millimetres.
//! Images and other nodes are skipped.
//!
//! Entry points:
//! - [`OniReplay`]: opens a file and yields [`tacmesh_source::Observation::Depth`] frames,
//!   paced at the recorded rate or as fast as read, looping or ending
//!   ([`ReplayOptions`]).
//! - [`OniRecording`]: the file indexed; [`OniRecording::read_depth_mm`] decodes one frame,
//!   [`DepthStream`] holds resolution, field of view, properties and the frame index.
//! - [`decode_16zt`]: the depth codec alone.
//! - [`OniError`]: everything that can be wrong with a file, naming the file and record offset.
//!
//! Modules follow the data: [`container`] (records) → `recording` (depth node and frame index)
//! → [`codec`] (`16zT`) → `replay` (the source).
//!
//! [`DepthSource`]: tacmesh_source::DepthSource

pub mod codec;
pub mod container;
mod error;
mod recording;
mod replay;

pub use codec::{decode_16zt, CodecError};
pub use container::{FileHeader, Property, Version};
pub use error::OniError;
pub use recording::{DepthStream, FrameIndex, OniRecording};
pub use replay::{AtEnd, OniReplay, Pacing, ReplayOptions};
