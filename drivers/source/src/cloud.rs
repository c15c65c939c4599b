use glam::Vec3;

use crate::FrameError;

/// An unorganised set of 3-D points in metres, optionally with unit normals.
///
/// `normals`, when present, has exactly one entry per point. A cloud that came from a
/// camera's pixel grid says so beside it, with a [`CloudGrid`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PointCloud {
    pub points: Vec<Vec3>,
    pub normals: Option<Vec<Vec3>>,
}

impl PointCloud {
    pub fn new(points: Vec<Vec3>) -> Self {
        Self {
            points,
            normals: None,
        }
    }

    pub fn with_normals(points: Vec<Vec3>, normals: Vec<Vec3>) -> Self {
        debug_assert_eq!(points.len(), normals.len());
        Self {
            points,
            normals: Some(normals),
        }
    }

    pub fn len(&self) -> usize {
        self.points.len()
    }

    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Axis-aligned bounds `(min, max)` of the points, or `None` for an empty cloud.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        bounds_of(&self.points)
    }

    /// Drops every point with a non-finite coordinate (and its normal); returns how many went.
    pub fn retain_finite(&mut self) -> usize {
        let before = self.points.len();
        match &mut self.normals {
            Some(normals) => {
                let mut keep = self.points.iter().map(|p| p.is_finite());
                normals.retain(|_| keep.next().unwrap_or(false));
                self.points.retain(|p| p.is_finite());
            }
            None => self.points.retain(|p| p.is_finite()),
        }
        before - self.points.len()
    }
}

/// The pixel grid of an organised cloud (an organised PCD, a depth camera's cloud): point
/// `v * width + u` is pixel `(u, v)`, row-major, and a pixel without a reading holds a
/// non-finite point, so that every point stays at its pixel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CloudGrid {
    pub width: u32,
    pub height: u32,
}

impl CloudGrid {
    /// How many points a cloud on this grid has: `width * height`.
    pub fn points(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// Whether `cloud` lies on this grid: exactly one point per pixel (and a normal per point
    /// when it has normals).
    pub fn check(&self, cloud: &PointCloud) -> Result<(), FrameError> {
        let fits = cloud.len() == self.points()
            && cloud
                .normals
                .as_ref()
                .is_none_or(|n| n.len() == cloud.len());
        if fits {
            Ok(())
        } else {
            Err(FrameError::OffGrid {
                width: self.width,
                height: self.height,
                points: cloud.len(),
            })
        }
    }
}

/// Axis-aligned bounds `(min, max)` of a point set, or `None` when it is empty.
pub(crate) fn bounds_of(points: &[Vec3]) -> Option<(Vec3, Vec3)> {
    let first = *points.first()?;
    Some(
        points
            .iter()
            .fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retain_finite_drops_nan_points_with_their_normals() {
        let mut cloud = PointCloud::with_normals(
            vec![Vec3::ZERO, Vec3::new(f32::NAN, 0.0, 0.0), Vec3::ONE],
            vec![Vec3::X, Vec3::Y, Vec3::Z],
        );
        assert_eq!(cloud.retain_finite(), 1);
        assert_eq!(cloud.points, vec![Vec3::ZERO, Vec3::ONE]);
        assert_eq!(cloud.normals, Some(vec![Vec3::X, Vec3::Z]));
    }

    #[test]
    fn grid_check_wants_one_point_per_pixel() {
        let grid = CloudGrid {
            width: 2,
            height: 2,
        };
        let on_grid = PointCloud::new(vec![Vec3::ZERO, Vec3::NAN, Vec3::NAN, Vec3::ONE]);
        assert_eq!(grid.check(&on_grid), Ok(()));
        let short = PointCloud::new(vec![Vec3::ZERO; 3]);
        assert_eq!(
            grid.check(&short),
            Err(FrameError::OffGrid {
                width: 2,
                height: 2,
                points: 3
            })
        );
    }

    #[test]
    fn bounds_of_empty_cloud_is_none() {
        assert_eq!(PointCloud::default().bounds(), None);
    }
}
