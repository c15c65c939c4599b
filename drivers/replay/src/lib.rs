//! Recorded depth images and point clouds replayed as tacmesh depth sources.
//!
//! Entry points:
//! - [`ReplaySpec`]: what to replay, from `PATH?key=value&...` ([`ReplaySpec::parse`]) or a
//!   serde table; [`ReplaySpec::open`] gives a [`ReplaySource`], a [`DepthSource`].
//! - [`ImageSequence`]: depth images (16-bit PNG, TIFF, PGM, raw Z16) as
//!   [`Observation::Depth`](tacmesh_source::Observation::Depth) frames.
//! - [`CloudSequence`]: PLY/PCD/XYZ files as
//!   [`Observation::Cloud`](tacmesh_source::Observation::Cloud); an organised PCD (one with
//!   `HEIGHT` > 1) plays organised, with its [`CloudGrid`](tacmesh_source::CloudGrid) and its
//!   non-finite points in place, so that the daemon segments it as it does a depth image.
//! - [`decode`]: the pure depth image decoders ([`read_depth_image`] and one per format).
//! - [`list_depth_images`], [`read_association_file`], [`read_pose_file`]: which files play,
//!   with which timestamps and poses.
//!
//! # Replay specs
//!
//! `PATH?key=value&key=value` (or the same keys in a TOML table with `path`). Unknown keys are
//! an error.
//!
//! | key | meaning | default |
//! |---|---|---|
//! | `path` | a depth image, a cloud, a directory of either, or a TUM `depth.txt` | required |
//! | `kind` | `images` or `clouds` | from the path (below) |
//! | `fx`, `fy`, `cx`, `cy` | pinhole intrinsics in pixels | required for images |
//! | `width`, `height` | image size in pixels; needed for `.z16` files not named `_WxH` | read from the first frame |
//! | `row_stride_bytes` | bytes per row of a `.z16` frame, padding included | `2 * width` |
//! | `depth_scale_m` | metres per raw depth unit: 0.001 for Kinect/RealSense millimetres, 0.0002 for TUM RGB-D | 0.001 |
//! | `rate` | `recorded` (needs timestamps), `max`, or frames per second | `recorded` with timestamps, else `max` |
//! | `loop` | `true` to start over after the last frame (`loop` alone means `true`) | `false` |
//! | `poses` | a pose file, `tx ty tz qx qy qz qw` per line, one per frame (slambook `pose.txt`) | none |
//! | `world_from_sensor` | `tx,ty,tz,qx,qy,qz,qw`; per-frame poses are composed after it | identity |
//!
//! The kind comes from the path: a directory with a `depth.txt` plays that association file;
//! otherwise a directory's depth images (`.png`, `.tif`, `.tiff`, `.pgm`, `.z16`, `.raw`, minus
//! names containing `rgb`/`color`/`colour`) in name order, or if there are none its clouds
//! (`.ply`, `.pcd`, `.xyz`, `.pts`). A single file plays as a one-frame sequence; a `.txt`
//! whose first line is "timestamp image-file" is an association file, any other `.txt` an
//! XYZ cloud. `.oni` and `.bag` recordings are played by `tacmesh-oni` and `tacmesh-rosbag`;
//! here they give [`ReplayError::NotASequence`].
//!
//! A frame that cannot be read mid-sequence (missing, corrupt, wrong size) is reported as
//! [`SourceError::Malformed`](tacmesh_source::SourceError::Malformed) and the next call goes on
//! with the next frame; the end of a non-looping sequence is
//! [`SourceError::EndOfStream`](tacmesh_source::SourceError::EndOfStream).
//!
//! A looping sequence keeps the frames it has decoded in memory, up to
//! [`DEFAULT_LOOP_CACHE_BYTES`] (64 MiB; `loop_cache_bytes` in [`ImageSequenceConfig`] and
//! [`CloudSequenceConfig`]), so that later passes copy them instead of decoding their files
//! again; frames past the budget are decoded on every pass. A frame that cannot be read is
//! never kept, and is reported on every pass.

mod cache;
mod clouds;
pub mod decode;
mod images;
mod listing;
mod pacing;
mod spec;

pub use cache::DEFAULT_LOOP_CACHE_BYTES;
pub use clouds::{CloudSequence, CloudSequenceConfig};
pub use decode::{read_depth_image, DecodeError, DepthImage, Z16Layout};
pub use images::{ImageSequence, ImageSequenceConfig};
pub use listing::{
    is_cloud_path, list_clouds, list_depth_images, looks_like_association_file,
    read_association_file, read_pose_file, DepthFile,
};
pub use pacing::Pacing;
pub use spec::{
    handled_elsewhere, Rate, ReplayInput, ReplayKind, ReplaySource, ReplaySpec,
    DEFAULT_DEPTH_SCALE_M,
};

#[cfg(doc)]
use tacmesh_source::DepthSource;

/// Why a replay could not be set up. (Per-frame trouble during replay is a
/// [`tacmesh_source::SourceError`].)
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Decode(#[from] DecodeError),
    #[error("{name}: cannot {action}: {error}")]
    Io {
        name: String,
        action: &'static str,
        error: std::io::Error,
    },
    /// A line of an association or pose file.
    #[error("{name} line {line}: {reason}")]
    ListFile {
        name: String,
        line: usize,
        reason: String,
    },
    #[error("{name}: no frames to replay (no depth images or clouds found)")]
    NoFrames { name: String },
    #[error("{name}: not an image or cloud sequence; recordings of this kind are played by {handled_by}")]
    NotASequence {
        name: String,
        handled_by: &'static str,
    },
    #[error(
        "{name}: cannot tell what to replay; give a depth image (.png .tif .tiff .pgm .z16 .raw), \
         a cloud (.ply .pcd .xyz .pts), a directory of them or a TUM depth.txt, or set kind"
    )]
    UnknownKind { name: String },
    #[error("{name}: depth images need intrinsics: give fx, fy, cx and cy in pixels")]
    MissingIntrinsics { name: String },
    #[error(
        "{name}: rate \"recorded\" needs per-frame timestamps (a TUM depth.txt); \
         use rate=max or a frames-per-second rate"
    )]
    NoTimestamps { name: String },
    #[error("{name}: {poses} poses for {frames} frames; the pose file needs a line per frame")]
    TooFewPoses {
        name: String,
        poses: usize,
        frames: usize,
    },
    #[error("{name}: {reason}")]
    InvalidConfig { name: String, reason: String },
    /// The first frame cannot be played: a recording that would serve nothing fails the start,
    /// as an unreadable `.oni` or `.bag` does (a bad frame later is skipped and counted).
    #[error("{name}: its first frame cannot be played, so nothing would be served: {reason}")]
    FirstFrame { name: String, reason: String },
    #[error("replay spec {spec:?}: {reason}")]
    Spec { spec: String, reason: String },
}
