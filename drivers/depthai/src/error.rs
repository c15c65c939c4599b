use std::path::PathBuf;

use tacmesh_source::SourceError;

/// Why a DepthAI camera or recording could not be opened or read.
///
/// The hardware-free variants (options, frames, virtual environments) are built without the
/// `device` feature too, so that their messages are tested everywhere.
#[derive(Debug, thiserror::Error)]
pub enum DepthAiError {
    #[error("depthai spec {spec:?}: {reason}")]
    BadOption { spec: String, reason: String },
    #[error("DepthAI frame: {0}")]
    Frame(#[from] tacmesh_v4l2::V4l2Error),
    #[error(
        "DepthAI frame of type {type_name}: tacmesh reads depth as RAW16 (millimetres from \
         StereoDepth's `depth` output)"
    )]
    NotDepth { type_name: String },
    #[error(
        "DepthAI frame is {width}x{height} but its intrinsics are for {intrinsics_width}x\
         {intrinsics_height}"
    )]
    SizeMismatch {
        width: u32,
        height: u32,
        intrinsics_width: u32,
        intrinsics_height: u32,
    },
    #[error(
        "DepthAI frame has no usable intrinsics ({reason}); a recording made without the \
         device's calibration needs fx, fy, cx and cy in the spec"
    )]
    NoIntrinsics { reason: String },
    #[error("virtual environment {venv}: {reason}")]
    Venv { venv: PathBuf, reason: String },
    #[error(
        "no DepthAI device found within {timeout_ms} ms (DEPTHAI_SEARCH_TIMEOUT){device}: is the \
         camera plugged in (lsusb shows 03e7:2485 or 03e7:f63b), powered, and readable by this \
         user (Luxonis' udev rule, 80-movidius.rules)? DepthAI said: {message}"
    )]
    NoDevice {
        device: String,
        timeout_ms: u32,
        message: String,
    },
    #[error(
        "the `depthai` Python package is not importable by the embedded Python {python}: \
         install it with `pip install depthai` into the interpreter or a virtual environment \
         and name that environment with `venv=PATH` ({message})"
    )]
    NotInstalled { python: String, message: String },
    #[error("no DepthAI recording at {path}: {reason}")]
    Recording { path: PathBuf, reason: String },
    #[error("DepthAI (Python) failed while {action}: {message}")]
    Python { action: String, message: String },
    #[error("the DepthAI interpreter thread is gone: {0}")]
    InterpreterGone(String),
}

impl DepthAiError {
    /// The error as the daemon's supervisor sees it: a missing device or recording, or bad
    /// options, is [`SourceError::DeviceMissing`] (retried with backoff); anything else that
    /// happens to an open stream is [`SourceError::Disconnected`].
    pub fn into_source_error(self, device: &str) -> SourceError {
        match self {
            DepthAiError::Frame(_)
            | DepthAiError::NotDepth { .. }
            | DepthAiError::SizeMismatch { .. }
            | DepthAiError::NoIntrinsics { .. } => SourceError::Malformed {
                device: device.into(),
                reason: self.to_string(),
            },
            DepthAiError::Python { .. } | DepthAiError::InterpreterGone(_) => {
                SourceError::Disconnected {
                    device: device.into(),
                    reason: self.to_string(),
                }
            }
            _ => SourceError::DeviceMissing {
                device: device.into(),
                hint: self.to_string(),
            },
        }
    }
}
