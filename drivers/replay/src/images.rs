//! A sequence of recorded depth images as a [`DepthSource`].
//!
//! Entry points: [`ImageSequence::new`] over an explicit list, [`ImageSequence::from_directory`],
//! [`ImageSequence::from_association_file`]; configured by [`ImageSequenceConfig`].

use std::path::Path;

use glam::Affine3A;
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::decode::{read_depth_image, DepthImage, Z16Layout};
use crate::listing::{list_depth_images, read_association_file, DepthFile};
use crate::pacing::{Pacer, Pacing, Playhead};
use crate::ReplayError;

/// How to turn an image sequence into depth frames.
#[derive(Debug, Clone, PartialEq)]
pub struct ImageSequenceConfig {
    /// The camera's pinhole model; every frame must be `width` x `height`.
    pub intrinsics: Intrinsics,
    /// Metres per raw unit: 0.001 for Kinect/RealSense millimetres, 1/5000 for TUM RGB-D.
    pub depth_scale_m: f32,
    pub pacing: Pacing,
    /// Start again from the first frame after the last, instead of ending the stream.
    pub looping: bool,
    /// The sensor's pose, or the frame the per-frame poses are given in.
    pub world_from_sensor: Affine3A,
    /// Optional per-frame poses (frame `i` gets `world_from_sensor * poses[i]`), e.g. from
    /// [`crate::read_pose_file`]. There must be at least one per frame.
    pub poses: Option<Vec<Affine3A>>,
    /// Layout of `.z16`/`.raw` frames; `None` reads it from each file name.
    pub z16_layout: Option<Z16Layout>,
}

impl ImageSequenceConfig {
    /// Identity pose, as fast as possible, no looping, no per-frame poses.
    pub fn new(intrinsics: Intrinsics, depth_scale_m: f32) -> Self {
        Self {
            intrinsics,
            depth_scale_m,
            pacing: Pacing::Max,
            looping: false,
            world_from_sensor: Affine3A::IDENTITY,
            poses: None,
            z16_layout: None,
        }
    }
}

/// Recorded depth images replayed as [`Observation::Depth`] frames stamped with
/// [`monotonic_now`] when handed out.
///
/// A frame that cannot be read (missing, corrupt, wrong size) is reported as
/// [`SourceError::Malformed`]; the next call goes on with the next frame.
#[derive(Debug)]
pub struct ImageSequence {
    name: String,
    files: Vec<DepthFile>,
    config: ImageSequenceConfig,
    playhead: Playhead,
    pacer: Pacer,
}

impl ImageSequence {
    /// Replays `files` in order. `name` is the source's name in logs and errors.
    pub fn new(
        name: impl Into<String>,
        files: Vec<DepthFile>,
        config: ImageSequenceConfig,
    ) -> Result<Self, ReplayError> {
        let name = name.into();
        if files.is_empty() {
            return Err(ReplayError::NoFrames { name });
        }
        if !(config.depth_scale_m.is_finite() && config.depth_scale_m > 0.0) {
            return Err(ReplayError::InvalidConfig {
                name,
                reason: format!(
                    "depth_scale_m is {}; it must be positive metres per unit (0.001 for millimetres)",
                    config.depth_scale_m
                ),
            });
        }
        if config.pacing == Pacing::Recorded && files.iter().any(|f| f.timestamp_s.is_none()) {
            return Err(ReplayError::NoTimestamps { name });
        }
        if let Some(poses) = &config.poses {
            if poses.len() < files.len() {
                return Err(ReplayError::TooFewPoses {
                    name,
                    poses: poses.len(),
                    frames: files.len(),
                });
            }
        }
        Pacer::check(config.pacing).map_err(|reason| ReplayError::InvalidConfig {
            name: name.clone(),
            reason,
        })?;
        let pacer = Pacer::new(config.pacing);
        let playhead = Playhead::new(files.len(), config.looping);
        Ok(Self {
            playhead,
            name,
            files,
            config,
            pacer,
        })
    }

    /// Replays the depth images of a directory in file-name order (see
    /// [`crate::list_depth_images`]).
    pub fn from_directory(dir: &Path, config: ImageSequenceConfig) -> Result<Self, ReplayError> {
        Self::new(
            format!("replay:{}", dir.display()),
            list_depth_images(dir)?,
            config,
        )
    }

    /// Replays the frames of a TUM-style `depth.txt`, with their timestamps.
    pub fn from_association_file(
        path: &Path,
        config: ImageSequenceConfig,
    ) -> Result<Self, ReplayError> {
        Self::new(
            format!("replay:{}", path.display()),
            read_association_file(path)?,
            config,
        )
    }

    /// The frames in replay order.
    pub fn files(&self) -> &[DepthFile] {
        &self.files
    }

    fn malformed(&self, reason: String) -> SourceError {
        SourceError::Malformed {
            device: self.name.clone(),
            reason,
        }
    }

    /// Checks the decoded image against the intrinsics and scales it to metres.
    fn depth_m(&self, file: &DepthFile, image: DepthImage) -> Result<Vec<f32>, SourceError> {
        let Intrinsics { width, height, .. } = self.config.intrinsics;
        if (image.width, image.height) != (width, height) {
            return Err(self.malformed(format!(
                "{} is {}x{}, but the sequence is configured for {width}x{height}",
                file.path.display(),
                image.width,
                image.height
            )));
        }
        let scale = self.config.depth_scale_m;
        Ok(image.depth.iter().map(|&d| f32::from(d) * scale).collect())
    }
}

impl DepthSource for ImageSequence {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let index = self.playhead.advance(&mut self.pacer, &self.name)?;
        let file = &self.files[index];
        let image = read_depth_image(&file.path, self.config.z16_layout)
            .map_err(|e| self.malformed(e.to_string()))?;
        let depth_m = self.depth_m(file, image)?;
        let pose = self
            .config
            .poses
            .as_ref()
            .map_or(Affine3A::IDENTITY, |p| p[index]);
        self.pacer.wait(file.timestamp_s);
        tracing::trace!("{}: frame {index} from {}", self.name, file.path.display());
        Ok(Observation::Depth(DepthFrame {
            intrinsics: self.config.intrinsics,
            depth_m,
            world_from_sensor: self.config.world_from_sensor * pose,
            capture_time: monotonic_now(),
        }))
    }
}
