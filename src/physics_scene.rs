//! A physics scene of what a subscriber holds (`tacmesh subscribe --out DIR --mjcf --sdf`): each
//! object a moving body with convex collision parts and mass properties, each support plane a
//! finite slab under what was seen of it, gravity towards the largest support. Pairs that
//! start inside each other (two one-view proxies that each take in the space behind them, a
//! body reaching into a slab) do not collide with each other; the rest all collide. An object whose body does not stand on a
//! support by itself (it touches it in fewer than three points, or its centre of mass is not
//! above them: a fragment held up by another object) is held still instead, a static body
//! that still collides.
//!
//! Each object's collision parts are its published Body's (docs/protocol.md: the daemon's
//! proxy, swept along the sensor's rays, its convex hulls and mass properties) when it has
//! one. Until it does (a daemon that sends none, a body still being made), they come from its
//! published shape: a closed shape is decomposed as it is; an open one (a one-view shell) is
//! first closed into a proxy, extruded straight down onto the support it stands on (the
//! subscriber knows neither the sensor's position nor what it saw as empty, so it cannot sweep
//! the shell along the sensor's rays as the daemon does) and grown by the shape's residual.
//! The parts are recomputed only when an object's shape or body changes: a move only moves the
//! body.

use std::collections::HashMap;

use glam::Vec3;
use tacmesh_physics::proxy::{collision_proxy, Proxy, ProxyConfig, SupportPlane};
use tacmesh_physics::scene::{
    Exclusion, Member, Motion, Scene as SimScene, SceneBody, SceneSupport, WorldFromBody,
    SUPPORT_MARGIN_M, SUPPORT_THICKNESS_M,
};
use tacmesh_physics::{
    convex_parts, lift_onto_supports, primitive_of_shape, rests_on, starting_overlaps,
    ConvexConfig, MassProperties, Primitive, PrimitiveShape, WorldSupport, LIFT_MAX_M,
    OVERLAP_TOLERANCE_M,
};
use tacmesh_protocol::{Body, BodyPrimitive, Hull, Scene, SceneObject};
use tacmesh_source::TriMesh;

use crate::daemon::planes::FIRST_PLANE_ID;

/// How high above its support an object's parts count as its foot, metres.
const FOOT_M: f32 = 0.03;

/// Standard gravity, m/s².
const GRAVITY_M_S2: f32 = 9.806_65;

/// An object's collision parts, for one shape version and body.
struct Collision {
    shape_version: u64,
    /// The shape version of the published Body they are, or `None` when made here.
    body_version: Option<u64>,
    /// The parts and their mass, or why there are none.
    parts: Result<(Vec<TriMesh>, MassProperties), String>,
    /// The primitive the object is (its published Body's, or fitted here to its shape until
    /// a Body comes), with its covering hull and mass properties, made once per shape.
    primitive: Option<(Primitive, Vec<TriMesh>, MassProperties)>,
}

/// Collision parts of a subscriber's objects, kept from update to update.
#[derive(Default)]
pub struct PhysicsScene {
    collisions: HashMap<u64, Collision>,
}

/// What [`PhysicsScene::update`] made of the scene.
pub struct PhysicsUpdate {
    pub scene: SimScene,
    /// Objects whose collision parts were (re)computed in this update.
    pub decomposed: usize,
    /// Objects whose collision parts are their published Body's.
    pub from_bodies: usize,
    /// Objects left out, with why (a shape too flat or small to hold a volume).
    pub left_out: Vec<(u64, String)>,
    /// Objects held still (static) because their body does not stand on a support by itself,
    /// with why: a fragment of an object held up by another, or a proxy that leans off its
    /// foot would topple or fall in the simulation.
    pub held_still: Vec<(u64, String)>,
    /// Pairs that start inside each other and do not collide with each other: names (the
    /// scene's `object-N`, `plane-N`) and how deep, metres.
    pub overlaps: Vec<(String, String, f32)>,
    /// Bodies lifted onto the support they reached a little into (a proxy grown by the
    /// sensor's noise): body, support, metres.
    pub lifted: Vec<(String, String, f32)>,
    /// Objects whose collision was made anew: id, and the primitive their shape is, if any:
    /// which (`box`, `cylinder`, `sphere`) and the 95th percentile of the shape's distances
    /// from it, metres.
    pub primitives: Vec<(u64, Option<(&'static str, f32)>)>,
}

/// A support's plane and the outline of what was seen of it, in the world.
fn world_support(object: &SceneObject) -> Option<(WorldSupport, Vec<glam::Vec3>)> {
    let fan = object.world_mesh();
    WorldSupport::of_fan(object.object_id(), &fan).map(|s| (s, fan.vertices))
}

/// The mass properties a body is simulated with: the published (or computed) ones when an
/// engine can take them, else those of its convex parts together (a fallback body is held to
/// the same rules: MuJoCo refuses a scene with one implausible inertia). `Err` with why when
/// neither will do.
fn plausible_mass(parts: &[TriMesh], mass: &MassProperties) -> Result<MassProperties, String> {
    let Some(why) = mass.implausible() else {
        return Ok(*mass);
    };
    let of_parts: Result<Vec<MassProperties>, _> =
        parts.iter().map(MassProperties::of_closed_mesh).collect();
    match of_parts.ok().and_then(|m| MassProperties::sum(&m).ok()) {
        Some(sum) if sum.implausible().is_none() => Ok(sum),
        _ => Err(format!("its mass properties cannot be simulated: {why}")),
    }
}

impl PhysicsScene {
    pub fn new() -> Self {
        Self::default()
    }

    /// The physics scene of `scene` now: collision parts of new shapes computed, those of
    /// objects gone forgotten.
    pub fn update(&mut self, scene: &Scene) -> PhysicsUpdate {
        let (supports, mut outlines): (Vec<WorldSupport>, Vec<Vec<glam::Vec3>>) = scene
            .objects()
            .filter(|o| o.shape.is_support())
            .filter_map(world_support)
            .unzip();
        // Gravity pulls towards the largest support (the floor or the table the camera looks
        // at); with none, along −z.
        let up = supports
            .iter()
            .max_by(|a, b| a.area_m2.total_cmp(&b.area_m2))
            .map_or(Vec3::Z, |s| s.normal);

        self.collisions
            .retain(|id, _| scene.get(*id).is_some_and(|o| !o.shape.is_support()));
        let mut decomposed = 0;
        let mut from_bodies = 0;
        let mut left_out = Vec::new();
        let mut held_still = Vec::new();
        let mut primitives = Vec::new();
        let mut bodies = Vec::new();
        let mut objects: Vec<&SceneObject> =
            scene.objects().filter(|o| !o.shape.is_support()).collect();
        objects.sort_by_key(|o| o.object_id());
        for object in objects {
            let id = object.object_id();
            let world_from_object = object.pose.world_from_object();
            // The support it stands on (an index into `supports`), and that plane in its frame:
            // looked up once, from its mesh in the world.
            let standing_on =
                tacmesh_physics::support_under(&supports, &object.world_mesh().vertices)
                    .and_then(|s| supports.iter().position(|t| t.object_id == s.object_id));
            let support = standing_on.map(|k| supports[k].in_frame(world_from_object));
            let body_version = object.body.as_ref().map(|b| b.shape_version);
            let stale = self.collisions.get(&id).is_none_or(|c| {
                c.shape_version != object.shape.version() || c.body_version != body_version
            });
            if stale {
                // The daemon fits the same way from the same shape: its Body says. Until a
                // Body comes, the fit must lie within the proxy made here.
                let proxy = object.body.is_none().then(|| object_proxy(object, support));
                let primitive = match (&object.body, &proxy) {
                    (Some(body), _) => body.primitive.as_ref().map(physics_primitive),
                    (None, Some(proxy)) if proxy.closed => primitive_of_shape(
                        &object.shape.mesh,
                        None,
                        support,
                        object.shape.report.max_residual_m,
                        &proxy.mesh,
                    ),
                    (None, _) => None,
                };
                primitives.push((id, primitive.map(|p| (p.shape.name(), p.residual_m))));
                let parts = match &object.body {
                    Some(body) => Ok(published_parts(body)),
                    None => {
                        decomposed += 1;
                        match proxy {
                            Some(proxy) => collision_parts(proxy),
                            None => Err("no proxy".to_owned()),
                        }
                    }
                };
                self.collisions.insert(
                    id,
                    Collision {
                        shape_version: object.shape.version(),
                        body_version,
                        parts,
                        primitive: primitive.map(|p| (p, vec![p.covering_mesh()], p.mass())),
                    },
                );
            }
            if body_version.is_some() {
                from_bodies += 1;
            }
            let collision = &self.collisions[&id];
            // A primitive is the object whole: its mass, and the engine's exact collisions.
            let parts = match (&collision.parts, &collision.primitive) {
                (_, Some((_, mesh, mass))) => Ok((mesh, mass)),
                (Ok((parts, mass)), None) => Ok((parts, mass)),
                (Err(why), None) => Err(why),
            };
            match parts {
                Ok((parts, mass)) => {
                    // What stands on a support is evidence of it: the table goes on under the
                    // object, where the camera could not see it. Its foot joins the support's
                    // outline, so that the slab reaches under it.
                    if let Some(k) = standing_on {
                        let on = &supports[k];
                        outlines[k].extend(
                            parts
                                .iter()
                                .flat_map(|part| part.vertices.iter())
                                .map(|&v| world_from_object.transform_point3(v))
                                .filter(|&v| on.normal.dot(v - on.point) < FOOT_M),
                        );
                    }
                    let plausible = plausible_mass(parts, mass);
                    let motion = match (support, &plausible) {
                        (_, Err(why)) => {
                            held_still.push((id, why.clone()));
                            Motion::Static
                        }
                        // A primitive was fitted resting on this support (a ball touches it
                        // in one point, a lying drum along a line: too few for the footprint).
                        (Some(_), Ok(_)) if collision.primitive.is_some() => Motion::Dynamic,
                        (Some(support), Ok(mass))
                            if rests_on(parts, mass.centre_of_mass, support) =>
                        {
                            Motion::Dynamic
                        }
                        (Some(_), Ok(_)) => {
                            held_still.push((
                                id,
                                "its centre of mass is not above where it touches its support"
                                    .to_owned(),
                            ));
                            Motion::Static
                        }
                        (None, Ok(_)) => {
                            held_still.push((id, "it stands on no support".to_owned()));
                            Motion::Static
                        }
                    };
                    bodies.push(SceneBody {
                        name: format!("object-{id}"),
                        world_from_body: WorldFromBody {
                            rotation: object.pose.rotation,
                            translation_m: object.pose.translation,
                        },
                        visual: object.shape.mesh.clone(),
                        convex_parts: parts.clone(),
                        primitive: collision.primitive.as_ref().map(|(p, _, _)| *p),
                        mass: plausible.unwrap_or(*mass),
                        motion,
                    })
                }
                Err(why) => left_out.push((id, why.clone())),
            }
        }
        let slabs: Vec<SceneSupport> = supports
            .iter()
            .zip(&outlines)
            .filter_map(|(s, outline)| {
                let name = match s.object_id.checked_sub(FIRST_PLANE_ID) {
                    Some(n) => format!("plane-{}", n + 1),
                    None => format!("support-{}", s.object_id),
                };
                SceneSupport::from_outline(
                    name,
                    s.point,
                    s.normal,
                    outline,
                    SUPPORT_MARGIN_M,
                    SUPPORT_THICKNESS_M,
                )
            })
            .collect();
        let mut scene = SimScene {
            gravity_m_s2: -GRAVITY_M_S2 * up,
            supports: slabs,
            bodies,
            exclusions: Vec::new(),
        };
        let lifted = lift_onto_supports(&mut scene, OVERLAP_TOLERANCE_M, LIFT_MAX_M)
            .into_iter()
            .map(|(body, support, lift_m)| {
                (
                    scene.bodies[body].name.clone(),
                    scene.supports[support].name.clone(),
                    lift_m,
                )
            })
            .collect();
        scene.exclusions = starting_overlaps(&scene, OVERLAP_TOLERANCE_M);
        let name = |m: Member| match m {
            Member::Support(k) => scene.supports[k].name.clone(),
            Member::Body(k) => scene.bodies[k].name.clone(),
        };
        let overlaps = scene
            .exclusions
            .iter()
            .map(|&Exclusion { a, b, depth_m }| (name(a), name(b), depth_m))
            .collect();
        PhysicsUpdate {
            scene,
            decomposed,
            from_bodies,
            left_out,
            held_still,
            overlaps,
            lifted,
            primitives,
        }
    }
}

/// The convex parts and mass properties of a published Body.
fn published_parts(body: &Body) -> (Vec<TriMesh>, MassProperties) {
    let mass = MassProperties {
        volume_m3: body.volume_m3,
        centre_of_mass: body.centre_of_mass,
        inertia: body.inertia,
    };
    (body.hulls.iter().map(Hull::mesh).collect(), mass)
}

/// A Body's primitive as the physics crate has it.
pub fn physics_primitive(primitive: &BodyPrimitive) -> Primitive {
    use tacmesh_protocol::PrimitiveShape as Wire;
    Primitive {
        shape: match primitive.shape {
            Wire::Box { half_m } => PrimitiveShape::Box { half_m },
            Wire::Cylinder {
                radius_m,
                half_height_m,
            } => PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            },
            Wire::Sphere { radius_m } => PrimitiveShape::Sphere { radius_m },
            Wire::Capsule {
                radius_m,
                half_height_m,
            } => PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            },
        },
        rotation: primitive.rotation,
        centre: primitive.centre,
        residual_m: primitive.residual_m,
    }
}

/// The closed proxy of one object's shape: its closed shape, or its open shell extruded onto
/// its support and grown by its residual.
fn object_proxy(object: &SceneObject, support: Option<SupportPlane>) -> Proxy {
    collision_proxy(
        &object.shape.mesh,
        None,
        support,
        &ProxyConfig {
            margin_m: object.shape.report.max_residual_m,
            ..ProxyConfig::default()
        },
    )
}

/// The convex parts and mass properties of an object's proxy.
fn collision_parts(proxy: Proxy) -> Result<(Vec<TriMesh>, MassProperties), String> {
    if !proxy.closed {
        return Err(format!(
            "its {} is not closed (an open shell with no support under it)",
            proxy.kind.as_str()
        ));
    }
    let parts = convex_parts(&proxy.mesh, &ConvexConfig::default()).map_err(|e| e.to_string())?;
    Ok((parts.hulls, parts.mesh_mass))
}

/// One object meshed offline, for [`offline_scene`], in the cloud's frame.
#[derive(Debug, Clone)]
pub struct OfflineObject {
    /// Its id (from 1).
    pub id: u64,
    pub mesh: TriMesh,
    /// Its simplification's residual bound, metres.
    pub residual_m: f32,
    /// The points it was meshed from, and the voxel they were fused in: what its primitive is
    /// fitted to and its walls measured on, as the daemon does.
    pub points: Vec<Vec3>,
    pub voxel_m: f32,
}

/// A physics scene of meshes made offline (`tacmesh mesh --mjcf/--sdf/--urdf`): each object's
/// mesh and each support's outline in one frame (the cloud's), as the daemon would publish
/// them with identity poses, each object with the body the daemon would make of it
/// ([`crate::daemon::make_body`]: seen from `viewpoint`, on the support under it, from its
/// points fused as the daemon fuses them), through the same [`PhysicsScene`] a subscriber
/// keeps. With `free`, an object that stands on no support is free rather than static (one
/// object meshed alone, for the user to place).
pub fn offline_scene(
    objects: &[OfflineObject],
    support_outlines: &[Vec<glam::Vec3>],
    viewpoint: Option<Vec3>,
    free: bool,
) -> PhysicsUpdate {
    use tacmesh_protocol::{
        Encoding, Message, Pose, Shape, SimplifyStats, SHAPE_CLOSED, SHAPE_SUPPORT,
    };
    let mut scene = Scene::new();
    let shape = |id: u64, mesh: TriMesh, flags: u8, residual_m: f32| Shape {
        pose: Pose {
            object_id: id,
            shape_version: 1,
            pose_time_ns: 0,
            pose_time_realtime_ns: 0,
            last_seen_ns: 0,
            rotation: glam::Quat::IDENTITY,
            translation: glam::Vec3::ZERO,
            linear_velocity: glam::Vec3::ZERO,
            angular_velocity: glam::Vec3::ZERO,
        },
        shape_time_ns: 0,
        shape_time_realtime_ns: 0,
        flags,
        report: SimplifyStats {
            faces_in: mesh.triangles.len() as u32,
            faces_out: mesh.triangles.len() as u32,
            max_residual_m: residual_m,
        },
        mesh,
        encoding: Encoding::Full,
    };
    for (k, outline) in support_outlines.iter().enumerate() {
        let fan = crate::daemon::planes::fan(outline);
        scene.apply(&Message::Shape(shape(
            FIRST_PLANE_ID + k as u64,
            fan,
            SHAPE_SUPPORT,
            0.0,
        )));
    }
    for object in objects {
        let flags = if object.mesh.is_closed() {
            SHAPE_CLOSED
        } else {
            0
        };
        scene.apply(&Message::Shape(shape(
            object.id,
            object.mesh.clone(),
            flags,
            object.residual_m,
        )));
    }
    let supports: Vec<WorldSupport> = scene
        .objects()
        .filter(|o| o.shape.is_support())
        .filter_map(world_support)
        .map(|(s, _)| s)
        .collect();
    for object in objects {
        let Some(body) = offline_body(object, objects, &supports, viewpoint) else {
            continue;
        };
        scene.apply(&Message::Body(body));
    }
    let mut update = PhysicsScene::new().update(&scene);
    if free {
        for body in &mut update.scene.bodies {
            if body.motion == Motion::Static && body.mass.implausible().is_none() {
                body.motion = Motion::Dynamic;
            }
        }
        update
            .held_still
            .retain(|(_, why)| why != "it stands on no support");
    }
    update
}

/// The body the daemon would make of an object meshed offline (identity pose: its frame is
/// the cloud's): on the support under it, or on the top of another object it rests on. `None`
/// when it has none (the scene then makes its collision from the shape, as for an object
/// whose body has not come yet).
fn offline_body(
    object: &OfflineObject,
    all: &[OfflineObject],
    supports: &[WorldSupport],
    viewpoint: Option<Vec3>,
) -> Option<Body> {
    let others = || {
        all.iter()
            .filter(|o| o.id != object.id)
            .map(|o| o.mesh.vertices.clone())
            .collect()
    };
    let support = tacmesh_physics::standing_on(supports, &object.mesh.vertices, others)
        .map(|plane| plane.in_frame(glam::Affine3A::IDENTITY));
    let fused = (object.voxel_m > 0.0 && !object.points.is_empty()).then(|| {
        let mut grid = tacmesh_reconstruct::moment_grid::MomentGrid::new(object.voxel_m);
        grid.integrate(&object.points);
        grid.surface_means(crate::daemon::MAX_FUSED_POINTS)
    });
    let job = crate::daemon::BodyJob {
        object_id: object.id,
        shape_version: 1,
        mesh_in_object: object.mesh.clone(),
        viewpoint_in_object: viewpoint,
        support,
        margin_m: object.residual_m,
        fused_roughness_m: fused.as_ref().map_or(0.0, |f| f.roughness_m),
        fused_points: fused.map(|f| f.points).unwrap_or_default(),
    };
    match crate::daemon::make_body(&job, None, |mesh, config| {
        Ok(tacmesh_physics::split_part_points(mesh, config))
    }) {
        Ok(body) => Some(body),
        Err(why) => {
            tracing::debug!("object {}: no body: {why}", object.id);
            None
        }
    }
}
