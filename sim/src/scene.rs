//! A static scene of triangle meshes for the simulated depth camera, and its ray-casting index.
//!
//! Entry points:
//! - [`Scene`] / [`SceneObject`]: meshes in their own frames with a `world_from_object` pose and
//!   an id; [`Scene::tabletop`] is the demo scene (a table and three of the paper's shapes).
//! - [`Scene::build_bvh`] → [`SceneBvh`]: the scene at one instant with an AABB tree per
//!   object; [`SceneBvh::cast_ray`] gives the nearest hit and the object it belongs to,
//!   [`SceneBvh::distance_to_surface`] the exact distance to the nearest surface (parry's
//!   closest-point query). Moving scenes ([`crate::DynamicScene`]) build the same index.
//!
//! One tree per object rather than one merged tree: the table's two huge triangles would
//! overlap every node of a merged tree, and most rays miss most objects' world boxes, which
//! one slab test rejects at once. A fixed object is baked into world coordinates once, so its
//! rays need no transform; a moving object keeps its tree in its own frame, built once, and
//! each instant only poses it: rays that enter its world box are carried into the object frame
//! by the inverse pose.
//!
//! Layout: the public scene types, then the ray-casting tree (triangles → nodes → traversal).

use std::sync::Arc;

use glam::{Affine3A, Vec3};
use parry3d::query::PointQuery;
use parry3d::shape::TriMesh as ParryTriMesh;
use tacmesh_source::TriMesh;

use crate::{check_mesh, fit_to_extent, Shape, SimError};

/// One rigid object of a [`Scene`]: a mesh in its own frame, placed in the world.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneObject {
    /// The id the camera's id image ([`crate::SimulatedDepthCamera::render_ids`]) reports.
    pub id: u32,
    /// The surface in the object frame, metres.
    pub mesh: TriMesh,
    pub world_from_object: Affine3A,
}

/// A static set of objects. Ids should be unique (they are not checked).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scene {
    pub objects: Vec<SceneObject>,
}

/// Why a scene could not be indexed.
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("scene object {id} has an unusable mesh: fix or remove it")]
    BadObject {
        id: u32,
        #[source]
        source: SimError,
    },

    #[error("scene object {id} cannot move as scripted: {reason}")]
    BadMotion { id: u32, reason: String },

    #[error("scene object {id} must appear before it leaves and at finite times, got appear_s {appear_s:?} and leave_s {leave_s:?}")]
    BadPresence {
        id: u32,
        appear_s: Option<f32>,
        leave_s: Option<f32>,
    },

    #[error("loop_s must be a finite number of seconds > 0 (or absent not to loop), got {loop_s}")]
    InvalidLoop { loop_s: f32 },
}

/// Side of the demo table, metres.
pub const TABLETOP_TABLE_SIDE_M: f32 = 2.0;
/// Largest bounding-box side of each demo object, metres.
pub const TABLETOP_OBJECT_EXTENT_M: f32 = 0.2;

impl Scene {
    /// The demo scene: a 2 m × 2 m table top at z = 0 (id 0, two triangles facing +Z) with a
    /// cube (id 1), a sphere (id 2) and a torus (id 3) of the paper's shapes, each fitted into a
    /// 0.2 m box and resting on the table, spaced 0.3 m apart around the table centre.
    ///
    /// Each object's mesh is centred on its own origin; `world_from_object` is a translation.
    pub fn tabletop() -> Scene {
        let table = crate::shapes::square(TABLETOP_TABLE_SIDE_M);
        let mut objects = vec![SceneObject {
            id: 0,
            mesh: table,
            world_from_object: Affine3A::IDENTITY,
        }];
        // (shape, x, y) of each object's footprint centre on the table.
        const PLACEMENTS: [(Shape, f32, f32); 3] = [
            (Shape::Cube, -0.3, 0.0),
            (Shape::Sphere, 0.0, 0.15),
            (Shape::Torus, 0.3, 0.0),
        ];
        for (id, (shape, x, y)) in (1..).zip(PLACEMENTS) {
            let mut mesh = shape.mesh();
            fit_to_extent(&mut mesh, TABLETOP_OBJECT_EXTENT_M);
            // Centred on the origin, so the bottom is at -height / 2.
            let bottom_z = mesh.bounds().map_or(0.0, |(lo, _)| lo.z);
            objects.push(SceneObject {
                id,
                mesh,
                world_from_object: Affine3A::from_translation(Vec3::new(x, y, -bottom_z)),
            });
        }
        Scene { objects }
    }

    /// Indexes the scene for ray casting. Fails if an object's mesh is empty, has an index out
    /// of range or a non-finite vertex (after its pose is applied).
    pub fn build_bvh(&self) -> Result<SceneBvh, SceneError> {
        let objects =
            self.objects
                .iter()
                .map(|object| {
                    let trees = ObjectTrees::baked(&object.mesh, object.world_from_object)
                        .map_err(|source| SceneError::BadObject {
                            id: object.id,
                            source,
                        })?;
                    Ok((object.id, Arc::new(trees), Affine3A::IDENTITY))
                })
                .collect::<Result<Vec<_>, SceneError>>()?;
        Ok(SceneBvh::from_posed(objects))
    }
}

/// The nearest surface a ray hits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// The [`SceneObject::id`] of the surface hit.
    pub object_id: u32,
    /// The hit is at `origin + time_of_impact * dir`, in units of the ray's `dir`.
    pub time_of_impact: f32,
}

/// A scene at one instant, ready for ray casting: one AABB tree per object, either baked into
/// world coordinates (fixed objects) or in the object's own frame with its pose at that
/// instant (moving objects; rays are transformed into the object frame).
#[derive(Debug, Clone)]
pub struct SceneBvh {
    objects: Vec<PosedObject>,
}

/// One object's trees in the frame they were built in ("tree frame": the world for a baked
/// object, the object frame for a moving one). Shared between instants of a moving scene.
#[derive(Debug)]
pub(crate) struct ObjectTrees {
    /// For ray casting: our own tree (see [`TriangleBvh`]).
    rays: TriangleBvh,
    /// For closest-point queries: parry's tree.
    mesh: ParryTriMesh,
}

impl ObjectTrees {
    /// Checks `mesh` and indexes it with `tree_from_mesh` applied to its vertices (the pose,
    /// to bake a fixed object into world coordinates; the identity for a moving one).
    pub(crate) fn baked(mesh: &TriMesh, tree_from_mesh: Affine3A) -> Result<Self, SimError> {
        let posed = TriMesh::new(
            mesh.vertices
                .iter()
                .map(|&p| tree_from_mesh.transform_point3(p))
                .collect(),
            mesh.triangles.clone(),
        );
        check_mesh(&posed)?;
        // No flags: no merging, no topology, just the BVH. Without flags parry only fails on
        // an empty index buffer, which `check_mesh` already rejected.
        let mesh =
            ParryTriMesh::new(posed.vertices, posed.triangles).map_err(|_| SimError::EmptyMesh)?;
        let triangles = (0..mesh.indices().len() as u32)
            .map(|t| {
                let triangle = mesh.triangle(t);
                EdgeTriangle::new([triangle.a, triangle.b, triangle.c])
            })
            .collect();
        Ok(ObjectTrees {
            rays: TriangleBvh::new(triangles),
            mesh,
        })
    }

    /// The bounding box of the triangles, in the tree frame.
    fn bounds(&self) -> (Vec3, Vec3) {
        let root = &self.rays.nodes[0];
        (root.lo, root.hi)
    }
}

/// [`ObjectTrees`] placed in the world at one instant.
#[derive(Debug, Clone)]
struct PosedObject {
    id: u32,
    trees: Arc<ObjectTrees>,
    /// `None` when the trees are already in world coordinates.
    pose: Option<RigidPose>,
}

/// The pose of a moving object's trees, with what ray casting needs precomputed.
#[derive(Debug, Clone, Copy)]
struct RigidPose {
    world_from_tree: Affine3A,
    tree_from_world: Affine3A,
    /// The tree's bounding box carried into the world (the box of its eight moved corners).
    world_lo: Vec3,
    world_hi: Vec3,
}

impl RigidPose {
    fn new(world_from_tree: Affine3A, (lo, hi): (Vec3, Vec3)) -> Self {
        let (world_lo, world_hi) = (0..8)
            .map(|corner| {
                let pick = |bit: u32, l: f32, h: f32| if corner & bit == 0 { l } else { h };
                let p = Vec3::new(
                    pick(1, lo.x, hi.x),
                    pick(2, lo.y, hi.y),
                    pick(4, lo.z, hi.z),
                );
                world_from_tree.transform_point3(p)
            })
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        RigidPose {
            world_from_tree,
            tree_from_world: world_from_tree.inverse(),
            world_lo,
            world_hi,
        }
    }
}

impl SceneBvh {
    /// Places shared trees: `(id, trees, world_from_tree)` per object. An identity pose means
    /// the trees are in world coordinates already; any other must be rigid (rotation and
    /// translation) for [`distance_to_surface`](Self::distance_to_surface) to be exact.
    pub(crate) fn from_posed(objects: Vec<(u32, Arc<ObjectTrees>, Affine3A)>) -> Self {
        let objects = objects
            .into_iter()
            .map(|(id, trees, world_from_tree)| {
                let pose = (world_from_tree != Affine3A::IDENTITY)
                    .then(|| RigidPose::new(world_from_tree, trees.bounds()));
                PosedObject { id, trees, pose }
            })
            .collect();
        SceneBvh { objects }
    }

    /// The nearest hit of the ray `origin + t * dir` with `0 <= t < max_time_of_impact` on any
    /// object (both faces of every triangle count), or `None`. `dir` need not be unit length:
    /// `t` is in units of `dir`.
    pub fn cast_ray(&self, origin: Vec3, dir: Vec3, max_time_of_impact: f32) -> Option<RayHit> {
        self.cast_ray_among(origin, dir, max_time_of_impact, 0..self.objects.len())
    }

    /// The world bounding box `(lo, hi)` of each object, in index order (for culling).
    pub(crate) fn world_boxes(&self) -> impl Iterator<Item = (Vec3, Vec3)> + '_ {
        self.objects.iter().map(|object| match &object.pose {
            None => object.trees.bounds(),
            Some(pose) => (pose.world_lo, pose.world_hi),
        })
    }

    /// As [`cast_ray`](Self::cast_ray), trying only the objects at the given indices (in the
    /// order of [`world_boxes`](Self::world_boxes)); the caller has culled the others.
    pub(crate) fn cast_ray_among(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_time_of_impact: f32,
        candidates: impl IntoIterator<Item = usize>,
    ) -> Option<RayHit> {
        self.cast_nearest_among(origin, dir, max_time_of_impact, candidates)
            .map(|(i, t)| RayHit {
                object_id: self.objects[i].id,
                time_of_impact: t,
            })
    }

    /// As [`cast_ray_among`](Self::cast_ray_among), the hit as (object index, time of
    /// impact); on a tie the earlier index wins.
    pub(crate) fn cast_nearest_among(
        &self,
        origin: Vec3,
        dir: Vec3,
        max_time_of_impact: f32,
        candidates: impl IntoIterator<Item = usize>,
    ) -> Option<(usize, f32)> {
        let inv_dir = dir.recip();
        let mut best = None;
        let mut max_t = max_time_of_impact;
        for i in candidates {
            let object = &self.objects[i];
            let rays = &object.trees.rays;
            let t = match &object.pose {
                None => rays.cast_ray(origin, dir, inv_dir, max_t),
                Some(pose) => {
                    // Most rays miss most objects: test the world box before transforming.
                    if slab_entry(origin, inv_dir, pose.world_lo, pose.world_hi, max_t).is_none() {
                        continue;
                    }
                    // An affine map keeps `t`: origin + t·dir maps to origin' + t·dir'.
                    let origin = pose.tree_from_world.transform_point3(origin);
                    let dir = pose.tree_from_world.transform_vector3(dir);
                    rays.cast_ray(origin, dir, dir.recip(), max_t)
                }
            };
            if let Some(t) = t {
                max_t = t;
                best = Some((i, t));
            }
        }
        best
    }

    /// The unsigned distance from `p_in_world` to the nearest surface of the scene, metres
    /// (`f32::INFINITY` for an empty scene).
    pub fn distance_to_surface(&self, p_in_world: Vec3) -> f32 {
        self.objects
            .iter()
            .map(|object| {
                let (p_in_tree, world_from_tree) = match &object.pose {
                    None => (p_in_world, Affine3A::IDENTITY),
                    Some(pose) => (
                        pose.tree_from_world.transform_point3(p_in_world),
                        pose.world_from_tree,
                    ),
                };
                // `solid = false`: project onto the surface even from inside a closed mesh.
                let projection = object.trees.mesh.project_local_point(p_in_tree, false);
                world_from_tree
                    .transform_point3(projection.point)
                    .distance(p_in_world)
            })
            .fold(f32::INFINITY, f32::min)
    }

    /// The ids of the indexed objects, in scene order.
    pub fn object_ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.objects.iter().map(|object| object.id)
    }
}

// ---------------------------------------------------------------------------------------------
// Ray casting: a binary AABB tree over one object's triangles.
//
// Why not parry's `TriMesh::cast_local_ray`: measured on this machine, it costs about 250 ns
// per ray that enters an object's box, which alone took a third of the 33 ms frame budget at
// 640×480. This tree is the textbook one (median split on the longest axis of the centroids,
// leaves of up to `LEAF_TRIANGLES`, nearer child first, Möller–Trumbore triangles) and is
// several times faster for these small meshes; parry still answers the closest-point queries.

/// Most triangles in a leaf of [`TriangleBvh`].
const LEAF_TRIANGLES: usize = 4;

/// Below this depth the tree splits by the surface-area heuristic, deeper by the median (which
/// bounds the depth, see [`TriangleBvh::cast_ray`]).
const SAH_MAX_DEPTH: usize = 24;

/// Centroid bins per axis of the binned SAH build.
const SAH_BINS: usize = 16;

/// Half the surface area of the box `[lo, hi]`.
fn half_area(lo: Vec3, hi: Vec3) -> f32 {
    let d = (hi - lo).max(Vec3::ZERO);
    d.x * d.y + d.y * d.z + d.z * d.x
}

/// Partitions `triangles` at the cheapest binned surface-area-heuristic split over all three
/// axes (Wald: "On fast construction of SAH-based bounding volume hierarchies", 2007) and
/// returns the size of the left part, or `None` if no split separates the centroids.
fn sah_split(triangles: &mut [EdgeTriangle], c_lo: Vec3, c_hi: Vec3) -> Option<usize> {
    #[derive(Clone, Copy)]
    struct Bin {
        lo: Vec3,
        hi: Vec3,
        count: usize,
    }
    const EMPTY: Bin = Bin {
        lo: Vec3::INFINITY,
        hi: Vec3::NEG_INFINITY,
        count: 0,
    };
    let extent = c_hi - c_lo;
    let bin_of = |t: &EdgeTriangle, axis: usize| {
        let f = (t.centroid()[axis] - c_lo[axis]) / extent[axis];
        ((f * SAH_BINS as f32) as usize).min(SAH_BINS - 1)
    };
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        if extent[axis].is_nan() || extent[axis] <= 0.0 {
            continue;
        }
        let mut bins = [EMPTY; SAH_BINS];
        for t in triangles.iter() {
            let bin = &mut bins[bin_of(t, axis)];
            for p in t.corners() {
                bin.lo = bin.lo.min(p);
                bin.hi = bin.hi.max(p);
            }
            bin.count += 1;
        }
        // Right-to-left sweep: the cost of everything right of each boundary.
        let mut right_cost = [0.0f32; SAH_BINS];
        let mut acc = EMPTY;
        for b in (1..SAH_BINS).rev() {
            acc.lo = acc.lo.min(bins[b].lo);
            acc.hi = acc.hi.max(bins[b].hi);
            acc.count += bins[b].count;
            right_cost[b] = half_area(acc.lo, acc.hi) * acc.count as f32;
        }
        let mut acc = EMPTY;
        for b in 0..SAH_BINS - 1 {
            acc.lo = acc.lo.min(bins[b].lo);
            acc.hi = acc.hi.max(bins[b].hi);
            acc.count += bins[b].count;
            if acc.count == 0 || acc.count == triangles.len() {
                continue;
            }
            let cost = half_area(acc.lo, acc.hi) * acc.count as f32 + right_cost[b + 1];
            if best.is_none_or(|(best_cost, _, _)| cost < best_cost) {
                best = Some((cost, axis, b));
            }
        }
    }
    let (_, axis, split_bin) = best?;
    // Two-pointer partition: bins up to `split_bin` to the left.
    let (mut i, mut j) = (0, triangles.len());
    while i < j {
        if bin_of(&triangles[i], axis) <= split_bin {
            i += 1;
        } else {
            j -= 1;
            triangles.swap(i, j);
        }
    }
    Some(i)
}

/// A triangle as a corner and two edges, for Möller–Trumbore ray intersection
/// (Möller, Trumbore: "Fast, minimum storage ray-triangle intersection", JGT 1997).
#[derive(Debug, Clone, Copy)]
struct EdgeTriangle {
    a: Vec3,
    ab: Vec3,
    ac: Vec3,
}

impl EdgeTriangle {
    fn new([a, b, c]: [Vec3; 3]) -> Self {
        EdgeTriangle {
            a,
            ab: b - a,
            ac: c - a,
        }
    }

    fn corners(&self) -> [Vec3; 3] {
        [self.a, self.a + self.ab, self.a + self.ac]
    }

    fn centroid(&self) -> Vec3 {
        self.a + (self.ab + self.ac) / 3.0
    }

    /// The `t` in `[0, max_t)` where the ray crosses the triangle (either face), if any.
    #[inline]
    fn cast_ray(&self, origin: Vec3, dir: Vec3, max_t: f32) -> Option<f32> {
        let p = dir.cross(self.ac);
        let det = self.ab.dot(p);
        if det == 0.0 {
            // The ray is parallel to the triangle's plane (edge-on: nothing to see).
            return None;
        }
        let inv_det = det.recip();
        let s = origin - self.a;
        let bu = s.dot(p) * inv_det;
        if !(0.0..=1.0).contains(&bu) {
            return None;
        }
        let q = s.cross(self.ab);
        let bv = dir.dot(q) * inv_det;
        if bv < 0.0 || bu + bv > 1.0 {
            return None;
        }
        let t = self.ac.dot(q) * inv_det;
        (t >= 0.0 && t < max_t).then_some(t)
    }
}

/// A node of [`TriangleBvh`]: a leaf holds `triangles[first..first + count]`; an inner node
/// (`count == 0`) has its children at `nodes[first]` and `nodes[first + 1]`.
#[derive(Debug, Clone, Copy)]
struct Node {
    lo: Vec3,
    hi: Vec3,
    first: u32,
    count: u32,
}

#[derive(Debug, Clone)]
struct TriangleBvh {
    nodes: Vec<Node>,
    /// Reordered so every leaf's triangles are contiguous.
    triangles: Vec<EdgeTriangle>,
}

impl TriangleBvh {
    /// Builds the tree; `triangles` must not be empty.
    fn new(mut triangles: Vec<EdgeTriangle>) -> Self {
        let mut nodes = Vec::with_capacity(2 * triangles.len().div_ceil(LEAF_TRIANGLES));
        nodes.push(Node {
            lo: Vec3::ZERO,
            hi: Vec3::ZERO,
            first: 0,
            count: 0,
        });
        Self::build(&mut nodes, 0, &mut triangles, 0, 0);
        TriangleBvh { nodes, triangles }
    }

    /// Fills `nodes[node]` (at `depth` below the root) for `triangles` (which start at
    /// `offset` in the final order).
    fn build(
        nodes: &mut Vec<Node>,
        node: usize,
        triangles: &mut [EdgeTriangle],
        offset: u32,
        depth: usize,
    ) {
        let (lo, hi) = triangles
            .iter()
            .flat_map(EdgeTriangle::corners)
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        if triangles.len() <= LEAF_TRIANGLES {
            nodes[node] = Node {
                lo,
                hi,
                first: offset,
                count: triangles.len() as u32,
            };
            return;
        }
        let (c_lo, c_hi) = triangles
            .iter()
            .map(EdgeTriangle::centroid)
            .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), p| {
                (lo.min(p), hi.max(p))
            });
        let sah_split = if depth < SAH_MAX_DEPTH {
            sah_split(triangles, c_lo, c_hi)
        } else {
            None
        };
        let mid = match sah_split {
            Some(mid) => mid,
            None => {
                let axis = (c_hi - c_lo).max_position();
                let mid = triangles.len() / 2;
                triangles.select_nth_unstable_by(mid, |a, b| {
                    a.centroid()[axis].total_cmp(&b.centroid()[axis])
                });
                mid
            }
        };
        let left = nodes.len();
        nodes[node] = Node {
            lo,
            hi,
            first: left as u32,
            count: 0,
        };
        let empty = nodes[node];
        nodes.extend([empty, empty]);
        let (left_triangles, right_triangles) = triangles.split_at_mut(mid);
        Self::build(nodes, left, left_triangles, offset, depth + 1);
        Self::build(
            nodes,
            left + 1,
            right_triangles,
            offset + mid as u32,
            depth + 1,
        );
    }

    /// The nearest `t` in `[0, max_t)` where the ray hits a triangle, if any.
    #[inline]
    fn cast_ray(&self, origin: Vec3, dir: Vec3, inv_dir: Vec3, mut max_t: f32) -> Option<f32> {
        let root = &self.nodes[0];
        slab_entry(origin, inv_dir, root.lo, root.hi, max_t)?;
        let mut best = None;
        // Subtrees still to visit, at most one per level: SAH splits stop at depth
        // SAH_MAX_DEPTH = 24, then median splits halve every node, so the depth is at most
        // 24 + log2(triangles) + 1 < 58 for any u32-indexed mesh.
        let mut pending = [0u32; 64];
        let mut top = 0usize;
        let mut node = 0u32;
        loop {
            let n = &self.nodes[node as usize];
            if n.count > 0 {
                let leaf = &self.triangles[n.first as usize..(n.first + n.count) as usize];
                for triangle in leaf {
                    if let Some(t) = triangle.cast_ray(origin, dir, max_t) {
                        max_t = t;
                        best = Some(t);
                    }
                }
            } else {
                let (l, r) = (n.first, n.first + 1);
                let tl = self.entry(l, origin, inv_dir, max_t);
                let tr = self.entry(r, origin, inv_dir, max_t);
                let next = match (tl, tr) {
                    (Some(tl), Some(tr)) => {
                        let (near, far) = if tl <= tr { (l, r) } else { (r, l) };
                        pending[top] = far;
                        top += 1;
                        Some(near)
                    }
                    (Some(_), None) => Some(l),
                    (None, Some(_)) => Some(r),
                    (None, None) => None,
                };
                if let Some(next) = next {
                    node = next;
                    continue;
                }
            }
            // Pop the next pending subtree that can still hold a nearer hit.
            loop {
                if top == 0 {
                    return best;
                }
                top -= 1;
                if self.entry(pending[top], origin, inv_dir, max_t).is_some() {
                    node = pending[top];
                    break;
                }
            }
        }
    }

    #[inline]
    fn entry(&self, node: u32, origin: Vec3, inv_dir: Vec3, max_t: f32) -> Option<f32> {
        let n = &self.nodes[node as usize];
        slab_entry(origin, inv_dir, n.lo, n.hi, max_t)
    }
}

/// Where the ray enters the box `[lo, hi]` if it does at some `t` in `[0, max_t]` (slab test).
/// A zero direction component gives an infinite `inv_dir`, which the min/max handle; the NaN
/// of a ray lying exactly in a slab plane is resolved towards "enters" (glam's `min`/`max`
/// drop NaN), and the exact triangle test follows anyway.
#[inline]
fn slab_entry(origin: Vec3, inv_dir: Vec3, lo: Vec3, hi: Vec3, max_t: f32) -> Option<f32> {
    let t0 = (lo - origin) * inv_dir;
    let t1 = (hi - origin) * inv_dir;
    let t_enter = t0.min(t1).max_element().max(0.0);
    let t_exit = t0.max(t1).min_element().min(max_t);
    (t_enter <= t_exit).then_some(t_enter)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tabletop_objects_rest_on_the_table() {
        let scene = Scene::tabletop();
        let ids: Vec<u32> = scene.objects.iter().map(|o| o.id).collect();
        assert_eq!(ids, [0, 1, 2, 3]);
        assert_eq!(scene.objects[0].mesh.triangles.len(), 2);
        for object in &scene.objects[1..] {
            let (lo, hi) = object.mesh.bounds().unwrap();
            let lo = object.world_from_object.transform_point3(lo);
            let hi = object.world_from_object.transform_point3(hi);
            assert!(lo.z.abs() < 1e-6, "object {} floats: {lo}", object.id);
            let extent = (hi - lo).max_element();
            assert!((extent - TABLETOP_OBJECT_EXTENT_M).abs() < 1e-5);
        }
    }

    #[test]
    fn cast_ray_reports_the_nearest_object() {
        let bvh = Scene::tabletop().build_bvh().unwrap();
        // Straight down onto the cube's top (0.2 m high) at (-0.3, 0).
        let hit = bvh
            .cast_ray(Vec3::new(-0.3, 0.01, 1.0), Vec3::NEG_Z, 10.0)
            .unwrap();
        assert_eq!(hit.object_id, 1);
        assert!((hit.time_of_impact - 0.8).abs() < 1e-5);
        // Beside every object: the table.
        let hit = bvh
            .cast_ray(Vec3::new(0.7, 0.7, 1.0), Vec3::new(0.0, 0.0, -2.0), 10.0)
            .unwrap();
        assert_eq!(hit.object_id, 0);
        assert!((hit.time_of_impact - 0.5).abs() < 1e-6);
        // Too short, and pointing away.
        assert!(bvh
            .cast_ray(Vec3::new(0.7, 0.7, 1.0), Vec3::NEG_Z, 0.9)
            .is_none());
        assert!(bvh
            .cast_ray(Vec3::new(0.7, 0.7, 1.0), Vec3::Z, 10.0)
            .is_none());
    }

    #[test]
    fn cast_ray_agrees_with_parry() {
        use parry3d::query::{Ray, RayCast};
        use rand::{Rng, SeedableRng};
        let bvh = Scene::tabletop().build_bvh().unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let mut hits = [0usize; 4];
        for _ in 0..20_000 {
            let origin = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(0.05..1.5),
            );
            let target = Vec3::new(
                rng.random_range(-0.5..0.5),
                rng.random_range(-0.3..0.3),
                rng.random_range(-0.1..0.25),
            );
            let dir = (target - origin) * rng.random_range(0.5..2.0);
            let ours = bvh.cast_ray(origin, dir, 10.0);
            let parry = bvh
                .objects
                .iter()
                .filter_map(|o| {
                    let t = o
                        .trees
                        .mesh
                        .cast_local_ray(&Ray::new(origin, dir), 10.0, false)?;
                    Some((o.id, t))
                })
                .min_by(|a, b| a.1.total_cmp(&b.1));
            match (ours, parry) {
                (Some(hit), Some((id, t))) => {
                    assert!(
                        (hit.time_of_impact - t).abs() < 1e-5,
                        "{origin} {dir}: {hit:?} vs {id} at {t}"
                    );
                    hits[hit.object_id as usize] += 1;
                }
                (None, None) => {}
                (ours, parry) => panic!("{origin} {dir}: {ours:?} vs {parry:?}"),
            }
        }
        assert!(hits.iter().all(|&n| n > 500), "{hits:?}");
    }

    #[test]
    fn build_bvh_names_the_bad_object() {
        let mut scene = Scene::tabletop();
        scene.objects[2].mesh.triangles.clear();
        let err = scene.build_bvh().unwrap_err();
        assert!(matches!(
            err,
            SceneError::BadObject {
                id: 2,
                source: SimError::EmptyMesh
            }
        ));
    }
}
