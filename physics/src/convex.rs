//! Convex parts of a closed mesh, for a body a physics engine moves: MuJoCo, Bullet and PhysX
//! collide convex shapes, so a concave object (a torus, a mug) needs a few convex hulls
//! whose union is close to it.
//!
//! The stages, in the order they run:
//! 1. **check**: the mesh must enclose a positive volume and not be flat
//!    ([`PhysicsError::FlatMesh`], [`PhysicsError::NoVolume`]: errors, not fallbacks, because
//!    a flat or open mesh has no solid to decompose; give it a closed proxy first);
//! 2. **one hull** when the mesh fills most of its convex hull
//!    ([`ConvexConfig::min_fill_for_one_hull`]): a box, a sphere or a cone is its own hull;
//! 3. otherwise **V-HACD** (Mamou and Ghorbel, "A simple and efficient approach for 3D mesh
//!    approximate convex decomposition", ICIP 2009), parry3d's port, hulls taken from the
//!    mesh's own triangles clipped to each voxel part (not from the voxels, which would
//!    inflate each part by up to a voxel). If V-HACD finds no part with volume (a mesh
//!    thinner than a voxel), the fallback is the single hull;
//! 4. **cover**: a mesh vertex outside every hull joins the hull nearest to it (V-HACD loses
//!    thin features at coarse resolutions, and the hulls must not miss the surface they
//!    stand for; the triangles between covered vertices can still cross a gap between hulls);
//! 5. **merge** the pair of hulls whose merged hull adds the least volume, while there are
//!    more than [`ConvexConfig::max_hulls`] or the cheapest merge adds less than V-HACD's own
//!    concavity bound (parry's V-HACD only bounds the depth of its splits, so it may return
//!    up to twice `max_hulls` parts, and it splits off slivers a merge costs nothing to undo);
//! 6. **reduce** each hull to at most [`ConvexConfig::max_hull_vertices`] by growing it from
//!    four extreme vertices, always adding the vertex farthest outside, then growing the
//!    reduced hull about its centroid until it holds every vertex of the full one, so that the
//!    hulls still cover the mesh; the farthest a vertex moved out is
//!    [`ConvexParts::hull_reduction_m`].
//!
//! Entry point: [`convex_parts`].

use glam::Vec3;
use parry3d::transformation::try_convex_hull;
use parry3d::transformation::vhacd::{VHACDParameters, VHACD};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;
use crate::mass::MassProperties;

/// How to cut a mesh into convex parts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConvexConfig {
    /// Most hulls per mesh (default 8).
    pub max_hulls: usize,
    /// Most vertices per hull (default 64; at least 4). MuJoCo takes any hull size, but the
    /// cost of a convex-convex contact grows with it.
    pub max_hull_vertices: usize,
    /// A mesh whose volume is at least this fraction of its convex hull's is one hull
    /// (default 0.9, that is a hull at most 11 % larger than the mesh).
    pub min_fill_for_one_hull: f32,
    /// V-HACD's voxel grid: voxels along the mesh's largest side (default 64).
    pub resolution: u32,
    /// V-HACD's concavity bound: a part is split while its hull exceeds it by more than this
    /// fraction of the whole mesh's hull volume (default 0.01). Also the merge threshold.
    pub concavity: f32,
}

impl Default for ConvexConfig {
    fn default() -> Self {
        Self {
            max_hulls: 8,
            max_hull_vertices: 64,
            min_fill_for_one_hull: 0.9,
            resolution: 64,
            concavity: 0.01,
        }
    }
}

/// How the parts were found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Decomposition {
    /// The mesh filled enough of its convex hull to be that hull.
    SingleHull,
    /// The decomposition (V-HACD, or [`crate::split_part_points`]) found `parts` parts,
    /// merged down to the hulls returned.
    Decomposed { parts: usize },
    /// The decomposition found no part with volume; the mesh's convex hull was used instead.
    SingleHullFallback,
}

/// Convex parts of a mesh, in the mesh's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct ConvexParts {
    /// Closed convex hulls, counter-clockwise seen from outside, each with at most
    /// `max_hull_vertices` vertices; at most `max_hulls` of them, at least one.
    pub hulls: Vec<TriMesh>,
    /// Mass properties of the hulls together at unit density (overlaps counted twice).
    pub hulls_mass: MassProperties,
    /// Mass properties of the mesh itself at unit density (exact; the better figure for a
    /// body's inertia, since the hulls over-approximate the mesh).
    pub mesh_mass: MassProperties,
    /// How the parts were found.
    pub decomposition: Decomposition,
    /// How far a reduced hull reaches beyond its full one, metres: its farthest vertex's move
    /// when it was grown to hold the full hull (0 when no hull needed reducing).
    pub hull_reduction_m: f32,
}

impl ConvexParts {
    /// Total hull volume over mesh volume: 1 for a convex mesh, more where the hulls bridge
    /// concavities.
    pub fn volume_ratio(&self) -> f32 {
        self.hulls_mass.volume_m3 / self.mesh_mass.volume_m3
    }
}

/// A convex hull as points and outward triangles, with its volume.
#[derive(Debug, Clone)]
pub(crate) struct Hull {
    points: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    pub(crate) volume_m3: f64,
}

impl Hull {
    /// The convex hull of `points`; `None` when they span no volume.
    pub(crate) fn of(points: &[Vec3]) -> Option<Hull> {
        if points.len() < 4 {
            return None;
        }
        let (points, mut triangles) = try_convex_hull(points).ok()?;
        let reference = points[0].as_dvec3();
        let signed_volume: f64 = triangles
            .iter()
            .map(|&[a, b, c]| {
                let [a, b, c] = [a, b, c].map(|i| points[i as usize].as_dvec3() - reference);
                a.dot(b.cross(c)) / 6.0
            })
            .sum();
        if signed_volume < 0.0 {
            for t in &mut triangles {
                t.swap(1, 2);
            }
        }
        let volume_m3 = signed_volume.abs();
        (volume_m3 > 0.0 && triangles.len() >= 4).then_some(Hull {
            points,
            triangles,
            volume_m3,
        })
    }

    /// How far `p` lies outside the hull (negative inside), metres.
    pub(crate) fn distance_outside(&self, p: Vec3) -> f32 {
        self.triangles
            .iter()
            .filter_map(|&[a, b, c]| {
                let [a, b, c] = [a, b, c].map(|i| self.points[i as usize]);
                let normal = (b - a).cross(c - a).try_normalize()?;
                Some(normal.dot(p - a))
            })
            .fold(f32::NEG_INFINITY, f32::max)
    }

    /// How far the farthest vertex lies outside a face's plane (≤ 0 for a convex hull: its
    /// faces all face away from every vertex).
    fn fold_m(&self) -> f32 {
        self.points
            .iter()
            .map(|&p| self.distance_outside(p))
            .fold(f32::NEG_INFINITY, f32::max)
    }

    fn into_trimesh(self) -> TriMesh {
        TriMesh::new(self.points, self.triangles)
    }
}

// ---- check ----------------------------------------------------------------------------------

/// The largest side of the bounds and the hull's thinnest width along its own face normals
/// (the width of a convex polytope is attained along a face normal or an edge-edge
/// direction; face normals give an upper bound that is exact for boxes and prisms).
fn extent_and_thickness(hull: &Hull) -> (f32, f32) {
    let (lo, hi) = hull.points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let thickness = hull
        .triangles
        .iter()
        .filter_map(|&[a, b, c]| {
            let [a, b, c] = [a, b, c].map(|i| hull.points[i as usize]);
            let normal = (b - a).cross(c - a).try_normalize()?;
            let (min, max) = hull
                .points
                .iter()
                .map(|p| normal.dot(*p))
                .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), d| {
                    (lo.min(d), hi.max(d))
                });
            Some(max - min)
        })
        .fold(f32::INFINITY, f32::min);
    ((hi - lo).max_element(), thickness)
}

/// A mesh vertex farther than this (relative to the extent) outside every hull is added to
/// the nearest one.
const COVER_TOLERANCE: f32 = 1e-4;

/// Below this thickness relative to the extent a mesh is flat.
const FLAT_RATIO: f32 = 1e-3;

fn check_solid(mesh: &TriMesh) -> Result<(Hull, MassProperties), PhysicsError> {
    let mesh_mass = MassProperties::of_closed_mesh(mesh)?;
    let extent = mesh
        .bounds()
        .map(|(lo, hi)| (hi - lo).max_element())
        .unwrap_or(0.0);
    let flat = PhysicsError::FlatMesh {
        thickness_m: 0.0,
        extent_m: extent,
    };
    let hull = Hull::of(&mesh.vertices).ok_or(flat)?;
    let (extent_m, thickness_m) = extent_and_thickness(&hull);
    let solid = thickness_m > FLAT_RATIO * extent_m; // false for NaN too
    if !solid {
        return Err(PhysicsError::FlatMesh {
            thickness_m,
            extent_m,
        });
    }
    Ok((hull, mesh_mass))
}

// ---- V-HACD ---------------------------------------------------------------------------------

/// The points of each part parry3d's V-HACD finds (each part's exact convex hull of the mesh
/// inside it). Can panic inside parry on degenerate geometry: see [`convex_parts_with`].
pub fn vhacd_part_points(mesh: &TriMesh, config: &ConvexConfig) -> Vec<Vec<Vec3>> {
    let params = VHACDParameters {
        resolution: config.resolution.max(8),
        concavity: config.concavity,
        max_convex_hulls: config.max_hulls.max(1) as u32,
        ..VHACDParameters::default()
    };
    let decomposition = VHACD::decompose(&params, &mesh.vertices, &mesh.triangles, true);
    decomposition
        .compute_exact_convex_hulls(&mesh.vertices, &mesh.triangles)
        .into_iter()
        .map(|(points, _)| points)
        .collect()
}

// ---- cover ----------------------------------------------------------------------------------

/// Adds each mesh vertex that lies outside every hull (by more than `tolerance_m`) to the
/// hull it is nearest outside of. V-HACD's exact hulls can miss a thin feature where its
/// voxel parts lose it (3.8 mm of the 92-face torus at 20 mm noise was outside every hull).
/// Only vertices: covering whole triangles too made the hulls bulge far more (hull volume
/// 1.46 times the monkey's, against 1.08) for little gain.
fn cover_vertices(hulls: Vec<Hull>, vertices: &[Vec3], tolerance_m: f32) -> Vec<Hull> {
    let mut missed: Vec<Vec<Vec3>> = vec![Vec::new(); hulls.len()];
    for &v in vertices {
        let nearest = hulls
            .iter()
            .enumerate()
            .map(|(k, hull)| (k, hull.distance_outside(v)))
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((k, outside)) = nearest {
            if outside > tolerance_m {
                missed[k].push(v);
            }
        }
    }
    hulls
        .into_iter()
        .zip(missed)
        .map(|(hull, missed)| {
            if missed.is_empty() {
                return hull;
            }
            let points: Vec<Vec3> = hull.points.iter().chain(&missed).copied().collect();
            Hull::of(&points).unwrap_or(hull)
        })
        .collect()
}

// ---- merge ----------------------------------------------------------------------------------

/// The hull of two hulls' points and the volume it adds to theirs.
fn merged(a: &Hull, b: &Hull) -> Option<(Hull, f64)> {
    let points: Vec<Vec3> = a.points.iter().chain(&b.points).copied().collect();
    let hull = Hull::of(&points)?;
    let cost = hull.volume_m3 - a.volume_m3 - b.volume_m3;
    Some((hull, cost))
}

/// Merges the cheapest pair while there are more than `max_hulls`, or while the cheapest
/// merge adds less than `free_volume_m3`.
fn merge_hulls(mut hulls: Vec<Hull>, max_hulls: usize, free_volume_m3: f64) -> Vec<Hull> {
    let max_hulls = max_hulls.max(1);
    while hulls.len() > 1 {
        let mut best: Option<(usize, usize, Hull, f64)> = None;
        for i in 0..hulls.len() {
            for j in i + 1..hulls.len() {
                if let Some((hull, cost)) = merged(&hulls[i], &hulls[j]) {
                    if best.as_ref().is_none_or(|b| cost < b.3) {
                        best = Some((i, j, hull, cost));
                    }
                }
            }
        }
        let Some((i, j, hull, cost)) = best else {
            break;
        };
        if hulls.len() <= max_hulls && cost >= free_volume_m3 {
            break;
        }
        hulls.swap_remove(j); // j > i, so i keeps its place
        hulls[i] = hull;
    }
    hulls
}

// ---- reduce ---------------------------------------------------------------------------------

/// The index of the point with the largest `distance`.
fn farthest(points: &[Vec3], distance: impl Fn(Vec3) -> f32) -> usize {
    points
        .iter()
        .enumerate()
        .max_by(|a, b| distance(*a.1).total_cmp(&distance(*b.1)))
        .map_or(0, |(i, _)| i)
}

/// Reduces `hull` to at most `max_vertices` of its own vertices, returning the reduced hull
/// and the farthest a dropped vertex lies outside it.
fn reduce_hull(hull: Hull, max_vertices: usize) -> (Hull, f32) {
    let max_vertices = max_vertices.max(4);
    if hull.points.len() <= max_vertices {
        return (hull, 0.0);
    }
    let points = hull.points.clone();
    // Four extreme points: the two farthest apart along the longest axis, the farthest from
    // their line, the farthest from their plane.
    let (lo, hi) = points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let axis = (hi - lo).max_position();
    let a = farthest(&points, |p| -p[axis]);
    let b = farthest(&points, |p| p[axis]);
    let (pa, pb) = (points[a], points[b]);
    let c = farthest(&points, |p| (p - pa).cross(pb - pa).length());
    let normal = (pb - pa).cross(points[c] - pa);
    let d = farthest(&points, |p| normal.dot(p - pa).abs());
    let mut chosen = vec![a, b, c, d];
    loop {
        let selected: Vec<Vec3> = chosen.iter().map(|&i| points[i]).collect();
        let Some(current) = Hull::of(&selected) else {
            // Four extreme vertices of a hull with volume span a volume; keep the full hull
            // should rounding say otherwise.
            return (hull, 0.0);
        };
        let worst = points
            .iter()
            .enumerate()
            .filter(|(i, _)| !chosen.contains(i))
            .map(|(i, &p)| (i, current.distance_outside(p)))
            .filter(|&(_, outside)| outside > 0.0)
            .max_by(|x, y| x.1.total_cmp(&y.1));
        match worst {
            None => return (current, 0.0),
            Some(_) if chosen.len() >= max_vertices => return grown_to_cover(current, &points),
            Some((i, _)) => chosen.push(i),
        }
    }
}

/// `reduced` grown about its centroid just enough that every one of `points` is inside it, so
/// that a reduced hull still covers what its full hull covered (docs/protocol.md promises the
/// hulls cover the proxy; a hull reduced inside its full one once left 6.5 mm of a proxy
/// uncovered). Returns it and how far its farthest vertex moved out.
fn grown_to_cover(reduced: Hull, points: &[Vec3]) -> (Hull, f32) {
    // About the full hull's points' mean, when it is inside (it is for any hull not much
    // thinner than its reduction error): the reduced vertices are picked unevenly, and grown
    // about their own mean a ball's hull came out lopsided and rolled away.
    let full_mean = points.iter().copied().sum::<Vec3>() / points.len().max(1) as f32;
    let centre = if reduced.distance_outside(full_mean) < 0.0 {
        full_mean
    } else {
        reduced.points.iter().copied().sum::<Vec3>() / reduced.points.len() as f32
    };
    // Each face's plane n·(x − c) = d, d > 0 for a centroid inside: a point p is inside the
    // hull grown by s when n·(p − c) ≤ s·d for every face.
    let mut scale = 1.0f32;
    for &[a, b, c] in &reduced.triangles {
        let [a, b, c] = [a, b, c].map(|i| reduced.points[i as usize]);
        let Some(normal) = (b - a).cross(c - a).try_normalize() else {
            continue;
        };
        let d = normal.dot(a - centre);
        if d <= 1e-9 {
            continue;
        }
        for &p in points {
            scale = scale.max(normal.dot(p - centre) / d);
        }
    }
    let moved = reduced
        .points
        .iter()
        .map(|v| (*v - centre).length() * (scale - 1.0))
        .fold(0.0f32, f32::max);
    let grown: Vec<Vec3> = reduced
        .points
        .iter()
        .map(|&v| centre + (v - centre) * scale)
        .collect();
    match Hull::of(&grown) {
        Some(hull) => (hull, moved),
        None => (reduced, 0.0),
    }
}

/// How far outside a face's plane a hull's own vertex may lie before the hull counts as
/// folded, metres (rounding of a hull's faces in f32).
const FOLD_TOLERANCE_M: f32 = 1e-4;

/// `hull`, or its points' hull made again when a face of it is folded (a vertex outside the
/// face's plane: on TUM 2 hulls of 83 had vertices up to 159 mm outside a face, which an engine
/// takes for a different solid). Made again it is convex by construction; should it still be
/// folded, its points' bounding box stands in (convex, and it holds them).
fn unfolded(hull: Hull) -> Hull {
    let fold = hull.fold_m();
    if fold <= FOLD_TOLERANCE_M {
        return hull;
    }
    tracing::debug!("a hull was folded by {fold} m; made again");
    if let Some(again) = Hull::of(&hull.points).filter(|h| h.fold_m() <= FOLD_TOLERANCE_M) {
        return again;
    }
    let (lo, hi) = hull.points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let corners: Vec<Vec3> = (0..8)
        .map(|i| {
            Vec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            )
        })
        .collect();
    Hull::of(&corners).unwrap_or(hull)
}

// ---- entry point ----------------------------------------------------------------------------

/// Approximate convex decomposition of a closed, outward mesh (metres) into at most
/// `config.max_hulls` closed convex hulls of at most `config.max_hull_vertices` vertices each.
///
/// A mesh that fills at least `min_fill_for_one_hull` of its convex hull is that one hull.
///
/// Errors (no fallback: there is no solid to stand in for): [`PhysicsError::EmptyMesh`] for
/// no triangles, [`PhysicsError::NoVolume`] for an open or inward mesh,
/// [`PhysicsError::FlatMesh`] when fewer than four vertices span a volume or the mesh is
/// thinner than 1/1000 of its extent.
pub fn convex_parts(mesh: &TriMesh, config: &ConvexConfig) -> Result<ConvexParts, PhysicsError> {
    convex_parts_with(mesh, config, |mesh, config| {
        Ok(vhacd_part_points(mesh, config))
    })
}

/// [`convex_parts`] with the V-HACD step done by `decompose`, which returns the points of each
/// part (the daemon runs it in a child process: parry's V-HACD can panic on degenerate
/// geometry, and a panic aborts the daemon). When `decompose` fails, the mesh's convex hull
/// stands in ([`Decomposition::SingleHullFallback`]): conservative, one hull.
pub fn convex_parts_with(
    mesh: &TriMesh,
    config: &ConvexConfig,
    decompose: impl FnOnce(&TriMesh, &ConvexConfig) -> Result<Vec<Vec<Vec3>>, String>,
) -> Result<ConvexParts, PhysicsError> {
    let (whole_hull, mesh_mass) = check_solid(mesh)?;
    let fill = f64::from(mesh_mass.volume_m3) / whole_hull.volume_m3;
    let (hulls, decomposition) = if fill >= f64::from(config.min_fill_for_one_hull) {
        (vec![whole_hull], Decomposition::SingleHull)
    } else {
        let found: Vec<Hull> = match decompose(mesh, config) {
            Ok(parts) => parts.iter().filter_map(|points| Hull::of(points)).collect(),
            Err(why) => {
                // The caller's `decompose` knows its failures (and says them as it sees fit).
                tracing::debug!("convex decomposition failed ({why}); using the convex hull");
                Vec::new()
            }
        };
        if found.is_empty() {
            (vec![whole_hull], Decomposition::SingleHullFallback)
        } else {
            let parts = found.len();
            let (extent_m, _) = extent_and_thickness(&whole_hull);
            let found = cover_vertices(found, &mesh.vertices, COVER_TOLERANCE * extent_m);
            let free_volume_m3 = f64::from(config.concavity) * whole_hull.volume_m3;
            (
                merge_hulls(found, config.max_hulls, free_volume_m3),
                Decomposition::Decomposed { parts },
            )
        }
    };
    let mut hull_reduction_m = 0.0f32;
    let mut meshes = Vec::with_capacity(hulls.len());
    let mut masses = Vec::with_capacity(hulls.len());
    for hull in hulls {
        let (hull, missed_m) = reduce_hull(hull, config.max_hull_vertices);
        let hull = unfolded(hull);
        hull_reduction_m = hull_reduction_m.max(missed_m);
        let mesh = hull.into_trimesh();
        masses.push(MassProperties::of_closed_mesh(&mesh)?);
        meshes.push(mesh);
    }
    Ok(ConvexParts {
        hulls: meshes,
        hulls_mass: MassProperties::sum(&masses)?,
        mesh_mass,
        decomposition,
        hull_reduction_m,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tacmesh_sim::{cube, torus, uv_sphere};

    fn assert_closed_outward(hull: &TriMesh) {
        let mass = MassProperties::of_closed_mesh(hull).expect("a hull encloses volume");
        assert!(mass.volume_m3 > 0.0);
        // Every directed edge appears once and its reverse once: closed and consistent.
        let mut edges = std::collections::HashMap::new();
        for &[a, b, c] in &hull.triangles {
            for (u, v) in [(a, b), (b, c), (c, a)] {
                *edges.entry((u, v)).or_insert(0) += 1;
            }
        }
        for (&(u, v), &n) in &edges {
            assert_eq!(n, 1, "edge {u}-{v} used {n} times");
            assert_eq!(edges.get(&(v, u)), Some(&1), "edge {u}-{v} has no twin");
        }
    }

    #[test]
    fn cube_is_one_hull() {
        let parts = convex_parts(&cube(0.1), &ConvexConfig::default()).unwrap();
        assert_eq!(parts.hulls.len(), 1);
        assert_eq!(parts.decomposition, Decomposition::SingleHull);
        assert_closed_outward(&parts.hulls[0]);
        assert!((parts.volume_ratio() - 1.0).abs() < 1e-4);
    }

    #[test]
    fn a_folded_hull_is_made_again() {
        let good = Hull::of(&cube(0.2).vertices).expect("a cube's hull");
        assert!(good.fold_m() <= FOLD_TOLERANCE_M);
        // One face turned inside out: its far corner lies outside the flipped face's plane.
        let mut folded = Hull {
            points: good.points.clone(),
            triangles: good.triangles.clone(),
            volume_m3: good.volume_m3,
        };
        folded.triangles[0].swap(1, 2);
        assert!(folded.fold_m() > 0.1, "{}", folded.fold_m());
        let mended = unfolded(folded);
        assert!(mended.fold_m() <= FOLD_TOLERANCE_M);
        assert!((mended.volume_m3 - 0.008).abs() < 1e-6);
    }

    #[test]
    fn dense_sphere_is_one_hull_of_bounded_size() {
        let sphere = uv_sphere(32, 16, 0.5); // 482 vertices
        let config = ConvexConfig::default();
        let parts = convex_parts(&sphere, &config).unwrap();
        assert_eq!(parts.hulls.len(), 1);
        let hull = &parts.hulls[0];
        assert!(hull.vertices.len() <= config.max_hull_vertices);
        assert_closed_outward(hull);
        // The reduced hull is grown to hold every vertex of the sphere: it covers it, and
        // reaches a few centimetres at most beyond it.
        assert!(parts.hull_reduction_m > 0.0 && parts.hull_reduction_m < 0.05);
        let grown = Hull::of(&hull.vertices).expect("a hull");
        for &v in &sphere.vertices {
            assert!(grown.distance_outside(v) <= 1e-5, "{v} is outside the hull");
        }
        assert!(parts.volume_ratio() >= 1.0 && parts.volume_ratio() < 1.15);
    }

    #[test]
    fn torus_is_several_bounded_hulls_close_to_its_volume() {
        let mesh = torus(24, 12, 0.4, 0.1);
        let config = ConvexConfig::default();
        let parts = convex_parts(&mesh, &config).unwrap();
        assert!(matches!(
            parts.decomposition,
            Decomposition::Decomposed { .. }
        ));
        assert!(
            parts.hulls.len() >= 3 && parts.hulls.len() <= config.max_hulls,
            "{} hulls",
            parts.hulls.len()
        );
        for hull in &parts.hulls {
            assert!(hull.vertices.len() <= config.max_hull_vertices);
            assert_closed_outward(hull);
        }
        // The torus's hull is about 3.5 times its volume; the parts are far closer.
        let ratio = parts.volume_ratio();
        assert!(
            ratio > 0.9 && ratio < 1.6,
            "hull volume / mesh volume {ratio}"
        );
    }

    #[test]
    fn max_hulls_bounds_the_count() {
        let mesh = torus(24, 12, 0.4, 0.1);
        let config = ConvexConfig {
            max_hulls: 2,
            ..ConvexConfig::default()
        };
        let parts = convex_parts(&mesh, &config).unwrap();
        assert!(parts.hulls.len() <= 2, "{} hulls", parts.hulls.len());
    }

    #[test]
    fn flat_mesh_is_refused() {
        // A square as two triangles, both sides: closed but flat (no volume).
        let square = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
            vec![[0, 1, 2], [0, 2, 3], [0, 2, 1], [0, 3, 2]],
        );
        let error = convex_parts(&square, &ConvexConfig::default()).unwrap_err();
        assert!(
            matches!(
                error,
                PhysicsError::NoVolume { .. } | PhysicsError::FlatMesh { .. }
            ),
            "{error}"
        );
    }

    #[test]
    fn thin_slab_is_flat() {
        let mut slab = cube(1.0);
        for v in &mut slab.vertices {
            v.z *= 1e-4;
        }
        let error = convex_parts(&slab, &ConvexConfig::default()).unwrap_err();
        assert!(matches!(error, PhysicsError::FlatMesh { .. }), "{error}");
    }

    #[test]
    fn empty_mesh_is_refused() {
        let error = convex_parts(&TriMesh::default(), &ConvexConfig::default()).unwrap_err();
        assert!(matches!(error, PhysicsError::EmptyMesh { .. }), "{error}");
    }
}
