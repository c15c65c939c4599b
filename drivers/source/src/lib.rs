//! The types that flow out of every tacmesh depth source, and the trait a source implements.
//!
//! Entry points:
//! - [`DepthSource`]: a backend that yields timestamped [`Observation`]s.
//! - [`DepthFrame`] with its [`Intrinsics`]: one organised depth image from a camera.
//! - [`PointCloud`]: points (and optional normals) in metres, in one named frame; with a
//!   [`CloudGrid`] when it is organised.
//! - [`TriMesh`]: an indexed triangle mesh in metres.
//! - [`floor_i32`], [`floor_ivec3`]: grid indices of coordinates, without a call to `floorf`.
//! - [`read_regular_file`]: a file named from outside, refused when it is not a regular file or
//!   larger than its kind's cap.
//! - [`monotonic_now`]: the host's monotonic clock, on which every capture time is read;
//!   [`realtime_now_ns`], [`realtime_of`]: the wall clock, for clients on other hosts.
//!
//! This crate is a leaf: backends, the simulator and the daemon depend on it, it depends on
//! nothing of theirs.

mod clock;
mod cloud;
mod file;
mod floor;
mod frame;
mod mesh;
mod source;

pub use clock::{monotonic_now, now_on_both_clocks_ns, realtime_now_ns, realtime_of};
pub use cloud::{CloudGrid, PointCloud};
pub use file::{check_regular_file, read_regular_file, read_regular_text};
pub use floor::{floor_i32, floor_ivec3};
pub use frame::{Deprojection, DepthFrame, FrameError, Intrinsics};
pub use mesh::TriMesh;
pub use source::{DepthSource, Observation, SourceError};

/// Re-exported so that users of these types agree on one `glam` version.
pub use glam;
