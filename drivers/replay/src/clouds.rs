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

use crate::cache::{FrameCache, HeapBytes, DEFAULT_LOOP_CACHE_BYTES};
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
    /// When looping, decoded clouds are kept in memory up to this many bytes, so that later
    /// passes copy them instead of decoding their files again (see [`DEFAULT_LOOP_CACHE_BYTES`]).
    pub loop_cache_bytes: usize,
}

impl Default for CloudSequenceConfig {
    /// Identity pose, as fast as possible, no looping, a 64 MiB loop cache.
    fn default() -> Self {
        Self {
            pacing: Pacing::Max,
            looping: false,
            world_from_sensor: Affine3A::IDENTITY,
            loop_cache_bytes: DEFAULT_LOOP_CACHE_BYTES,
        }
    }
}

/// Recorded point clouds replayed as [`Observation::Cloud`] stamped with [`monotonic_now`],
/// organised (with their [`CloudGrid`]) when the file is.
///
/// A file that cannot be read is reported as [`SourceError::Malformed`] (on every pass); the
/// next call goes on with the next file. A looping sequence keeps its decoded clouds, within
/// [`CloudSequenceConfig::loop_cache_bytes`].
#[derive(Debug)]
pub struct CloudSequence {
    name: String,
    files: Vec<PathBuf>,
    config: CloudSequenceConfig,
    playhead: Playhead,
    pacer: Pacer,
    decoded: FrameCache<Frame>,
    /// The first file's cloud, read when the sequence was made, until it is played.
    first: Option<Frame>,
}

/// One file's cloud as it is played: organised with its grid when the file is.
#[derive(Debug, Clone)]
struct Frame {
    cloud: PointCloud,
    grid: Option<CloudGrid>,
}

impl HeapBytes for Frame {
    fn heap_bytes(&self) -> usize {
        self.cloud.points.heap_bytes() + self.cloud.normals.as_ref().map_or(0, Vec::heap_bytes)
    }
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
        let cache_bytes = if config.looping {
            config.loop_cache_bytes
        } else {
            0
        };
        let decoded = FrameCache::new(files.len(), cache_bytes);
        let first = read_frame(&files[0]).map_err(|e| ReplayError::FirstFrame {
            name: name.clone(),
            reason: e.to_string(),
        })?;
        if !first.cloud.points.iter().any(|p| p.is_finite()) {
            return Err(ReplayError::FirstFrame {
                name,
                reason: format!("{} holds no finite point", files[0].display()),
            });
        }
        Ok(Self {
            playhead,
            name,
            files,
            config,
            pacer,
            decoded,
            first: Some(first),
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
        let first = if index == 0 { self.first.take() } else { None };
        let Frame { cloud, grid } = self
            .decoded
            .get_or_decode(index, &self.name, || {
                first.map_or_else(|| read_frame(path), Ok)
            })
            .map_err(|e| SourceError::Malformed {
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
fn read_frame(path: &Path) -> Result<Frame, tacmesh_formats::FormatError> {
    let mut file = read_cloud_file(path, NonFinite::Keep)?;
    if file.grid.is_none() && file.non_finite > 0 {
        file.cloud.retain_finite();
        tracing::debug!(
            "{}: dropped {} points with a NaN or infinite coordinate",
            path.display(),
            file.non_finite
        );
    }
    Ok(Frame {
        cloud: file.cloud,
        grid: file.grid,
    })
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

    /// The clouds of `n` calls, or the error's text.
    fn play(source: &mut CloudSequence, n: usize) -> Vec<Result<PointCloud, String>> {
        (0..n)
            .map(|_| match source.next_observation() {
                Ok(Observation::Cloud { cloud, .. }) => Ok(cloud),
                Ok(other) => panic!("expected a cloud, got {other:?}"),
                Err(err) => Err(err.to_string()),
            })
            .collect()
    }

    fn looping(loop_cache_bytes: usize) -> CloudSequenceConfig {
        CloudSequenceConfig {
            looping: true,
            loop_cache_bytes,
            ..CloudSequenceConfig::default()
        }
    }

    #[test]
    fn a_looped_replay_plays_its_kept_clouds_again_without_reading_them() {
        let dir = tempfile::tempdir().expect("temp dir");
        let files = vec![dir.path().join("a.pcd"), dir.path().join("b.xyz")];
        std::fs::write(&files[0], pcd(2, 2)).expect("write");
        std::fs::write(&files[1], "0 0 1\n1 0 1\n").expect("write");
        let mut source = CloudSequence::new("t", files.clone(), looping(1 << 20)).expect("seq");
        let first = play(&mut source, 2);
        // Later passes copy what the first decoded: the files are not read again.
        for file in &files {
            std::fs::remove_file(file).expect("remove");
        }
        for _pass in 0..2 {
            let again = play(&mut source, 2);
            // NaN != NaN: compare the organised cloud's points bit for bit.
            let bits = |r: &[Result<PointCloud, String>]| -> Vec<Vec<[u32; 3]>> {
                r.iter()
                    .map(|c| {
                        let c = c.as_ref().expect("a cloud");
                        c.points
                            .iter()
                            .map(|p| p.to_array().map(f32::to_bits))
                            .collect()
                    })
                    .collect()
            };
            assert_eq!(bits(&again), bits(&first));
        }
    }

    #[test]
    fn clouds_past_the_loop_budget_are_read_on_every_pass() {
        let dir = tempfile::tempdir().expect("temp dir");
        let files = vec![dir.path().join("a.xyz"), dir.path().join("b.xyz")];
        for file in &files {
            std::fs::write(file, "0 0 1\n").expect("write");
        }
        // One point is 12 bytes: room for the first file's cloud only.
        let mut source = CloudSequence::new("t", files.clone(), looping(20)).expect("seq");
        play(&mut source, 2);
        assert_eq!(source.decoded.kept(), 1);
        for file in &files {
            std::fs::write(file, "0 0 1\n0 0 2\n").expect("rewrite");
        }
        let lens: Vec<usize> = play(&mut source, 2)
            .into_iter()
            .map(|c| c.expect("a cloud").len())
            .collect();
        assert_eq!(lens, [1, 2], "the first is kept, the second read again");
        // A replay that does not loop keeps nothing.
        let mut once = CloudSequence::new("t", files, CloudSequenceConfig::default()).expect("seq");
        play(&mut once, 2);
        assert_eq!(once.decoded.kept(), 0);
    }

    #[test]
    fn a_bad_file_in_a_looped_replay_is_an_error_on_every_pass() {
        let dir = tempfile::tempdir().expect("temp dir");
        let files = vec![dir.path().join("good.xyz"), dir.path().join("bad.pcd")];
        std::fs::write(&files[0], "0 0 1\n").expect("write");
        std::fs::write(&files[1], "VERSION .7\nFIELDS x y z\n").expect("write");
        let mut source = CloudSequence::new("t", files, looping(1 << 20)).expect("seq");
        for _pass in 0..3 {
            let played = play(&mut source, 2);
            assert_eq!(played[0].as_ref().map(PointCloud::len), Ok(1));
            let err = played[1].as_ref().expect_err("bad.pcd is malformed");
            assert!(
                err.contains("malformed") && err.contains("bad.pcd"),
                "{err}"
            );
        }
        assert_eq!(source.decoded.kept(), 1);
    }
}
