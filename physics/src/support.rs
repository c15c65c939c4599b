//! The support planes of a scene (tables, floors, published as fans of triangles in the world)
//! and which one an object stands on, in the object's frame: what [`collision_proxy`](crate::collision_proxy)
//! (crate::collision_proxy) closes a one-view shell towards.

use glam::{Affine3A, Vec3};
use tacmesh_source::TriMesh;

use crate::proxy::SupportPlane;

/// A support plane in the world: a point on it, its unit normal (towards the side its fan
/// faces, where objects stand), its area and how far its fan reaches from that point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldSupport {
    pub object_id: u64,
    pub point: Vec3,
    pub normal: Vec3,
    pub area_m2: f32,
    pub half_size_m: f32,
}

impl WorldSupport {
    /// The plane of a support's fan, in the world (area-weighted normal and centroid); `None`
    /// for a fan with no area.
    pub fn of_fan(object_id: u64, fan_in_world: &TriMesh) -> Option<WorldSupport> {
        let mut area_normal = Vec3::ZERO;
        let mut centre = Vec3::ZERO;
        let mut area = 0.0;
        for t in &fan_in_world.triangles {
            let [a, b, c] = t.map(|i| fan_in_world.vertices[i as usize]);
            let n = (b - a).cross(c - a);
            area_normal += n;
            area += 0.5 * n.length();
            centre += 0.5 * n.length() * (a + b + c) / 3.0;
        }
        let normal = area_normal.try_normalize()?;
        let point = centre / area;
        let half_size_m = fan_in_world
            .vertices
            .iter()
            .map(|v| v.distance(point))
            .fold(0.0f32, f32::max);
        Some(WorldSupport {
            object_id,
            point,
            normal,
            area_m2: area,
            half_size_m,
        })
    }

    /// The plane parallel to this one `height_m` above it (the top of an object on it).
    pub fn raised(&self, height_m: f32) -> WorldSupport {
        WorldSupport {
            point: self.point + self.normal.normalize_or_zero() * height_m,
            ..*self
        }
    }

    /// This plane in an object's frame, given `world_from_object`.
    pub fn in_frame(&self, world_from_object: Affine3A) -> SupportPlane {
        // n·x = n·p in the world; with x = R·x_o + t: (Rᵀn)·x_o = n·p − n·t.
        let normal = world_from_object
            .inverse()
            .transform_vector3(self.normal)
            .normalize_or_zero();
        let offset = self.normal.dot(self.point)
            - self.normal.dot(Vec3::from(world_from_object.translation));
        SupportPlane { normal, offset }
    }
}

/// The support an object (its vertices in the world) stands on: of those it is above, up to a
/// few centimetres under (noise, and the segmentation's margin), the nearest by its lowest
/// vertex along each support's normal.
pub fn support_under<'a>(
    supports: &'a [WorldSupport],
    object_in_world: &[Vec3],
) -> Option<&'a WorldSupport> {
    supports
        .iter()
        .filter_map(|s| {
            let lowest = object_in_world
                .iter()
                .map(|v| s.normal.dot(*v - s.point))
                .fold(f32::INFINITY, f32::min);
            (lowest > -0.05).then_some((lowest, s))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, s)| s)
}

/// How far above the top of an object under it another object's lowest point may be and
/// still rest on it, metres: the segmentation cuts each off a little short where they meet.
pub const RESTING_GAP_M: f32 = 0.03;

/// What an object (its vertices in the world) stands on: the support under it
/// ([`support_under`]), or the top of another object on that support it rests on
/// ([`resting_top`]: the support raised to that top). `others` gives the other objects'
/// vertices in the world, asked for only when there is a support.
pub fn standing_on(
    supports: &[WorldSupport],
    object_in_world: &[Vec3],
    others: impl FnOnce() -> Vec<Vec<Vec3>>,
) -> Option<WorldSupport> {
    let plane = support_under(supports, object_in_world)?;
    Some(match resting_top(plane, object_in_world, &others()) {
        Some(top) => plane.raised(top),
        None => *plane,
    })
}

/// The top an object (its vertices in the world) rests on when it stands on another object
/// rather than on `support` itself: the highest top among `others` (each one's vertices in the
/// world) that is above the support, within [`RESTING_GAP_M`] of the object's lowest point
/// either way, and under its footprint (their extents across the support's plane overlap). The height above the support it rests at (the lower
/// of that top and the object's lowest point), metres, or `None`.
pub fn resting_top(support: &WorldSupport, object: &[Vec3], others: &[Vec<Vec3>]) -> Option<f32> {
    let normal = support.normal.normalize_or_zero();
    let u = normal.any_orthonormal_vector();
    let v = normal.cross(u);
    // Height over the support, and the extent across its plane.
    let extent = |points: &[Vec3]| {
        points.iter().fold(
            (
                f32::INFINITY,
                f32::NEG_INFINITY,
                glam::Vec2::splat(f32::INFINITY),
                glam::Vec2::splat(f32::NEG_INFINITY),
            ),
            |(low, high, lo, hi), p| {
                let h = normal.dot(*p - support.point);
                let q = glam::Vec2::new(p.dot(u), p.dot(v));
                (low.min(h), high.max(h), lo.min(q), hi.max(q))
            },
        )
    };
    let (bottom, _, lo, hi) = extent(object);
    if !bottom.is_finite() || bottom <= TOUCHING_M {
        return None;
    }
    others
        .iter()
        .filter_map(|other| {
            let (_, top, other_lo, other_hi) = extent(other);
            // Where they meet, each shape runs on a little into the other's space (the
            // lower one's top past the upper one's bottom on the demo's stack, by 15 mm):
            // the upper one rests at whichever is lower.
            let under = top > TOUCHING_M
                && (bottom - top).abs() <= RESTING_GAP_M
                && other_lo.cmple(hi).all()
                && lo.cmple(other_hi).all();
            under.then_some(top.min(bottom))
        })
        .max_by(f32::total_cmp)
}

/// How close to the support a part's vertex must be to count as touching it, metres.
pub const TOUCHING_M: f32 = 0.005;

/// Whether a body made of `parts` (convex hulls, in the frame `support` is given in) stands on
/// the support by itself: it touches it in at least three points, and its centre of mass is
/// above the polygon they span. A body that does not (a fragment of an object held up by
/// another, a proxy that leans off its foot) would topple or fall in a simulation: the caller
/// holds it still instead.
pub fn rests_on(parts: &[TriMesh], centre_of_mass: Vec3, support: SupportPlane) -> bool {
    let normal = support.normal.normalize_or_zero();
    if normal == Vec3::ZERO {
        return false;
    }
    // Two directions in the plane, for 2-D coordinates of the contact points.
    let u = normal.any_orthonormal_vector();
    let v = normal.cross(u);
    let flat = |p: Vec3| glam::Vec2::new(p.dot(u), p.dot(v));
    let touching: Vec<glam::Vec2> = parts
        .iter()
        .flat_map(|part| part.vertices.iter())
        .filter(|&&p| support.height(p) <= TOUCHING_M)
        .map(|&p| flat(p))
        .collect();
    let footprint = convex_polygon(touching);
    footprint.len() >= 3 && inside_convex(&footprint, flat(centre_of_mass))
}

/// The smallest rectangle (by area) around `points` in a plane: its centre, its first axis
/// (unit) and its half sides along that axis and the one across. One side of the smallest
/// rectangle lies along an edge of the points' convex hull (Freeman & Shapira 1975), so each
/// edge's direction is tried. `None` for fewer than three points that are not all on a line.
pub fn min_area_rectangle(points: &[glam::Vec2]) -> Option<(glam::Vec2, glam::Vec2, glam::Vec2)> {
    let hull = convex_polygon(points.to_vec());
    if hull.len() < 3 {
        return None;
    }
    let mut best: Option<(f32, glam::Vec2, glam::Vec2, glam::Vec2)> = None;
    for (k, &a) in hull.iter().enumerate() {
        let Some(axis) = (hull[(k + 1) % hull.len()] - a).try_normalize() else {
            continue;
        };
        let across = axis.perp();
        let (mut lo, mut hi) = (glam::Vec2::splat(f32::INFINITY), glam::Vec2::NEG_INFINITY);
        for p in &hull {
            let q = glam::Vec2::new(p.dot(axis), p.dot(across));
            lo = lo.min(q);
            hi = hi.max(q);
        }
        let area = (hi.x - lo.x) * (hi.y - lo.y);
        if best.is_none_or(|b| area < b.0) {
            let middle = 0.5 * (lo + hi);
            let centre = axis * middle.x + across * middle.y;
            best = Some((area, centre, axis, 0.5 * (hi - lo)));
        }
    }
    best.map(|(_, centre, axis, half)| (centre, axis, half))
}

/// The convex hull of points in the plane, counter-clockwise (Andrew's monotone chain). By
/// hand: a footprint has a few dozen points, and none of our dependencies has a 2-D hull.
fn convex_polygon(mut points: Vec<glam::Vec2>) -> Vec<glam::Vec2> {
    points.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.y.total_cmp(&b.y)));
    points.dedup();
    if points.len() < 3 {
        return points;
    }
    let turns_left = |o: glam::Vec2, a: glam::Vec2, b: glam::Vec2| (a - o).perp_dot(b - o) > 0.0;
    let mut hull: Vec<glam::Vec2> = Vec::with_capacity(points.len() * 2);
    for pass in [points.clone(), points.into_iter().rev().collect()] {
        let start = hull.len();
        for p in pass {
            while hull.len() >= start + 2
                && !turns_left(hull[hull.len() - 2], hull[hull.len() - 1], p)
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop(); // the last point of each pass starts the other
    }
    hull
}

/// Whether `p` lies inside (or on) a counter-clockwise convex polygon.
fn inside_convex(polygon: &[glam::Vec2], p: glam::Vec2) -> bool {
    (0..polygon.len()).all(|i| {
        let (a, b) = (polygon[i], polygon[(i + 1) % polygon.len()]);
        (b - a).perp_dot(p - a) >= 0.0
    })
}

#[cfg(test)]
mod tests {
    /// A box on a box rests on the lower one's top; a box beside it, or high above it, does
    /// not; the table's own objects rest on nothing.
    #[test]
    fn an_object_on_another_rests_on_its_top() {
        let table = WorldSupport {
            object_id: 1 << 32,
            point: Vec3::ZERO,
            normal: Vec3::Z,
            area_m2: 4.0,
            half_size_m: 1.0,
        };
        let cube = |centre: Vec3, half: f32| -> Vec<Vec3> {
            (0..8)
                .map(|k| {
                    let s = |b: u32| if k & (1 << b) == 0 { -half } else { half };
                    centre + Vec3::new(s(0), s(1), s(2))
                })
                .collect()
        };
        let lower = cube(Vec3::new(0.0, 0.0, 0.1), 0.1);
        // Segmented a little short of where they meet: 8 mm over the lower one's top.
        let upper = cube(Vec3::new(0.02, 0.0, 0.258), 0.05);
        let top = resting_top(&table, &upper, std::slice::from_ref(&lower))
            .expect("it rests on the lower");
        assert!((top - 0.2).abs() < 1e-5, "{top}");
        // The lower one's top runs on 15 mm into the upper one: it rests at its own bottom.
        let into = cube(Vec3::new(0.02, 0.0, 0.241), 0.05);
        let top = resting_top(&table, &into, std::slice::from_ref(&lower))
            .expect("it rests on the lower");
        assert!((top - 0.191).abs() < 1e-5, "{top}");
        assert_eq!(table.raised(top).in_frame(Affine3A::IDENTITY).offset, top);
        let beside = cube(Vec3::new(0.5, 0.0, 0.05), 0.05);
        assert_eq!(
            resting_top(&table, &beside, std::slice::from_ref(&lower)),
            None
        );
        let above = cube(Vec3::new(0.0, 0.0, 0.45), 0.05);
        assert_eq!(
            resting_top(&table, &above, std::slice::from_ref(&lower)),
            None
        );
        assert_eq!(resting_top(&table, &lower, &[upper]), None);
    }

    use super::*;

    fn table(height: f32) -> TriMesh {
        TriMesh::new(
            vec![
                Vec3::new(-1.0, -1.0, height),
                Vec3::new(1.0, -1.0, height),
                Vec3::new(1.0, 1.0, height),
                Vec3::new(-1.0, 1.0, height),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn an_object_stands_on_the_nearest_support_below_it_in_its_own_frame() {
        let floor = WorldSupport::of_fan(1, &table(0.0)).expect("a fan with area");
        let desk = WorldSupport::of_fan(2, &table(0.7)).expect("a fan with area");
        assert_eq!(desk.normal, Vec3::Z);
        assert!((desk.area_m2 - 4.0).abs() < 1e-5);
        let supports = [floor, desk];
        let on_desk = [Vec3::new(0.0, 0.0, 0.71), Vec3::new(0.1, 0.0, 0.9)];
        assert_eq!(
            support_under(&supports, &on_desk).map(|s| s.object_id),
            Some(2)
        );
        let on_floor = [Vec3::new(0.0, 0.0, 0.01)];
        assert_eq!(
            support_under(&supports, &on_floor).map(|s| s.object_id),
            Some(1)
        );
        // In a frame turned upside down and moved: the plane keeps its place.
        let world_from_object = Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_x(std::f32::consts::PI),
            Vec3::new(0.0, 0.0, 1.0),
        );
        let plane = desk.in_frame(world_from_object);
        let p_world = Vec3::new(0.3, -0.2, 0.7);
        let p_object = world_from_object.inverse().transform_point3(p_world);
        assert!(plane.height(p_object).abs() < 1e-5);
        assert!(plane.normal.distance(-Vec3::Z) < 1e-5);
    }

    fn boxed(lo: Vec3, hi: Vec3) -> TriMesh {
        let corners = (0..8)
            .map(|i| {
                Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                )
            })
            .collect();
        TriMesh::new(corners, vec![])
    }

    #[test]
    fn a_body_rests_when_its_centre_of_mass_is_above_its_footprint() {
        let table = SupportPlane {
            normal: Vec3::Z,
            offset: 0.0,
        };
        let block = [boxed(Vec3::ZERO, Vec3::new(0.1, 0.1, 0.3))];
        assert!(rests_on(&block, Vec3::new(0.05, 0.05, 0.15), table));
        // Its centre of mass past its foot's edge: it would topple.
        assert!(!rests_on(&block, Vec3::new(0.15, 0.05, 0.15), table));
        // Floating 2 cm above the table: nothing touches.
        let floating = [boxed(Vec3::new(0.0, 0.0, 0.02), Vec3::new(0.1, 0.1, 0.3))];
        assert!(!rests_on(&floating, Vec3::new(0.05, 0.05, 0.15), table));
        // Two parts: an overhang whose centre of mass is above the first part's foot.
        let l_shape = [
            boxed(Vec3::ZERO, Vec3::new(0.1, 0.1, 0.1)),
            boxed(Vec3::new(0.0, 0.0, 0.1), Vec3::new(0.3, 0.1, 0.15)),
        ];
        assert!(rests_on(&l_shape, Vec3::new(0.08, 0.05, 0.1), table));
        assert!(!rests_on(&l_shape, Vec3::new(0.2, 0.05, 0.12), table));
    }

    #[test]
    fn the_smallest_rectangle_of_a_turned_rectangle_is_itself() {
        let turn = glam::Mat2::from_angle(0.4);
        let corners = [
            (-2.0, -1.0),
            (2.0, -1.0),
            (2.0, 1.0),
            (-2.0, 1.0),
            (0.5, 0.2),
        ]
        .map(|(x, y)| turn * glam::Vec2::new(x, y) + glam::Vec2::new(5.0, -3.0));
        let (centre, axis, half) = min_area_rectangle(&corners).expect("a rectangle");
        assert!(
            centre.distance(glam::Vec2::new(5.0, -3.0)) < 1e-4,
            "{centre}"
        );
        let (long, short) = if half.x > half.y {
            (half.x, half.y)
        } else {
            (half.y, half.x)
        };
        assert!(
            (long - 2.0).abs() < 1e-4 && (short - 1.0).abs() < 1e-4,
            "{half}"
        );
        let along = turn * glam::Vec2::X;
        assert!(axis.dot(along).abs() > 0.9999 || axis.dot(along).abs() < 1e-4);
        assert!(
            min_area_rectangle(&[glam::Vec2::ZERO, glam::Vec2::X, 2.0 * glam::Vec2::X]).is_none()
        );
    }

    #[test]
    fn the_footprint_is_the_convex_hull_of_the_contacts() {
        let square = convex_polygon(vec![
            glam::Vec2::new(0.0, 0.0),
            glam::Vec2::new(1.0, 0.0),
            glam::Vec2::new(0.5, 0.5),
            glam::Vec2::new(1.0, 1.0),
            glam::Vec2::new(0.0, 1.0),
            glam::Vec2::new(0.0, 1.0),
        ]);
        assert_eq!(square.len(), 4, "{square:?}");
        assert!(inside_convex(&square, glam::Vec2::new(0.5, 0.5)));
        assert!(
            inside_convex(&square, glam::Vec2::new(1.0, 0.5)),
            "on an edge"
        );
        assert!(!inside_convex(&square, glam::Vec2::new(1.1, 0.5)));
    }
}
