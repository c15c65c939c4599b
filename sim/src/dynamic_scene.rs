//! A scene whose objects move, appear and leave over scene time, and its ray-casting index.
//!
//! Entry points:
//! - [`DynamicScene`] / [`DynamicObject`]: meshes in their own frames with a [`Motion`] and an
//!   optional presence window `[appear_s, leave_s)`; [`DynamicScene::objects_at`] is the scene
//!   at one instant as [`SceneObject`]s (the ground truth). A static [`Scene`] converts into a
//!   `DynamicScene` whose objects never move.
//! - [`DynamicScene::build_bvh`] → [`DynamicSceneBvh`]: each object's ray-casting tree built
//!   once; [`DynamicSceneBvh::at`] poses the objects present at an instant as a [`SceneBvh`].
//!   The camera splits the same index in two: the static objects once
//!   (`DynamicSceneBvh::static_part`), the others per frame (`DynamicSceneBvh::moving_at`).
//!
//! Scene time: `loop_s`, if set, wraps every time `t` given here to `t mod loop_s` first, so a
//! demo runs for ever with objects coming and going.

use std::sync::Arc;

use glam::Affine3A;
use tacmesh_source::TriMesh;

use crate::motion::Motion;
use crate::scene::{ObjectTrees, Scene, SceneBvh, SceneError, SceneObject};

/// One object of a [`DynamicScene`].
#[derive(Debug, Clone, PartialEq)]
pub struct DynamicObject {
    /// The id the camera's id image reports; unique within the scene.
    pub id: u32,
    /// For people: the shape or file it came from (`"cube"`, `"mug.ply"`).
    pub name: String,
    /// The surface in the object frame, metres.
    pub mesh: TriMesh,
    pub motion: Motion,
    /// Scene time the object enters the scene, seconds; `None`: from the start.
    pub appear_s: Option<f32>,
    /// Scene time the object leaves the scene, seconds; `None`: never.
    pub leave_s: Option<f32>,
}

impl DynamicObject {
    /// Whether the object is in the scene at (already wrapped) scene time `t_s`: inside
    /// `[appear_s, leave_s)`.
    pub fn is_present_at(&self, t_s: f32) -> bool {
        present(self.appear_s, self.leave_s, t_s)
    }

    /// Whether the object is always present and never moves.
    pub fn is_static(&self) -> bool {
        self.motion.is_fixed() && self.appear_s.is_none() && self.leave_s.is_none()
    }

    fn check(&self) -> Result<(), SceneError> {
        self.motion
            .check()
            .map_err(|reason| SceneError::BadMotion {
                id: self.id,
                reason,
            })?;
        let finite = |t: Option<f32>| t.is_none_or(f32::is_finite);
        let ordered = match (self.appear_s, self.leave_s) {
            (Some(appear_s), Some(leave_s)) => appear_s < leave_s,
            _ => true,
        };
        if !(finite(self.appear_s) && finite(self.leave_s) && ordered) {
            return Err(SceneError::BadPresence {
                id: self.id,
                appear_s: self.appear_s,
                leave_s: self.leave_s,
            });
        }
        Ok(())
    }
}

/// `t_s mod loop_s` in double precision (a frame index over fps can be large), then rounded.
fn wrap_time_s(loop_s: Option<f32>, t_s: f64) -> f32 {
    match loop_s {
        Some(loop_s) if loop_s > 0.0 => t_s.rem_euclid(f64::from(loop_s)) as f32,
        _ => t_s as f32,
    }
}

fn present(appear_s: Option<f32>, leave_s: Option<f32>, t_s: f32) -> bool {
    appear_s.is_none_or(|appear_s| t_s >= appear_s) && leave_s.is_none_or(|leave_s| t_s < leave_s)
}

/// A set of objects that may move, appear and leave; see the module docs.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct DynamicScene {
    pub objects: Vec<DynamicObject>,
    /// If set, scene time wraps to `t mod loop_s`, seconds.
    pub loop_s: Option<f32>,
}

impl DynamicScene {
    /// Scene time `t_s` wrapped by `loop_s` (unchanged without it).
    pub fn wrap_time_s(&self, t_s: f64) -> f32 {
        wrap_time_s(self.loop_s, t_s)
    }

    /// The objects present at scene time `t_s` (wrapped by `loop_s`), posed at that time, in
    /// scene order: each mesh in its object frame with its true `world_from_object`.
    pub fn objects_at(&self, t_s: f32) -> Vec<SceneObject> {
        let t_s = self.wrap_time_s(f64::from(t_s));
        self.objects
            .iter()
            .filter(|object| object.is_present_at(t_s))
            .map(|object| SceneObject {
                id: object.id,
                mesh: object.mesh.clone(),
                world_from_object: object.motion.world_from_object_at(t_s),
            })
            .collect()
    }

    /// Whether nothing ever moves, appears or leaves.
    pub fn is_static(&self) -> bool {
        self.objects.iter().all(DynamicObject::is_static)
    }

    /// Checks every object (mesh, motion, presence window) and `loop_s`, then builds each
    /// object's ray-casting tree: fixed objects baked into world coordinates, moving ones in
    /// their object frame. Ids are not checked for uniqueness (scene files check them).
    pub fn build_bvh(&self) -> Result<DynamicSceneBvh, SceneError> {
        if let Some(loop_s) = self.loop_s {
            if !(loop_s.is_finite() && loop_s > 0.0) {
                return Err(SceneError::InvalidLoop { loop_s });
            }
        }
        let objects = self
            .objects
            .iter()
            .map(|object| {
                object.check()?;
                let fixed_pose = match &object.motion {
                    Motion::Fixed(pose) => Some(*pose),
                    Motion::Path { .. } => None,
                };
                let tree_from_mesh = fixed_pose.unwrap_or(Affine3A::IDENTITY);
                let trees = ObjectTrees::baked(&object.mesh, tree_from_mesh).map_err(|source| {
                    SceneError::BadObject {
                        id: object.id,
                        source,
                    }
                })?;
                Ok(IndexedObject {
                    id: object.id,
                    is_static: object.is_static(),
                    motion: (fixed_pose.is_none()).then(|| object.motion.clone()),
                    appear_s: object.appear_s,
                    leave_s: object.leave_s,
                    trees: Arc::new(trees),
                })
            })
            .collect::<Result<_, SceneError>>()?;
        Ok(DynamicSceneBvh {
            objects,
            loop_s: self.loop_s,
        })
    }
}

impl From<Scene> for DynamicScene {
    /// Every object fixed at its pose and always present; no loop.
    fn from(scene: Scene) -> Self {
        let objects = scene
            .objects
            .into_iter()
            .map(|object| DynamicObject {
                id: object.id,
                name: format!("object {}", object.id),
                mesh: object.mesh,
                motion: Motion::Fixed(object.world_from_object),
                appear_s: None,
                leave_s: None,
            })
            .collect();
        DynamicScene {
            objects,
            loop_s: None,
        }
    }
}

impl From<&Scene> for DynamicScene {
    fn from(scene: &Scene) -> Self {
        DynamicScene::from(scene.clone())
    }
}

/// A [`DynamicScene`] with every object's tree built once; [`at`](Self::at) poses them.
#[derive(Debug, Clone)]
pub struct DynamicSceneBvh {
    objects: Vec<IndexedObject>,
    loop_s: Option<f32>,
}

#[derive(Debug, Clone)]
struct IndexedObject {
    id: u32,
    /// [`DynamicObject::is_static`]: always present and never moving.
    is_static: bool,
    /// `None`: fixed, the tree is in world coordinates.
    motion: Option<Motion>,
    appear_s: Option<f32>,
    leave_s: Option<f32>,
    trees: Arc<ObjectTrees>,
}

impl DynamicSceneBvh {
    /// The objects present at scene time `t_s` (wrapped by `loop_s`), posed for ray casting.
    /// Cheap: no tree is rebuilt, each moving object only gets its pose and world box.
    pub fn at(&self, t_s: f32) -> SceneBvh {
        self.posed_at(t_s, |_| true).0
    }

    /// As [`at`](Self::at), with each object's index in the scene (the order a full cast
    /// breaks ties in).
    #[cfg(test)]
    pub(crate) fn indexed_at(&self, t_s: f32) -> (SceneBvh, Vec<u32>) {
        self.posed_at(t_s, |_| true)
    }

    /// The static objects ([`DynamicObject::is_static`]) with their scene indices, the same
    /// at every instant: what they show can be computed once.
    pub(crate) fn static_part(&self) -> (SceneBvh, Vec<u32>) {
        self.posed_at(0.0, |object| object.is_static)
    }

    /// The objects present at scene time `t_s` that are not static, posed, with their scene
    /// indices: with [`static_part`](Self::static_part), the whole of [`at`](Self::at).
    pub(crate) fn moving_at(&self, t_s: f32) -> (SceneBvh, Vec<u32>) {
        self.posed_at(t_s, |object| !object.is_static)
    }

    /// The objects present at `t_s` that `keep` accepts, in scene order, posed, and the
    /// index in the scene of each.
    fn posed_at(&self, t_s: f32, keep: impl Fn(&IndexedObject) -> bool) -> (SceneBvh, Vec<u32>) {
        let t_s = wrap_time_s(self.loop_s, f64::from(t_s));
        let (indices, posed) = (0u32..)
            .zip(&self.objects)
            .filter(|(_, object)| keep(object) && present(object.appear_s, object.leave_s, t_s))
            .map(|(index, object)| {
                let world_from_tree = object.motion.as_ref().map_or(Affine3A::IDENTITY, |motion| {
                    motion.world_from_object_at(t_s)
                });
                (
                    index,
                    (object.id, Arc::clone(&object.trees), world_from_tree),
                )
            })
            .unzip();
        (SceneBvh::from_posed(posed), indices)
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec3;

    use super::*;
    use crate::motion::{PathMode, Waypoint};
    use crate::Shape;

    fn sliding_cube(appear_s: Option<f32>, leave_s: Option<f32>) -> DynamicObject {
        let at = |time_s, x| Waypoint {
            time_s,
            position: Vec3::new(x, 0.0, 0.0),
            yaw_deg: 0.0,
        };
        DynamicObject {
            id: 5,
            name: "cube".into(),
            mesh: Shape::Cube.mesh(),
            motion: Motion::Path {
                waypoints: vec![at(0.0, 0.0), at(10.0, 10.0)],
                mode: PathMode::Once,
            },
            appear_s,
            leave_s,
        }
    }

    fn x_of(objects: &[SceneObject]) -> Vec<f32> {
        objects
            .iter()
            .map(|o| o.world_from_object.translation.x)
            .collect()
    }

    #[test]
    fn objects_are_present_from_appear_until_leave() {
        let scene = DynamicScene {
            objects: vec![sliding_cube(Some(2.0), Some(4.0))],
            loop_s: None,
        };
        assert!(scene.objects_at(1.99).is_empty());
        assert_eq!(x_of(&scene.objects_at(2.0)), [2.0]);
        assert_eq!(x_of(&scene.objects_at(3.5)), [3.5]);
        assert!(scene.objects_at(4.0).is_empty());
        assert!(!scene.is_static());
        let bvh = scene.build_bvh().unwrap();
        assert_eq!(bvh.at(1.0).object_ids().count(), 0);
        assert_eq!(bvh.at(3.0).object_ids().collect::<Vec<_>>(), [5]);
        assert_eq!(bvh.at(4.0).object_ids().count(), 0);
    }

    #[test]
    fn loop_s_wraps_scene_time() {
        let scene = DynamicScene {
            objects: vec![sliding_cube(Some(1.0), None)],
            loop_s: Some(5.0),
        };
        assert_eq!(scene.wrap_time_s(12.5), 2.5);
        assert_eq!(x_of(&scene.objects_at(12.5)), [2.5]);
        // 10.5 s is 0.5 s into the third lap: not yet appeared.
        assert!(scene.objects_at(10.5).is_empty());
        let bvh = scene.build_bvh().unwrap();
        assert_eq!(bvh.at(10.5).object_ids().count(), 0);
        // The index casts against the pose at the wrapped time: a ray down x = 2.5.
        let hit = bvh
            .at(12.5)
            .cast_ray(Vec3::new(2.5, 0.0, 2.0), Vec3::NEG_Z, 10.0)
            .unwrap();
        assert!((hit.time_of_impact - 1.5).abs() < 1e-5, "{hit:?}");
    }

    #[test]
    fn static_scene_converts_to_fixed_objects() {
        let scene = Scene::tabletop();
        let dynamic = DynamicScene::from(&scene);
        assert!(dynamic.is_static());
        assert_eq!(dynamic.objects_at(123.0), scene.objects);
    }

    #[test]
    fn moving_object_is_hit_where_it_is() {
        let scene = DynamicScene {
            objects: vec![sliding_cube(None, None)],
            loop_s: None,
        };
        let bvh = scene.build_bvh().unwrap();
        let down = |x: f32, t_s: f32| {
            bvh.at(t_s)
                .cast_ray(Vec3::new(x, 0.1, 2.0), Vec3::NEG_Z, 10.0)
        };
        // The 1 m cube is centred on its origin: its top is at z = 0.5.
        assert!(down(0.0, 0.0).is_some());
        assert!(down(3.0, 0.0).is_none());
        let hit = down(3.0, 3.0).unwrap();
        assert!((hit.time_of_impact - 1.5).abs() < 1e-5);
        assert!(down(0.0, 3.0).is_none());
        let d = bvh.at(3.0).distance_to_surface(Vec3::new(3.0, 0.0, 1.0));
        assert!((d - 0.5).abs() < 1e-5, "{d}");
    }

    #[test]
    fn static_part_and_moving_objects_split_the_scene() {
        let mut scene = DynamicScene::from(Scene::tabletop());
        scene.objects.insert(1, sliding_cube(None, None));
        // Fixed but not always present: not static either.
        let mut late = sliding_cube(Some(2.0), None);
        late.id = 6;
        late.motion = Motion::Fixed(Affine3A::IDENTITY);
        scene.objects.push(late);
        let bvh = scene.build_bvh().unwrap();
        let ids = |bvh: &SceneBvh| bvh.object_ids().collect::<Vec<_>>();
        let (still, still_indices) = bvh.static_part();
        assert_eq!(
            (ids(&still), still_indices),
            (vec![0, 1, 2, 3], vec![0, 2, 3, 4])
        );
        let (moving, moving_indices) = bvh.moving_at(1.0);
        assert_eq!((ids(&moving), moving_indices), (vec![5], vec![1]));
        let (moving, moving_indices) = bvh.moving_at(3.0);
        assert_eq!((ids(&moving), moving_indices), (vec![5, 6], vec![1, 5]));
        let (all, all_indices) = bvh.indexed_at(3.0);
        assert_eq!(ids(&all), ids(&bvh.at(3.0)));
        assert_eq!(all_indices, [0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn build_bvh_rejects_bad_timing() {
        let scene = DynamicScene {
            objects: vec![sliding_cube(Some(3.0), Some(2.0))],
            loop_s: None,
        };
        assert!(matches!(
            scene.build_bvh(),
            Err(SceneError::BadPresence { id: 5, .. })
        ));
        let scene = DynamicScene {
            objects: vec![],
            loop_s: Some(0.0),
        };
        assert!(matches!(
            scene.build_bvh(),
            Err(SceneError::InvalidLoop { .. })
        ));
    }
}
