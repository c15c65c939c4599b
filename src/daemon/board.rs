//! What has been published of each object: its shape in its own frame, its pose, their times
//! and versions. The perception thread (new objects, poses, sightings, removals) and the mesher
//! (new shapes) both publish through it, so that shape versions grow by one per shape whoever
//! sends it, a rigid move goes out as a Pose (never the mesh again), and no time of an object
//! goes backwards.

use std::collections::HashMap;
use std::time::Duration;

use glam::{Affine3A, Quat, Vec3};
use tacmesh_physics::WorldSupport;
use tacmesh_protocol::{
    Body, Encoding, Pose, Shape, SimplifyStats, FIRST_SUPPORT_ID, SHAPE_CLOSED, SHAPE_NEW_FRAME,
    SHAPE_SUPPORT,
};
use tacmesh_publish::Publisher;
use tacmesh_source::{monotonic_now, realtime_of, TriMesh};

use super::counters::{Counters, Stage};

/// A static object seen again is told so (a Pose with a newer last-seen time) at most this
/// often, so that a client can tell a converged object from a stale one.
pub const SEEN_REPORT_INTERVAL: Duration = Duration::from_secs(1);

/// Two poses further apart in time than this give no velocity (the object was not followed
/// between them).
const MAX_VELOCITY_GAP: Duration = Duration::from_millis(500);

#[derive(Debug)]
struct Published {
    mesh_in_object: TriMesh,
    stats: SimplifyStats,
    closed: bool,
}

/// A shape the board just published, for its collision body.
#[derive(Debug)]
pub struct PublishedShape {
    pub shape_version: u64,
    pub world_from_object: Affine3A,
    pub mesh_in_object: TriMesh,
}

#[derive(Debug)]
struct Entry {
    world_from_object: Affine3A,
    /// Capture time of the frame the pose is from, of the newest frame that saw the object
    /// there, and of the newest frame fused into the shape.
    pose_time: Duration,
    last_seen: Duration,
    shape_time: Duration,
    linear_velocity: Vec3,
    angular_velocity: Vec3,
    shape_version: u64,
    mesh: Option<Published>,
    /// The published shape is in another frame than `world_from_object` (the object was
    /// reframed): the next publication must be a Shape, since a Pose would place the client's
    /// shape by the new frame.
    frame_changed: bool,
    /// The first shape version published in the object's current frame: a body made from an
    /// earlier shape does not fit.
    frame_since_version: u64,
    /// The shape version of the last body published, if any.
    body_version: Option<u64>,
    /// The last-seen time subscribers were last sent, and when (monotonic now).
    last_seen_sent: Duration,
    sent_at: Duration,
}

/// The objects alive now and their last published shapes.
#[derive(Debug, Default)]
pub struct Board {
    entries: HashMap<u64, Entry>,
}

fn nanos(time: Duration) -> u64 {
    time.as_nanos().min(u64::MAX as u128) as u64
}

impl Board {
    /// A new object seen first at `capture_time` (nothing is published until it has a mesh).
    pub fn create(&mut self, id: u64, world_from_object: Affine3A, capture_time: Duration) {
        self.entries.entry(id).or_insert(Entry {
            world_from_object,
            pose_time: capture_time,
            last_seen: capture_time,
            shape_time: capture_time,
            linear_velocity: Vec3::ZERO,
            angular_velocity: Vec3::ZERO,
            shape_version: 0,
            mesh: None,
            frame_changed: false,
            frame_since_version: 0,
            body_version: None,
            last_seen_sent: Duration::ZERO,
            sent_at: Duration::ZERO,
        });
    }

    /// The object is gone: forget it and tell subscribers, if they had a shape of it.
    pub fn remove(&mut self, id: u64, publisher: &Publisher) {
        if let Some(entry) = self.entries.remove(&id) {
            if entry.mesh.is_some() {
                publisher.remove(id);
            }
        }
    }

    /// The object was seen at `capture_time` where it is held. An object seen and not moved
    /// stands still: its velocity is zero until a move says otherwise.
    pub fn seen(&mut self, id: u64, capture_time: Duration) {
        let Some(entry) = self.entries.get_mut(&id) else {
            return;
        };
        if capture_time > entry.pose_time {
            entry.linear_velocity = Vec3::ZERO;
            entry.angular_velocity = Vec3::ZERO;
        }
        entry.last_seen = entry.last_seen.max(capture_time);
    }

    /// The object moved, seen at `capture_time`: publish the new pose (and a velocity from the
    /// last two poses), without re-meshing.
    pub fn move_to(
        &mut self,
        id: u64,
        world_from_object: Affine3A,
        capture_time: Duration,
        publisher: &Publisher,
        counters: &Counters,
    ) {
        let Some(entry) = self.entries.get_mut(&id) else {
            return;
        };
        if capture_time < entry.pose_time {
            return; // an older frame's estimate: the held pose is newer
        }
        let dt = capture_time.saturating_sub(entry.pose_time);
        if !dt.is_zero() && dt <= MAX_VELOCITY_GAP {
            let (from, to) = (entry.world_from_object, world_from_object);
            let seconds = dt.as_secs_f32();
            entry.linear_velocity = Vec3::from(to.translation - from.translation) / seconds;
            let turn = Quat::from_mat3a(&to.matrix3) * Quat::from_mat3a(&from.matrix3).inverse();
            let (axis, angle) = turn.normalize().to_axis_angle();
            // to_axis_angle gives an angle in [0, 2π): the short way round is below π.
            let angle = if angle > std::f32::consts::PI {
                angle - std::f32::consts::TAU
            } else {
                angle
            };
            entry.angular_velocity = axis * (angle / seconds);
        } else {
            entry.linear_velocity = Vec3::ZERO;
            entry.angular_velocity = Vec3::ZERO;
        }
        entry.world_from_object = world_from_object;
        entry.pose_time = capture_time;
        entry.last_seen = entry.last_seen.max(capture_time);
        if entry.mesh.is_some() {
            Counters::add(&counters.pose_updates, 1);
            Self::publish_pose(id, entry, publisher, counters);
        }
    }

    /// Tells subscribers about static objects seen again since they were last told, at most
    /// once per [`SEEN_REPORT_INTERVAL`] each.
    pub fn report_sightings(&mut self, publisher: &Publisher, counters: &Counters) {
        let now = monotonic_now();
        for (&id, entry) in &mut self.entries {
            if entry.mesh.is_some()
                && entry.last_seen > entry.last_seen_sent
                && now.saturating_sub(entry.sent_at) >= SEEN_REPORT_INTERVAL
            {
                Self::publish_pose(id, entry, publisher, counters);
            }
        }
    }

    /// The object's frame was moved (its fused state restarted, with its origin at the new
    /// cluster): the stored mesh is re-expressed in the new frame, so that it stays where it
    /// was in the world until its next mesh replaces it. Nothing is published now, but the
    /// next publication of the object is a Shape (subscribers hold the shape in the old
    /// frame). Without this, the next mesh (made in the new frame) went out at the old frame's
    /// pose, off by the distance between the two origins (2–3 cm on the mOSD scene changes).
    pub fn reframe(&mut self, id: u64, world_from_object: Affine3A) {
        let Some(entry) = self.entries.get_mut(&id) else {
            return;
        };
        let new_from_old = world_from_object.inverse() * entry.world_from_object;
        entry.world_from_object = world_from_object;
        if let Some(mesh) = &mut entry.mesh {
            for v in &mut mesh.mesh_in_object.vertices {
                *v = new_from_old.transform_point3(*v);
            }
            entry.frame_changed = true;
        }
    }

    /// A new mesh of the object (in its own frame), made from data up to `capture_time`.
    /// Ignored if the object was removed meanwhile. Returns what was published, for its
    /// collision body.
    pub fn new_mesh(
        &mut self,
        id: u64,
        mesh_in_object: TriMesh,
        stats: SimplifyStats,
        capture_time: Duration,
        publisher: &Publisher,
        counters: &Counters,
    ) -> Option<PublishedShape> {
        let entry = self.entries.get_mut(&id)?;
        entry.shape_time = entry.shape_time.max(capture_time);
        entry.mesh = Some(Published {
            closed: mesh_in_object.is_closed(),
            mesh_in_object,
            stats,
        });
        let version_before = entry.shape_version;
        Self::publish_shape(id, entry, publisher, counters, capture_time);
        if entry.shape_version == version_before || id >= FIRST_SUPPORT_ID {
            return None;
        }
        Some(PublishedShape {
            shape_version: entry.shape_version,
            world_from_object: entry.world_from_object,
            mesh_in_object: entry.mesh.as_ref()?.mesh_in_object.clone(),
        })
    }

    /// The published shapes of the objects (not the supports) other than `id`, each as its
    /// vertices in the world: what an object may rest on.
    pub fn other_objects_in_world(&self, id: u64) -> Vec<Vec<Vec3>> {
        self.entries
            .iter()
            .filter(|(&other, _)| other != id && other < FIRST_SUPPORT_ID)
            .filter_map(|(_, entry)| {
                let mesh = &entry.mesh.as_ref()?.mesh_in_object;
                Some(
                    mesh.vertices
                        .iter()
                        .map(|&v| entry.world_from_object.transform_point3(v))
                        .collect(),
                )
            })
            .collect()
    }

    /// The support planes published now, in the world.
    pub fn supports(&self) -> Vec<WorldSupport> {
        self.entries
            .iter()
            .filter(|(&id, _)| id >= FIRST_SUPPORT_ID)
            .filter_map(|(&id, entry)| {
                let mesh = &entry.mesh.as_ref()?.mesh_in_object;
                let in_world = TriMesh::new(
                    mesh.vertices
                        .iter()
                        .map(|&v| entry.world_from_object.transform_point3(v))
                        .collect(),
                    mesh.triangles.clone(),
                );
                WorldSupport::of_fan(id, &in_world)
            })
            .collect()
    }

    /// A collision body made from the object's shape of `body.shape_version`: published, unless
    /// the object was removed or reframed since (the body is in the frame before) or its shape
    /// was never published.
    pub fn new_body(&mut self, body: Body, publisher: &Publisher) {
        let id = body.object_id;
        let Some(entry) = self.entries.get(&id) else {
            return;
        };
        if body.shape_version < entry.frame_since_version
            || body.shape_version > entry.shape_version
            || entry.frame_changed
        {
            tracing::debug!(
                "object {id}: the body of shape {} no longer fits (reframed since)",
                body.shape_version
            );
            return;
        }
        let version = body.shape_version;
        match publisher.body(body) {
            Ok(()) => {
                if let Some(entry) = self.entries.get_mut(&id) {
                    entry.body_version = Some(version);
                }
            }
            Err(err) => tracing::warn!("object {id}: body not published: {err}"),
        }
    }

    /// The objects whose published body fits their current frame.
    pub fn objects_with_a_body(&self) -> std::collections::HashSet<u64> {
        self.entries
            .iter()
            .filter(|(_, e)| {
                !e.frame_changed && e.body_version.is_some_and(|v| v >= e.frame_since_version)
            })
            .map(|(&id, _)| id)
            .collect()
    }

    fn pose_of(id: u64, entry: &Entry) -> Pose {
        let (_, rotation, translation) = entry.world_from_object.to_scale_rotation_translation();
        Pose {
            object_id: id,
            shape_version: entry.shape_version,
            pose_time_ns: nanos(entry.pose_time),
            pose_time_realtime_ns: realtime_of(entry.pose_time),
            last_seen_ns: nanos(entry.last_seen.max(entry.pose_time)),
            rotation: rotation.normalize(),
            translation,
            linear_velocity: entry.linear_velocity,
            angular_velocity: entry.angular_velocity,
        }
    }

    fn publish_pose(id: u64, entry: &mut Entry, publisher: &Publisher, counters: &Counters) {
        if entry.frame_changed {
            let newest = entry.pose_time.max(entry.last_seen);
            Self::publish_shape(id, entry, publisher, counters, newest);
            return;
        }
        let started = std::time::Instant::now();
        match publisher.pose(Self::pose_of(id, entry)) {
            Ok(()) => {
                Self::sent(entry);
                counters.record(Stage::Publish, started.elapsed());
                // From the frame that prompted it: the move's, or the sighting's.
                let newest = entry.last_seen.max(entry.pose_time);
                counters.record_frame_to_publish(monotonic_now().saturating_sub(newest));
            }
            Err(err) => tracing::warn!("object {id}: pose not published: {err}"),
        }
    }

    /// Publishes the object's shape with its pose; `newest` is the capture time of the data
    /// that prompted it, for the frame-to-publish latency.
    fn publish_shape(
        id: u64,
        entry: &mut Entry,
        publisher: &Publisher,
        counters: &Counters,
        newest: Duration,
    ) {
        let Some(mesh) = &entry.mesh else {
            return;
        };
        let started = std::time::Instant::now();
        entry.shape_version += 1;
        let mut flags = 0;
        if mesh.closed {
            flags |= SHAPE_CLOSED;
        }
        if entry.frame_changed {
            flags |= SHAPE_NEW_FRAME;
        }
        if id >= FIRST_SUPPORT_ID {
            flags |= SHAPE_SUPPORT;
        }
        let shape = Shape {
            pose: Self::pose_of(id, entry),
            shape_time_ns: nanos(entry.shape_time),
            shape_time_realtime_ns: realtime_of(entry.shape_time),
            flags,
            mesh: mesh.mesh_in_object.clone(),
            report: mesh.stats,
            encoding: Encoding::Full,
        };
        match publisher.shape(shape) {
            Ok(()) => {
                if entry.frame_changed {
                    entry.frame_since_version = entry.shape_version;
                }
                entry.frame_changed = false;
                Self::sent(entry);
                counters.record(Stage::Publish, started.elapsed());
                counters.record_frame_to_publish(monotonic_now().saturating_sub(newest));
            }
            Err(err) => tracing::warn!("object {id}: shape not published: {err}"),
        }
    }

    fn sent(entry: &mut Entry) {
        entry.last_seen_sent = entry.last_seen.max(entry.pose_time);
        entry.sent_at = monotonic_now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A restarted object's stored mesh stays where it was in the world in its new frame.
    #[test]
    fn reframing_keeps_the_stored_mesh_in_place_in_the_world() {
        let mut board = Board::default();
        let old = Affine3A::from_translation(Vec3::new(1.0, 0.0, 0.0));
        board.create(7, old, Duration::ZERO);
        let vertices = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        board.entries.get_mut(&7).expect("created").mesh = Some(Published {
            mesh_in_object: TriMesh::new(vertices.clone(), vec![[0, 1, 2]]),
            stats: SimplifyStats {
                faces_in: 1,
                faces_out: 1,
                max_residual_m: 0.0,
            },
            closed: false,
        });
        let new = Affine3A::from_rotation_translation(
            glam::Quat::from_rotation_z(0.5),
            Vec3::new(0.2, 0.3, 0.0),
        );
        board.reframe(7, new);
        let entry = &board.entries[&7];
        assert_eq!(entry.world_from_object, new);
        let mesh = &entry.mesh.as_ref().expect("kept").mesh_in_object;
        for (v, original) in mesh.vertices.iter().zip(&vertices) {
            let world = new.transform_point3(*v);
            assert!(world.distance(old.transform_point3(*original)) < 1e-5);
        }
        assert_eq!(entry.shape_version, 0, "nothing published");
        assert!(entry.frame_changed, "the next publication must be a shape");
    }

    /// A move's velocity is the change from the pose before over the time between them; an
    /// object seen and not moved stands still.
    #[test]
    fn a_move_carries_its_velocity_and_a_still_sighting_zeroes_it() {
        let dir = tempfile::tempdir().expect("a temporary folder");
        let publisher = Publisher::bind(tacmesh_publish::PublisherConfig::new(
            dir.path().join("t.sock"),
        ))
        .expect("binds");
        let counters = Counters::default();
        let mut board = Board::default();
        let at = |ms: u64| Duration::from_millis(1000 + ms);
        board.create(3, Affine3A::IDENTITY, at(0));
        let mesh = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let stats = SimplifyStats {
            faces_in: 1,
            faces_out: 1,
            max_residual_m: 0.0,
        };
        board.new_mesh(3, mesh, stats, at(0), &publisher, &counters);
        let moved = Affine3A::from_rotation_translation(
            Quat::from_rotation_z(-0.1),
            Vec3::new(0.01, 0.0, 0.0),
        );
        board.move_to(3, moved, at(100), &publisher, &counters);
        let entry = &board.entries[&3];
        assert!(entry.linear_velocity.distance(Vec3::new(0.1, 0.0, 0.0)) < 1e-4);
        assert!(
            entry.angular_velocity.distance(Vec3::new(0.0, 0.0, -1.0)) < 1e-3,
            "{}",
            entry.angular_velocity
        );
        assert_eq!(entry.shape_version, 1, "a move is not a new shape");
        board.seen(3, at(133));
        let entry = &board.entries[&3];
        assert_eq!(entry.linear_velocity, Vec3::ZERO);
        assert_eq!(entry.last_seen, at(133));
        assert_eq!(entry.pose_time, at(100));
        // An older frame's estimate does not move the object back in time.
        board.move_to(3, Affine3A::IDENTITY, at(50), &publisher, &counters);
        assert_eq!(board.entries[&3].pose_time, at(100));
    }
}
