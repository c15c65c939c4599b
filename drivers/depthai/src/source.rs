//! [`DepthAiSource`]: an OAK camera's stereo depth, or a DepthAI recording, as a
//! [`DepthSource`]; and [`record_depth_frames`], which writes a recording without a camera.

use std::path::Path;
use std::time::Duration;

use crossbeam_channel::{Receiver, RecvTimeoutError};
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::frame::{depth_frame, intrinsics_from_matrix, raw16_from_metres, RawDepthImage};
use crate::interpreter::{Delivery, Interpreter, RecordFrame};
use crate::options::{DepthAiOptions, Mode};
use crate::DepthAiError;

/// How long dropping a source waits for its pipeline to stop.
const STOP_PATIENCE: Duration = Duration::from_secs(5);
/// A device timestamp further than this from the host clock is not trusted as a capture time.
const CLOCK_SLACK: Duration = Duration::from_secs(5);

/// A DepthAI stereo-depth stream (or recording) delivering [`DepthFrame`]s.
///
/// Opening starts (once per process) the thread that owns the embedded Python interpreter and
/// asks it to build the pipeline; reading takes the frames it copied out. Dropping the source
/// stops the pipeline and waits for it.
pub struct DepthAiSource {
    name: String,
    id: u64,
    interpreter: &'static Interpreter,
    frames: Receiver<Delivery>,
    options: DepthAiOptions,
    /// From the device calibration (live), else each frame's own.
    calibrated: Option<Intrinsics>,
    frames_read: u64,
    ended: bool,
}

impl std::fmt::Debug for DepthAiSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DepthAiSource")
            .field("name", &self.name)
            .field("id", &self.id)
            .field("frames_read", &self.frames_read)
            .finish()
    }
}

impl DepthAiSource {
    /// Opens the camera or recording `options` name. A missing camera fails once DepthAI's
    /// search (`search_timeout_ms`) gives up, with [`DepthAiError::NoDevice`].
    pub fn open(options: DepthAiOptions) -> Result<Self, DepthAiError> {
        if let Mode::Replay(replay) = &options.mode {
            if !replay.path.is_file() {
                return Err(DepthAiError::Recording {
                    path: replay.path.clone(),
                    reason: "no such file".into(),
                });
            }
        }
        let interpreter = Interpreter::get(options.venv.as_deref())?;
        let (opened, frames) = interpreter.open(&options)?;
        Ok(Self {
            name: format!("depthai:{}", opened.name),
            id: opened.id,
            interpreter,
            frames,
            calibrated: opened.intrinsics,
            options,
            frames_read: 0,
            ended: false,
        })
    }

    /// Starts the embedded interpreter with `venv` if no source has yet, and returns the
    /// versions of its Python and of DepthAI: a check that the installation works.
    pub fn versions(venv: Option<&Path>) -> Result<(String, String), DepthAiError> {
        Interpreter::get(venv).map(|i| (i.python.clone(), i.depthai.clone()))
    }

    /// The intrinsics of a live camera, from its calibration.
    pub fn calibrated_intrinsics(&self) -> Option<Intrinsics> {
        self.calibrated
    }

    fn decode(&self, raw: &RawDepthImage) -> Result<DepthFrame, DepthAiError> {
        let intrinsics = match (self.calibrated, raw.intrinsic_matrix, &self.options.mode) {
            (Some(calibrated), _, _) => calibrated,
            (None, Some(matrix), _) => intrinsics_from_matrix(matrix, raw.width, raw.height)?,
            (None, None, Mode::Replay(replay)) => match replay.intrinsics {
                Some(given) => Intrinsics {
                    width: raw.width,
                    height: raw.height,
                    ..given
                },
                None => {
                    return Err(DepthAiError::NoIntrinsics {
                        reason: format!("frame {} carries no transformation", raw.sequence),
                    })
                }
            },
            (None, None, Mode::Live(_)) => {
                return Err(DepthAiError::NoIntrinsics {
                    reason: "the device reported no calibration".into(),
                })
            }
        };
        let capture_time = match self.options.mode {
            Mode::Live(_) => host_capture_time(raw.timestamp, monotonic_now()),
            // A recording's timestamps are from when it was made.
            Mode::Replay(_) => monotonic_now(),
        };
        depth_frame(
            raw,
            intrinsics,
            self.options.world_from_sensor,
            capture_time,
        )
    }
}

/// The frame's own timestamp (DepthAI's host-synchronised `steady_clock`, our
/// `CLOCK_MONOTONIC`) if it is plausible, else the time it was read.
fn host_capture_time(stamped: Duration, now: Duration) -> Duration {
    if stamped > Duration::ZERO && stamped <= now && now - stamped < CLOCK_SLACK {
        stamped
    } else {
        now
    }
}

impl DepthSource for DepthAiSource {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        if self.ended {
            return Err(SourceError::EndOfStream {
                device: self.name.clone(),
            });
        }
        let timeout = Duration::from_millis(u64::from(self.options.frame_timeout_ms));
        match self.frames.recv_timeout(timeout) {
            Ok(Delivery::Frame(raw)) => {
                self.frames_read += 1;
                let frame = self
                    .decode(&raw)
                    .map_err(|e| e.into_source_error(&self.name))?;
                Ok(Observation::Depth(frame))
            }
            Ok(Delivery::End) => {
                self.ended = true;
                Err(SourceError::EndOfStream {
                    device: self.name.clone(),
                })
            }
            Ok(Delivery::Failed(err)) => {
                self.ended = true;
                Err(match err.into_source_error(&self.name) {
                    SourceError::DeviceMissing { device, hint } => SourceError::Disconnected {
                        device,
                        reason: hint,
                    },
                    other => other,
                })
            }
            Err(RecvTimeoutError::Timeout) => Err(SourceError::Disconnected {
                device: self.name.clone(),
                reason: format!(
                    "no depth frame for {} ms (frame_timeout_ms); is the camera still connected?",
                    self.options.frame_timeout_ms
                ),
            }),
            Err(RecvTimeoutError::Disconnected) => {
                self.ended = true;
                Err(SourceError::Disconnected {
                    device: self.name.clone(),
                    reason: "the DepthAI interpreter thread closed the stream".into(),
                })
            }
        }
    }
}

impl Drop for DepthAiSource {
    fn drop(&mut self) {
        self.interpreter.close(self.id, STOP_PATIENCE);
    }
}

/// Writes `frames` into a DepthAI `.mcap` recording at `path` with DepthAI's own recorder
/// (`dai.node.RecordMessage`, host-only: no camera needed), as StereoDepth would deliver them:
/// RAW16 millimetres with each frame's pinhole matrix. Returns the number of frames written.
/// `venv` is as in [`DepthAiOptions::venv`].
pub fn record_depth_frames(
    path: &Path,
    venv: Option<&Path>,
    frames: &[DepthFrame],
) -> Result<usize, DepthAiError> {
    let interpreter = Interpreter::get(venv)?;
    let start = frames.first().map_or(Duration::ZERO, |f| f.capture_time);
    let frames = frames
        .iter()
        .enumerate()
        .map(|(i, frame)| RecordFrame {
            raw16: raw16_from_metres(&frame.depth_m),
            intrinsics: frame.intrinsics,
            sequence: i as i64,
            timestamp: frame.capture_time.saturating_sub(start),
        })
        .collect();
    interpreter.record(path, frames)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn device_timestamps_are_used_only_when_plausible() {
        let now = Duration::from_secs(1000);
        let recent = Duration::from_millis(999_970);
        assert_eq!(host_capture_time(recent, now), recent);
        assert_eq!(host_capture_time(Duration::ZERO, now), now);
        assert_eq!(host_capture_time(Duration::from_secs(1001), now), now);
        assert_eq!(host_capture_time(Duration::from_secs(10), now), now);
    }
}
