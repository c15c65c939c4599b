use glam::Affine3A;
use tacmesh_source::Intrinsics;

use crate::decode::{DepthDecoder, PixelFormat};

/// How to open and stream a V4L2 depth camera. Always compiled, so a configuration can be built
/// and checked without the `device` feature.
#[derive(Debug, Clone, PartialEq)]
pub struct V4l2Config {
    /// The device node of the depth stream, e.g. `/dev/video2`.
    pub device: String,
    /// Calibration of the streamed resolution; its `width` and `height` are the resolution
    /// requested from the device, so the two cannot disagree.
    pub intrinsics: Intrinsics,
    /// Frame rate requested from the device (drivers without `VIDIOC_S_PARM` keep theirs).
    pub fps: u32,
    /// Pixel formats to try, best first; empty means [`PixelFormat::PREFERENCE`] (Z16, then Y16).
    pub formats: Vec<PixelFormat>,
    /// Metres per depth unit ([`DepthDecoder::REALSENSE_DEPTH_SCALE_M`] = 0.001 for RealSense).
    pub depth_scale_m: f32,
    /// Pose of the sensor in the world frame, stamped on every frame.
    pub world_from_sensor: Affine3A,
    /// Memory-mapped buffers the driver fills in turn.
    pub buffer_count: u32,
    /// Longest wait for one frame before the source reports itself disconnected.
    pub read_timeout_ms: u64,
}

impl V4l2Config {
    /// `device` at the resolution of `intrinsics`, 30 fps, Z16 then Y16, RealSense depth scale,
    /// identity pose, 4 buffers, 2 s read timeout.
    pub fn new(device: impl Into<String>, intrinsics: Intrinsics) -> Self {
        Self {
            device: device.into(),
            intrinsics,
            fps: 30,
            formats: PixelFormat::PREFERENCE.to_vec(),
            depth_scale_m: DepthDecoder::REALSENSE_DEPTH_SCALE_M,
            world_from_sensor: Affine3A::IDENTITY,
            buffer_count: 4,
            read_timeout_ms: 2_000,
        }
    }

    /// The formats to try, best first ([`PixelFormat::PREFERENCE`] when none are configured).
    pub fn formats_to_try(&self) -> Vec<PixelFormat> {
        if self.formats.is_empty() {
            PixelFormat::PREFERENCE.to_vec()
        } else {
            self.formats.clone()
        }
    }
}
