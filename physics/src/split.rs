//! Convex parts by splitting a closed mesh with planes, fast enough for a body in a frame's
//! time: a part whose vertices all lie on its own convex hull (within a depth) is convex
//! enough; the deepest part is cut in two by the plane, across one of its principal axes
//! through its centroid, whose two halves' hulls hold the least volume, until every part is
//! convex enough or there are `2 × max_hulls` of them ([`crate::convex_parts_with`] then
//! covers, merges and reduces them as it does V-HACD's parts).
//!
//! Why not parry's V-HACD in the daemon: at 64 voxels it takes 0.1–0.3 s on one of the
//! paper's shapes and seconds on a real scene's proxies, and it panics on degenerate voxel
//! clusters (so it runs in a child process, which took 10 s and timed out under load). This
//! cuts the mesh's own triangles (each goes whole to the side its centroid is on), so every
//! triangle lies inside its part's hull and the hulls together cover the surface; it costs a
//! few convex hulls of the mesh's vertices per cut. It is the project's own: no crate splits
//! a mesh into covering convex parts by its own triangles.

use glam::Vec3;

use crate::convex::{ConvexConfig, Hull};
use tacmesh_source::TriMesh;

/// How deep a vertex may lie inside its part's hull, over the mesh's largest side, for the
/// part to count as convex.
pub const SPLIT_DEPTH_FRACTION: f32 = 0.03;

/// One part: the triangles (indices into the mesh) it holds, its hull, and how deep its
/// deepest vertex lies inside that hull.
struct Part {
    triangles: Vec<usize>,
    points: Vec<Vec3>,
    hull_volume_m3: f64,
    depth_m: f32,
}

impl Part {
    fn of(mesh: &TriMesh, triangles: Vec<usize>) -> Option<Part> {
        let points = points_of(mesh, &triangles);
        let hull = Hull::of(&points)?;
        let depth_m = points
            .iter()
            .map(|&p| -hull.distance_outside(p))
            .fold(0.0f32, f32::max);
        Some(Part {
            triangles,
            points,
            hull_volume_m3: hull.volume_m3,
            depth_m,
        })
    }
}

/// The corners of the given triangles, each once.
fn points_of(mesh: &TriMesh, triangles: &[usize]) -> Vec<Vec3> {
    let mut seen = vec![false; mesh.vertices.len()];
    let mut points = Vec::new();
    for &t in triangles {
        for i in mesh.triangles[t] {
            let i = i as usize;
            if i < seen.len() && !seen[i] {
                seen[i] = true;
                points.push(mesh.vertices[i]);
            }
        }
    }
    points
}

/// The points of each part (see the module's documentation). Empty when the mesh spans no
/// volume.
pub fn split_part_points(mesh: &TriMesh, config: &ConvexConfig) -> Vec<Vec<Vec3>> {
    let Some((lo, hi)) = mesh.bounds() else {
        return Vec::new();
    };
    let tolerance_m = SPLIT_DEPTH_FRACTION * (hi - lo).max_element();
    let all: Vec<usize> = (0..mesh.triangles.len()).collect();
    let Some(whole) = Part::of(mesh, all) else {
        return Vec::new();
    };
    let max_parts = 2 * config.max_hulls.max(1);
    let mut parts = vec![whole];
    while parts.len() < max_parts {
        let Some((deepest, _)) = parts
            .iter()
            .enumerate()
            .filter(|(_, p)| p.depth_m > tolerance_m && p.triangles.len() >= 2)
            .max_by(|a, b| a.1.depth_m.total_cmp(&b.1.depth_m))
        else {
            break;
        };
        match cut(mesh, &parts[deepest]) {
            Some((a, b)) => {
                parts[deepest] = a;
                parts.push(b);
            }
            // No plane across it leaves a volume on both sides: it stays as it is.
            None => parts[deepest].depth_m = 0.0,
        }
    }
    parts.into_iter().map(|p| p.points).collect()
}

/// The best cut of a part in two: across each of its principal axes through its triangles'
/// mean centroid, the one whose halves' hulls hold the least volume.
fn cut(mesh: &TriMesh, part: &Part) -> Option<(Part, Part)> {
    let centroids: Vec<Vec3> = part
        .triangles
        .iter()
        .map(|&t| {
            let [a, b, c] = mesh.triangles[t].map(|i| mesh.vertices[i as usize]);
            (a + b + c) / 3.0
        })
        .collect();
    let mean = centroids.iter().copied().sum::<Vec3>() / centroids.len() as f32;
    let mut covariance = glam::Mat3::ZERO;
    for c in &centroids {
        let d = *c - mean;
        covariance += glam::Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let eigen = parry3d::math::SymmetricEigen3::new(covariance);
    let axes = [
        eigen.eigenvectors.x_axis,
        eigen.eigenvectors.y_axis,
        eigen.eigenvectors.z_axis,
    ];
    axes.iter()
        .filter_map(|axis| axis.try_normalize())
        .filter_map(|axis| {
            let (mut front, mut back) = (Vec::new(), Vec::new());
            for (&t, c) in part.triangles.iter().zip(&centroids) {
                if axis.dot(*c - mean) >= 0.0 {
                    front.push(t);
                } else {
                    back.push(t);
                }
            }
            let side = |half: Vec<usize>| Part::of(mesh, half);
            let (a, b) = (side(front)?, side(back)?);
            Some((a.hull_volume_m3 + b.hull_volume_m3, a, b))
        })
        .min_by(|x, y| x.0.total_cmp(&y.0))
        .map(|(_, a, b)| (a, b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convex::convex_parts_with;
    use crate::MassProperties;

    /// A torus is cut into arcs whose hulls cover it and bridge little of its hole; a box is
    /// one part.
    #[test]
    fn a_torus_is_cut_into_covering_arcs_and_a_box_is_left_whole() {
        let torus = tacmesh_sim::torus(32, 16, 0.4, 0.1);
        let config = ConvexConfig::default();
        let parts = convex_parts_with(&torus, &config, |m, c| Ok(split_part_points(m, c)))
            .expect("a torus has parts");
        assert!(
            (3..=config.max_hulls).contains(&parts.hulls.len()),
            "{} hulls",
            parts.hulls.len()
        );
        let ratio = parts.volume_ratio();
        eprintln!("torus: {} hulls, {ratio:.3}× its volume", parts.hulls.len());
        assert!((1.0..1.6).contains(&ratio), "hulls {ratio}× the torus");
        // Every vertex of the torus is inside or on some hull.
        for &v in &torus.vertices {
            let inside = parts.hulls.iter().any(|hull| {
                hull.triangles.iter().all(|t| {
                    let [a, b, c] = t.map(|i| hull.vertices[i as usize]);
                    (b - a).cross(c - a).normalize_or_zero().dot(v - a) <= 1e-4
                })
            });
            assert!(inside, "{v} is outside every hull");
        }
        let cube = tacmesh_sim::cube(0.3);
        assert_eq!(split_part_points(&cube, &config).len(), 1);
        let hulls_mass = MassProperties::sum(
            &parts
                .hulls
                .iter()
                .map(|h| MassProperties::of_closed_mesh(h).expect("closed"))
                .collect::<Vec<_>>(),
        )
        .expect("a sum");
        assert!(hulls_mass.volume_m3 > 0.0);
    }

    #[test]
    fn a_mesh_with_no_volume_has_no_parts() {
        assert!(split_part_points(&TriMesh::default(), &ConvexConfig::default()).is_empty());
    }
}
