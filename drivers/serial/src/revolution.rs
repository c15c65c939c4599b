//! Range samples → revolutions → planar point clouds.
//!
//! Both scanners deliver a stream of `(angle, distance)` samples; this module cuts the stream
//! into revolutions and turns one revolution into a [`PointCloud`] in the sensor frame.
//!
//! Sensor frame (the convention of every cloud this crate yields): x forward (angle 0), y left,
//! z up; the scan plane is z = 0. Scan angles increase **clockwise seen from above**, as the
//! RPLIDAR protocol documents and as the Camsense-style sensors spin, so a sample at angle θ
//! and range d lies at `(d cos θ, −d sin θ, 0)`.

use glam::Vec3;
use tacmesh_source::PointCloud;

/// One range reading of a spinning scanner.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScanSample {
    /// Clockwise from the sensor's forward axis, in `[0, 360)` degrees.
    pub angle_deg: f32,
    /// Range in metres; meaningful only when `valid`.
    pub distance_m: f32,
    /// The sensor's signal-quality figure (scale depends on the sensor).
    pub quality: u8,
    /// False when the sensor flagged the reading as invalid or reported a zero range.
    pub valid: bool,
}

impl ScanSample {
    /// The sample as a point in the sensor frame, or `None` when it is invalid or at zero range.
    pub fn point_in_sensor(&self) -> Option<Vec3> {
        if !self.valid || !self.distance_m.is_finite() || self.distance_m <= 0.0 {
            return None;
        }
        let theta = self.angle_deg.to_radians();
        Some(Vec3::new(
            self.distance_m * theta.cos(),
            -self.distance_m * theta.sin(),
            0.0,
        ))
    }
}

/// The samples of one revolution, in arrival order.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Revolution {
    pub samples: Vec<ScanSample>,
    /// True when the revolution began at a wrap through 0° (or a start flag); false for the
    /// partial revolution the stream happened to start in, and for a final partial one.
    pub complete: bool,
}

impl Revolution {
    /// The valid samples as a planar cloud in the sensor frame (see the module doc), and how many
    /// samples were skipped (invalid flag or zero range).
    pub fn to_cloud(&self) -> (PointCloud, usize) {
        let points: Vec<Vec3> = self
            .samples
            .iter()
            .filter_map(ScanSample::point_in_sensor)
            .collect();
        let skipped = self.samples.len() - points.len();
        (PointCloud::new(points), skipped)
    }

    /// How many samples the sensor flagged invalid or reported at zero range.
    pub fn invalid_samples(&self) -> usize {
        self.samples
            .iter()
            .filter(|s| s.point_in_sensor().is_none())
            .count()
    }
}

/// A backwards step larger than this between consecutive samples is a wrap through 0°; smaller
/// backwards steps are jitter and stay in the revolution.
const WRAP_STEP_DEG: f32 = 180.0;

/// Cuts a sample stream into revolutions: a new one starts when the angle wraps through 0°
/// (drops by more than 180°) or when the sensor marks a sample as the start of a scan.
#[derive(Debug, Default)]
pub struct RevolutionAssembler {
    current: Revolution,
    previous_angle_deg: Option<f32>,
    started_at_wrap: bool,
}

impl RevolutionAssembler {
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds one sample; returns the revolution it closed, if it started a new one.
    /// `starts_scan` is the sensor's own start-of-scan flag (RPLIDAR's S bit), `false` if none.
    pub fn push(&mut self, sample: ScanSample, starts_scan: bool) -> Option<Revolution> {
        let wrapped = self
            .previous_angle_deg
            .is_some_and(|previous| previous - sample.angle_deg > WRAP_STEP_DEG);
        self.previous_angle_deg = Some(sample.angle_deg);
        let mut closed = None;
        if (wrapped || starts_scan) && !self.current.samples.is_empty() {
            let next = Revolution {
                samples: Vec::with_capacity(self.current.samples.len() + 16),
                complete: true,
            };
            let mut done = std::mem::replace(&mut self.current, next);
            done.complete = self.started_at_wrap;
            closed = Some(done);
            self.started_at_wrap = true;
        } else if self.current.samples.is_empty() && starts_scan {
            self.started_at_wrap = true;
        }
        self.current.samples.push(sample);
        closed
    }

    /// Hands out the unfinished revolution (marked incomplete), if it has any samples.
    pub fn flush(&mut self) -> Option<Revolution> {
        self.previous_angle_deg = None;
        self.started_at_wrap = false;
        let mut rest = std::mem::take(&mut self.current);
        rest.complete = false;
        (!rest.samples.is_empty()).then_some(rest)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(angle_deg: f32, distance_m: f32) -> ScanSample {
        ScanSample {
            angle_deg,
            distance_m,
            quality: 10,
            valid: true,
        }
    }

    #[test]
    fn clockwise_angle_maps_to_right_hand_side() {
        let p = sample(90.0, 2.0).point_in_sensor().unwrap();
        assert!((p - Vec3::new(0.0, -2.0, 0.0)).length() < 1e-5, "{p}");
        let p = sample(0.0, 1.5).point_in_sensor().unwrap();
        assert!((p - Vec3::new(1.5, 0.0, 0.0)).length() < 1e-6, "{p}");
    }

    #[test]
    fn invalid_and_zero_range_samples_are_skipped_and_counted() {
        let mut bad = sample(10.0, 3.0);
        bad.valid = false;
        let revolution = Revolution {
            samples: vec![sample(0.0, 1.0), bad, sample(20.0, 0.0)],
            complete: true,
        };
        let (cloud, skipped) = revolution.to_cloud();
        assert_eq!((cloud.len(), skipped), (1, 2));
        assert_eq!(revolution.invalid_samples(), 2);
    }

    #[test]
    fn assembler_splits_at_wrap_and_marks_the_first_partial() {
        let mut assembler = RevolutionAssembler::new();
        let angles = [300.0, 350.0, 5.0, 100.0, 200.0, 359.0, 1.0, 2.0];
        let closed: Vec<Revolution> = angles
            .iter()
            .filter_map(|&a| assembler.push(sample(a, 1.0), false))
            .collect();
        assert_eq!(closed.len(), 2);
        assert_eq!((closed[0].samples.len(), closed[0].complete), (2, false));
        assert_eq!((closed[1].samples.len(), closed[1].complete), (4, true));
        let rest = assembler.flush().unwrap();
        assert_eq!((rest.samples.len(), rest.complete), (2, false));
    }

    #[test]
    fn assembler_ignores_small_backward_jitter() {
        let mut assembler = RevolutionAssembler::new();
        for a in [10.0, 12.0, 11.5, 13.0] {
            assert!(assembler.push(sample(a, 1.0), false).is_none());
        }
    }

    #[test]
    fn start_flag_splits_without_wrap_and_counts_as_complete() {
        let mut assembler = RevolutionAssembler::new();
        assert!(assembler.push(sample(0.5, 1.0), true).is_none());
        assert!(assembler.push(sample(180.0, 1.0), false).is_none());
        let closed = assembler.push(sample(359.0, 1.0), true).unwrap();
        assert!(closed.complete);
        assert_eq!(closed.samples.len(), 2);
    }
}
