//! What has been published of each object: its mesh in its own frame, its pose and its
//! version. The perception thread (new objects, poses, removals) and the mesher (new meshes)
//! both publish through it, so versions grow by one per upsert whoever sends it.

use std::collections::HashMap;
use std::time::Duration;

use glam::Affine3A;
use tacmesh_protocol::{SimplifyStats, Upsert};
use tacmesh_publish::Publisher;
use tacmesh_source::{monotonic_now, TriMesh};

use super::counters::{Counters, Stage};

#[derive(Debug)]
struct Published {
    mesh_in_object: TriMesh,
    stats: SimplifyStats,
    capture_time: Duration,
}

#[derive(Debug)]
struct Entry {
    world_from_object: Affine3A,
    version: u64,
    mesh: Option<Published>,
}

/// The objects alive now and their last published meshes.
#[derive(Debug, Default)]
pub struct Board {
    entries: HashMap<u64, Entry>,
}

impl Board {
    /// A new object (nothing is published until it has a mesh).
    pub fn create(&mut self, id: u64, world_from_object: Affine3A) {
        self.entries.entry(id).or_insert(Entry {
            world_from_object,
            version: 0,
            mesh: None,
        });
    }

    /// The object is gone: forget it and tell subscribers, if they had a mesh of it.
    pub fn remove(&mut self, id: u64, publisher: &Publisher) {
        if let Some(entry) = self.entries.remove(&id) {
            if entry.mesh.is_some() {
                publisher.remove(id);
            }
        }
    }

    /// The object moved: republish its last mesh at the new pose, without re-meshing.
    /// `capture_time` is that of the frame that saw the move.
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
        entry.world_from_object = world_from_object;
        if let Some(mesh) = &mut entry.mesh {
            mesh.capture_time = capture_time;
            Counters::add(&counters.pose_updates, 1);
            Self::publish(id, entry, publisher, counters);
        }
    }

    /// The object's frame was moved (its fused state restarted, with its origin at the new
    /// cluster): the stored mesh is re-expressed in the new frame, so that it stays where it
    /// was in the world until its next mesh replaces it, and nothing is published. Without
    /// this, the next mesh (made in the new frame) went out at the old frame's pose, off by
    /// the distance between the two origins (2–3 cm on the mOSD scene changes).
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
        }
    }

    /// A new mesh of the object (in its own frame), made from data up to `capture_time`.
    /// Ignored if the object was removed meanwhile.
    pub fn new_mesh(
        &mut self,
        id: u64,
        mesh_in_object: TriMesh,
        stats: SimplifyStats,
        capture_time: Duration,
        publisher: &Publisher,
        counters: &Counters,
    ) {
        let Some(entry) = self.entries.get_mut(&id) else {
            return;
        };
        entry.mesh = Some(Published {
            mesh_in_object,
            stats,
            capture_time,
        });
        Self::publish(id, entry, publisher, counters);
    }

    fn publish(id: u64, entry: &mut Entry, publisher: &Publisher, counters: &Counters) {
        let Some(mesh) = &entry.mesh else {
            return;
        };
        let started = std::time::Instant::now();
        entry.version += 1;
        let pose = entry.world_from_object;
        let world = TriMesh::new(
            mesh.mesh_in_object
                .vertices
                .iter()
                .map(|&v| pose.transform_point3(v))
                .collect(),
            mesh.mesh_in_object.triangles.clone(),
        );
        let upsert = Upsert {
            object_id: id,
            version: entry.version,
            capture_time_ns: mesh.capture_time.as_nanos().min(u64::MAX as u128) as u64,
            mesh: world,
            report: mesh.stats,
        };
        match publisher.upsert(upsert) {
            Ok(()) => {
                counters.record(Stage::Publish, started.elapsed());
                counters.record_frame_to_publish(monotonic_now().saturating_sub(mesh.capture_time));
            }
            Err(err) => tracing::warn!("object {id}: not published: {err}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    /// A restarted object's stored mesh stays where it was in the world in its new frame.
    #[test]
    fn reframing_keeps_the_stored_mesh_in_place_in_the_world() {
        let mut board = Board::default();
        let old = Affine3A::from_translation(Vec3::new(1.0, 0.0, 0.0));
        board.create(7, old);
        let vertices = vec![Vec3::ZERO, Vec3::X, Vec3::Y];
        board.entries.get_mut(&7).expect("created").mesh = Some(Published {
            mesh_in_object: TriMesh::new(vertices.clone(), vec![[0, 1, 2]]),
            stats: SimplifyStats {
                faces_in: 1,
                faces_out: 1,
                max_residual_m: 0.0,
            },
            capture_time: Duration::ZERO,
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
        assert_eq!(entry.version, 0, "nothing published");
    }
}
