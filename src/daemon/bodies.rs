//! The bodies worker: turns each published object shape into its collision body (a closed
//! proxy, convex parts, mass properties: docs/protocol.md, "Body") and publishes it, off the
//! mesher's thread. The proxy of a one-view shell is its shadow volume along the sensor's rays
//! to the support it stands on; its convex decomposition runs in a child process
//! ([`crate::isolated_vhacd`]) so that a panic inside parry's V-HACD cannot abort the daemon.

use std::time::Instant;

use glam::Vec3;
use tacmesh_physics::{
    collision_proxy, convex_parts_with, ConvexConfig, MassProperties, ProxyConfig, ProxyKind,
    SupportPlane,
};
use tacmesh_protocol::{Body, BodyProxy, Encoding, Hull};
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
}

impl ObjectJob for BodyJob {
    fn object_id(&self) -> u64 {
        self.object_id
    }
}

/// Body jobs waiting for the worker, at most one per object.
pub type BodyQueue = LatestJobs<BodyJob>;

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
    let exe = std::env::current_exe().ok();
    loop {
        heartbeat.idle();
        // Objects with no body that fits their frame come first: a V-HACD run takes a few
        // hundred milliseconds on a real scene's concave proxies, and an object's first body
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
        let mut child_failed = None;
        let decompose = |mesh: &TriMesh, config: &ConvexConfig| {
            let parts = match &exe {
                Some(exe) => crate::isolated_vhacd::decompose(
                    exe,
                    mesh,
                    config,
                    crate::isolated_vhacd::CHILD_TIMEOUT,
                ),
                None => Err("the daemon's own executable cannot be found".into()),
            };
            if let Err(why) = &parts {
                child_failed = Some(why.clone());
            }
            parts
        };
        let made = make_body(&job, decompose);
        if let Some(why) = child_failed {
            // The first failure and every power of two after it: a binary replaced under a
            // running daemon fails every time, and one line a body would flood the log.
            let failed = Counters::add(&shared.counters.decompositions_failed, 1) + 1;
            if failed.is_power_of_two() {
                tracing::warn!(
                    "object {}: the V-HACD child failed ({why}); its body is one convex hull \
                     ({failed} such so far)",
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
                    body.proxy.as_str(),
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

/// The body of one shape; `decompose` is the V-HACD step (see
/// [`tacmesh_physics::convex_parts_with`]).
pub fn make_body(
    job: &BodyJob,
    decompose: impl FnOnce(&TriMesh, &ConvexConfig) -> Result<Vec<Vec<Vec3>>, String>,
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
    let mass = MassProperties::of_closed_mesh(&proxy.mesh)?;
    let parts = convex_parts_with(&proxy.mesh, &ConvexConfig::default(), decompose)?;
    let hulls = parts
        .hulls
        .iter()
        .map(|hull| {
            if hull.vertices.len() > tacmesh_protocol::MAX_HULL_VERTICES {
                return Err(BodyError::HullTooLarge {
                    vertices: hull.vertices.len(),
                    max: tacmesh_protocol::MAX_HULL_VERTICES,
                });
            }
            Ok(Hull {
                vertices: hull.vertices.clone(),
                // Below the vertex count, checked just above, so each fits in a byte.
                triangles: hull.triangles.iter().map(|t| t.map(|i| i as u8)).collect(),
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    let (proxy_kind, mesh, margin_m) = match proxy.kind {
        // The shape itself: nothing to repeat on the wire.
        ProxyKind::Surface => (BodyProxy::Shape, TriMesh::default(), 0.0),
        ProxyKind::ShadowVolume => (BodyProxy::ShadowVolume, proxy.mesh, job.margin_m),
        ProxyKind::Extrusion => (BodyProxy::Extrusion, proxy.mesh, job.margin_m),
        ProxyKind::OpenShell => return Err(BodyError::NotClosed { kind: proxy.kind }),
    };
    Ok(Body {
        object_id: job.object_id,
        shape_version: job.shape_version,
        proxy: proxy_kind,
        margin_m,
        volume_m3: mass.volume_m3,
        centre_of_mass: mass.centre_of_mass,
        inertia: mass.inertia,
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
        }
    }

    /// A closed shape is its own proxy; its body carries no proxy mesh, its mass is the
    /// shape's, and a failed decomposition leaves it one conservative hull.
    #[test]
    fn a_closed_shape_is_its_own_proxy_and_a_failed_decomposition_is_one_hull() {
        let torus = tacmesh_sim::torus(24, 12, 0.4, 0.1);
        let body = make_body(&job(torus.clone()), |m, c| {
            Ok(tacmesh_physics::vhacd_part_points(m, c))
        })
        .expect("a torus has a body");
        assert_eq!(body.proxy, BodyProxy::Shape);
        assert!(body.mesh.triangles.is_empty(), "the shape is not repeated");
        assert_eq!((body.object_id, body.shape_version), (3, 7));
        assert!(body.hulls.len() >= 3, "{} hulls", body.hulls.len());
        let exact = MassProperties::of_closed_mesh(&torus).expect("a closed torus");
        assert!((body.volume_m3 - exact.volume_m3).abs() < 1e-6);
        let fallback =
            make_body(&job(torus), |_, _| Err("the child crashed".into())).expect("still a body");
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
        let body = make_body(&job(shell), |m, c| {
            Ok(tacmesh_physics::vhacd_part_points(m, c))
        })
        .expect("a shell has a body");
        assert_eq!(body.proxy, BodyProxy::ShadowVolume);
        assert!(!body.mesh.triangles.is_empty());
        assert!(body.volume_m3 > 0.2f32.powi(3), "{} m³", body.volume_m3);
        assert_eq!(body.margin_m, 0.004);
    }
}
