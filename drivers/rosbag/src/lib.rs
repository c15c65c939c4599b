//! Reads ROS bag v2.0 files — RealSense `.bag` recordings in particular — and replays their
//! depth frames as a tacmesh depth source. Pure Rust, no `unsafe`, no ROS installation.
//!
//! Entry points:
//! - [`BagReplay`]: a [`tacmesh_source::DepthSource`] playing a RealSense bag's depth stream
//!   (intrinsics from camera_info, metres via the `Depth Units` option), paced as recorded or
//!   at full speed, looping or ending with `EndOfStream`.
//! - [`Bag`]: open a bag, list its [`Connection`]s and topics, iterate its [`Message`]s.
//! - [`Image`], [`CameraInfo`], [`decode_float32`]: decoders of the messages a replay needs.
//! - [`record`] and [`chunk`]: the record/header layer and chunk decompression (`none`, `lz4`).
//!
//! Every length read from a file is checked against the bytes that remain before anything is
//! allocated, and a truncated or corrupt file is a typed error naming the file and byte offset.

#![forbid(unsafe_code)]

mod bag;
pub mod chunk;
mod messages;
pub mod record;
mod replay;

pub use bag::{Bag, BagError, Connection, Message, Messages};
pub use chunk::ChunkError;
pub use messages::{decode_float32, CameraInfo, Image, MessageError, RosHeader};
pub use replay::{BagReplay, Pacing, ReplayError, ReplayOptions, DEFAULT_DEPTH_UNITS_M};

use std::time::Duration;

/// A ROS time: seconds and nanoseconds since the Unix epoch (or since start, for sim time).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Default, Hash)]
pub struct Time {
    pub sec: u32,
    pub nsec: u32,
}

impl Time {
    /// As a duration since the epoch (nanoseconds past 10⁹ carry into the seconds).
    pub fn as_duration(self) -> Duration {
        Duration::from_secs(u64::from(self.sec)) + Duration::from_nanos(u64::from(self.nsec))
    }
}

impl std::fmt::Display for Time {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}.{:09}", self.sec, self.nsec)
    }
}
