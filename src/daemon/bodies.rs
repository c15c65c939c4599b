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
        let decompose = |mesh: &TriMesh, config: &ConvexConfig| match &exe {
            Some(exe) => crate::isolated_vhacd::decompose(
                exe,
                mesh,
                config,
                crate::isolated_vhacd::CHILD_TIMEOUT,
            ),
            None => Err("the daemon's own executable cannot be found".into()),
        };
        let made = make_body(&job, decompose);
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
