//! A sequence of recorded point clouds as a [`DepthSource`].
//!
//! Entry points: [`CloudSequence::new`] over an explicit list, [`CloudSequence::from_directory`];
//! configured by [`CloudSequenceConfig`]. Files are read by `tacmesh_formats::read_cloud_file`
//! (PLY, PCD, XYZ). An organised file (a PCD with `HEIGHT` > 1) plays organised: every point
//! stays at its pixel, non-finite ones included, and the observation carries its
//! [`CloudGrid`], so that the daemon segments it as it does a depth image. From any other file
//! the non-finite points are dropped.

use std::path::{Path, PathBuf};

use glam::Affine3A;
use tacmesh_formats::{read_cloud_file, NonFinite};
use tacmesh_source::{monotonic_now, CloudGrid, DepthSource, Observation, PointCloud, SourceError};

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

/// Recorded point clouds replayed as [`Observation::Cloud`] stamped with [`monotonic_now`],
/// organised (with their [`CloudGrid`]) when the file is.
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
        let (cloud, grid) = read_frame(path).map_err(|e| SourceError::Malformed {
            device: self.name.clone(),
            reason: e.to_string(),
        })?;
        self.pacer.wait(None);
        tracing::trace!(
            "{}: {} points from {}{}",
            self.name,
            cloud.len(),
            path.display(),
            grid.map_or(String::new(), |g| format!(
                " (organised, {}x{})",
                g.width, g.height
            ))
        );
        Ok(Observation::Cloud {
            cloud,
            grid,
            world_from_sensor: self.config.world_from_sensor,
            capture_time: monotonic_now(),
        })
    }
}

/// One file's cloud: organised with its grid when the file is (non-finite points in place),
/// else its finite points.
fn read_frame(
    path: &Path,
) -> Result<(PointCloud, Option<CloudGrid>), tacmesh_formats::FormatError> {
    let mut file = read_cloud_file(path, NonFinite::Keep)?;
    if file.grid.is_none() && file.non_finite > 0 {
        file.cloud.retain_finite();
        tracing::debug!(
            "{}: dropped {} points with a NaN or infinite coordinate",
            path.display(),
            file.non_finite
        );
    }
    Ok((file.cloud, file.grid))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A PCD of `width` x `height` points, `nan` in the second.
    fn pcd(width: u32, height: u32) -> String {
        let points = width * height;
        let mut text = format!(
            "VERSION .7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nWIDTH {width}\nHEIGHT {height}\n\
             POINTS {points}\nDATA ascii\n"
        );
        for i in 0..points {
            text += &if i == 1 {
                "nan nan nan\n".to_owned()
            } else {
                format!("{i} 0 1\n")
            };
        }
        text
    }

    fn play_one(file_name: &str, contents: &str) -> (PointCloud, Option<CloudGrid>) {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join(file_name);
        std::fs::write(&path, contents).expect("write");
        let mut source =
            CloudSequence::new("t", vec![path], CloudSequenceConfig::default()).expect("sequence");
        match source.next_observation().expect("a cloud") {
            Observation::Cloud { cloud, grid, .. } => (cloud, grid),
            other => panic!("expected a cloud, got {other:?}"),
        }
    }

    #[test]
    fn organised_pcd_replays_organised_with_nans_in_place() {
        let (cloud, grid) = play_one("organised.pcd", &pcd(2, 2));
        assert_eq!(
            grid,
            Some(CloudGrid {
                width: 2,
                height: 2
            })
        );
        assert_eq!(cloud.len(), 4);
        assert!(cloud.points[1].is_nan());
        assert_eq!(cloud.points[3], Vec3::new(3.0, 0.0, 1.0));
    }

    #[test]
    fn unorganised_clouds_replay_as_their_finite_points() {
        let (cloud, grid) = play_one("row.pcd", &pcd(4, 1));
        assert_eq!(grid, None);
        assert_eq!(cloud.points.len(), 3);
        assert!(cloud.points.iter().all(|p| p.is_finite()));
        let (cloud, grid) = play_one("scan.xyz", "0 0 1\nnan 0 1\n2 0 1\n");
        assert_eq!((cloud.len(), grid), (2, None));
    }
}
