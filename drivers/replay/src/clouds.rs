//! A sequence of recorded point clouds as a [`DepthSource`].
//!
//! Entry points: [`CloudSequence::new`] over an explicit list, [`CloudSequence::from_directory`];
//! configured by [`CloudSequenceConfig`]. Files are read by `tacmesh_formats::read_cloud`
//! (PLY, PCD, XYZ), which drops non-finite points.

use std::path::{Path, PathBuf};

use glam::Affine3A;
use tacmesh_source::{monotonic_now, DepthSource, Observation, SourceError};

use crate::listing::list_clouds;
use crate::pacing::{Pacer, Pacing, Playhead};
use crate::ReplayError;

/// How to replay a cloud sequence.
#[derive(Debug, Clone, PartialEq)]
pub struct CloudSequenceConfig {
    /// [`Pacing::Max`] or [`Pacing::Fixed`]: cloud files carry no timestamps.
    pub pacing: Pacing,
    pub looping: bool,
    /// The pose every cloud's points are given in.
    pub world_from_sensor: Affine3A,
}

impl Default for CloudSequenceConfig {
    /// Identity pose, as fast as possible, no looping.
    fn default() -> Self {
        Self {
            pacing: Pacing::Max,
            looping: false,
            world_from_sensor: Affine3A::IDENTITY,
        }
    }
}

/// Recorded point clouds replayed as [`Observation::Cloud`] stamped with [`monotonic_now`].
///
/// A file that cannot be read is reported as [`SourceError::Malformed`]; the next call goes on
/// with the next file.
#[derive(Debug)]
pub struct CloudSequence {
    name: String,
    files: Vec<PathBuf>,
    config: CloudSequenceConfig,
    playhead: Playhead,
    pacer: Pacer,
}

impl CloudSequence {
    /// Replays `files` in order. `name` is the source's name in logs and errors.
    pub fn new(
        name: impl Into<String>,
        files: Vec<PathBuf>,
        config: CloudSequenceConfig,
    ) -> Result<Self, ReplayError> {
        let name = name.into();
        if files.is_empty() {
            return Err(ReplayError::NoFrames { name });
        }
        if config.pacing == Pacing::Recorded {
            return Err(ReplayError::NoTimestamps { name });
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

    /// Replays the clouds of a directory in file-name order (see [`crate::list_clouds`]).
    pub fn from_directory(dir: &Path, config: CloudSequenceConfig) -> Result<Self, ReplayError> {
        Self::new(
            format!("replay:{}", dir.display()),
            list_clouds(dir)?,
            config,
        )
    }

    /// The files in replay order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

impl DepthSource for CloudSequence {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let index = self.playhead.advance(&mut self.pacer, &self.name)?;
        let path = &self.files[index];
        let cloud = tacmesh_formats::read_cloud(path).map_err(|e| SourceError::Malformed {
            device: self.name.clone(),
            reason: e.to_string(),
        })?;
        self.pacer.wait(None);
        tracing::trace!(
            "{}: {} points from {}",
            self.name,
            cloud.len(),
            path.display()
        );
        Ok(Observation::Cloud {
            cloud,
            world_from_sensor: self.config.world_from_sensor,
            capture_time: monotonic_now(),
        })
    }
}
