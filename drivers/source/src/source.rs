use std::time::Duration;

use glam::Affine3A;

use crate::{CloudGrid, DepthFrame, PointCloud};

/// What a source yields: an organised depth image or an already-deprojected cloud
/// (range scanners, recorded clouds).
#[derive(Debug, Clone, PartialEq)]
pub enum Observation {
    Depth(DepthFrame),
    Cloud {
        cloud: PointCloud,
        /// `Some` when the cloud is organised (a recorded organised PCD): one point per pixel
        /// of the grid, non-finite where there was no reading ([`CloudGrid::check`] tells
        /// whether it fits). `None`: a plain set of points (a range scanner's revolution, a
        /// PLY or XYZ file).
        grid: Option<CloudGrid>,
        world_from_sensor: Affine3A,
        capture_time: Duration,
    },
}

/// Why a source could not deliver.
#[derive(Debug, thiserror::Error)]
pub enum SourceError {
    #[error("no device {device}: {hint}")]
    DeviceMissing { device: String, hint: String },
    #[error("device {device} stopped delivering: {reason}")]
    Disconnected { device: String, reason: String },
    #[error("malformed frame from {device}: {reason}")]
    Malformed { device: String, reason: String },
    #[error("{device} has no more frames")]
    EndOfStream { device: String },
}

/// A backend that yields timestamped observations with their intrinsics and sensor pose.
pub trait DepthSource: Send {
    /// A short human name for logs, e.g. `sim:tabletop` or `v4l2:/dev/video2`.
    fn name(&self) -> &str;

    /// Blocks until the next observation is ready.
    fn next_observation(&mut self) -> Result<Observation, SourceError>;
}
