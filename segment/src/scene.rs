//! The scene model: which planes are supports, which are background, and which clusters can be
//! objects at all. A robot's camera sees a table or a floor to put things on, and, at room
//! scale, walls, a ceiling and furniture that are no object anyone picks up or touches on
//! purpose. For a physics proxy that is the difference between the mug and the wall behind it.
//!
//! Planes (RANSAC's, largest first) by orientation and size:
//! - A **support** faces up: its normal (towards the sensor) is within
//!   [`SegmentConfig::max_support_tilt_deg`] of [`SegmentConfig::up`], and it is at least
//!   [`SegmentConfig::min_support_size_m`] across and covers half the square of that. Objects rest on it. A smaller plane facing up
//!   (a book, a box's lid) is part of an object: a small plane raised above the table is not a
//!   table. Nor is a large one with sides down to the support below it (a flat box as large
//!   as a small table; [`object_tops`], after the points are classified): its points go back
//!   to the objects.
//! - A **background** plane faces sideways or down (a wall, a ceiling, a cupboard's front) and
//!   is larger than any object: [`SegmentConfig::max_object_size_m`] across, covering half the
//!   square of that. Its points are dropped.
//! - Any other plane is the face of an object (a box's side, a laptop's screen): its points stay
//!   object candidates.
//!
//! Clusters that cannot be objects are background:
//! - lying on the background planes (80 % of its points within [`WALL_RELIEF_M`] of one of
//!   them): the bumps of a wall, a whiteboard, what the noise of a far wall leaves beside the
//!   band, the corner where two walls meet (half on each);
//! - larger than [`SegmentConfig::max_object_size_m`] (twice the largest distance from the
//!   centroid): furniture, pieces of wall;
//! - flat and facing up with no support below it: a strip of floor too small or too hidden to
//!   be found as a plane (on a support, such a patch is a book or a lid: an object);
//! - a flat layer just above a support, 20 cm or wider: a rug or a mat on the floor, which
//!   the support's band and margin leave out (`covering_of`);
//! - no deeper along the sensor's axis ([`SegmentConfig::forward`]) than one depth step at
//!   their depth ([`SegmentConfig::range_step_per_m2`]): a slice of a far wall at one disparity
//!   level, which is an artefact of the sensor, not a thing.

use glam::Vec3;

use crate::planes::SupportPlane;
use crate::range::RangeDistance;
use crate::SegmentConfig;

/// What a plane found by RANSAC is, by [`plane_role`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PlaneRole {
    Support,
    Background,
    ObjectFace,
}

/// Whether `normal` faces up: within [`SegmentConfig::max_support_tilt_deg`] of
/// [`SegmentConfig::up`].
fn faces_up(normal: Vec3, config: &SegmentConfig) -> bool {
    let up = config.up.normalize_or_zero();
    let max_tilt = config.max_support_tilt_deg.clamp(0.0, 180.0).to_radians();
    up != Vec3::ZERO && normal.dot(up) >= max_tilt.cos()
}

/// The role of each of `planes` (RANSAC's, largest first; see the module docs). The first
/// plane facing up may be half [`SegmentConfig::min_support_size_m`]: the one table of a
/// tabletop scan may be small and mostly hidden; a second support (a table above the floor)
/// must be the full size, or it is the top of an object.
pub(crate) fn plane_roles(
    planes: &[SupportPlane],
    band: &RangeDistance,
    config: &SegmentConfig,
) -> Vec<PlaneRole> {
    let mut dominant_taken = false;
    let mut roles: Vec<PlaneRole> = planes
        .iter()
        .map(|plane| {
            let faces_up = faces_up(plane.normal, config);
            // Half the square of the size: a table or wall partly hidden behind objects still
            // covers that much; a plane that only grazes the tops or sides of a few objects
            // does not.
            let large = |size_m: f32| {
                plane.extent_m() >= size_m && plane.area_m2() >= 0.5 * size_m * size_m
            };
            let support_size = if dominant_taken {
                config.min_support_size_m
            } else {
                0.5 * config.min_support_size_m
            };
            if faces_up && large(support_size) {
                dominant_taken = true;
                PlaneRole::Support
            } else if !faces_up && large(config.max_object_size_m) {
                PlaneRole::Background
            } else {
                PlaneRole::ObjectFace
            }
        })
        .collect();
    // A smaller plane parallel to a background plane and within its relief is more of the same
    // wall (a whiteboard on it, or the wall's noise fitted twice).
    for k in 0..planes.len() {
        if roles[k] != PlaneRole::ObjectFace {
            continue;
        }
        let plane = &planes[k];
        let foot = band.viewpoint - plane.normal * plane.signed_distance_m(band.viewpoint);
        let same_wall = planes.iter().zip(&roles).any(|(wall, &role)| {
            role == PlaneRole::Background
                && wall.normal.dot(plane.normal) >= SAME_SURFACE_COS
                && (wall.offset_m - plane.offset_m).abs() <= relief_at(band, foot)
        });
        if same_wall {
            roles[k] = PlaneRole::Background;
        }
    }
    roles
}

/// Why a cluster is not an object, by [`background_cluster`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum NotAnObject {
    TooLarge,
    OneDepthStep,
    OnBackground,
    PieceOfFloor,
    EdgeOfSupport,
    CoveringOfSupport,
}

/// A support is this thick at most, in metres: a cluster that hangs no deeper below it and
/// rises nowhere above it is its edge (see [`background_cluster`]).
const SUPPORT_EDGE_DEPTH_M: f32 = 0.06;

/// A cluster with at least this fraction of its points near the background planes is part of
/// them.
const ON_BACKGROUND_FRACTION: f32 = 0.8;

/// What stands out of a wall by less than this, in metres, is part of the wall (a whiteboard,
/// a poster, a light switch, and the noise of a stereo camera at 2 m, which is about ±2 cm for
/// a RealSense D435: its wall came out as four parallel RANSAC planes 2 cm apart); an object
/// in front of a wall stands out farther. Far away, three plane bands if that is more.
const WALL_RELIEF_M: f32 = 0.05;

/// Planes within this angle of a background plane's orientation, and within its relief, are
/// the same surface.
const SAME_SURFACE_COS: f32 = 0.996; // 5°

fn relief_at(band: &RangeDistance, p: Vec3) -> f32 {
    WALL_RELIEF_M.max(3.0 * band.at(p))
}

/// Whether the cluster of `indices` into `points` is background (see the module docs).
/// `band` is the plane inlier distance at a point.
pub(crate) fn background_cluster(
    points: &[Vec3],
    indices: &[u32],
    supports: &[SupportPlane],
    background: &[SupportPlane],
    band: &RangeDistance,
    config: &SegmentConfig,
) -> Option<NotAnObject> {
    if indices.is_empty() {
        return None;
    }
    // On the background planes together: a cluster in the corner where two walls (or a wall
    // and the ceiling) meet lies half on each, and on neither alone.
    let near = indices
        .iter()
        .filter(|&&i| {
            let p = points[i as usize];
            background
                .iter()
                .any(|plane| plane.signed_distance_m(p).abs() <= relief_at(band, p))
        })
        .count();
    if near as f32 >= ON_BACKGROUND_FRACTION * indices.len() as f32 {
        return Some(NotAnObject::OnBackground);
    }
    let n = indices.len() as f32;
    let centroid = indices
        .iter()
        .fold(Vec3::ZERO, |sum, &i| sum + points[i as usize])
        / n;
    let forward = config.forward.normalize_or_zero();
    let (mut nearest, mut farthest, mut radius_sq) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
    let mut mean_depth = 0.0;
    for &i in indices {
        let p = points[i as usize];
        let depth = (p - config.viewpoint_m).dot(forward);
        nearest = nearest.min(depth);
        farthest = farthest.max(depth);
        mean_depth += depth / n;
        radius_sq = radius_sq.max(p.distance_squared(centroid));
    }
    if 2.0 * radius_sq.sqrt() > config.max_object_size_m {
        return Some(NotAnObject::TooLarge);
    }
    let step_m = config.range_step_per_m2.max(0.0) * mean_depth * mean_depth;
    // Noise spreads a real surface over more than a step; a near object's step is a few
    // millimetres, far below any object's depth, so this only ever takes far slices.
    if farthest - nearest <= step_m {
        return Some(NotAnObject::OneDepthStep);
    }
    if flat_and_facing_up(points, indices, centroid, band, config)
        && !supports.iter().any(|s| s.signed_distance_m(centroid) > 0.0)
    {
        return Some(NotAnObject::PieceOfFloor);
    }
    if supports.iter().any(|s| edge_of(s, points, indices, band)) {
        return Some(NotAnObject::EdgeOfSupport);
    }
    if supports
        .iter()
        .any(|s| covering_of(s, points, indices, centroid, band))
    {
        return Some(NotAnObject::CoveringOfSupport);
    }
    None
}

/// Whether the cluster is the edge of `support`: the front face of a table's top or a shelf's
/// lip, which the plane's band leaves out (it faces sideways) and which hangs from the plane.
/// Every point lies at most a plane band above the support and at most
/// [`SUPPORT_EDGE_DEPTH_M`] below it: nothing of it rises above the table, as everything
/// standing on it does, and nothing reaches farther down, as a chair or a box under the table
/// does. The TUM desk's front edge came out as two long thin objects (0.92 and 0.33 m, 3 cm
/// tall).
fn edge_of(support: &SupportPlane, points: &[Vec3], indices: &[u32], band: &RangeDistance) -> bool {
    indices.iter().all(|&i| {
        let p = points[i as usize];
        let d = support.signed_distance_m(p);
        d <= band.at(p) && d >= -SUPPORT_EDGE_DEPTH_M - band.at(p)
    })
}

/// Flat for [`flat_and_facing_up`]: 90 % of the points within this many plane bands (at the
/// centroid) of the cluster's own plane.
const FLAT_BANDS: f32 = 1.5;

/// Whether the cluster is a flat patch facing up: its own plane faces up (within
/// [`SegmentConfig::max_support_tilt_deg`]) and 90 % of its points lie within
/// [`FLAT_BANDS`] plane bands of it. On a support that is a book or a lid, an object; with
/// no support below it, it is a strip of a floor or a table that was too small, or too much
/// hidden, to be found as a plane (the PrimeSense room's floor along the bottom of the view).
fn flat_and_facing_up(
    points: &[Vec3],
    indices: &[u32],
    centroid: Vec3,
    band: &RangeDistance,
    config: &SegmentConfig,
) -> bool {
    let Some((normal, offset)) = crate::planes::fit_plane(points, indices) else {
        return false;
    };
    // A fitted plane's normal has either sign.
    if !(faces_up(normal, config) || faces_up(-normal, config)) {
        return false;
    }
    let limit = FLAT_BANDS * band.at(centroid);
    let near = indices
        .iter()
        .filter(|&&i| (normal.dot(points[i as usize]) - offset).abs() <= limit)
        .count();
    near as f32 >= 0.9 * indices.len() as f32
}

/// A covering of a support (a rug, a mat, a sheet) lies no higher than this above it, in
/// metres …
const COVER_HEIGHT_M: f32 = 0.03;

/// … is no thicker than this (or one plane band, where that is more), in metres …
const COVER_THICKNESS_M: f32 = 0.01;

/// … and at least this wide, in metres: a phone or a tablet lying flat is narrower, and
/// thinner than the support's band and margin anyway.
const COVER_SIZE_M: f32 = 0.2;

/// Whether the cluster is a covering of `support`: a flat layer just above it, such as the rug
/// on the milk recording's floor (24 × 24 and 28 × 27 cm patches, 8 mm thick, 2 cm above the
/// floor's plane), which the plane's band and margin leave out. Heights are taken at the 5th
/// and 95th percentile, so the noise's tails do not make a layer thick.
fn covering_of(
    support: &SupportPlane,
    points: &[Vec3],
    indices: &[u32],
    centroid: Vec3,
    band: &RangeDistance,
) -> bool {
    let mut heights: Vec<f32> = indices
        .iter()
        .map(|&i| support.signed_distance_m(points[i as usize]))
        .collect();
    let n = heights.len();
    if n < 10 {
        return false;
    }
    let (low_at, high_at) = (n / 20, n - 1 - n / 20);
    let low = *heights.select_nth_unstable_by(low_at, f32::total_cmp).1;
    let high = *heights.select_nth_unstable_by(high_at, f32::total_cmp).1;
    let band_m = band.at(centroid);
    if low < 0.0 || high > COVER_HEIGHT_M + band_m || high - low > COVER_THICKNESS_M.max(band_m) {
        return false;
    }
    // Wide: the largest distance of a point from the centroid along the support.
    let along = |p: Vec3| {
        let r = p - centroid;
        (r - support.normal * r.dot(support.normal)).length()
    };
    let reach = indices
        .iter()
        .map(|&i| along(points[i as usize]))
        .fold(0.0f32, f32::max);
    2.0 * reach >= COVER_SIZE_M
}

/// A support this far at least above the lowest one can be an object's top, in metres.
const MIN_TOP_HEIGHT_M: f32 = 0.03;

/// Points this close to a raised support's outline (across it, on the lowest support's
/// plane), in metres, are its sides.
const SIDE_REACH_M: f32 = 0.03;

/// The outline's perimeter is judged in bins this long, in metres.
const SIDE_BIN_M: f32 = 0.04;

/// A top has sides along at least this much of its outline without a gap, in metres: a box's
/// face, where a table has legs, a few centimetres each at its corners.
const MIN_SIDE_RUN_M: f32 = 0.15;

/// The raised supports among `planes` that are the tops of objects, by index: bounded (no
/// larger than [`SegmentConfig::max_object_size_m`]), raised above the lowest support by
/// [`MIN_TOP_HEIGHT_M`] or more, and with sides down to it: along [`MIN_SIDE_RUN_M`] of the
/// top's outline, the `candidates` (points on no plane) within [`SIDE_REACH_M`] of it fill
/// every quarter of the height between the two planes. A table's top has an apron under its
/// edge (the top quarter only) and legs at its corners; a flat box's top has its faces.
pub(crate) fn object_tops(
    points: &[Vec3],
    candidates: &[u32],
    planes: &[SupportPlane],
    band: &RangeDistance,
    config: &SegmentConfig,
) -> Vec<usize> {
    if planes.len() < 2 {
        return Vec::new();
    }
    // The lowest support is the one the sensor is highest above (as `classify` takes it).
    let Some(lowest) = (0..planes.len()).max_by(|&a, &b| {
        let height = |k: usize| planes[k].signed_distance_m(config.viewpoint_m);
        height(a).total_cmp(&height(b))
    }) else {
        return Vec::new();
    };
    let floor = &planes[lowest];
    let (e1, e2) = floor.normal.any_orthonormal_pair();
    let flat = |p: Vec3| glam::Vec2::new(p.dot(e1), p.dot(e2));
    let mut tops = Vec::new();
    for (k, top) in planes.iter().enumerate() {
        if k == lowest || top.extent_m() > config.max_object_size_m {
            continue;
        }
        // The top's height above the lowest support: the median over its points.
        let step = top.inliers.len().div_ceil(2000).max(1);
        let mut heights: Vec<f32> = top
            .inliers
            .iter()
            .step_by(step)
            .map(|&i| floor.signed_distance_m(points[i as usize]))
            .collect();
        if heights.is_empty() {
            continue;
        }
        let middle = heights.len() / 2;
        let height = *heights.select_nth_unstable_by(middle, f32::total_cmp).1;
        if height < MIN_TOP_HEIGHT_M {
            continue;
        }
        let corners: Vec<glam::Vec2> = top.outline.iter().map(|&p| flat(p)).collect();
        if corners.len() < 3 {
            continue;
        }
        let lengths: Vec<f32> = (0..corners.len())
            .map(|c| corners[c].distance(corners[(c + 1) % corners.len()]))
            .collect();
        let perimeter: f32 = lengths.iter().sum();
        let bins = (perimeter / SIDE_BIN_M).ceil().max(1.0) as usize;
        let (lo, hi) = corners.iter().fold(
            (
                glam::Vec2::splat(f32::INFINITY),
                glam::Vec2::splat(f32::NEG_INFINITY),
            ),
            |(lo, hi), &c| (lo.min(c), hi.max(c)),
        );
        let (lo, hi) = (lo - SIDE_REACH_M, hi + SIDE_REACH_M);
        // Per bin of the perimeter, the quarters of the height its side points fill.
        let mut filled = vec![0u8; bins];
        for &i in candidates {
            let p = points[i as usize];
            let h = floor.signed_distance_m(p);
            let band_m = band.at(p);
            if h <= band_m || h >= height - band_m {
                continue;
            }
            let q = flat(p);
            if q.cmplt(lo).any() || q.cmpgt(hi).any() {
                continue;
            }
            // The nearest point of the outline, and how far along the perimeter it is.
            let mut nearest = (f32::INFINITY, 0.0f32);
            let mut along = 0.0;
            for c in 0..corners.len() {
                let (a, b) = (corners[c], corners[(c + 1) % corners.len()]);
                let ab = b - a;
                let t = ((q - a).dot(ab) / ab.length_squared().max(1e-12)).clamp(0.0, 1.0);
                let d = q.distance(a + t * ab);
                if d < nearest.0 {
                    nearest = (d, along + t * lengths[c]);
                }
                along += lengths[c];
            }
            if nearest.0 > SIDE_REACH_M {
                continue;
            }
            let bin = ((nearest.1 / perimeter * bins as f32) as usize).min(bins - 1);
            let quarter = ((4.0 * h / height) as usize).min(3);
            filled[bin] |= 1 << quarter;
        }
        // The longest run of bins with all four quarters, around the outline.
        let sided: Vec<bool> = filled.iter().map(|&f| f == 0b1111).collect();
        let mut longest = 0;
        let mut run = 0;
        for k in 0..2 * bins {
            if sided[k % bins] {
                run += 1;
                longest = longest.max(run.min(bins));
            } else {
                run = 0;
            }
        }
        if longest as f32 * perimeter / bins as f32 >= MIN_SIDE_RUN_M {
            tops.push(k);
        }
    }
    tops
}

#[cfg(test)]
mod tests {
    use super::*;

    fn plane(normal: Vec3, offset_m: f32, extent_m: f32, area_m2: f32) -> SupportPlane {
        SupportPlane {
            normal: normal.normalize(),
            offset_m,
            inliers: Vec::new(),
            outline: Vec::new(),
            extent_m,
            area_m2,
        }
    }

    #[test]
    fn tables_support_walls_are_background_small_planes_are_objects() {
        // A camera's optical frame: up is −y. A table seen 45° from above, a wall ahead, a
        // ceiling, a box's lid on the table, and a second, small plane facing up.
        let config = SegmentConfig::default();
        let band = RangeDistance::new(0.008, 0.0035, 0.75, Vec3::ZERO);
        let planes = [
            plane(Vec3::new(0.0, -1.0, -1.0), -0.8, 1.2, 0.9),
            plane(Vec3::NEG_Z, -3.0, 2.5, 3.0),
            plane(Vec3::Y, -1.2, 2.0, 2.0),
            plane(Vec3::new(0.0, -1.0, -0.9), -0.7, 0.3, 0.06),
            plane(Vec3::NEG_Z, -2.97, 0.8, 0.4),
            plane(Vec3::NEG_X, -0.5, 0.4, 0.1),
        ];
        let roles = plane_roles(&planes, &band, &config);
        use PlaneRole::*;
        assert_eq!(
            roles,
            [Support, Background, Background, ObjectFace, Background, ObjectFace],
            "the fifth is more of the wall (3 cm in front of it, parallel); the sixth a box side"
        );
        // A plane that grazes a few objects' tops: wide, but covers little.
        let grazing = plane(Vec3::new(0.0, -1.0, -1.0), -0.7, 0.8, 0.03);
        assert_eq!(plane_roles(&[grazing], &band, &config), [ObjectFace]);
    }

    #[test]
    fn far_slices_walls_bumps_and_furniture_are_not_objects() {
        let config = SegmentConfig::default();
        let band = RangeDistance::new(0.008, 0.0035, 0.75, Vec3::ZERO);
        let grid = |origin: Vec3, du: Vec3, dv: Vec3, n: usize| -> Vec<Vec3> {
            (0..n * n)
                .map(|k| origin + du * (k % n) as f32 + dv * (k / n) as f32)
                .collect()
        };
        let all = |points: &[Vec3]| (0..points.len() as u32).collect::<Vec<u32>>();
        // A 20 cm box face at 1 m, turned 45° to the camera: an object.
        let face = grid(
            Vec3::new(-0.1, 0.0, 1.0),
            Vec3::new(0.007, 0.0, 0.007),
            Vec3::new(0.0, 0.01, 0.0),
            20,
        );
        assert_eq!(
            background_cluster(&face, &all(&face), &[], &[], &band, &config),
            None
        );
        // A strip of a wall at 3.5 m at one depth level (flat in z): a sensor artefact.
        let slice = grid(
            Vec3::new(-0.3, 0.0, 3.5),
            Vec3::new(0.03, 0.0, 0.0),
            Vec3::new(0.0, 0.01, 0.0),
            20,
        );
        assert_eq!(
            background_cluster(&slice, &all(&slice), &[], &[], &band, &config),
            Some(NotAnObject::OneDepthStep)
        );
        // A 1.5 m piece of furniture.
        let big = grid(
            Vec3::new(-0.75, -0.5, 2.0),
            Vec3::new(0.075, 0.0, 0.02),
            Vec3::new(0.0, 0.05, 0.0),
            21,
        );
        assert_eq!(
            background_cluster(&big, &all(&big), &[], &[], &band, &config),
            Some(NotAnObject::TooLarge)
        );
        // A 30 cm flat patch facing up (optical frame: up is -y) 1 m below a camera looking
        // down at 45 degrees: with no support below it, a strip of floor; above a table, a book.
        let patch = grid(
            Vec3::new(-0.15, 1.0, 1.0),
            Vec3::new(0.015, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 0.015),
            20,
        );
        let forward = SegmentConfig {
            forward: Vec3::new(0.0, 1.0, 1.0).normalize(),
            ..config.clone()
        };
        assert_eq!(
            background_cluster(&patch, &all(&patch), &[], &[], &band, &forward),
            Some(NotAnObject::PieceOfFloor)
        );
        let table = plane(Vec3::NEG_Y, -1.05, 1.2, 1.0);
        assert_eq!(
            background_cluster(&patch, &all(&patch), &[table], &[], &band, &forward),
            None
        );
        // The same patch 2 cm above the floor is a rug on it; a 10 cm one there is a thing.
        let floor = plane(Vec3::NEG_Y, -1.02, 1.2, 1.0);
        assert_eq!(
            background_cluster(
                &patch,
                &all(&patch),
                std::slice::from_ref(&floor),
                &[],
                &band,
                &forward
            ),
            Some(NotAnObject::CoveringOfSupport)
        );
        let small: Vec<Vec3> = patch
            .iter()
            .copied()
            .filter(|p| p.x < -0.05 && p.z < 1.1)
            .collect();
        assert_eq!(
            background_cluster(&small, &all(&small), &[floor], &[], &band, &forward),
            None
        );
        // A table top 0.8 m below the camera (up is −y), and below its front edge a strip 3 cm
        // tall and 0.9 m long seen at a slant: the top's front face, part of the table. A box
        // face standing on the table, and one under it, are objects.
        let table = plane(Vec3::NEG_Y, -0.8, 1.2, 1.0);
        let strip = |top_y: f32, height_m: f32| {
            let rows = (height_m / 0.005) as usize;
            (0..90 * rows)
                .map(|k| {
                    let x = -0.45 + 0.01 * (k % 90) as f32;
                    Vec3::new(x, top_y + 0.005 * (k / 90) as f32, 1.2 + 0.3 * x)
                })
                .collect::<Vec<Vec3>>()
        };
        let edge = strip(0.805, 0.03);
        assert_eq!(
            background_cluster(
                &edge,
                &all(&edge),
                std::slice::from_ref(&table),
                &[],
                &band,
                &config
            ),
            Some(NotAnObject::EdgeOfSupport)
        );
        let standing = strip(0.6, 0.2);
        assert_eq!(
            background_cluster(
                &standing,
                &all(&standing),
                std::slice::from_ref(&table),
                &[],
                &band,
                &config
            ),
            None
        );
        let under = strip(1.0, 0.2);
        assert_eq!(
            background_cluster(&under, &all(&under), &[table], &[], &band, &config),
            None
        );
        // The same box face with a wall 2 cm behind it, parallel: a whiteboard, part of it.
        let normal = Vec3::new(1.0, 0.0, -1.0).normalize();
        let wall = plane(normal, normal.dot(face[0]) - 0.02, 2.0, 2.0);
        assert_eq!(
            background_cluster(&face, &all(&face), &[], &[wall], &band, &config),
            Some(NotAnObject::OnBackground)
        );
        // The corner where two walls 2.5 m away meet, 20 cm of each side of it: half on each
        // wall, on neither alone, and part of them.
        let corner = Vec3::new(0.0, 0.0, 2.5);
        let (left, right) = (
            Vec3::new(-1.0, 0.0, -1.0).normalize(),
            Vec3::new(1.0, 0.0, -1.0).normalize(),
        );
        let mut sides = grid(
            corner,
            Vec3::new(-0.0095, 0.0, 0.0095),
            Vec3::new(0.0, 0.01, 0.0),
            15,
        );
        sides.extend(grid(
            corner,
            Vec3::new(0.0095, 0.0, 0.0095),
            Vec3::new(0.0, 0.01, 0.0),
            15,
        ));
        let walls = [
            plane(right, right.dot(corner), 2.0, 2.0),
            plane(left, left.dot(corner), 2.0, 2.0),
        ];
        for one in &walls {
            assert_eq!(
                background_cluster(
                    &sides,
                    &all(&sides),
                    &[],
                    std::slice::from_ref(one),
                    &band,
                    &config
                ),
                None,
                "on one wall alone"
            );
        }
        assert_eq!(
            background_cluster(&sides, &all(&sides), &[], &walls, &band, &config),
            Some(NotAnObject::OnBackground)
        );
    }
}
