//! Support planes (table, floor) as published objects: each plane's visible extent is a convex
//! polygon, published as a fan of a few triangles, and kept under one id across frames.
//!
//! A plane's outline changes a little every frame with noise at its border; it is republished
//! only when it grew or moved by more than [`PlaneTracker::REPUBLISH_M`], so that a static table
//! is published once (and again when more of it comes into view).

use glam::Vec3;
use tacmesh_segment::SupportPlane;
use tacmesh_source::TriMesh;

/// Support planes get ids from 2^32 up, apart from the object ids the tracker hands out (from
/// 1 up): a client can tell a static support from an object by its id alone.
pub const FIRST_PLANE_ID: u64 = 1 << 32;

/// A plane matches a tracked one when their normals are within ~10° and their offsets within
/// 5 cm.
const MATCH_COS: f32 = 0.985;
const MATCH_OFFSET_M: f32 = 0.05;

#[derive(Debug)]
struct TrackedPlane {
    id: u64,
    normal: Vec3,
    offset_m: f32,
    /// The published outline (counter-clockwise about `normal`).
    published: Vec<Vec3>,
    last_seen_frame: u64,
}

/// What to publish after a frame.
#[derive(Debug, Default, PartialEq)]
pub struct PlaneUpdate {
    /// `(id, mesh in world)` for new or changed planes.
    pub upserts: Vec<(u64, TriMesh)>,
    pub removed: Vec<u64>,
}

/// The support planes currently seen, with stable ids.
#[derive(Debug, Default)]
pub struct PlaneTracker {
    planes: Vec<TrackedPlane>,
    next_id: u64,
    frame: u64,
}

impl PlaneTracker {
    /// Outline changes smaller than this (largest distance of any corner of either polygon to
    /// the other polygon) are not republished.
    pub const REPUBLISH_M: f32 = 0.03;
    /// A plane unseen for this many frames is removed.
    pub const FORGET_AFTER_FRAMES: u64 = 30;

    pub fn new() -> Self {
        Self {
            planes: Vec::new(),
            next_id: FIRST_PLANE_ID,
            frame: 0,
        }
    }

    /// Takes one frame's support planes; returns what changed.
    pub fn update(&mut self, planes: &[SupportPlane]) -> PlaneUpdate {
        self.frame += 1;
        let mut update = PlaneUpdate::default();
        for plane in planes {
            let outline = plane.outline();
            if outline.len() < 3 {
                continue;
            }
            let matched = self.planes.iter_mut().find(|t| {
                t.normal.dot(plane.normal) > MATCH_COS
                    && (t.offset_m - plane.offset_m).abs() < MATCH_OFFSET_M
                    && t.last_seen_frame != self.frame
            });
            let tracked = match matched {
                Some(tracked) => tracked,
                None => {
                    self.planes.push(TrackedPlane {
                        id: self.next_id,
                        normal: plane.normal,
                        offset_m: plane.offset_m,
                        published: Vec::new(),
                        last_seen_frame: self.frame,
                    });
                    self.next_id += 1;
                    self.planes.last_mut().expect("just pushed")
                }
            };
            tracked.last_seen_frame = self.frame;
            tracked.normal = plane.normal;
            tracked.offset_m = plane.offset_m;
            if tracked.published.is_empty()
                || polygon_distance_m(&tracked.published, &outline) > Self::REPUBLISH_M
            {
                tracked.published = outline.clone();
                update.upserts.push((tracked.id, fan(&outline)));
            }
        }
        let frame = self.frame;
        self.planes.retain(|t| {
            let keep = frame - t.last_seen_frame < Self::FORGET_AFTER_FRAMES;
            if !keep {
                update.removed.push(t.id);
            }
            keep
        });
        update
    }
}

/// A convex polygon as a triangle fan from its first corner.
pub fn fan(outline: &[Vec3]) -> TriMesh {
    let triangles = (1..outline.len().saturating_sub(1) as u32)
        .map(|k| [0, k, k + 1])
        .collect();
    TriMesh::new(outline.to_vec(), triangles)
}

/// The largest distance from a corner of either polygon to the other polygon's boundary.
fn polygon_distance_m(a: &[Vec3], b: &[Vec3]) -> f32 {
    let one_way = |from: &[Vec3], to: &[Vec3]| {
        from.iter()
            .map(|&p| {
                (0..to.len())
                    .map(|k| segment_distance(p, to[k], to[(k + 1) % to.len()]))
                    .fold(f32::INFINITY, f32::min)
            })
            .fold(0.0f32, f32::max)
    };
    one_way(a, b).max(one_way(b, a))
}

fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    let ab = b - a;
    let t = if ab.length_squared() > 0.0 {
        ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0)
    } else {
        0.0
    };
    p.distance(a + t * ab)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_square_is_a_fan_of_two_triangles() {
        let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let mesh = fan(&square);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
        assert!((mesh.area() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn polygon_distance_sees_a_moved_corner() {
        let square = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y];
        let mut moved = square;
        moved[2] = Vec3::new(1.1, 1.1, 0.0);
        let d = polygon_distance_m(&square, &moved);
        // The moved corner is 0.1·√2 from the square's corner (1, 1).
        assert!((d - 0.1f32.hypot(0.1)).abs() < 1e-4, "{d}");
        assert_eq!(polygon_distance_m(&square, &square), 0.0);
    }
}
