//! Vertex positions fitted to the data after simplification (the continuous step of Hoppe et
//! al., "Mesh Optimization", SIGGRAPH 1993: with connectivity fixed, minimise the squared
//! distances from the data points to the mesh plus a small spring term).
//!
//! Why: marching cubes over a smoothed distance rounds every sharp edge and corner by about the
//! smoothing radius, and the simplifier, held to that rounded surface by its residual bound,
//! keeps corner vertices pulled inwards; a large flat triangle hanging from such a corner is
//! tilted over its whole area. Fitting the few output vertices to the raw data (as weighted
//! voxel centroids) puts each flat face where its thousands of points say and each corner where
//! its faces' planes meet.
//!
//! Stages, in the order they run, repeated `iterations` times:
//! 1. assign: each sample to its nearest output triangle (exact point-to-triangle distance),
//!    samples farther than `reject_m` ignored (outliers, neighbouring objects);
//! 2. solve: Gauss–Seidel over vertices, each vertex's 3×3 least-squares system of the point-
//!    to-plane residuals of its samples, regularised towards its position before the fit;
//! 3. guard: a move that would flip or degenerate an incident triangle, or carry the vertex
//!    farther than `max_move_m` from where simplification left it, is cut back.
//!
//! Entry points: [`FitSamples::new`] (the samples and their grid, made once for a mesh's
//! fits), then [`fit_to_samples`] and [`rms_distance_m`] as often as the mesh changes.

use glam::{DMat3, DVec3, Vec3};
use rayon::prelude::*;
use tacmesh_source::TriMesh;

use crate::point_triangle::TriangleQuery;
use crate::triangle_grid::PointCells;

/// A data point with a weight (for a voxel centroid: the number of points it stands for).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WeightedSample {
    pub point: Vec3,
    pub weight: f32,
}

/// Settings of the fit, metres where they are lengths.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitConfig {
    pub iterations: usize,
    /// No vertex moves farther than this from its simplified position.
    pub max_move_m: f32,
    /// Spring towards the simplified position, relative to a vertex's data weight.
    pub stiffness: f32,
    /// Whether to measure [`FitReport::rms_after_m`]: one more nearest-triangle pass over the
    /// samples, as costly as an iteration. A caller that changes the mesh and fits again
    /// measures once at the end with [`rms_distance_m`] instead.
    pub measure_after: bool,
}

/// What the fit did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct FitReport {
    pub samples_used: usize,
    /// Weighted RMS point-to-mesh distance of the used samples before and after, metres.
    pub rms_before_m: f32,
    /// Zero unless [`FitConfig::measure_after`].
    pub rms_after_m: f32,
    /// The largest distance a vertex moved, metres.
    pub max_move_m: f32,
}

/// The data a mesh is fitted to: the samples, the distance beyond which a sample is not data
/// for the mesh (outliers, neighbouring objects), and the samples' grid at that distance, made
/// once: the samples do not move, and a mesh that is simplified again and refitted (see the
/// pipeline) is fitted to the same data up to four times and measured against it once more.
/// Making the grid took 0.24 ms of each 0.6-0.9 ms fit on a 1 m cube's 5,500 samples.
pub struct FitSamples<'a> {
    samples: &'a [WeightedSample],
    reject_m: f32,
    cells: PointCells,
}

impl<'a> FitSamples<'a> {
    /// `reject_m` must be positive.
    pub fn new(samples: &'a [WeightedSample], reject_m: f32) -> Self {
        Self {
            samples,
            reject_m,
            cells: PointCells::new(samples.iter().map(|s| s.point), reject_m),
        }
    }
}

struct Assignment {
    triangle: u32,
    /// Barycentric weights of the nearest point on the triangle, corners 0, 1, 2.
    weights: [f32; 3],
    distance_sq_m2: f32,
}

/// Each sample's nearest triangle within the data's `reject_m`.
fn assign(mesh: &TriMesh, data: &FitSamples) -> Vec<Option<Assignment>> {
    let FitSamples {
        samples,
        reject_m,
        cells,
    } = data;
    let queries: Vec<TriangleQuery> = (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            TriangleQuery::new(a, b, c)
        })
        .collect();
    let lists = cells.bucket((0..mesh.triangles.len()).map(|t| mesh.corners(t)));
    let reject_sq = reject_m * reject_m;
    samples
        .par_iter()
        .enumerate()
        .map(|(i, s)| {
            let mut best: Option<Assignment> = None;
            for &t in cells.near_point(&lists, i) {
                let query = &queries[t as usize];
                let bound = best.as_ref().map_or(reject_sq, |b| b.distance_sq_m2);
                // The plane is never farther than the triangle: a triangle whose plane is
                // already as far as the best needs no exact distance.
                let h = query.plane_distance(s.point);
                if h * h >= bound {
                    continue;
                }
                let (d_sq, [beta, gamma]) = query.closest(s.point);
                if d_sq < bound {
                    best = Some(Assignment {
                        triangle: t,
                        weights: [1.0 - beta - gamma, beta, gamma],
                        distance_sq_m2: d_sq,
                    });
                }
            }
            best
        })
        .collect()
}

fn weighted_rms(samples: &[WeightedSample], assignments: &[Option<Assignment>]) -> (f32, usize) {
    let (mut sum, mut weight, mut used) = (0.0f64, 0.0f64, 0usize);
    for (s, a) in samples.iter().zip(assignments) {
        if let Some(a) = a {
            sum += f64::from(s.weight) * f64::from(a.distance_sq_m2);
            weight += f64::from(s.weight);
            used += 1;
        }
    }
    let rms = if weight > 0.0 {
        (sum / weight).sqrt() as f32
    } else {
        0.0
    };
    (rms, used)
}

fn unit_normal(mesh: &TriMesh, t: usize) -> Vec3 {
    let [a, b, c] = mesh.corners(t);
    (b - a).cross(c - a).normalize_or_zero()
}

/// Whether moving vertex `v` keeps every incident triangle facing within 60° of before and
/// with area.
fn move_keeps_triangles(mesh: &TriMesh, incident: &[u32], v: usize, to: Vec3) -> bool {
    incident.iter().all(|&t| {
        let tri = mesh.triangles[t as usize];
        let before = unit_normal(mesh, t as usize);
        let corner = |i: u32| {
            if i as usize == v {
                to
            } else {
                mesh.vertices[i as usize]
            }
        };
        let (a, b, c) = (corner(tri[0]), corner(tri[1]), corner(tri[2]));
        let cross = (b - a).cross(c - a);
        let scale = (b - a).length_squared().max((c - a).length_squared());
        cross.length_squared() > 1e-10 * scale * scale && cross.normalize().dot(before) > 0.5
    })
}

/// Moves the vertices of `mesh` (not its boundary vertices) to fit `data`; see the module
/// docs. Connectivity is unchanged.
pub fn fit_to_samples(mesh: &mut TriMesh, data: &FitSamples, config: &FitConfig) -> FitReport {
    let samples = data.samples;
    let n = mesh.vertices.len();
    let mut report = FitReport::default();
    if mesh.triangles.is_empty() || samples.is_empty() || mesh.first_bad_index().is_some() {
        return report;
    }
    let mut incident: Vec<Vec<u32>> = vec![Vec::new(); n];
    let mut edge_uses = std::collections::HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            incident[tri[k] as usize].push(t as u32);
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            *edge_uses.entry((a.min(b), a.max(b))).or_insert(0u32) += 1;
        }
    }
    let mut on_boundary = vec![false; n];
    for (&(a, b), &uses) in &edge_uses {
        if uses == 1 {
            on_boundary[a as usize] = true;
            on_boundary[b as usize] = true;
        }
    }
    let start = mesh.vertices.clone();

    for iteration in 0..config.iterations {
        let assignments = assign(mesh, data);
        let (rms, used) = weighted_rms(samples, &assignments);
        if iteration == 0 {
            report.rms_before_m = rms;
            report.samples_used = used;
        }
        // Per triangle, the samples on it, so a vertex reads only its own triangles' samples.
        let mut on_triangle: Vec<Vec<u32>> = vec![Vec::new(); mesh.triangles.len()];
        for (i, a) in assignments.iter().enumerate() {
            if let Some(a) = a {
                on_triangle[a.triangle as usize].push(i as u32);
            }
        }
        let normals: Vec<DVec3> = (0..mesh.triangles.len())
            .map(|t| unit_normal(mesh, t).as_dvec3())
            .collect();
        for v in 0..n {
            if on_boundary[v] || incident[v].is_empty() {
                continue;
            }
            let mut system = DMat3::ZERO;
            let mut rhs = DVec3::ZERO;
            let mut data_weight = 0.0f64;
            for &t in &incident[v] {
                let tri = mesh.triangles[t as usize];
                let normal = normals[t as usize];
                let k = tri.iter().position(|&i| i as usize == v).unwrap_or(0);
                // Each sample's residual is n·(Σ_j b_j v_j − p); solving for v_k with the others
                // held, the other corners enter only through n·v_j, the same for every sample
                // of the triangle, and the system only through n nᵀ: both are taken once per
                // triangle, and the samples add up scalars (they each added a 3 × 3 product).
                let along_normal = tri.map(|j| normal.dot(mesh.vertices[j as usize].as_dvec3()));
                let (mut weight_sum, mut target_sum) = (0.0f64, 0.0f64);
                for &s in &on_triangle[t as usize] {
                    let Some(a) = &assignments[s as usize] else {
                        continue;
                    };
                    let bk = f64::from(a.weights[k]);
                    if bk <= 0.0 {
                        continue;
                    }
                    let w = f64::from(samples[s as usize].weight);
                    let others: f64 = (0..3)
                        .filter(|&j| j != k)
                        .map(|j| f64::from(a.weights[j]) * along_normal[j])
                        .sum();
                    let target = normal.dot(samples[s as usize].point.as_dvec3()) - others;
                    weight_sum += w * bk * bk;
                    target_sum += w * bk * target;
                }
                system += DMat3::from_cols(normal * normal.x, normal * normal.y, normal * normal.z)
                    * weight_sum;
                rhs += normal * target_sum;
                data_weight += weight_sum;
            }
            if data_weight <= 0.0 {
                continue;
            }
            let spring = f64::from(config.stiffness) * data_weight;
            let anchor = start[v].as_dvec3();
            system += DMat3::from_diagonal(DVec3::splat(spring));
            rhs += anchor * spring;
            if system.determinant().abs() < 1e-300 {
                continue;
            }
            let mut to = (system.inverse() * rhs).as_vec3();
            let moved = to - start[v];
            if moved.length() > config.max_move_m {
                to = start[v] + moved.normalize_or_zero() * config.max_move_m;
            }
            if to.is_finite() && move_keeps_triangles(mesh, &incident[v], v, to) {
                mesh.vertices[v] = to;
            }
        }
    }
    if config.measure_after {
        let assignments = assign(mesh, data);
        report.rms_after_m = weighted_rms(samples, &assignments).0;
    }
    report.max_move_m = mesh
        .vertices
        .iter()
        .zip(&start)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0, f32::max);
    report
}

/// The weighted RMS distance from the samples of `data` to `mesh`, metres, over the samples
/// within its `reject_m` of it (what [`FitReport`] reports); zero when none is.
pub fn rms_distance_m(mesh: &TriMesh, data: &FitSamples) -> f32 {
    if mesh.triangles.is_empty() || data.samples.is_empty() || mesh.first_bad_index().is_some() {
        return 0.0;
    }
    weighted_rms(data.samples, &assign(mesh, data)).0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An octahedron whose vertices sit 10% inside the unit octahedron's, and samples on the
    /// unit octahedron's faces: the fit should push the vertices out to the data.
    #[test]
    fn fit_moves_shrunken_octahedron_onto_its_samples() {
        let axes = [
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ];
        let triangles = vec![
            [0, 2, 4],
            [2, 1, 4],
            [1, 3, 4],
            [3, 0, 4],
            [2, 0, 5],
            [1, 2, 5],
            [3, 1, 5],
            [0, 3, 5],
        ];
        let truth = TriMesh::new(axes.to_vec(), triangles.clone());
        let mut mesh = TriMesh::new(axes.iter().map(|&a| a * 0.9).collect(), triangles);
        let mut samples = Vec::new();
        for t in 0..truth.triangles.len() {
            let [a, b, c] = truth.corners(t);
            for i in 1..10 {
                for j in 1..(10 - i) {
                    let (u, v) = (i as f32 / 10.0, j as f32 / 10.0);
                    samples.push(WeightedSample {
                        point: a + (b - a) * u + (c - a) * v,
                        weight: 1.0,
                    });
                }
            }
        }
        let data = FitSamples::new(&samples, 1.0);
        let report = fit_to_samples(
            &mut mesh,
            &data,
            &FitConfig {
                iterations: 8,
                max_move_m: 0.5,
                stiffness: 1e-3,
                measure_after: true,
            },
        );
        assert!(report.rms_after_m < 0.2 * report.rms_before_m, "{report:?}");
        for (v, truth) in mesh.vertices.iter().zip(&truth.vertices) {
            assert!(v.distance(*truth) < 0.02, "{v} should be near {truth}");
        }
        // Measured apart, the same figure; unmeasured, none.
        assert_eq!(rms_distance_m(&mesh, &data), report.rms_after_m);
        let unmeasured = fit_to_samples(
            &mut mesh,
            &data,
            &FitConfig {
                iterations: 1,
                max_move_m: 0.5,
                stiffness: 1e-3,
                measure_after: false,
            },
        );
        assert_eq!(unmeasured.rms_after_m, 0.0);
        assert!(unmeasured.rms_before_m > 0.0);
    }

    /// Found by fuzzing (`fuzz/`, target `simplify`): a 2 m cube of 12 triangles with a
    /// 2.5 mm reject distance filled every 2.5 mm cell of every triangle's bounding box, 23
    /// million of them, and took over a minute. Only cells holding samples are filled now: the
    /// grid has no more cells than samples, and the fit still finds every sample's triangle.
    #[test]
    fn large_triangles_fill_only_the_grid_cells_that_hold_samples() {
        let corners: Vec<Vec3> = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, (i >> 1 & 1) as f32, (i >> 2) as f32) * 2.0 - 1.0)
            .collect();
        let triangles = vec![
            [0, 2, 3],
            [0, 3, 1],
            [4, 5, 7],
            [4, 7, 6],
            [0, 1, 5],
            [0, 5, 4],
            [2, 6, 7],
            [2, 7, 3],
            [0, 4, 6],
            [0, 6, 2],
            [1, 3, 7],
            [1, 7, 5],
        ];
        let mut mesh = TriMesh::new(corners.clone(), triangles);
        let samples: Vec<WeightedSample> = corners
            .iter()
            .map(|&point| WeightedSample { point, weight: 1.0 })
            .collect();
        let cells = PointCells::new(samples.iter().map(|s| s.point), 0.0025);
        let lists = cells.bucket((0..mesh.triangles.len()).map(|t| mesh.corners(t)));
        assert!(
            cells.cell_count() <= samples.len(),
            "{} cells",
            cells.cell_count()
        );
        assert!((0..samples.len()).all(|i| !cells.near_point(&lists, i).is_empty()));
        let report = fit_to_samples(
            &mut mesh,
            &FitSamples::new(&samples, 0.0025),
            &FitConfig {
                iterations: 3,
                max_move_m: 0.001,
                stiffness: 1e-3,
                measure_after: true,
            },
        );
        assert_eq!(report.samples_used, 8, "{report:?}");
    }

    #[test]
    fn fit_never_moves_a_vertex_past_the_limit() {
        let mut mesh = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(0.3, 0.3, 0.0)],
            vec![[0, 1, 3], [1, 2, 3], [2, 0, 3]],
        );
        let samples = [WeightedSample {
            point: Vec3::new(0.3, 0.3, 1.0),
            weight: 100.0,
        }];
        let report = fit_to_samples(
            &mut mesh,
            &FitSamples::new(&samples, 2.0),
            &FitConfig {
                iterations: 3,
                max_move_m: 0.05,
                stiffness: 1e-3,
                measure_after: true,
            },
        );
        assert!(report.max_move_m <= 0.05 + 1e-6, "{report:?}");
        // The outer vertices are on the boundary and stay.
        assert_eq!(mesh.vertices[0], Vec3::ZERO);
    }
}
