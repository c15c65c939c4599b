//! Distances that grow with range, as a depth sensor's resolution coarsens.
//!
//! A structured-light or stereo camera measures disparity, `d = f·b / z`, in steps of a fixed
//! fraction of a pixel, so one step of depth is `Δz = z² · Δd / (f·b)`: it grows with the
//! square of the range. For a Kinect v1 class sensor (f ≈ 580 px, b ≈ 75 mm, 1/8-pixel steps)
//! that is about 3 mm at 1 m and 40–45 mm at 3.5 m, where a wall seen at a slant becomes a
//! staircase of flat slices one step apart. A fixed distance threshold that suits a table at 1 m
//! would cut such a wall into one "object" per slice; a threshold that follows the step does not.

use glam::Vec3;

/// The last range band ([`RangeDistance::band`]).
pub(crate) const MAX_BAND: usize = 12;

/// A distance that is `base_m` near the sensor and `factor` depth steps far from it, whichever
/// is larger: `max(base_m, factor · step_per_m2 · r²)` at range `r` from the viewpoint.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct RangeDistance {
    pub(crate) base_m: f32,
    /// `factor · step_per_m2`: metres per square metre of range.
    per_m2: f32,
    pub(crate) viewpoint: Vec3,
}

impl RangeDistance {
    /// `step_per_m2` is the sensor's depth step per square metre of range (0 for a fixed
    /// distance); `factor` how many steps the distance spans far away.
    pub(crate) fn new(base_m: f32, step_per_m2: f32, factor: f32, viewpoint: Vec3) -> Self {
        let per_m2 = step_per_m2 * factor;
        Self {
            base_m: base_m.max(0.0),
            per_m2: if per_m2.is_finite() && per_m2 > 0.0 {
                per_m2
            } else {
                0.0
            },
            viewpoint,
        }
    }

    /// The distance at point `p`.
    pub(crate) fn at(&self, p: Vec3) -> f32 {
        self.base_m
            .max(self.per_m2 * p.distance_squared(self.viewpoint))
    }

    /// The range from the viewpoint where band `band` (≥ 1) begins: nearer points are all in
    /// lower bands (infinity for a fixed distance, which has only band 0).
    pub(crate) fn band_start_m(&self, band: usize) -> f32 {
        if self.per_m2 > 0.0 {
            (2f32.powi(band as i32 - 1) * self.base_m / self.per_m2).sqrt()
        } else {
            f32::INFINITY
        }
    }

    /// The range band of `p`: 0 where the distance is the base one, `k` where it is more than
    /// `2^(k-1)` and at most `2^k` times it (at most [`MAX_BAND`]).
    pub(crate) fn band(&self, p: Vec3) -> usize {
        let ratio = self.at(p) / self.base_m;
        if ratio <= 1.0 || !ratio.is_finite() {
            0
        } else {
            (ratio.log2().ceil() as usize).clamp(1, MAX_BAND)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fixed_near_growing_far() {
        let d = RangeDistance::new(0.015, 0.0035, 1.5, Vec3::ZERO);
        assert_eq!(d.at(Vec3::new(0.0, 0.0, 1.0)), 0.015);
        let far = d.at(Vec3::new(0.0, 0.0, 3.5));
        // Band 1 begins where the distance passes the base: 0.015 = 0.00525 r².
        assert!((d.band_start_m(1) - (0.015f32 / 0.00525).sqrt()).abs() < 1e-6);
        assert_eq!(d.band(Vec3::new(0.0, 0.0, 0.999 * d.band_start_m(2))), 1);
        assert_eq!(d.band(Vec3::new(0.0, 0.0, 1.001 * d.band_start_m(2))), 2);
        assert!((far - 1.5 * 0.0035 * 12.25).abs() < 1e-6, "{far}");
        assert_eq!(
            RangeDistance::new(0.015, 0.0, 1.5, Vec3::ZERO).at(far * Vec3::Z),
            0.015
        );
    }
}
