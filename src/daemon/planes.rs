//! Support planes (table, floor) as published objects: each plane's visible extent is a convex
//! polygon, published as a fan of a few triangles, and kept under one id across frames.
//!
//! A plane's outline changes every frame with noise at its border, with what stands on it and
//! with where the camera looks; the published outline is the union of what was seen of it, and
//! is republished only when a frame sees it reach [`PlaneTracker::REPUBLISH_M`] beyond that,
//! or the plane itself moved by more than [`PlaneTracker::PLACEMENT_M`] under the outline's
//! middle or turned by 2°: a static table is published once, and again when more of it comes into view.
//! (Republished whenever its outline changed by 3 cm, the floor of the PCL Kinect frames and
//! TUM's desk went out about 40 times a second.)

use glam::Vec3;
use tacmesh_segment::{convex_outline, SupportPlane};
use tacmesh_source::TriMesh;

/// Support planes get ids from 2^32 up, apart from the object ids the tracker hands out (from
/// 1 up): a client can tell a static support from an object by its id alone.
pub const FIRST_PLANE_ID: u64 = 1 << 32;

/// A plane matches a tracked one when their normals are within ~10° and their offsets within
/// 5 cm.
const MATCH_COS: f32 = 0.985;
const MATCH_OFFSET_M: f32 = 0.05;

/// Each frame moves a tracked plane this share of the way to where the frame sees it.
const SMOOTHING: f32 = 0.2;

#[derive(Debug)]
struct TrackedPlane {
    id: u64,
    /// Where the frames put the plane, on average (see [`SMOOTHING`]).
    normal: Vec3,
    offset_m: f32,
    /// The normal when it was last published.
    published_normal: Vec3,
    /// The published outline (counter-clockwise about `normal`).
    published: Vec<Vec3>,
    last_seen_frame: u64,
}

/// A support plane as one frame saw it.
#[derive(Debug, Clone)]
struct SeenPlane {
    normal: Vec3,
    offset_m: f32,
    /// Counter-clockwise about `normal`.
    outline: Vec<Vec3>,
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
    /// A plane is republished when a frame sees it reach this far beyond its published
    /// outline, in metres.
    pub const REPUBLISH_M: f32 = 0.03;
    /// … or when the plane moved by this much under the middle of its published outline, in
    /// metres (about a plane band, 8 mm at 1 m: a support's residual bound), or turned by
    /// more than 2° ([`PlaneTracker::PLACEMENT_COS`]). The PCL Kinect frames, taken by a hand
    /// that shakes by a centimetre, see their floor turn by up to 0.8° and move its far
    /// corners by 12 mm; its middle moves by 4 mm.
    pub const PLACEMENT_M: f32 = 0.01;
    pub const PLACEMENT_COS: f32 = 0.9994; // cos 2°
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
        let seen: Vec<SeenPlane> = planes
            .iter()
            .map(|plane| SeenPlane {
                normal: plane.normal,
                offset_m: plane.offset_m,
                outline: plane.outline(),
            })
            .collect();
        self.update_seen(&seen)
    }

    fn update_seen(&mut self, planes: &[SeenPlane]) -> PlaneUpdate {
        self.frame += 1;
        let frame = self.frame;
        let mut update = PlaneUpdate::default();
        for plane in planes {
            if plane.outline.len() < 3 {
                continue;
            }
            // The nearest tracked plane not yet matched this frame (the first one in reach
            // let two estimates of one floor trade ids every frame).
            let matched = self
                .planes
                .iter_mut()
                .filter(|t| {
                    t.normal.dot(plane.normal) > MATCH_COS
                        && (t.offset_m - plane.offset_m).abs() < MATCH_OFFSET_M
                        && t.last_seen_frame != frame
                })
                .min_by(|a, b| {
                    let gap = |t: &TrackedPlane| (t.offset_m - plane.offset_m).abs();
                    gap(a).total_cmp(&gap(b))
                });
            let tracked = match matched {
                Some(tracked) => {
                    // The plane where the frames put it on average: frames of a camera whose
                    // poses are a little off see one floor a few degrees apart.
                    let normal = tracked
                        .normal
                        .lerp(plane.normal, SMOOTHING)
                        .normalize_or_zero();
                    if normal != Vec3::ZERO {
                        tracked.normal = normal;
                    }
                    tracked.offset_m += SMOOTHING * (plane.offset_m - tracked.offset_m);
                    tracked
                }
                None => {
                    self.planes.push(TrackedPlane {
                        id: self.next_id,
                        normal: plane.normal,
                        offset_m: plane.offset_m,
                        published_normal: plane.normal,
                        published: Vec::new(),
                        last_seen_frame: frame,
                    });
                    self.next_id += 1;
                    self.planes.last_mut().expect("just pushed")
                }
            };
            tracked.last_seen_frame = frame;
            // How far the plane moved under the middle of its published outline (and how far
            // it turned) since it was published, and how far this frame sees it reach beyond
            // that outline.
            let middle = tracked.published.iter().fold(Vec3::ZERO, |s, &c| s + c)
                / tracked.published.len().max(1) as f32;
            let moved = (tracked.normal.dot(middle) - tracked.offset_m).abs();
            let turned = tracked.published_normal.dot(tracked.normal) < Self::PLACEMENT_COS;
            let beyond = plane
                .outline
                .iter()
                .map(|&p| outside_m(&tracked.published, tracked.published_normal, p))
                .fold(0.0f32, f32::max);
            if !(tracked.published.is_empty()
                || moved > Self::PLACEMENT_M
                || turned
                || beyond > Self::REPUBLISH_M)
            {
                continue;
            }
            // What was seen of it, on the plane where it is now.
            let mut seen = tracked.published.clone();
            seen.extend(&plane.outline);
            let union = convex_outline(&seen, tracked.normal, tracked.offset_m);
            if union.len() < 3 {
                continue;
            }
            tracked.published = union;
            tracked.published_normal = tracked.normal;
            update.upserts.push((tracked.id, fan(&tracked.published)));
        }
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

/// How far `p` lies outside the convex polygon `outline` (counter-clockwise about `normal`),
/// in metres: the largest distance beyond one of its edges' lines (0 inside; beyond a corner,
/// a little less than the distance to it). Infinite for an empty outline.
fn outside_m(outline: &[Vec3], normal: Vec3, p: Vec3) -> f32 {
    if outline.len() < 3 {
        return f32::INFINITY;
    }
    (0..outline.len())
        .map(|k| {
            let (a, b) = (outline[k], outline[(k + 1) % outline.len()]);
            let out = (b - a).cross(normal).normalize_or_zero();
            (p - a).dot(out)
        })
        .fold(0.0f32, f32::max)
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

    /// A table 1 × 0.8 m at height `z`, its far edge at `far_y`, its outline's corners
    /// moved by `jitter` (as noise at its border moves them from frame to frame).
    fn table(z: f32, far_y: f32, jitter: f32) -> SeenPlane {
        SeenPlane {
            normal: Vec3::Z,
            offset_m: z,
            outline: vec![
                Vec3::new(-0.5 + jitter, 0.0, z),
                Vec3::new(0.5, jitter, z),
                Vec3::new(0.5 - jitter, far_y, z),
                Vec3::new(-0.5, far_y - jitter, z),
            ],
        }
    }

    #[test]
    fn a_table_whose_border_jitters_is_published_once() {
        let mut tracker = PlaneTracker::new();
        let first = tracker.update_seen(&[table(0.0, 0.8, 0.0)]);
        assert_eq!(first.upserts.len(), 1);
        for k in 0..60 {
            // 2.5 cm of border noise either way, and a frame that sees less of it (an object
            // in front): nothing to republish.
            let jitter = if k % 2 == 0 { 0.025 } else { -0.025 };
            let far_y = if k % 7 == 0 { 0.5 } else { 0.8 };
            let update = tracker.update_seen(&[table(0.002, far_y, jitter)]);
            assert!(
                update.upserts.is_empty() && update.removed.is_empty(),
                "frame {k}"
            );
        }
    }

    #[test]
    fn more_of_a_table_in_view_or_a_moved_table_is_published_again() {
        let mut tracker = PlaneTracker::new();
        let id = tracker.update_seen(&[table(0.0, 0.8, 0.0)]).upserts[0].0;
        // 10 cm more of it: the union of both views.
        let grown = tracker.update_seen(&[table(0.0, 0.9, 0.0)]);
        assert_eq!(grown.upserts.len(), 1);
        let (grown_id, mesh) = &grown.upserts[0];
        assert_eq!(*grown_id, id);
        assert!((mesh.area() - 0.9).abs() < 0.02, "{}", mesh.area());
        // Seen 2 cm higher from now on (the camera's pose corrected): published again within
        // a few frames, within the placement bound of where it is now, and then left alone.
        let mut republished = Vec::new();
        for k in 0..30 {
            let update = tracker.update_seen(&[table(0.02, 0.9, 0.0)]);
            republished.extend(update.upserts.into_iter().map(|(_, mesh)| (k, mesh)));
        }
        assert_eq!(republished.len(), 1, "published again once");
        let (frame, mesh) = &republished[0];
        assert!(*frame < 10, "after {frame} frames");
        let z = mesh.vertices.iter().map(|v| v.z).sum::<f32>() / mesh.vertices.len() as f32;
        assert!(
            (z - 0.02).abs() <= PlaneTracker::PLACEMENT_M,
            "published at {z}"
        );
    }
}
