//! Which members of a scene start inside each other: two one-view proxies that each take in
//! unseen space another object stands in, or a body reaching into a support. An engine throws
//! such a pair apart on its first step (two proxies 89 mm into each other threw the lighter one
//! 0.4 m on the milk recording), so the pair is kept from colliding with each other, and each
//! still collides with everything else.
//!
//! Penetration depths come from parry's contact query between the convex parts (and a
//! support's slab as a box).

use glam::Vec3;
use parry3d::math::Pose;
use parry3d::query::contact;
use parry3d::shape::{ConvexPolyhedron, Cuboid, Shape};

use crate::scene::{Exclusion, Member, Motion, Scene};

/// A penetration at most this deep at the start is left to the engine, metres: an object
/// resting on its support or against its neighbour touches it within the sensor's noise, and
/// the engine takes a few millimetres up without a jump.
pub const OVERLAP_TOLERANCE_M: f32 = 0.005;

/// One member's collision shapes in the world, and a sphere around them all.
struct Shapes {
    member: Member,
    dynamic: bool,
    /// A body's centre of mass in the world.
    centre_of_mass: Option<Vec3>,
    parts: Vec<(Pose, Box<dyn Shape>)>,
    centre: Vec3,
    radius: f32,
}

fn body_shapes(scene: &Scene) -> impl Iterator<Item = Shapes> + '_ {
    scene.bodies.iter().enumerate().map(|(k, body)| {
        let pose = Pose::from_parts(
            body.world_from_body.translation_m,
            body.world_from_body.rotation.normalize(),
        );
        let vertices: Vec<Vec3> = body
            .convex_parts
            .iter()
            .flat_map(|part| part.vertices.iter())
            .map(|v| body.world_from_body.rotation * *v + body.world_from_body.translation_m)
            .collect();
        let (centre, radius) = bounding_sphere(&vertices);
        let parts = body
            .convex_parts
            .iter()
            .filter_map(|part| ConvexPolyhedron::from_convex_hull(&part.vertices))
            .map(|shape| (pose, Box::new(shape) as Box<dyn Shape>))
            .collect();
        Shapes {
            member: Member::Body(k),
            dynamic: body.motion == Motion::Dynamic,
            centre_of_mass: Some(
                body.world_from_body.rotation * body.mass.centre_of_mass
                    + body.world_from_body.translation_m,
            ),
            parts,
            centre,
            radius,
        }
    })
}

fn support_shapes(scene: &Scene) -> impl Iterator<Item = Shapes> + '_ {
    scene.supports.iter().enumerate().map(|(k, support)| {
        let half = support.box_half_size_m();
        let centre = support.box_centre_in_world();
        let pose = Pose::from_parts(centre, support.rotation());
        Shapes {
            member: Member::Support(k),
            dynamic: false,
            centre_of_mass: None,
            parts: vec![(pose, Box::new(Cuboid::new(half)) as Box<dyn Shape>)],
            centre,
            radius: half.length(),
        }
    })
}

/// Whether `centre` is above `support`'s top and over its slab.
fn stands_over(support: &crate::scene::SceneSupport, centre: Vec3) -> bool {
    support.height(centre) > 0.0 && support.over(centre)
}

/// A sphere around `points` (their centroid and farthest distance): loose, for skipping
/// pairs that are far apart.
fn bounding_sphere(points: &[Vec3]) -> (Vec3, f32) {
    if points.is_empty() {
        return (Vec3::ZERO, 0.0);
    }
    let centre = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    let radius = points
        .iter()
        .map(|p| p.distance(centre))
        .fold(0.0f32, f32::max);
    (centre, radius)
}

/// How deep two members' shapes are inside each other at the start (0 when apart).
fn depth(a: &Shapes, b: &Shapes) -> f32 {
    if a.centre.distance(b.centre) > a.radius + b.radius {
        return 0.0;
    }
    let mut deepest = 0.0f32;
    for (pose_a, shape_a) in &a.parts {
        for (pose_b, shape_b) in &b.parts {
            if let Ok(Some(hit)) = contact(pose_a, shape_a.as_ref(), pose_b, shape_b.as_ref(), 0.0)
            {
                deepest = deepest.max(-hit.dist);
            }
        }
    }
    deepest
}

/// A body that reaches at most this far into the top of the support it stands on is lifted
/// onto it rather than kept from colliding with it (which would drop it through), metres: a
/// one-view proxy is grown by the shape's residual, so its foot sits that far under the table.
pub const LIFT_MAX_M: f32 = 0.03;

/// Lifts each dynamic body whose parts reach under the top of a support it stands over by at
/// most `max_m` (and by more than `tolerance_m`) onto that top, along the support's normal.
/// Returns `(body, support, lift_m)` for each body lifted.
pub fn lift_onto_supports(
    scene: &mut Scene,
    tolerance_m: f32,
    max_m: f32,
) -> Vec<(usize, usize, f32)> {
    let mut lifted = Vec::new();
    for (k, body) in scene.bodies.iter_mut().enumerate() {
        if body.motion != Motion::Dynamic {
            continue;
        }
        let pose = body.world_from_body;
        let vertices: Vec<Vec3> = body
            .convex_parts
            .iter()
            .flat_map(|part| part.vertices.iter())
            .map(|v| pose.rotation * *v + pose.translation_m)
            .collect();
        let centre = pose.rotation * body.mass.centre_of_mass + pose.translation_m;
        let mut best: Option<(usize, f32, Vec3)> = None;
        for (j, support) in scene.supports.iter().enumerate() {
            let normal = support.normal_in_world.normalize_or_zero();
            if !stands_over(support, centre) {
                continue;
            }
            let depth = vertices
                .iter()
                .filter(|&&p| support.over(p))
                .map(|&p| -support.height(p))
                .fold(0.0f32, f32::max);
            if depth > tolerance_m && depth <= max_m && best.is_none_or(|b| depth > b.1) {
                best = Some((j, depth, normal));
            }
        }
        if let Some((j, depth, normal)) = best {
            body.world_from_body.translation_m += normal * depth;
            lifted.push((k, j, depth));
        }
    }
    lifted
}

/// The pairs of `scene` (bodies with bodies, bodies with supports) whose collision shapes
/// start more than `tolerance_m` inside each other, with how deep; a pair of which neither can
/// move is left out (nothing would throw it).
pub fn starting_overlaps(scene: &Scene, tolerance_m: f32) -> Vec<Exclusion> {
    let members: Vec<Shapes> = body_shapes(scene).chain(support_shapes(scene)).collect();
    let mut overlaps = Vec::new();
    for (i, a) in members.iter().enumerate() {
        for b in &members[i + 1..] {
            if !(a.dynamic || b.dynamic) {
                continue;
            }
            // A body standing over a support always collides with it: kept from it, it would
            // fall through what holds it up (one reaching a little into it is lifted instead,
            // see `lift_onto_supports`).
            if let (Some(centre), Member::Support(k)) = (a.centre_of_mass, b.member) {
                if stands_over(&scene.supports[k], centre) {
                    continue;
                }
            }
            let depth_m = depth(a, b);
            if depth_m > tolerance_m {
                overlaps.push(Exclusion {
                    a: a.member,
                    b: b.member,
                    depth_m,
                });
            }
        }
    }
    overlaps
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convex::{convex_parts, ConvexConfig};
    use crate::scene::{SceneBody, SceneSupport, WorldFromBody};
    use glam::Quat;
    use tacmesh_sim::cube;

    fn block(name: &str, at: Vec3) -> SceneBody {
        let mesh = cube(0.1);
        let parts = convex_parts(&mesh, &ConvexConfig::default()).unwrap();
        SceneBody {
            name: name.into(),
            world_from_body: WorldFromBody {
                rotation: Quat::IDENTITY,
                translation_m: at,
            },
            visual: mesh,
            convex_parts: parts.hulls,
            primitive: None,
            mass: parts.mesh_mass,
            motion: Motion::Dynamic,
        }
    }

    fn table(height: f32, half: f32) -> SceneSupport {
        let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)]
            .map(|(x, y)| Vec3::new(x * half, y * half, height));
        SceneSupport::from_outline("table", corners[0], Vec3::Z, &corners, 0.0, 0.05)
            .expect("a slab")
    }

    #[test]
    fn only_pairs_that_start_inside_each_other_are_found() {
        // A 0.1 m cube (centred on its origin) resting on a table at 0, a second one 4 cm into
        // the first, a third clear of both, and a desk top whose slab the first reaches into.
        let scene = Scene {
            gravity_m_s2: Vec3::new(0.0, 0.0, -9.81),
            supports: vec![table(0.0, 1.0), table(0.13, 0.2)],
            bodies: vec![
                block("a", Vec3::new(0.0, 0.0, 0.05)),
                block("b", Vec3::new(0.06, 0.0, 0.05)),
                block("c", Vec3::new(0.5, 0.5, 0.05)),
            ],
            exclusions: vec![],
        };
        let found = starting_overlaps(&scene, OVERLAP_TOLERANCE_M);
        let pairs: Vec<(Member, Member)> = found.iter().map(|e| (e.a, e.b)).collect();
        assert_eq!(
            pairs,
            vec![
                (Member::Body(0), Member::Body(1)),
                (Member::Body(0), Member::Support(1)),
                (Member::Body(1), Member::Support(1)),
            ],
            "{found:?}"
        );
        assert!((found[0].depth_m - 0.04).abs() < 1e-3, "{found:?}");
        // Resting on the table (touching it) is no overlap.
        assert!(!pairs.contains(&(Member::Body(2), Member::Support(0))));
    }

    #[test]
    fn a_body_a_little_into_its_support_is_lifted_onto_it() {
        let mut scene = Scene {
            gravity_m_s2: Vec3::new(0.0, 0.0, -9.81),
            supports: vec![table(0.0, 1.0)],
            bodies: vec![
                // 1 cm into the table: lifted; 8 cm into it: too deep to be noise, left.
                block("sunk", Vec3::new(0.0, 0.0, 0.04)),
                block("deep", Vec3::new(0.5, 0.0, -0.03)),
                block("resting", Vec3::new(-0.5, 0.0, 0.05)),
            ],
            exclusions: vec![],
        };
        let lifted = lift_onto_supports(&mut scene, OVERLAP_TOLERANCE_M, LIFT_MAX_M);
        assert_eq!(lifted.len(), 1, "{lifted:?}");
        assert_eq!((lifted[0].0, lifted[0].1), (0, 0));
        assert!((lifted[0].2 - 0.01).abs() < 1e-4, "{lifted:?}");
        assert!((scene.bodies[0].world_from_body.translation_m.z - 0.05).abs() < 1e-4);
        let found = starting_overlaps(&scene, OVERLAP_TOLERANCE_M);
        assert!(!found.iter().any(|e| e.a == Member::Body(0)), "{found:?}");
    }
}
