//! What a client keeps of the stream: per object, the latest shape, the latest pose for it and
//! the latest collision body (`docs/protocol.md`, "The scene a client keeps"). Pure bookkeeping, no I/O: feed it every
//! message a [`crate::FrameDecoder`] gives, in order, with [`Scene::apply`].

use std::collections::BTreeMap;

use tacmesh_source::TriMesh;

use crate::message::{Body, Kinds, Message, Pose, Session, Shape, Subscribe, FIRST_SUPPORT_ID};

/// One object as the client knows it: its latest shape, the latest pose of that shape, and its
/// latest collision body.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// The latest Shape (highest `shape_version`), as received; `shape.pose` is the pose it came
    /// with, which a later [`Message::Pose`] may have replaced.
    pub shape: Shape,
    /// The current pose: `world_from_object` for `shape`'s vertices.
    pub pose: Pose,
    /// The newest Body (by `shape_version`), in the same frame as `shape` (a Shape with the
    /// `new_frame` flag drops an older one), placed by `pose` too; `None` until one comes.
    pub body: Option<Body>,
    /// The version of the newest Shape held that said `new_frame` (0 if none has): a Body made
    /// from an older shape is in a frame before the current one and does not fit.
    pub frame_since_version: u64,
}

impl SceneObject {
    pub fn object_id(&self) -> u64 {
        self.shape.object_id()
    }

    /// The shape's mesh in the world: its vertices mapped by the current pose.
    pub fn world_mesh(&self) -> TriMesh {
        let world_from_object = self.pose.world_from_object();
        TriMesh::new(
            self.shape
                .mesh
                .vertices
                .iter()
                .map(|&p_in_object| world_from_object.transform_point3(p_in_object))
                .collect(),
            self.shape.mesh.triangles.clone(),
        )
    }
}

/// What one message did to a [`Scene`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SceneChange {
    /// A Session: every object was forgotten and a snapshot begins.
    Cleared,
    /// A Shape of an object the scene did not hold.
    Added(u64),
    /// A Shape of a held object, of a newer version (or the same version with a pose no older
    /// than the held one): shape and pose replaced.
    Reshaped(u64),
    /// A Pose of the held shape, no older than the held pose: pose replaced.
    Moved(u64),
    /// A Body of a held object, no older than its held body: body replaced.
    Bodied(u64),
    /// A Remove of a held object: forgotten.
    Removed(u64),
    /// SnapshotDone: the scene is the server's whole view as of the last Session.
    SnapshotDone,
    /// A Shape older than the held one, a Pose of another shape version than the held one or
    /// older than the held pose, a Body older than the held one or than the object's frame,
    /// or a Pose or Body of an object not held: ignored (see "Only the latest").
    Stale(u64),
    /// Nothing changed: a message that carries no scene (Hello, Stats, Goodbye, the client
    /// kinds), or a Remove of an object the scene does not hold.
    Unchanged,
}

/// The objects a client holds, built from the messages it receives.
///
/// Ordering rules (all from `docs/protocol.md`): a Shape replaces the held one only if its
/// `shape_version` is at least the held one's; a Pose replaces the held pose only if it names
/// the held shape's version and is not older by `(pose_time_ns, last_seen_ns)`; a Session
/// forgets everything; a Remove forgets one object.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    objects: BTreeMap<u64, SceneObject>,
    session: Option<Session>,
    snapshot_done: bool,
}

impl Scene {
    /// An empty scene, before any Session.
    pub fn new() -> Self {
        Self::default()
    }

    /// Takes one received message into the scene, and says what it did.
    pub fn apply(&mut self, message: &Message) -> SceneChange {
        match message {
            Message::Session(session) => {
                self.objects.clear();
                self.session = Some(session.clone());
                self.snapshot_done = false;
                SceneChange::Cleared
            }
            Message::Shape(shape) => self.apply_shape(shape),
            Message::Pose(pose) => self.apply_pose(pose),
            Message::Body(body) => self.apply_body(body),
            Message::Remove { object_id } => match self.objects.remove(object_id) {
                Some(_) => SceneChange::Removed(*object_id),
                None => SceneChange::Unchanged,
            },
            Message::SnapshotDone => {
                self.snapshot_done = true;
                SceneChange::SnapshotDone
            }
            Message::Hello { .. }
            | Message::Stats(_)
            | Message::Goodbye { .. }
            | Message::Subscribe(_)
            | Message::SubscribeV1 => SceneChange::Unchanged,
        }
    }

    fn apply_shape(&mut self, shape: &Shape) -> SceneChange {
        let id = shape.object_id();
        let Some(held) = self.objects.get_mut(&id) else {
            self.objects.insert(
                id,
                SceneObject {
                    shape: shape.clone(),
                    pose: shape.pose,
                    body: None,
                    frame_since_version: if shape.is_new_frame() {
                        shape.version()
                    } else {
                        0
                    },
                },
            );
            return SceneChange::Added(id);
        };
        let newer = shape.version() > held.shape.version()
            || (shape.version() == held.shape.version() && !is_older(&shape.pose, &held.pose));
        if !newer {
            return SceneChange::Stale(id);
        }
        held.shape = shape.clone();
        held.pose = shape.pose;
        if shape.is_new_frame() {
            held.frame_since_version = held.frame_since_version.max(shape.version());
        }
        let frame_since = held.frame_since_version;
        held.body = held
            .body
            .take()
            .filter(|body| body.shape_version >= frame_since);
        SceneChange::Reshaped(id)
    }

    fn apply_body(&mut self, body: &Body) -> SceneChange {
        let id = body.object_id;
        match self.objects.get_mut(&id) {
            Some(held)
                if body.shape_version >= held.frame_since_version
                    && held
                        .body
                        .as_ref()
                        .is_none_or(|b| body.shape_version >= b.shape_version) =>
            {
                held.body = Some(body.clone());
                SceneChange::Bodied(id)
            }
            _ => SceneChange::Stale(id),
        }
    }

    fn apply_pose(&mut self, pose: &Pose) -> SceneChange {
        let id = pose.object_id;
        match self.objects.get_mut(&id) {
            Some(held)
                if pose.shape_version == held.shape.version() && !is_older(pose, &held.pose) =>
            {
                held.pose = *pose;
                SceneChange::Moved(id)
            }
            _ => SceneChange::Stale(id),
        }
    }

    /// Forgets the objects a new Subscribe's filter leaves out, as a client does when it
    /// narrows its subscription without asking for a resend (the server sends nothing more
    /// about them, not even a Remove), and their bodies when it no longer asks for bodies.
    /// Objects have ids below [`FIRST_SUPPORT_ID`], support planes from it.
    pub fn retain_subscribed(&mut self, options: &Subscribe) {
        if !options.kinds.contains(Kinds::BODIES) {
            for object in self.objects.values_mut() {
                object.body = None;
            }
        }
        self.objects.retain(|&id, _| {
            let kind = if id < FIRST_SUPPORT_ID {
                Kinds::OBJECTS
            } else {
                Kinds::SUPPORTS
            };
            options.kinds.contains(kind)
                && (options.object_ids.is_empty() || options.object_ids.contains(&id))
        });
    }

    /// The objects held, by id.
    pub fn objects(&self) -> impl Iterator<Item = &SceneObject> {
        self.objects.values()
    }

    pub fn get(&self, object_id: u64) -> Option<&SceneObject> {
        self.objects.get(&object_id)
    }

    /// The object's mesh in the world (its shape mapped by its current pose), if it is held.
    pub fn world_mesh(&self, object_id: u64) -> Option<TriMesh> {
        self.get(object_id).map(SceneObject::world_mesh)
    }

    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }

    /// Whether the snapshot the last Session began is complete (false before any Session).
    pub fn snapshot_done(&self) -> bool {
        self.snapshot_done
    }

    /// The last Session received: the server's clocks then, and the options in effect.
    pub fn session(&self) -> Option<&Session> {
        self.session.as_ref()
    }

    /// A `CLOCK_MONOTONIC` time of the stream on the server's `CLOCK_REALTIME`, by the clocks
    /// of the last Session: `t + (realtime_ns − monotonic_ns)`. `None` before any Session, or
    /// when the result does not fit in a u64.
    pub fn realtime_ns(&self, monotonic_ns: u64) -> Option<u64> {
        let session = self.session.as_ref()?;
        let realtime = i128::from(monotonic_ns) + i128::from(session.realtime_ns)
            - i128::from(session.monotonic_ns);
        u64::try_from(realtime).ok()
    }
}

/// Whether `pose` is older than `held`: by pose time, then by last-seen time.
fn is_older(pose: &Pose, held: &Pose) -> bool {
    (pose.pose_time_ns, pose.last_seen_ns) < (held.pose_time_ns, held.last_seen_ns)
}

#[cfg(test)]
mod tests {
    use glam::{Quat, Vec3};

    use super::*;
    use crate::message::{Encoding, SimplifyStats};

    fn pose(object_id: u64, shape_version: u64, time_s: u64, translation: Vec3) -> Pose {
        Pose {
            object_id,
            shape_version,
            pose_time_ns: time_s * 1_000_000_000,
            pose_time_realtime_ns: 1_700_000_000_000_000_000 + time_s * 1_000_000_000,
            last_seen_ns: time_s * 1_000_000_000,
            rotation: Quat::IDENTITY,
            translation,
            linear_velocity: Vec3::ZERO,
            angular_velocity: Vec3::ZERO,
        }
    }

    fn shape(object_id: u64, version: u64, time_s: u64) -> Message {
        Message::Shape(Shape {
            pose: pose(object_id, version, time_s, Vec3::ZERO),
            shape_time_ns: time_s * 1_000_000_000,
            shape_time_realtime_ns: 1_700_000_000_000_000_000 + time_s * 1_000_000_000,
            flags: 0,
            mesh: TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]),
            report: SimplifyStats {
                faces_in: 1,
                faces_out: 1,
                max_residual_m: 0.0,
            },
            encoding: Encoding::Full,
        })
    }

    fn session() -> Message {
        Message::Session(Session {
            monotonic_ns: 5_000_000_000,
            realtime_ns: 1_700_000_005_000_000_000,
            options: Subscribe::default(),
        })
    }

    #[test]
    fn session_clears_and_snapshot_done_completes() {
        let mut scene = Scene::new();
        assert!(!scene.snapshot_done());
        assert_eq!(scene.apply(&session()), SceneChange::Cleared);
        assert_eq!(scene.apply(&shape(1, 1, 1)), SceneChange::Added(1));
        assert_eq!(scene.apply(&shape(2, 1, 1)), SceneChange::Added(2));
        assert_eq!(
            scene.apply(&Message::SnapshotDone),
            SceneChange::SnapshotDone
        );
        assert!(scene.snapshot_done());
        assert_eq!(scene.len(), 2);

        assert_eq!(scene.apply(&session()), SceneChange::Cleared);
        assert!(scene.is_empty());
        assert!(!scene.snapshot_done());
        assert_eq!(
            scene.session(),
            Some(&Session {
                monotonic_ns: 5_000_000_000,
                realtime_ns: 1_700_000_005_000_000_000,
                options: Subscribe::default(),
            })
        );
        assert_eq!(
            scene.realtime_ns(6_000_000_000),
            Some(1_700_000_006_000_000_000)
        );
    }

    #[test]
    fn remove_forgets_the_object() {
        let mut scene = Scene::new();
        scene.apply(&shape(1, 1, 1));
        scene.apply(&shape(2, 1, 1));
        assert_eq!(
            scene.apply(&Message::Remove { object_id: 1 }),
            SceneChange::Removed(1)
        );
        assert_eq!(
            scene.apply(&Message::Remove { object_id: 1 }),
            SceneChange::Unchanged
        );
        assert!(scene.get(1).is_none());
        assert_eq!(
            scene
                .objects()
                .map(SceneObject::object_id)
                .collect::<Vec<_>>(),
            [2]
        );
    }

    #[test]
    fn older_shape_is_ignored_and_newer_replaces() {
        let mut scene = Scene::new();
        scene.apply(&shape(1, 3, 5));
        assert_eq!(scene.apply(&shape(1, 2, 6)), SceneChange::Stale(1));
        assert_eq!(scene.get(1).map(|o| o.shape.version()), Some(3));
        assert_eq!(scene.apply(&shape(1, 5, 7)), SceneChange::Reshaped(1));
        assert_eq!(scene.get(1).map(|o| o.shape.version()), Some(5));
    }

    #[test]
    fn stale_pose_is_ignored() {
        let mut scene = Scene::new();
        scene.apply(&shape(1, 2, 5));
        let moved = pose(1, 2, 6, Vec3::X);
        assert_eq!(scene.apply(&Message::Pose(moved)), SceneChange::Moved(1));
        // Older than the held pose.
        let older = pose(1, 2, 4, Vec3::Y);
        assert_eq!(scene.apply(&Message::Pose(older)), SceneChange::Stale(1));
        // Seen again where it is: same pose time, later last seen.
        let mut seen_again = moved;
        seen_again.last_seen_ns += 1_000_000_000;
        assert_eq!(
            scene.apply(&Message::Pose(seen_again)),
            SceneChange::Moved(1)
        );
        // Same pose time, earlier last seen.
        assert_eq!(scene.apply(&Message::Pose(moved)), SceneChange::Stale(1));
        // Another shape version, newer or older, even with a later time.
        for version in [1, 3] {
            let other = pose(1, version, 9, Vec3::Z);
            assert_eq!(scene.apply(&Message::Pose(other)), SceneChange::Stale(1));
        }
        // An object the scene does not hold.
        let unknown = pose(9, 1, 9, Vec3::Z);
        assert_eq!(scene.apply(&Message::Pose(unknown)), SceneChange::Stale(9));
        assert_eq!(scene.get(1).map(|o| o.pose), Some(seen_again));
    }

    #[test]
    fn world_mesh_applies_the_latest_pose() {
        let mut scene = Scene::new();
        scene.apply(&shape(1, 1, 1));
        assert_eq!(
            scene.world_mesh(1).map(|m| m.vertices),
            Some(vec![Vec3::ZERO, Vec3::X, Vec3::Y])
        );
        let mut turned = pose(1, 1, 2, Vec3::new(0.0, 0.0, 2.0));
        turned.rotation = Quat::from_rotation_z(std::f32::consts::FRAC_PI_2);
        scene.apply(&Message::Pose(turned));
        let world = scene.world_mesh(1).expect("held");
        let expected = [
            Vec3::new(0.0, 0.0, 2.0),
            Vec3::new(0.0, 1.0, 2.0),
            Vec3::new(-1.0, 0.0, 2.0),
        ];
        for (got, want) in world.vertices.iter().zip(expected) {
            assert!(got.distance(want) < 1e-6, "{got} != {want}");
        }
        assert_eq!(world.triangles, [[0, 1, 2]]);
        assert_eq!(scene.world_mesh(2), None);
    }

    #[test]
    fn messages_without_a_scene_change_nothing() {
        let mut scene = Scene::new();
        scene.apply(&shape(1, 1, 1));
        for message in [
            Message::hello("tacmesh"),
            Message::Goodbye {
                reason: "bye".into(),
            },
            Message::SubscribeV1,
        ] {
            assert_eq!(scene.apply(&message), SceneChange::Unchanged);
        }
        assert_eq!(scene.len(), 1);
    }

    #[test]
    fn narrowing_the_subscription_forgets_what_it_leaves_out() {
        let mut scene = Scene::new();
        for id in [1, 2, FIRST_SUPPORT_ID] {
            scene.apply(&shape(id, 1, 1));
        }
        scene.retain_subscribed(&Subscribe {
            kinds: Kinds::OBJECTS,
            ..Subscribe::default()
        });
        assert_eq!(
            scene
                .objects()
                .map(SceneObject::object_id)
                .collect::<Vec<_>>(),
            [1, 2]
        );
        scene.retain_subscribed(&Subscribe {
            object_ids: vec![2, FIRST_SUPPORT_ID],
            ..Subscribe::default()
        });
        assert_eq!(
            scene
                .objects()
                .map(SceneObject::object_id)
                .collect::<Vec<_>>(),
            [2]
        );
    }
}
