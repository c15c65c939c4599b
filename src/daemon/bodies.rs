//! The bodies worker: turns each published object shape into its collision body (the object's
//! solid, convex parts, mass properties: docs/protocol.md, "Body") and publishes it, off the
//! mesher's thread. An object that is a primitive (a box, a cylinder, a sphere, a capsule
//! fitted to the points its shape was made from) is that primitive, whole; otherwise the solid of a one-view shell is
//! its shadow volume along the sensor's rays to the support it stands on, flagged as a
//! fallback, cut into convex parts by planes ([`tacmesh_physics::split_part_points`], a few
//! milliseconds: parry's V-HACD took seconds on a real scene's proxies and had to run in a
//! child process, since it panics on degenerate voxel clusters).

use std::time::Instant;

use glam::Vec3;
use tacmesh_physics::{
    collision_proxy, convex_parts_with, primitive_of_shape, revolve, split_part_points,
    ConvexConfig, ConvexParts, FusedPoints, MassProperties, Primitive, PrimitiveShape, ProxyConfig,
    ProxyKind, SupportPlane, PRIMITIVE_NOISE_M,
};
use tacmesh_protocol::{Body, BodyPrimitive, BodySolid, Encoding, Hull};
use tacmesh_source::TriMesh;

use super::counters::{Counters, Stage};
use super::job_queue::{LatestJobs, ObjectJob};
use super::notify::Heartbeat;
use super::Shared;

/// One published shape to make a body of, in its object's frame.
#[derive(Debug, Clone)]
pub struct BodyJob {
    pub object_id: u64,
    pub shape_version: u64,
    pub mesh_in_object: TriMesh,
    /// The sensor's position when the shape was made, object frame.
    pub viewpoint_in_object: Option<Vec3>,
    /// The support plane the object stands on, object frame.
    pub support: Option<SupportPlane>,
    /// How far to grow an open shell's proxy: the shape's residual bound.
    pub margin_m: f32,
    /// The points the shape was made from, fused (a voxel's mean each), object frame: what a
    /// primitive is fitted to. Empty: the shape's surface instead.
    pub fused_points: Vec<Vec3>,
    /// How far the fused points scatter about their own surface, metres
    /// ([`tacmesh_reconstruct::moment_grid::SurfaceMeans`]).
    pub fused_roughness_m: f32,
}

impl ObjectJob for BodyJob {
    fn object_id(&self) -> u64 {
        self.object_id
    }
}

/// Body jobs waiting for the worker, at most one per object.
pub type BodyQueue = LatestJobs<BodyJob>;

/// How much looser a refit may be and keep the primitive an object already is: a new shape
/// version a little bumpier than the last (the demo's ball, now and then) should not turn a
/// sphere into a shadow volume of twice its mass and back.
pub const HELD_PRIMITIVE_SLACK: f32 = 1.5;

/// Objects whose held primitive the worker remembers, at most: past it, it forgets them all
/// (ids only grow; a forgotten object is only refitted without slack once).
const MAX_HELD_PRIMITIVES: usize = 4096;

/// Why an object got no body.
#[derive(Debug, thiserror::Error)]
pub enum BodyError {
    #[error("its {} is not closed (an open shell with no support under it)", kind.as_str())]
    NotClosed { kind: ProxyKind },
    #[error(transparent)]
    Physics(#[from] tacmesh_physics::PhysicsError),
    #[error("a hull has {vertices} vertices, more than the wire's {max}")]
    HullTooLarge { vertices: usize, max: usize },
}

/// The worker loop: runs until the queue is closed (see `mesher::run_mesher` for the
/// heartbeat's use).
pub fn run_bodies(shared: &Shared, heartbeat: &Heartbeat) {
    // The kind of primitive each object's last body was.
    let mut held_primitives: std::collections::HashMap<u64, &'static str> =
        std::collections::HashMap::new();
    loop {
        heartbeat.idle();
        // Objects with no body that fits their frame come first: an object's first body
        // matters more than a newer version of another's (which keeps its body meanwhile).
        let bodied = crate::lock(&shared.board).objects_with_a_body();
        let Some(job) = shared
            .body_queue
            .take_first_by(|job| bodied.contains(&job.object_id))
        else {
            break;
        };
        heartbeat.beat();
        let started = Instant::now();
        let held = held_primitives.get(&job.object_id).copied();
        let mut found_none = false;
        let decompose = |mesh: &TriMesh, config: &ConvexConfig| {
            let parts = split_part_points(mesh, config);
            found_none = parts.is_empty();
            Ok(parts)
        };
        let made = make_body(&job, held, decompose);
        match made.as_ref().ok().and_then(|b| b.primitive) {
            Some(primitive) => {
                if held_primitives.len() >= MAX_HELD_PRIMITIVES {
                    held_primitives.clear();
                }
                held_primitives.insert(job.object_id, primitive.shape.name());
            }
            None => {
                held_primitives.remove(&job.object_id);
            }
        }
        if found_none {
            // The first and every power of two after it: one line a body would flood the log.
            let failed = Counters::add(&shared.counters.decompositions_failed, 1) + 1;
            if failed.is_power_of_two() {
                tracing::warn!(
                    "object {}: its solid could not be cut into convex parts; its body is one \
                     convex hull ({failed} such so far)",
                    job.object_id
                );
            }
        }
        shared.counters.record(Stage::Body, started.elapsed());
        match made {
            Ok(body) => {
                Counters::add(&shared.counters.bodies_made, 1);
                tracing::debug!(
                    "object {} (shape {}): {} body of {} hulls, {:.4} m³, in {:.1} ms",
                    job.object_id,
                    job.shape_version,
                    body.solid.as_str(),
                    body.hulls.len(),
                    body.volume_m3,
                    started.elapsed().as_secs_f64() * 1e3
                );
                crate::lock(&shared.board).new_body(body, &shared.publisher);
            }
            Err(err) => {
                Counters::add(&shared.counters.body_failures, 1);
                tracing::debug!(
                    "object {} (shape {}): no collision body: {err}",
                    job.object_id,
                    job.shape_version
                );
            }
        }
    }
    heartbeat.retire();
}

/// A physics primitive as the wire carries it.
pub fn wire_primitive(primitive: &Primitive) -> BodyPrimitive {
    use tacmesh_protocol::PrimitiveShape as Wire;
    BodyPrimitive {
        shape: match primitive.shape {
            PrimitiveShape::Box { half_m } => Wire::Box { half_m },
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            } => Wire::Cylinder {
                radius_m,
                half_height_m,
            },
            PrimitiveShape::Sphere { radius_m } => Wire::Sphere { radius_m },
            PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => Wire::Capsule {
                radius_m,
                half_height_m,
            },
        },
        rotation: primitive.rotation.normalize(),
        centre: primitive.centre,
        residual_m: primitive.residual_m,
    }
}

/// A convex mesh as a hull of the wire, if it is small enough for one.
fn wire_hull(vertices: &[Vec3], triangles: &[[u32; 3]]) -> Result<Hull, BodyError> {
    if vertices.len() > tacmesh_protocol::MAX_HULL_VERTICES {
        return Err(BodyError::HullTooLarge {
            vertices: vertices.len(),
            max: tacmesh_protocol::MAX_HULL_VERTICES,
        });
    }
    Ok(Hull {
        vertices: vertices.to_vec(),
        // Below the vertex count, checked just above, so each fits in a byte.
        triangles: triangles.iter().map(|t| t.map(|i| i as u8)).collect(),
    })
}

/// The body of a shape that is a primitive: the primitive whole, its mass properties, and its
/// covering tessellation as the one hull.
fn primitive_body(job: &BodyJob, primitive: &Primitive) -> Result<Body, BodyError> {
    let mass = primitive.mass();
    let cover = primitive.covering_mesh();
    Ok(Body {
        object_id: job.object_id,
        shape_version: job.shape_version,
        solid: BodySolid::Primitive,
        margin_m: 0.0,
        volume_m3: mass.volume_m3,
        centre_of_mass: mass.centre_of_mass,
        inertia: mass.inertia,
        primitive: Some(wire_primitive(primitive)),
        mesh: TriMesh::default(),
        encoding: Encoding::Full,
        hulls: vec![wire_hull(&cover.vertices, &cover.triangles)?],
    })
}

/// The body of one shape: the primitive it is, if one explains it (the kind its last body
/// was, `held`, within [`HELD_PRIMITIVE_SLACK`] times the bound); else its shell completed by
/// its symmetry; else its closed proxy decomposed by `decompose` (see
/// [`tacmesh_physics::convex_parts_with`]).
pub fn make_body(
    job: &BodyJob,
    held: Option<&'static str>,
    mut decompose: impl FnMut(&TriMesh, &ConvexConfig) -> Result<Vec<Vec<Vec3>>, String>,
) -> Result<Body, BodyError> {
    let proxy = collision_proxy(
        &job.mesh_in_object,
        job.viewpoint_in_object,
        job.support,
        &ProxyConfig {
            margin_m: job.margin_m,
            ..ProxyConfig::default()
        },
    );
    if !proxy.closed {
        return Err(BodyError::NotClosed { kind: proxy.kind });
    }
    // The proxy holds the object: a primitive must lie within it.
    let fused = FusedPoints {
        points: &job.fused_points,
        roughness_m: job.fused_roughness_m,
    };
    let fitted = primitive_of_shape(
        &job.mesh_in_object,
        Some(fused),
        job.support,
        job.margin_m,
        &proxy.mesh,
    )
    .or_else(|| {
        let kind = held?;
        let looser =
            HELD_PRIMITIVE_SLACK * (job.margin_m.max(0.0) + PRIMITIVE_NOISE_M) - PRIMITIVE_NOISE_M;
        primitive_of_shape(
            &job.mesh_in_object,
            Some(fused),
            job.support,
            looser,
            &proxy.mesh,
        )
        .filter(|p| p.shape.name() == kind)
    });
    if let Some(primitive) = fitted {
        if primitive.mass().implausible().is_none() {
            return primitive_body(job, &primitive);
        }
    }
    // An open shell standing on a support may be a solid of revolution: the seen side turned
    // about its axis, if that lies within the proxy too.
    let bound_m = job.margin_m.max(0.0) + PRIMITIVE_NOISE_M;
    let revolved = match (proxy.kind, job.support) {
        (ProxyKind::ShadowVolume | ProxyKind::Extrusion, Some(support)) => {
            revolve(&job.mesh_in_object, Some(fused), support, bound_m).filter(|r| {
                match r.lies_within(&proxy.mesh, Some(support), bound_m) {
                    Ok(()) => true,
                    Err(why) => {
                        tracing::debug!(
                            "object {}: its shell turned about an axis {why}",
                            job.object_id
                        );
                        false
                    }
                }
            })
        }
        _ => None,
    };
    if let Some(revolved) = revolved {
        if let Ok(mass) = MassProperties::of_closed_mesh(&revolved.mesh) {
            if mass.implausible().is_none() {
                // Its parts follow its axis (wedges around a hole), as many as the wire
                // carries; the plane cuts if the profile is not one its bands cut.
                let by_axis = revolved.part_points(
                    TURNED_PARTS_TOLERANCE * bound_m,
                    tacmesh_protocol::MAX_HULLS,
                );
                let parts = if by_axis.is_empty() {
                    convex_parts_with(&revolved.mesh, &ConvexConfig::default(), &mut decompose)?
                } else {
                    let config = ConvexConfig {
                        max_hulls: tacmesh_protocol::MAX_HULLS,
                        max_hull_vertices: tacmesh_protocol::MAX_HULL_VERTICES,
                        concavity: 0.0,
                        ..ConvexConfig::default()
                    };
                    convex_parts_with(&revolved.mesh, &config, |_, _| Ok(by_axis))?
                };
                // An engine collides the hulls: where they bridge what the solid leaves open
                // (a flat ring's hull spans a torus's hole) the completion is not what it
                // gets, and the conservative fallback is the honest body.
                let ratio = parts.volume_ratio();
                if ratio <= MAX_COMPLETED_HULLS_OVER_SOLID {
                    return solid_body(job, BodySolid::Completed, revolved.mesh, mass, 0.0, &parts);
                }
                tracing::debug!(
                    "object {}: the convex parts of its turned solid are {ratio:.2}× its \
                     volume; its body is the fallback",
                    job.object_id
                );
            }
        }
    }
    let mass = MassProperties::of_closed_mesh(&proxy.mesh)?;
    let (solid, margin_m) = match proxy.kind {
        // The shape itself: nothing to repeat on the wire.
        ProxyKind::Surface => (BodySolid::Shape, 0.0),
        ProxyKind::ShadowVolume => (BodySolid::ShadowVolume, job.margin_m),
        ProxyKind::Extrusion => (BodySolid::Extrusion, job.margin_m),
        ProxyKind::OpenShell => return Err(BodyError::NotClosed { kind: proxy.kind }),
    };
    let parts = convex_parts_with(&proxy.mesh, &ConvexConfig::default(), decompose)?;
    solid_body(job, solid, proxy.mesh, mass, margin_m, &parts)
}

/// How far, as a share of the residual bound, a turned solid's convex part may bulge past
/// the solid where its profile's bands are joined into one piece.
const TURNED_PARTS_TOLERANCE: f32 = 1.0;

/// How much more than a completed solid its convex hulls may hold before the completion is
/// dropped for the fallback (the demo's torus: 1.04–1.22× when its parts follow its hole,
/// 1.46× when they merged across it).
const MAX_COMPLETED_HULLS_OVER_SOLID: f32 = 1.3;

/// The body of a closed solid: its convex `parts`, its mass properties, and the solid itself
/// on the wire unless it is the shape.
fn solid_body(
    job: &BodyJob,
    solid: BodySolid,
    mesh: TriMesh,
    mass: MassProperties,
    margin_m: f32,
    parts: &ConvexParts,
) -> Result<Body, BodyError> {
    let hulls = parts
        .hulls
        .iter()
        .map(|hull| wire_hull(&hull.vertices, &hull.triangles))
        .collect::<Result<Vec<_>, _>>()?;
    let mesh = if solid.carries_mesh() {
        mesh
    } else {
        TriMesh::default()
    };
    Ok(Body {
        object_id: job.object_id,
        shape_version: job.shape_version,
        solid,
        margin_m,
        volume_m3: mass.volume_m3,
        centre_of_mass: mass.centre_of_mass,
        inertia: mass.inertia,
        primitive: None,
        mesh,
        encoding: Encoding::Full,
        hulls,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job(mesh: TriMesh) -> BodyJob {
        BodyJob {
            object_id: 3,
            shape_version: 7,
            mesh_in_object: mesh,
            viewpoint_in_object: Some(Vec3::new(0.0, -2.0, 1.0)),
            support: None,
            margin_m: 0.004,
            fused_points: Vec::new(),
            fused_roughness_m: 0.0,
        }
    }

    /// A closed shape is its own proxy; its body carries no proxy mesh, its mass is the
    /// shape's, and a failed decomposition leaves it one conservative hull.
    #[test]
    fn a_closed_shape_is_its_own_proxy_and_a_failed_decomposition_is_one_hull() {
        let torus = tacmesh_sim::torus(24, 12, 0.4, 0.1);
        let body = make_body(&job(torus.clone()), None, |m, c| {
            Ok(tacmesh_physics::vhacd_part_points(m, c))
        })
        .expect("a torus has a body");
        assert_eq!(body.solid, BodySolid::Shape);
        assert!(body.mesh.triangles.is_empty(), "the shape is not repeated");
        assert_eq!((body.object_id, body.shape_version), (3, 7));
        assert!(body.hulls.len() >= 3, "{} hulls", body.hulls.len());
        let exact = MassProperties::of_closed_mesh(&torus).expect("a closed torus");
        assert!((body.volume_m3 - exact.volume_m3).abs() < 1e-6);
        let fallback = make_body(&job(torus), None, |_, _| Err("the child crashed".into()))
            .expect("still a body");
        assert_eq!(fallback.hulls.len(), 1);
    }

    /// An open shell with no support is swept along the sensor's rays and capped: a closed
    /// shadow volume, grown by the margin, larger than nothing.
    #[test]
    fn a_one_view_shell_becomes_a_closed_shadow_volume() {
        let cube = tacmesh_sim::cube(0.2);
        // The faces turned to the sensor (at -y, above): the shell it saw.
        let eye = Vec3::new(0.0, -2.0, 1.0);
        let seen: Vec<[u32; 3]> = cube
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| cube.vertices[i as usize]);
                (b - a).cross(c - a).dot(eye - a) > 0.0
            })
            .collect();
        let shell = TriMesh::new(cube.vertices.clone(), seen);
        let body = make_body(&job(shell), None, |m, c| {
            Ok(tacmesh_physics::vhacd_part_points(m, c))
        })
        .expect("a shell has a body");
        assert_eq!(body.solid, BodySolid::ShadowVolume);
        assert!(body.solid.is_fallback());
        assert!(!body.mesh.triangles.is_empty());
        assert!(body.volume_m3 > 0.2f32.powi(3), "{} m³", body.volume_m3);
        assert_eq!(body.margin_m, 0.004);
    }

    /// A box seen from one side, standing on a table, is a box: its body the primitive whole,
    /// of the box's mass, with no V-HACD run and one hull that holds the box.
    #[test]
    fn a_one_view_box_on_a_table_is_a_primitive_body() {
        let cube = tacmesh_sim::cube(0.2);
        // Standing on z = 0, seen from the front and above.
        let lifted = TriMesh::new(
            cube.vertices.iter().map(|v| *v + Vec3::Z * 0.1).collect(),
            cube.triangles.clone(),
        );
        let eye = Vec3::new(0.3, -1.0, 0.9);
        let seen: Vec<[u32; 3]> = lifted
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| lifted.vertices[i as usize]);
                (b - a).cross(c - a).dot(eye - a) > 0.0
            })
            .collect();
        let shell = TriMesh::new(lifted.vertices.clone(), seen);
        let mut job = job(shell);
        job.viewpoint_in_object = Some(eye);
        job.support = Some(SupportPlane {
            normal: Vec3::Z,
            offset: 0.0,
        });
        let body = make_body(&job, None, |_, _| {
            panic!("a primitive needs no decomposition")
        })
        .expect("a box has a body");
        assert_eq!(body.solid, BodySolid::Primitive);
        let primitive = body.primitive.expect("its primitive");
        assert_eq!(primitive.shape.name(), "box");
        assert!(
            (body.volume_m3 / 0.008 - 1.0).abs() < 0.02,
            "{}",
            body.volume_m3
        );
        assert!(body.centre_of_mass.distance(Vec3::Z * 0.1) < 0.002);
        assert!(body.mesh.triangles.is_empty());
        assert_eq!(body.hulls.len(), 1);
        // It goes on the wire as it is.
        let mut out = Vec::new();
        tacmesh_protocol::encode(&tacmesh_protocol::Message::Body(body), &mut out)
            .expect("a valid Body");
    }

    /// Every kind of primitive makes a Body the wire takes: its covering hull within a hull's
    /// vertex cap.
    #[test]
    fn every_primitive_kind_makes_a_wire_body() {
        for shape in [
            PrimitiveShape::Box {
                half_m: Vec3::new(0.1, 0.2, 0.3),
            },
            PrimitiveShape::Cylinder {
                radius_m: 0.05,
                half_height_m: 0.1,
            },
            PrimitiveShape::Sphere { radius_m: 0.07 },
            PrimitiveShape::Capsule {
                radius_m: 0.03,
                half_height_m: 0.08,
            },
        ] {
            let primitive = Primitive {
                shape,
                rotation: glam::Quat::from_rotation_x(0.4),
                centre: Vec3::new(0.1, 0.0, 0.2),
                residual_m: 0.001,
            };
            let body = primitive_body(&job(TriMesh::default()), &primitive)
                .unwrap_or_else(|e| panic!("{}: {e}", shape.name()));
            let mut out = Vec::new();
            tacmesh_protocol::encode(&tacmesh_protocol::Message::Body(body.clone()), &mut out)
                .unwrap_or_else(|e| panic!("{}: {e}", shape.name()));
            let back = physics_primitive_of(&body);
            assert_eq!(back.shape, primitive.shape);
        }
    }

    fn physics_primitive_of(body: &Body) -> Primitive {
        crate::physics_scene::physics_primitive(body.primitive.as_ref().expect("a primitive"))
    }

    /// A torus lying on a table, seen from one side, is completed by turning it about its
    /// axis: its body is that solid (carried on the wire), within the bounds of the truth.
    #[test]
    fn a_one_view_torus_on_a_table_is_completed_by_its_symmetry() {
        let torus = tacmesh_sim::torus(48, 24, 0.15, 0.05);
        let torus = TriMesh::new(
            torus
                .vertices
                .iter()
                .map(|v| *v + Vec3::new(0.2, 0.1, 0.05))
                .collect(),
            torus.triangles.clone(),
        );
        let eye = Vec3::new(0.2, -0.9, 0.95);
        let seen: Vec<[u32; 3]> = torus
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| torus.vertices[i as usize]);
                (b - a).cross(c - a).dot(eye - (a + b + c) / 3.0) > 0.0
            })
            .collect();
        let mut job = job(TriMesh::new(torus.vertices.clone(), seen));
        job.viewpoint_in_object = Some(eye);
        job.support = Some(SupportPlane {
            normal: Vec3::Z,
            offset: 0.0,
        });
        let body = make_body(&job, None, |m, c| Ok(split_part_points(m, c))).expect("a body");
        assert_eq!(body.solid, BodySolid::Completed);
        assert!(
            !body.mesh.triangles.is_empty(),
            "the completed solid is carried"
        );
        let truth = MassProperties::of_closed_mesh(&torus).expect("closed");
        let ratio = body.volume_m3 / truth.volume_m3;
        assert!((0.7..1.5).contains(&ratio), "{ratio}× the torus");
        assert!(body.centre_of_mass.distance(truth.centre_of_mass) < 0.02);
        let mut out = Vec::new();
        tacmesh_protocol::encode(&tacmesh_protocol::Message::Body(body), &mut out)
            .expect("a valid Body");
    }

    /// A ball seen a little bumpier than the bound allows is no primitive the first time;
    /// held as a sphere from its last body, it stays one within the slack.
    #[test]
    fn a_held_primitive_is_kept_through_a_bumpier_shape() {
        let ball = tacmesh_sim::uv_sphere(32, 16, 0.1);
        let centre = Vec3::new(0.0, 0.0, 0.1);
        let eye = Vec3::new(0.0, -1.0, 0.9);
        // Radial bumps of up to ±9 mm, deterministic.
        let bumpy: Vec<Vec3> = ball
            .vertices
            .iter()
            .enumerate()
            .map(|(i, v)| {
                let bump = 0.009
                    * ((i as f32 * 12.9898).sin() * 43_758.547)
                        .rem_euclid(1.0)
                        .mul_add(2.0, -1.0);
                centre + *v * (1.0 + bump / 0.1)
            })
            .collect();
        let seen: Vec<[u32; 3]> = ball
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| bumpy[i as usize]);
                (b - a).cross(c - a).dot(eye - (a + b + c) / 3.0) > 0.0
            })
            .collect();
        let mut job = job(TriMesh::new(bumpy, seen));
        job.viewpoint_in_object = Some(eye);
        job.support = Some(SupportPlane {
            normal: Vec3::Z,
            offset: 0.0,
        });
        let decompose = |m: &TriMesh, c: &ConvexConfig| Ok(split_part_points(m, c));
        let fresh = make_body(&job, None, decompose).expect("a body");
        assert_eq!(fresh.primitive, None, "too bumpy for a fresh fit");
        let held = make_body(&job, Some("sphere"), decompose).expect("a body");
        assert_eq!(held.primitive.map(|p| p.shape.name()), Some("sphere"));
        let other = make_body(&job, Some("box"), decompose).expect("a body");
        assert_eq!(other.primitive, None, "only the kind it was");
    }
}
