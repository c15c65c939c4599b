//! A sequence of recorded depth images as a [`DepthSource`].
//!
//! Entry points: [`ImageSequence::new`] over an explicit list, [`ImageSequence::from_directory`],
//! [`ImageSequence::from_association_file`]; configured by [`ImageSequenceConfig`].

use std::path::Path;

use glam::Affine3A;
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::cache::{FrameCache, DEFAULT_LOOP_CACHE_BYTES};
use crate::decode::{read_depth_image, DecodeError, Z16Layout};
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
    /// When looping, decoded frames (depth in metres) are kept in memory up to this many
    /// bytes, so that later passes copy them instead of decoding their files again (see
    /// [`DEFAULT_LOOP_CACHE_BYTES`]).
    pub loop_cache_bytes: usize,
}

impl ImageSequenceConfig {
    /// Identity pose, as fast as possible, no looping, no per-frame poses, a 64 MiB loop
    /// cache.
    pub fn new(intrinsics: Intrinsics, depth_scale_m: f32) -> Self {
        Self {
            intrinsics,
            depth_scale_m,
            pacing: Pacing::Max,
            looping: false,
            world_from_sensor: Affine3A::IDENTITY,
            poses: None,
            z16_layout: None,
            loop_cache_bytes: DEFAULT_LOOP_CACHE_BYTES,
        }
    }
}

/// Recorded depth images replayed as [`Observation::Depth`] frames stamped with
/// [`monotonic_now`] when handed out.
///
/// A frame that cannot be read (missing, corrupt, wrong size) is reported as
/// [`SourceError::Malformed`] (on every pass); the next call goes on with the next frame. A
/// looping sequence keeps its decoded frames, within [`ImageSequenceConfig::loop_cache_bytes`].
#[derive(Debug)]
pub struct ImageSequence {
    name: String,
    files: Vec<DepthFile>,
    config: ImageSequenceConfig,
    playhead: Playhead,
    pacer: Pacer,
    /// Each frame's depth in metres.
    decoded: FrameCache<Vec<f32>>,
    /// The first frame's depth, read when the sequence was made, until it is played.
    first: Option<Vec<f32>>,
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
        config
            .intrinsics
            .check_plausible()
            .map_err(|reason| ReplayError::InvalidConfig {
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
        let first = read_depth_m(&files[0], &config).map_err(|e| ReplayError::FirstFrame {
            name: name.clone(),
            reason: e.to_string(),
        })?;
        check_depth_scale(&first, &config).map_err(|reason| ReplayError::FirstFrame {
            name: name.clone(),
            reason,
        })?;
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
}

/// The farthest a depth camera of this kind reads, metres: a first frame whose depths are all
/// beyond it is in other units than `depth_scale_m` says.
const FARTHEST_DEPTH_M: f32 = 20.0;

/// Refuses a first frame with no depth at all, or whose every depth is beyond
/// [`FARTHEST_DEPTH_M`] (a depth scale off by a factor: TUM RGB-D's 1/5000 read as
/// millimetres is 5 times too far, its 16-bit values read as metres 1000 times).
fn check_depth_scale(depth_m: &[f32], config: &ImageSequenceConfig) -> Result<(), String> {
    let valid = || depth_m.iter().copied().filter(|&d| d > 0.0);
    if valid().next().is_none() {
        return Err("every pixel is 0 (no depth): is this a depth image?".to_owned());
    }
    if valid().all(|d| d > FARTHEST_DEPTH_M) {
        // Only to say how far: a first frame that passes is not sorted.
        let mut far: Vec<f32> = valid().collect();
        let middle = far.len() / 2;
        let median = *far.select_nth_unstable_by(middle, f32::total_cmp).1;
        return Err(format!(
            "every depth is beyond {FARTHEST_DEPTH_M} m (median {median:.1} m) at \
             depth_scale_m={}: is the scale right? (0.001 for millimetres, 0.0002 for TUM RGB-D)",
            config.depth_scale_m
        ));
    }
    Ok(())
}

/// Why a frame of the sequence is malformed.
#[derive(Debug, thiserror::Error)]
enum BadFrame {
    #[error(transparent)]
    Decode(#[from] DecodeError),
    #[error("{name} is {found_width}x{found_height}, but the sequence is configured for {width}x{height}")]
    WrongSize {
        name: String,
        found_width: u32,
        found_height: u32,
        width: u32,
        height: u32,
    },
}

/// Reads and decodes a frame, checks it against the intrinsics and scales it to metres.
fn read_depth_m(file: &DepthFile, config: &ImageSequenceConfig) -> Result<Vec<f32>, BadFrame> {
    let image = read_depth_image(&file.path, config.z16_layout)?;
    let Intrinsics { width, height, .. } = config.intrinsics;
    if (image.width, image.height) != (width, height) {
        return Err(BadFrame::WrongSize {
            name: file.path.display().to_string(),
            found_width: image.width,
            found_height: image.height,
            width,
            height,
        });
    }
    let scale = config.depth_scale_m;
    Ok(image.depth.iter().map(|&d| f32::from(d) * scale).collect())
}

impl DepthSource for ImageSequence {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let index = self.playhead.advance(&mut self.pacer, &self.name)?;
        let file = &self.files[index];
        let config = &self.config;
        let first = if index == 0 { self.first.take() } else { None };
        let depth_m = self
            .decoded
            .get_or_decode(index, &self.name, || {
                first.map_or_else(|| read_depth_m(file, config), Ok)
            })
            .map_err(|e| SourceError::Malformed {
                device: self.name.clone(),
                reason: e.to_string(),
            })?;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16-bit PGM of one row.
    fn pgm(depth: &[u16]) -> Vec<u8> {
        let mut bytes = format!("P5 {} 1 65535\n", depth.len()).into_bytes();
        for d in depth {
            bytes.extend(d.to_be_bytes());
        }
        bytes
    }

    fn looping(width: u32, loop_cache_bytes: usize) -> ImageSequenceConfig {
        let intrinsics = Intrinsics {
            width,
            height: 1,
            fx: 1.0,
            fy: 1.0,
            cx: 0.0,
            cy: 0.0,
        };
        ImageSequenceConfig {
            looping: true,
            loop_cache_bytes,
            ..ImageSequenceConfig::new(intrinsics, 1.0)
        }
    }

    /// The depth of `n` calls, or the error's text.
    fn play(source: &mut ImageSequence, n: usize) -> Vec<Result<Vec<f32>, String>> {
        (0..n)
            .map(|_| match source.next_observation() {
                Ok(Observation::Depth(frame)) => Ok(frame.depth_m),
                Ok(other) => panic!("expected a depth frame, got {other:?}"),
                Err(err) => Err(err.to_string()),
            })
            .collect()
    }

    #[test]
    fn a_looped_replay_plays_kept_frames_again_and_reads_the_rest() {
        let dir = tempfile::tempdir().expect("temp dir");
        let paths = [dir.path().join("0.pgm"), dir.path().join("1.pgm")];
        std::fs::write(&paths[0], pgm(&[1, 2])).expect("write");
        std::fs::write(&paths[1], pgm(&[3, 0])).expect("write");
        let files = paths.iter().map(DepthFile::new).collect();
        // A frame is two f32: room for the first only.
        let mut source = ImageSequence::new("t", files, looping(2, 12)).expect("sequence");
        let first = play(&mut source, 2);
        assert_eq!(first, [Ok(vec![1.0, 2.0]), Ok(vec![3.0, 0.0])]);
        assert_eq!(source.decoded.kept(), 1);
        std::fs::write(&paths[0], pgm(&[9, 9])).expect("rewrite");
        std::fs::write(&paths[1], pgm(&[4, 4])).expect("rewrite");
        // The kept frame is the same; the one past the budget is read again.
        assert_eq!(
            play(&mut source, 2),
            [Ok(vec![1.0, 2.0]), Ok(vec![4.0, 4.0])]
        );
    }

    #[test]
    fn a_bad_frame_in_a_looped_replay_is_an_error_on_every_pass() {
        let dir = tempfile::tempdir().expect("temp dir");
        let good = dir.path().join("good.pgm");
        let wide = dir.path().join("wide.pgm");
        std::fs::write(&good, pgm(&[1, 2])).expect("write");
        std::fs::write(&wide, pgm(&[1, 2, 3])).expect("write");
        let files = vec![DepthFile::new(good), DepthFile::new(wide)];
        let mut source = ImageSequence::new("t", files, looping(2, 1 << 20)).expect("sequence");
        for _pass in 0..3 {
            let played = play(&mut source, 2);
            assert_eq!(played[0], Ok(vec![1.0, 2.0]));
            let err = played[1].as_ref().expect_err("wide.pgm is the wrong size");
            assert!(err.contains("wide.pgm is 3x1"), "{err}");
        }
        assert_eq!(source.decoded.kept(), 1);
    }
}
