//! [`OniReplay`]: a recording played back as a [`DepthSource`].

use std::path::Path;
use std::time::{Duration, Instant};

use tacmesh_source::glam::Affine3A;
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::{OniError, OniRecording};

/// Longest pause between two frames when pacing; a larger gap in the recorded timestamps is
/// treated as a glitch rather than waited out.
const MAX_PACING_SLEEP: Duration = Duration::from_secs(2);

/// How fast frames are delivered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pacing {
    /// Sleep so that frames leave as far apart as their recorded timestamps.
    #[default]
    Recorded,
    /// Deliver each frame as soon as it is decoded.
    AsFastAsRead,
}

/// What happens after the last frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum AtEnd {
    /// Start again from the first frame.
    Loop,
    /// Report [`SourceError::EndOfStream`] from then on.
    #[default]
    Stop,
}

/// Replay settings.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ReplayOptions {
    pub pacing: Pacing,
    pub at_end: AtEnd,
    /// Pose given to every frame (the recording has none).
    pub world_from_sensor: Affine3A,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        Self {
            pacing: Pacing::default(),
            at_end: AtEnd::default(),
            world_from_sensor: Affine3A::IDENTITY,
        }
    }
}

/// Plays an `.oni` recording's depth frames as [`Observation::Depth`], depth in metres,
/// intrinsics from the file, `capture_time` read at delivery.
pub struct OniReplay {
    name: String,
    recording: OniRecording,
    intrinsics: Intrinsics,
    options: ReplayOptions,
    next_frame: usize,
    /// Recorded timestamp and wall-clock instant of the last delivered frame.
    last_delivery: Option<(u64, Instant)>,
}

impl OniReplay {
    /// Opens and indexes `path`. Fails if it is not a readable recording with a `16zT` depth
    /// node that has at least one frame.
    pub fn open(path: impl AsRef<Path>, options: ReplayOptions) -> Result<Self, OniError> {
        let path = path.as_ref();
        let recording = OniRecording::open(path)?;
        let intrinsics =
            recording
                .depth()
                .intrinsics()
                .ok_or_else(|| OniError::MissingProperty {
                    file: recording.file().to_owned(),
                    node: recording.depth().node_name.clone(),
                    what: "usable intrinsics",
                })?;
        Ok(Self {
            name: format!("replay:{}", path.display()),
            recording,
            intrinsics,
            options,
            next_frame: 0,
            last_delivery: None,
        })
    }

    pub fn recording(&self) -> &OniRecording {
        &self.recording
    }

    fn end_of_stream(&self) -> SourceError {
        SourceError::EndOfStream {
            device: self.name.clone(),
        }
    }

    /// Sleeps until `timestamp_us` is as far after the last delivered frame's timestamp in
    /// wall time as it is in recorded time.
    fn pace(&self, timestamp_us: u64) {
        let Some((last_us, last_at)) = self.last_delivery else {
            return;
        };
        let gap = Duration::from_micros(timestamp_us.saturating_sub(last_us));
        if gap > MAX_PACING_SLEEP {
            tracing::warn!(
                source = %self.name,
                gap_ms = gap.as_millis(),
                "recorded frame gap too long to wait out; delivering at once"
            );
            return;
        }
        let due = last_at + gap;
        let now = Instant::now();
        if due > now {
            std::thread::sleep(due - now);
        }
    }
}

impl DepthSource for OniReplay {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let frame_count = self.recording.depth().frames.len();
        if self.next_frame >= frame_count {
            if self.options.at_end == AtEnd::Stop || frame_count == 0 {
                return Err(self.end_of_stream());
            }
            tracing::debug!(source = %self.name, "looping to the first frame");
            self.next_frame = 0;
            self.last_delivery = None;
        }
        let index = self.next_frame;
        // Advance first: a frame that fails to decode is reported once, then skipped.
        self.next_frame += 1;
        let timestamp_us = self.recording.depth().frames[index].timestamp_us;
        let depth_mm = self
            .recording
            .read_depth_mm(index)
            .map_err(|err| match err {
                OniError::Io { .. } => SourceError::Disconnected {
                    device: self.name.clone(),
                    reason: err.to_string(),
                },
                _ => SourceError::Malformed {
                    device: self.name.clone(),
                    reason: err.to_string(),
                },
            })?;
        if self.options.pacing == Pacing::Recorded {
            self.pace(timestamp_us);
        }
        self.last_delivery = Some((timestamp_us, Instant::now()));
        tracing::trace!(source = %self.name, index, timestamp_us, "depth frame");
        Ok(Observation::Depth(DepthFrame {
            intrinsics: self.intrinsics,
            depth_m: depth_mm.iter().map(|&mm| f32::from(mm) * 0.001).collect(),
            world_from_sensor: self.options.world_from_sensor,
            capture_time: monotonic_now(),
        }))
    }
}
