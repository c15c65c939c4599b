use std::time::Duration;

use glam::{Affine3A, Vec3};

/// Pinhole intrinsics of a depth camera, in pixels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Intrinsics {
    pub width: u32,
    pub height: u32,
    pub fx: f32,
    pub fy: f32,
    pub cx: f32,
    pub cy: f32,
}

impl Intrinsics {
    /// The ray direction (z = 1) through pixel centre `(u, v)` in the sensor frame
    /// (x right, y down, z forward).
    pub fn ray(&self, u: f32, v: f32) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }
}

/// One organised depth image, row-major, `depth_m[v * width + u]` in metres along the optical
/// axis; 0 or a non-finite value means "no reading".
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFrame {
    pub intrinsics: Intrinsics,
    pub depth_m: Vec<f32>,
    /// Pose of the sensor in the world frame.
    pub world_from_sensor: Affine3A,
    /// Capture time on the daemon's monotonic clock.
    pub capture_time: Duration,
}

impl DepthFrame {
    /// Whether the depth buffer has exactly `width * height` entries.
    pub fn is_consistent(&self) -> bool {
        self.depth_m.len() == self.intrinsics.width as usize * self.intrinsics.height as usize
    }
}
