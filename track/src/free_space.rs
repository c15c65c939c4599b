//! What one frame saw through: the nearest measured depth along each ray from the sensor, so
//! that fused voxels the camera now sees past can be forgotten.
//!
//! Why: fused moments only ever add. An object taken away, a box replaced by another, a model
//! smeared by a bad alignment all leave voxels behind that no later point contradicts, and
//! the mesh keeps them for ever (on real recordings the first scene's box absorbed every later
//! scene's objects). Volumetric mappers solve this with the sensor's free space: voxblox casts
//! each ray from the sensor to its point and lowers the weight of the voxels it passes, nvblox
//! does the same projectively (each voxel is projected into the depth image and compared with
//! the depth measured there) and also decays weights over time. This is the projective form:
//! each fused voxel is projected into a range image of the frame, which costs one projection
//! per voxel of the objects (they are few) instead of one ray march per pixel (they are
//! 300,000), and needs no voxels of free space to be stored.
//!
//! The range image is built from the frame's points themselves (every finite point, planes and
//! background included), binned by direction from the sensor, so it serves organised depth
//! frames and unorganised clouds alike. Each bin keeps its *nearest* depth: a voxel counts as
//! seen through only if even the nearest surface measured in its direction is behind it by
//! more than the sensor's depth uncertainty there. A bin with no measurement (no return,
//! beyond range, outside the view) says nothing, so missing depth never erases anything.
//!
//! The frame's support planes add what it cannot see through but knows all the same: a voxel
//! beyond a support (under the table, seen from above), in a direction where the nearest
//! measured surface is that support, is hidden by it (`FreeSpace::hidden_under_support`). No
//! part of an object standing on the support can be there; a smear of alignment there (a flat
//! object sliding along itself, frame after frame of camera shake) is never seen through and
//! would stay for ever.

use glam::{Affine3A, Vec3};
use tacmesh_source::{floor_i32, DepthFrame};

/// Angular width of a bin, radians: about two pixels of a 640-wide VGA depth camera, so a bin
/// holds a few measurements and one missing pixel does not leave a hole in the image.
pub const BIN_RAD: f32 = 0.0035;

/// Directions farther than this from the optical axis (tangent, about 72°) are not binned:
/// depth cameras see less, and a plane sensor's rays to the side have no use here.
const MAX_TAN: f32 = 3.0;

/// The most bins along a side; a wider view gets wider bins.
const MAX_BINS: usize = 1024;

/// A depth frame's column outside the image ([`FreeSpace::from_depth`]).
const NO_BIN: u32 = u32::MAX;

/// How much farther than a voxel the measured surface must be before the voxel counts as seen
/// through, as a function of the voxel's depth: `margin_m + per_m2 · z²`. Depth noise and the
/// disparity step of stereo and structured-light cameras both grow with z² (Kinect: about
/// 3 mm at 1 m, 45 mm at 3.5 m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthMargin {
    pub margin_m: f32,
    pub per_m2: f32,
}

impl DepthMargin {
    pub fn at(&self, depth_m: f32) -> f32 {
        self.margin_m + self.per_m2 * depth_m * depth_m
    }
}

/// The nearest measured depth per direction bin of one frame.
#[derive(Debug, Clone, PartialEq)]
pub struct FreeSpace {
    sensor_from_world: Affine3A,
    /// The sensor's position, world frame (the origin of every ray).
    sensor_in_world: Vec3,
    /// Bins per unit of tangent (1 / bin width).
    bins_per_tan: f32,
    /// Bin of tangent 0 on each axis (so bin = floor(tan · bins_per_tan) + origin).
    origin: (i32, i32),
    width: usize,
    height: usize,
    /// Nearest depth along the optical axis per bin, metres; infinity for no measurement.
    nearest_m: Vec<f32>,
    /// The frame's support planes, world frame: unit normal towards the sensor, and offset
    /// (`normal·p = offset` on the plane).
    supports: Vec<(Vec3, f32)>,
}

impl FreeSpace {
    /// The range image of the frame's points (world frame) seen from `world_from_sensor`
    /// (optical axis +z, as the depth frames' deprojection uses). Non-finite points and
    /// points behind the sensor are skipped.
    pub fn from_points(points_in_world: &[Vec3], world_from_sensor: Affine3A) -> Self {
        let sensor_from_world = world_from_sensor.inverse();
        // Projected once, and the image's bounds found in the same pass: the first pass sizes
        // the image, the second fills it.
        let mut bounds = TangentBounds::EMPTY;
        let mut projected: Vec<(f32, f32, f32)> = Vec::with_capacity(points_in_world.len());
        for &p in points_in_world {
            let Some((tx, ty, z)) = project(&sensor_from_world, p) else {
                continue;
            };
            if tx.abs() <= MAX_TAN && ty.abs() <= MAX_TAN {
                bounds.include(tx, ty);
                projected.push((tx, ty, z));
            }
        }
        let mut image = Self::sized(world_from_sensor, projected.is_empty(), bounds);
        // Every projected direction is within the bounds, so inside the image.
        for (tx, ty, z) in projected {
            let bin = image.bin_within(tx, ty);
            let nearest = &mut image.nearest_m[bin];
            *nearest = nearest.min(z);
        }
        image
    }

    /// The range image of a depth frame, straight from its pixels: the same image as
    /// [`FreeSpace::from_points`] of its deprojection with `max_range_m`
    /// (`DepthFrame::deproject_organised`), to the rounding of a bin's edge, without moving
    /// every point into the world and back. A pixel's direction is its ray's, `((u - cx) / fx,
    /// (v - cy) / fy)`, so a column shares one bin column and a row one bin row: the bins are
    /// found once per column and row, and a pixel costs two comparisons (0.7 ms for VGA on the
    /// 2-core machine of BENCHMARKS.md, where projecting the points took 3-4 ms).
    pub fn from_depth(frame: &DepthFrame, max_range_m: f32) -> Self {
        let k = frame.intrinsics;
        let (width, height) = (k.width as usize, k.height as usize);
        let (tan_x, tan_y) = (k.column_rays(), k.row_rays());
        let binned = |t: f32| t.abs() <= MAX_TAN;
        let reading = |z: f32| z > 0.0 && z <= max_range_m;
        // The columns and rows holding a reading (a short buffer's missing pixels hold none).
        let rows = || frame.depth_m.chunks(width.max(1)).take(height);
        let mut column_read = vec![false; width];
        let mut row_read = vec![false; height];
        for (row, read) in rows().zip(&mut row_read) {
            for (&z, column) in row.iter().zip(&mut column_read) {
                let here = reading(z);
                *column |= here;
                *read |= here;
            }
        }
        // Only directions both of whose tangents are binned count, as for points.
        let row_binned = |v: usize| row_read[v] && binned(tan_y[v]);
        let binned_rows = || (0..height).filter(|&v| row_binned(v));
        let binned_columns = || (0..width).filter(|&u| column_read[u] && binned(tan_x[u]));
        // The bounds of the binned rows and columns with a reading: those of the pixels with
        // one, but where a row's (a column's) only readings lie in columns (rows) beyond
        // `MAX_TAN`, in a view wider than 143°; that only widens the image.
        let mut bounds = TangentBounds::EMPTY;
        for v in binned_rows() {
            bounds.lo.1 = bounds.lo.1.min(tan_y[v]);
            bounds.hi.1 = bounds.hi.1.max(tan_y[v]);
        }
        for u in binned_columns() {
            bounds.lo.0 = bounds.lo.0.min(tan_x[u]);
            bounds.hi.0 = bounds.hi.0.max(tan_x[u]);
        }
        let empty = binned_rows().next().is_none() || binned_columns().next().is_none();
        let mut image = Self::sized(frame.world_from_sensor, empty, bounds);
        if empty {
            return image;
        }
        // The bin column of every binned column that holds a reading, and then each such
        // row's bins (the bounds hold them all, so they are inside the image).
        let mut columns = vec![NO_BIN; width];
        for u in binned_columns() {
            columns[u] = image.bin_along(tan_x[u], image.origin.0) as u32;
        }
        for (v, row) in rows().enumerate() {
            if !row_binned(v) {
                continue;
            }
            let start = image.bin_along(tan_y[v], image.origin.1) as usize * image.width;
            for (&z, &column) in row.iter().zip(&columns) {
                if column != NO_BIN && reading(z) {
                    let nearest = &mut image.nearest_m[start + column as usize];
                    *nearest = nearest.min(z);
                }
            }
        }
        image
    }

    /// An image with no measurement yet, covering `bounds` (nothing at all when `empty`).
    fn sized(world_from_sensor: Affine3A, empty: bool, bounds: TangentBounds) -> Self {
        let sensor_from_world = world_from_sensor.inverse();
        let sensor_in_world = world_from_sensor.translation.into();
        if empty {
            return Self {
                sensor_from_world,
                sensor_in_world,
                bins_per_tan: 1.0,
                origin: (0, 0),
                width: 0,
                height: 0,
                nearest_m: Vec::new(),
                supports: Vec::new(),
            };
        }
        let TangentBounds { lo, hi } = bounds;
        let span = (hi.0 - lo.0).max(hi.1 - lo.1).max(BIN_RAD);
        let bins_per_tan = (1.0 / BIN_RAD).min(MAX_BINS as f32 / span);
        let origin = (
            -floor_i32(lo.0 * bins_per_tan),
            -floor_i32(lo.1 * bins_per_tan),
        );
        let width = (floor_i32(hi.0 * bins_per_tan) + origin.0 + 1).max(1) as usize;
        let height = (floor_i32(hi.1 * bins_per_tan) + origin.1 + 1).max(1) as usize;
        Self {
            sensor_from_world,
            sensor_in_world,
            bins_per_tan,
            origin,
            width,
            height,
            nearest_m: vec![f32::INFINITY; width * height],
            supports: Vec::new(),
        }
    }

    fn bin(&self, tx: f32, ty: f32) -> Option<usize> {
        if !(tx.abs() <= MAX_TAN && ty.abs() <= MAX_TAN) {
            return None;
        }
        let (u, v) = (
            self.bin_along(tx, self.origin.0),
            self.bin_along(ty, self.origin.1),
        );
        if u < 0 || v < 0 || u as usize >= self.width || v as usize >= self.height {
            return None;
        }
        Some(v as usize * self.width + u as usize)
    }

    /// The bin of a direction known to lie within the image's bounds (one that sized it).
    fn bin_within(&self, tx: f32, ty: f32) -> usize {
        let u = self.bin_along(tx, self.origin.0);
        let v = self.bin_along(ty, self.origin.1);
        v as usize * self.width + u as usize
    }

    /// The bin column (row) of tangent `t` along x (y), whose tangent 0 is bin `origin`.
    fn bin_along(&self, t: f32, origin: i32) -> i32 {
        floor_i32(t * self.bins_per_tan) + origin
    }

    /// Whether the frame saw past `p_in_world`: the nearest surface measured in its direction
    /// lies farther than `p`'s depth plus `margin` at that depth. `false` where nothing was
    /// measured (no return, outside the view, behind the sensor).
    pub fn seen_through(&self, p_in_world: Vec3, margin: &DepthMargin) -> bool {
        let Some((tx, ty, z)) = project(&self.sensor_from_world, p_in_world) else {
            return false;
        };
        match self.bin(tx, ty) {
            Some(bin) => {
                let nearest = self.nearest_m[bin];
                nearest.is_finite() && nearest > z + margin.at(z)
            }
            None => false,
        }
    }

    /// The same free space knowing the frame's support planes (world frame: unit normal,
    /// offset with `normal·p = offset` on the plane; either orientation), for
    /// [`FreeSpace::hidden_under_support`]. Normals are turned towards the sensor.
    pub fn with_supports(mut self, supports: impl IntoIterator<Item = (Vec3, f32)>) -> Self {
        let sensor = self.sensor_in_world;
        self.supports = supports
            .into_iter()
            .filter(|(n, d)| n.is_finite() && d.is_finite() && n.length_squared() > 0.5)
            .map(|(n, d)| {
                if n.dot(sensor) - d < 0.0 {
                    (-n, -d)
                } else {
                    (n, d)
                }
            })
            .collect();
        self
    }

    /// The support planes (normal towards the sensor, offset), world frame.
    pub fn supports(&self) -> &[(Vec3, f32)] {
        &self.supports
    }

    /// Whether `p_in_world` lies beyond support `support` (an index into
    /// [`FreeSpace::supports`]) by more than `margin` at its depth, in a direction where the
    /// nearest surface measured is that support (within `margin` of it, and in front of `p`):
    /// the support hides it. `false` where nothing was measured or something else is nearer
    /// (an object on the table in front of `p` says nothing about the table there).
    pub fn hidden_under_support(
        &self,
        p_in_world: Vec3,
        support: usize,
        margin: &DepthMargin,
    ) -> bool {
        let Some(&(normal, offset)) = self.supports.get(support) else {
            return false;
        };
        let Some((tx, ty, z)) = project(&self.sensor_from_world, p_in_world) else {
            return false;
        };
        if normal.dot(p_in_world) - offset >= -margin.at(z) {
            return false;
        }
        let Some(bin) = self.bin(tx, ty) else {
            return false;
        };
        let nearest = self.nearest_m[bin];
        if !nearest.is_finite() || nearest >= z {
            return false;
        }
        // The nearest measured surface in p's direction: on p's ray, at its depth (depth along
        // the optical axis grows in proportion along a ray).
        let measured = self.sensor_in_world + (p_in_world - self.sensor_in_world) * (nearest / z);
        (normal.dot(measured) - offset).abs() <= margin.at(nearest)
    }

    /// The same free space in a world moved by `new_from_old` (the tracker's correction of a
    /// camera pose that was off, see `crate::camera_error`): the range image is unchanged, the
    /// sensor and the supports move with the world.
    pub fn moved(&self, new_from_old: &Affine3A) -> Self {
        Self {
            sensor_from_world: self.sensor_from_world * new_from_old.inverse(),
            sensor_in_world: new_from_old.transform_point3(self.sensor_in_world),
            supports: self
                .supports
                .iter()
                .map(|&(normal, offset)| {
                    let normal = new_from_old.transform_vector3(normal);
                    (normal, offset + normal.dot(new_from_old.translation.into()))
                })
                .collect(),
            ..self.clone()
        }
    }

    /// Bins holding a measurement (for logs and tests).
    pub fn measured_bins(&self) -> usize {
        self.nearest_m.iter().filter(|d| d.is_finite()).count()
    }
}

/// The smallest and largest tangents of the directions binned.
#[derive(Debug, Clone, Copy)]
struct TangentBounds {
    lo: (f32, f32),
    hi: (f32, f32),
}

impl TangentBounds {
    /// Bounds that any direction widens (inverted by the largest tangent binned).
    const EMPTY: Self = Self {
        lo: (MAX_TAN, MAX_TAN),
        hi: (-MAX_TAN, -MAX_TAN),
    };

    fn include(&mut self, tx: f32, ty: f32) {
        self.lo = (self.lo.0.min(tx), self.lo.1.min(ty));
        self.hi = (self.hi.0.max(tx), self.hi.1.max(ty));
    }
}

/// A world point's direction from the sensor as tangents of the optical axis, and its depth
/// along it; `None` for a non-finite point or one behind (or at) the sensor.
fn project(sensor_from_world: &Affine3A, p_in_world: Vec3) -> Option<(f32, f32, f32)> {
    let s = sensor_from_world.transform_point3(p_in_world);
    (s.is_finite() && s.z > 1e-3).then(|| (s.x / s.z, s.y / s.z, s.z))
}

#[cfg(test)]
mod tests {
    use super::*;

    const MARGIN: DepthMargin = DepthMargin {
        margin_m: 0.01,
        per_m2: 0.0,
    };

    /// A wall 2 m in front of a sensor at the origin looking along +z.
    fn wall(depth_m: f32) -> Vec<Vec3> {
        (-50..=50)
            .flat_map(|i| {
                (-50..=50).map(move |j| Vec3::new(i as f32 * 0.004, j as f32 * 0.004, depth_m))
            })
            .collect()
    }

    /// A posed frame (the middle of a VGA camera's image): a slanted wall with a nearer box in front of it, and pixels with
    /// no reading (zero, NaN, beyond the range) in a pattern.
    fn box_before_a_wall() -> DepthFrame {
        let intrinsics = tacmesh_source::Intrinsics {
            width: 160,
            height: 120,
            fx: 570.0,
            fy: 571.0,
            cx: 79.3,
            cy: 60.1,
        };
        let mut depth_m = Vec::new();
        for v in 0..120 {
            for u in 0..160 {
                let wall = 2.0 + 0.004 * u as f32 + 0.002 * v as f32;
                let z = match (u * 7 + v * 13) % 41 {
                    0 => 0.0,
                    1 => f32::NAN,
                    2 => 9.0,
                    _ if (50..90).contains(&u) && (40..80).contains(&v) => 1.2,
                    _ => wall,
                };
                depth_m.push(z);
            }
        }
        DepthFrame {
            intrinsics,
            depth_m,
            world_from_sensor: Affine3A::from_rotation_translation(
                glam::Quat::from_rotation_x(2.2) * glam::Quat::from_rotation_z(0.3),
                Vec3::new(0.4, -0.2, 1.1),
            ),
            capture_time: std::time::Duration::ZERO,
        }
    }

    #[test]
    fn a_depth_frame_gives_the_image_of_its_deprojected_points() {
        let frame = box_before_a_wall();
        let points = frame.deproject_organised(5.0).points_in_world;
        let from_points = FreeSpace::from_points(&points, frame.world_from_sensor);
        let from_depth = FreeSpace::from_depth(&frame, 5.0);
        assert_eq!(
            (from_depth.width, from_depth.height, from_depth.origin),
            (from_points.width, from_points.height, from_points.origin)
        );
        assert_eq!(from_depth.bins_per_tan, from_points.bins_per_tan);
        assert!(
            from_points.measured_bins() > 2000,
            "{}",
            from_points.measured_bins()
        );
        // The same nearest depth per bin, but where a pixel on a bin's edge rounds to the
        // other side through the world and back.
        let differ = from_depth
            .nearest_m
            .iter()
            .zip(&from_points.nearest_m)
            .filter(|(a, b)| !(a == b || (**a - **b).abs() <= 1e-5))
            .count();
        assert!(
            differ * 200 <= from_points.measured_bins(),
            "{differ} of {} bins differ",
            from_points.measured_bins()
        );
        // Nothing beyond the range or without a reading was binned: the box and the wall only.
        let nearest = from_depth
            .nearest_m
            .iter()
            .copied()
            .filter(|z| z.is_finite());
        assert!(nearest.clone().all(|z| (1.2..3.0).contains(&z)));
        assert!(nearest.clone().any(|z| z == 1.2) && nearest.clone().any(|z| z > 2.0));
        // And the two agree on what the frame saw through.
        let sensor = Vec3::from(frame.world_from_sensor.translation);
        for &p in points.iter().step_by(97).filter(|p| p.is_finite()) {
            let before = sensor + (p - sensor) * 0.8;
            assert_eq!(
                from_depth.seen_through(before, &MARGIN),
                from_points.seen_through(before, &MARGIN),
                "{before}"
            );
        }
    }

    #[test]
    fn a_frame_without_a_reading_measures_nothing() {
        let mut frame = box_before_a_wall();
        frame.depth_m.iter_mut().for_each(|z| *z = 0.0);
        let free = FreeSpace::from_depth(&frame, 5.0);
        assert_eq!(free.measured_bins(), 0);
        assert!(!free.seen_through(Vec3::new(0.4, -0.2, 0.0), &MARGIN));
        // A short buffer (a malformed frame that slipped through) reads as no reading.
        frame.depth_m.truncate(10);
        assert_eq!(FreeSpace::from_depth(&frame, 5.0).measured_bins(), 0);
    }

    #[test]
    fn a_point_in_front_of_the_measured_surface_is_seen_through() {
        let free = FreeSpace::from_points(&wall(2.0), Affine3A::IDENTITY);
        assert!(free.measured_bins() > 1000);
        assert!(free.seen_through(Vec3::new(0.05, 0.0, 1.0), &MARGIN));
        assert!(
            !free.seen_through(Vec3::new(0.05, 0.0, 1.995), &MARGIN),
            "within margin"
        );
        assert!(
            !free.seen_through(Vec3::new(0.05, 0.0, 2.5), &MARGIN),
            "behind: occluded"
        );
    }

    #[test]
    fn nothing_measured_means_nothing_seen_through() {
        let free = FreeSpace::from_points(&wall(2.0), Affine3A::IDENTITY);
        // Outside the wall's directions, and behind the sensor.
        assert!(!free.seen_through(Vec3::new(1.0, 0.0, 1.0), &MARGIN));
        assert!(!free.seen_through(Vec3::new(0.0, 0.0, -1.0), &MARGIN));
        let empty = FreeSpace::from_points(&[Vec3::NAN], Affine3A::IDENTITY);
        assert!(!empty.seen_through(Vec3::new(0.0, 0.0, 1.0), &MARGIN));
    }

    /// The nearest depth of a bin decides: a voxel at an object's silhouette, where the bin
    /// also sees the background, is not carved.
    #[test]
    fn the_nearest_surface_in_a_direction_decides() {
        let mut points = wall(2.0);
        points.push(Vec3::new(0.0, 0.0, 1.0));
        let free = FreeSpace::from_points(&points, Affine3A::IDENTITY);
        assert!(!free.seen_through(Vec3::new(0.0, 0.0, 0.999), &MARGIN));
    }

    /// The sensor pose is honoured: the same wall seen from a sensor moved and turned.
    #[test]
    fn a_posed_sensor_sees_along_its_own_axis() {
        let world_from_sensor = Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            Vec3::new(-2.0, 0.0, 0.0),
        );
        // The sensor's +z is the world's +x; a wall at world x = 0.
        let points: Vec<Vec3> = wall(2.0)
            .into_iter()
            .map(|p| world_from_sensor.transform_point3(p))
            .collect();
        let free = FreeSpace::from_points(&points, world_from_sensor);
        assert!(free.seen_through(Vec3::new(-1.0, 0.0, 0.0), &MARGIN));
        assert!(!free.seen_through(Vec3::new(0.5, 0.0, 0.0), &MARGIN));
    }

    /// A table (the plane y = 0.3 below a sensor at the origin, seen from above at a slant)
    /// with a box standing on it, as measured points.
    fn table_with_box() -> Vec<Vec3> {
        let mut points: Vec<Vec3> = (0..300)
            .flat_map(|i| {
                (0..200)
                    .map(move |j| Vec3::new(-0.6 + i as f32 * 0.004, 0.3, 0.4 + j as f32 * 0.006))
            })
            .collect();
        // The box's front face, 10 cm tall, at z = 0.8.
        points.extend((0..50).flat_map(|i| {
            (0..25).map(move |j| Vec3::new(-0.1 + i as f32 * 0.004, 0.2 + j as f32 * 0.004, 0.8))
        }));
        points
    }

    #[test]
    fn a_voxel_beneath_a_measured_support_is_hidden_by_it() {
        let table = (Vec3::new(0.0, 1.0, 0.0), 0.3);
        let free =
            FreeSpace::from_points(&table_with_box(), Affine3A::IDENTITY).with_supports([table]);
        // Normals are turned towards the sensor (above the table, y < 0.3).
        assert_eq!(free.supports(), &[(Vec3::new(0.0, -1.0, 0.0), -0.3)]);
        // 5 cm under the table top, in front of the box: the table hides it.
        assert!(free.hidden_under_support(Vec3::new(0.3, 0.35, 0.9), 0, &MARGIN));
        // On the table (within the margin) or above it: not hidden.
        assert!(!free.hidden_under_support(Vec3::new(0.3, 0.305, 0.9), 0, &MARGIN));
        assert!(!free.hidden_under_support(Vec3::new(0.3, 0.25, 0.9), 0, &MARGIN));
        // Under the table behind the box: the box is the nearest surface there, not the table.
        assert!(!free.hidden_under_support(Vec3::new(0.0, 0.32, 0.9), 0, &MARGIN));
        // Beyond the measured table (no return there): nothing is known.
        assert!(!free.hidden_under_support(Vec3::new(2.0, 0.4, 0.9), 0, &MARGIN));
        assert!(!free.hidden_under_support(Vec3::new(0.3, 0.35, 0.9), 1, &MARGIN));
    }

    /// A frame whose world is moved answers for the moved points as the original did for the
    /// original ones, supports included.
    #[test]
    fn a_moved_free_space_answers_for_moved_points() {
        let table = (Vec3::new(0.0, 1.0, 0.0), 0.3);
        let free =
            FreeSpace::from_points(&table_with_box(), Affine3A::IDENTITY).with_supports([table]);
        let new_from_old = Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_x(0.2) * glam::Quat::from_rotation_y(-0.3),
            Vec3::new(0.1, -0.05, 0.3),
        );
        let moved = free.moved(&new_from_old);
        for p in [
            Vec3::new(0.3, 0.35, 0.9),
            Vec3::new(0.3, 0.25, 0.9),
            Vec3::new(0.0, 0.32, 0.9),
            Vec3::new(0.05, 0.25, 0.6),
        ] {
            let q = new_from_old.transform_point3(p);
            assert_eq!(
                free.seen_through(p, &MARGIN),
                moved.seen_through(q, &MARGIN)
            );
            assert_eq!(
                free.hidden_under_support(p, 0, &MARGIN),
                moved.hidden_under_support(q, 0, &MARGIN)
            );
        }
        assert!(moved.hidden_under_support(
            new_from_old.transform_point3(Vec3::new(0.3, 0.35, 0.9)),
            0,
            &MARGIN
        ));
    }

    #[test]
    fn the_margin_grows_with_depth_squared() {
        let margin = DepthMargin {
            margin_m: 0.01,
            per_m2: 0.004,
        };
        assert!((margin.at(1.0) - 0.014).abs() < 1e-6);
        assert!((margin.at(3.5) - 0.059).abs() < 1e-6);
    }
}
