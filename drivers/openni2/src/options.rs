//! How an [`OpenNi2Source`](crate::OpenNi2Source) is opened.

use tacmesh_source::glam::Affine3A;

use crate::DepthPixelFormat;

/// A depth video mode (`OniVideoMode`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VideoMode {
    pub width: u32,
    pub height: u32,
    pub fps: u32,
    pub pixel_format: DepthPixelFormat,
}

impl Default for VideoMode {
    /// 640×480 at 30 Hz in millimetres: the mode every PrimeSense-family sensor offers.
    fn default() -> Self {
        Self {
            width: 640,
            height: 480,
            fps: 30,
            pixel_format: DepthPixelFormat::Millimetre,
        }
    }
}

/// Options of [`OpenNi2Source::open`](crate::OpenNi2Source::open).
#[derive(Debug, Clone, PartialEq)]
pub struct OpenNi2Options {
    /// The video mode to ask for. Set only if the stream lists it among its supported modes;
    /// otherwise (and for recordings, which have one fixed mode) the device's current mode is
    /// kept and logged.
    pub video_mode: VideoMode,
    /// Pose of the sensor in the world frame, stamped on every frame.
    pub world_from_sensor: Affine3A,
    /// How long `next_observation` waits for a frame before reporting the device as
    /// disconnected.
    pub frame_timeout_ms: u32,
    /// Fields of view `(horizontal, vertical)` in radians for devices that report none (the
    /// OpenNI2 dummy device, some third-party drivers). `None` makes such a device an error.
    /// The default is the PrimeSense Carmine/Xtion value, 1.0225 × 0.7959 rad (58.6° × 45.6°).
    pub fallback_fov_rad: Option<(f32, f32)>,
    /// For recordings: play back at this multiple of the recorded rate (1.0 = as recorded).
    /// OpenNI2 reads 0.0 as "as fast as possible" and -1.0 as "manual": the next frame only
    /// when the previous one was read, which replays every frame whatever the consumer's pace.
    pub playback_speed: f32,
}

impl Default for OpenNi2Options {
    fn default() -> Self {
        Self {
            video_mode: VideoMode::default(),
            world_from_sensor: Affine3A::IDENTITY,
            frame_timeout_ms: 2000,
            fallback_fov_rad: Some((1.0225, 0.7959)),
            playback_speed: -1.0,
        }
    }
}
