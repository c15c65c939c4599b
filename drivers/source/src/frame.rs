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

/// The widest and narrowest horizontal fields of view a depth camera has, degrees: the focal
/// length in pixels must put the image's width between them.
pub const FIELD_OF_VIEW_DEG: std::ops::RangeInclusive<f32> = 10.0..=170.0;

impl Intrinsics {
    /// Refuses, saying why, a pinhole model no depth camera has: a focal length that is not
    /// positive (`fx=-5` mirrors the image; 0 deprojects nothing), a field of view outside
    /// [`FIELD_OF_VIEW_DEG`] (focal lengths in other units), a principal point outside the
    /// image.
    pub fn check_plausible(&self) -> Result<(), String> {
        let k = self;
        let (width, height) = (k.width as f32, k.height as f32);
        if k.width == 0 || k.height == 0 {
            return Err(format!("a {}x{} image has no pixels", k.width, k.height));
        }
        for (name, f, side) in [("fx", k.fx, width), ("fy", k.fy, height)] {
            if !(f.is_finite() && f > 0.0) {
                return Err(format!(
                    "{name}={f}: a focal length is a positive number of pixels (about 525 for a \
                     Kinect at 640x480)"
                ));
            }
            let fov_deg = 2.0 * (0.5 * side / f).atan().to_degrees();
            if !FIELD_OF_VIEW_DEG.contains(&fov_deg) {
                return Err(format!(
                    "{name}={f} gives a {fov_deg:.1}° field of view over {side} pixels; depth \
                     cameras see {}° to {}°: is it in pixels, for this image size?",
                    FIELD_OF_VIEW_DEG.start(),
                    FIELD_OF_VIEW_DEG.end()
                ));
            }
        }
        for (name, c, side) in [("cx", k.cx, width), ("cy", k.cy, height)] {
            if !(c.is_finite() && (0.0..=side).contains(&c)) {
                return Err(format!(
                    "{name}={c}: the principal point is in the image, from 0 to {side} pixels"
                ));
            }
        }
        Ok(())
    }

    /// Whether these can deproject anything: a non-zero size, finite non-zero focal lengths and
    /// a finite principal point.
    pub fn is_usable(&self) -> bool {
        let focal_ok = |f: f32| f.is_finite() && f != 0.0;
        self.width != 0
            && self.height != 0
            && focal_ok(self.fx)
            && focal_ok(self.fy)
            && self.cx.is_finite()
            && self.cy.is_finite()
    }

    /// The ray direction (z = 1) through pixel centre `(u, v)` in the sensor frame
    /// (x right, y down, z forward).
    pub fn ray(&self, u: f32, v: f32) -> Vec3 {
        Vec3::new((u - self.cx) / self.fx, (v - self.cy) / self.fy, 1.0)
    }

    /// The x of [`ray`](Self::ray) through each column, `(u - cx) / fx`: the same values, for
    /// a pass over the whole image that should not divide per pixel.
    pub fn column_rays(&self) -> Vec<f32> {
        (0..self.width)
            .map(|u| (u as f32 - self.cx) / self.fx)
            .collect()
    }

    /// The y of [`ray`](Self::ray) through each row, `(v - cy) / fy`.
    pub fn row_rays(&self) -> Vec<f32> {
        (0..self.height)
            .map(|v| (v as f32 - self.cy) / self.fy)
            .collect()
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
    /// Capture time on the host's monotonic clock ([`crate::monotonic_now`]).
    pub capture_time: Duration,
}

/// Why a depth frame (or an organised cloud) cannot be used. A source that sends one sends a
/// malformed frame; the daemon counts it and skips it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("{width}×{height} intrinsics but {values} depth values: the driver's buffer does not match its resolution")]
    WrongSize {
        width: u32,
        height: u32,
        values: usize,
    },
    #[error("an organised cloud of {width}×{height} pixels with {points} points: the driver's cloud does not match its grid")]
    OffGrid {
        width: u32,
        height: u32,
        points: usize,
    },
    #[error("unusable intrinsics {intrinsics:?}: the size must be non-zero, the focal lengths finite and non-zero and the principal point finite (is the calibration corrupt?)")]
    BadIntrinsics { intrinsics: Intrinsics },
}

/// A depth frame turned into points: the valid pixels' points in the world frame, in row-major
/// pixel order, and how many pixels had no usable reading.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Deprojection {
    pub points_in_world: Vec<Vec3>,
    pub invalid_pixels: usize,
}

impl DepthFrame {
    /// Whether the depth buffer has exactly `width * height` entries.
    pub fn is_consistent(&self) -> bool {
        self.depth_m.len() == self.intrinsics.width as usize * self.intrinsics.height as usize
    }

    /// Whether the frame can be deprojected: a non-zero size, finite non-zero focal lengths, a
    /// finite principal point, and exactly `width * height` depth values. A frame that fails
    /// would deproject to no points (a zero or NaN focal length makes every ray non-finite)
    /// without a single pixel counted as invalid, or to points at the wrong pixels.
    pub fn check(&self) -> Result<(), FrameError> {
        let k = self.intrinsics;
        if !k.is_usable() {
            return Err(FrameError::BadIntrinsics { intrinsics: k });
        }
        if !self.is_consistent() {
            return Err(FrameError::WrongSize {
                width: k.width,
                height: k.height,
                values: self.depth_m.len(),
            });
        }
        Ok(())
    }

    /// Back-projects every pixel with a reading in `(0, max_range_m]` through the pinhole model
    /// (pixel `(u, v)` at integer coordinates, OpenCV/PCL convention) and moves it into the world
    /// frame. Zero, negative, non-finite and out-of-range depths become no point and are counted
    /// as invalid; so are pixels missing from a short buffer.
    pub fn deproject(&self, max_range_m: f32) -> Deprojection {
        let Intrinsics { width, height, .. } = self.intrinsics;
        let pixels = width as usize * height as usize;
        let mut out = Deprojection {
            points_in_world: Vec::with_capacity(pixels.min(self.depth_m.len())),
            invalid_pixels: pixels.saturating_sub(self.depth_m.len()),
        };
        for (i, &z) in self.depth_m.iter().take(pixels).enumerate() {
            if !(z > 0.0 && z <= max_range_m) {
                out.invalid_pixels += 1;
                continue;
            }
            let (u, v) = ((i % width as usize) as f32, (i / width as usize) as f32);
            let p_in_sensor = self.intrinsics.ray(u, v) * z;
            out.points_in_world
                .push(self.world_from_sensor.transform_point3(p_in_sensor));
        }
        out
    }

    /// As [`deproject`](Self::deproject), but organised: one entry per pixel, row-major, with
    /// `Vec3::NAN` where the pixel has no usable reading (counted in `invalid_pixels`). The
    /// daemon keeps pixel positions to segment a strided sub-image and label the rest.
    pub fn deproject_organised(&self, max_range_m: f32) -> Deprojection {
        let Intrinsics { width, height, .. } = self.intrinsics;
        let pixels = width as usize * height as usize;
        let mut out = Deprojection {
            points_in_world: Vec::with_capacity(pixels),
            invalid_pixels: 0,
        };
        // The rays' x per column and y per row, computed once each (without two divisions
        // and a division of the index per pixel).
        let ray_x = self.intrinsics.column_rays();
        for (v, ray_y) in self.intrinsics.row_rays().into_iter().enumerate() {
            for (u, &ray_x) in ray_x.iter().enumerate() {
                let z = self
                    .depth_m
                    .get(v * width as usize + u)
                    .copied()
                    .unwrap_or(f32::NAN);
                if !(z > 0.0 && z <= max_range_m) {
                    out.invalid_pixels += 1;
                    out.points_in_world.push(Vec3::NAN);
                    continue;
                }
                let p_in_sensor = Vec3::new(ray_x, ray_y, 1.0) * z;
                out.points_in_world
                    .push(self.world_from_sensor.transform_point3(p_in_sensor));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(depth_m: Vec<f32>) -> DepthFrame {
        DepthFrame {
            intrinsics: Intrinsics {
                width: 2,
                height: 2,
                fx: 2.0,
                fy: 2.0,
                cx: 0.5,
                cy: 0.5,
            },
            depth_m,
            world_from_sensor: Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0)),
            capture_time: Duration::ZERO,
        }
    }

    #[test]
    fn deproject_skips_and_counts_invalid_depths() {
        let d = frame(vec![0.0, f32::NAN, 2.0, 9.0]).deproject(5.0);
        assert_eq!(d.invalid_pixels, 3);
        // Pixel (0, 1) at 2 m: x = (0 - 0.5) / 2 * 2, y = (1 - 0.5) / 2 * 2, then +1 m in z.
        assert_eq!(d.points_in_world, vec![Vec3::new(-0.5, 0.5, 3.0)]);
    }

    #[test]
    fn column_and_row_rays_are_the_rays_through_the_pixels() {
        let k = Intrinsics {
            width: 5,
            height: 3,
            fx: 2.5,
            fy: -3.0,
            cx: 1.7,
            cy: 0.4,
        };
        let (xs, ys) = (k.column_rays(), k.row_rays());
        assert_eq!((xs.len(), ys.len()), (5, 3));
        for (v, &y) in ys.iter().enumerate() {
            for (u, &x) in xs.iter().enumerate() {
                assert_eq!(Vec3::new(x, y, 1.0), k.ray(u as f32, v as f32));
            }
        }
    }

    #[test]
    fn organised_deprojection_keeps_pixel_positions() {
        let d = frame(vec![0.0, f32::NAN, 2.0]).deproject_organised(5.0);
        assert_eq!(d.invalid_pixels, 3);
        assert_eq!(d.points_in_world.len(), 4);
        assert!(d.points_in_world[0].is_nan() && d.points_in_world[3].is_nan());
        assert_eq!(d.points_in_world[2], Vec3::new(-0.5, 0.5, 3.0));
    }

    /// A zero or NaN focal length turned every pixel into a non-finite "point" that no
    /// counter saw: the frame must be refused as malformed instead.
    #[test]
    fn check_refuses_absurd_intrinsics_and_wrong_sizes() {
        let good = frame(vec![1.0; 4]);
        assert_eq!(good.check(), Ok(()));
        let with = |change: fn(&mut Intrinsics)| {
            let mut bad = good.clone();
            change(&mut bad.intrinsics);
            bad.check()
        };
        let absurd: [fn(&mut Intrinsics); 6] = [
            |k| k.fx = 0.0,
            |k| k.fy = f32::NAN,
            |k| k.fx = f32::INFINITY,
            |k| k.cx = f32::NAN,
            |k| k.cy = f32::NEG_INFINITY,
            |k| k.width = 0,
        ];
        for change in absurd {
            assert!(
                matches!(with(change), Err(FrameError::BadIntrinsics { .. })),
                "{:?}",
                with(change)
            );
        }
        // Without the check, the fx = 0 frame deprojects to nothing with nothing invalid.
        let mut fx_zero = good.clone();
        fx_zero.intrinsics.fx = 0.0;
        let d = fx_zero.deproject(5.0);
        assert!(d.points_in_world.iter().all(|p| !p.is_finite()) && d.invalid_pixels == 0);
        let short = frame(vec![1.0; 3]).check().unwrap_err();
        assert_eq!(
            short,
            FrameError::WrongSize {
                width: 2,
                height: 2,
                values: 3
            }
        );
        assert!(short
            .to_string()
            .contains("2×2 intrinsics but 3 depth values"));
    }

    #[test]
    fn deproject_counts_pixels_missing_from_a_short_buffer() {
        let d = frame(vec![1.0]).deproject(5.0);
        assert_eq!((d.points_in_world.len(), d.invalid_pixels), (1, 3));
    }
}
