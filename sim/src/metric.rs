//! The paper's accuracy metric, the Mean Hausdorff Error (MHE, §3): points sampled on each
//! mesh's faces, each point's exact distance to the other mesh's surface, averaged.
//!
//! The paper: "Since the number of vertices can get quite low on the more simplified meshes,
//! vertices are also sampled from the faces of the mesh. The Mean Error results shown in this
//! paper are produced from averaging 50,000 samples of the Hausdorff Distance between meshes."
//! It does not say whether one or both directions were averaged; we sample both and report the
//! symmetric mean (the mean of the two one-sided means) as the MHE, with both one-sided means
//! alongside. This is the sampled form of the symmetric mean surface distance of Cignon, Rocchini
//! and Scopigno, "Metro: measuring error on simplified surfaces" (CGF 1998).
//!
//! Stages, in the order they run: sample each surface ([`SurfaceSampler`], sequential and
//! seeded), index each surface for closest-point queries (parry's BVH over the triangles),
//! measure each side in parallel, summarise each side in a fixed order in f64. The result does
//! not depend on the number of threads.

use glam::Vec3;
use parry3d::query::PointQuery;
use parry3d::shape::TriMesh as ParryTriMesh;
use rayon::prelude::*;
use tacmesh_source::TriMesh;

use crate::sampling::SurfaceSampler;
use crate::{check_mesh, SimError};

/// Samples per side that the paper's MHE uses.
pub const PAPER_SAMPLES: usize = 50_000;

/// ChaCha streams for the two sides' samples; distinct from the stream
/// [`sample_cloud`](crate::sample_cloud) draws its surface points from, so a scan and its
/// evaluation made with the same seed are still independent.
const REFERENCE_STREAM: u64 = 2;
const CANDIDATE_STREAM: u64 = 3;

/// How far apart two mesh surfaces are, measured on sampled points. All distances in metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshDistance {
    /// The paper's Mean Hausdorff Error: the mean of the two one-sided means below.
    pub mhe_m: f64,
    /// Mean distance from points on the reference to the candidate's surface (how well the
    /// candidate covers the reference).
    pub mean_reference_to_candidate_m: f64,
    /// Mean distance from points on the candidate to the reference's surface (how far the
    /// candidate strays from the reference).
    pub mean_candidate_to_reference_m: f64,
    /// The largest distance seen on either side: the sampled two-sided Hausdorff distance (a
    /// lower bound on the exact one).
    pub hausdorff_m: f64,
    /// The largest distance from a point on the reference to the candidate: where the
    /// candidate cut something off (a rounded corner, a lost thin part).
    pub max_reference_to_candidate_m: f64,
    /// The largest distance from a point on the candidate to the reference: where the
    /// candidate reaches out beyond the reference (a spike, a bulge, a phantom), what a
    /// simulation would touch first and wrongly.
    pub max_candidate_to_reference_m: f64,
    /// Root mean square over all `2 * samples_per_side` distances.
    pub rms_m: f64,
    pub samples_per_side: usize,
}

/// The sampled distance between two mesh surfaces.
///
/// Draws `samples_per_side` area-weighted points on each mesh (seeded by `seed`, the same
/// points for the same mesh and seed), and measures each point's exact unsigned distance to the
/// other mesh's surface (both meshes are treated as surfaces, not solids, so open meshes are
/// fine). Use [`PAPER_SAMPLES`] to match the paper.
///
/// Fails with [`SimError::NoSamples`] for zero samples, and with [`SimError::InMesh`] naming
/// the mesh when either has no triangles, zero area, a bad index or a non-finite vertex.
pub fn mesh_distance(
    reference: &TriMesh,
    candidate: &TriMesh,
    samples_per_side: usize,
    seed: u64,
) -> Result<MeshDistance, SimError> {
    if samples_per_side == 0 {
        return Err(SimError::NoSamples);
    }
    let prepare = |mesh: &TriMesh, role: &'static str, stream: u64| {
        let sampler = SurfaceSampler::new(mesh).map_err(SimError::in_mesh(role))?;
        let points = sampler.sample_points_on_stream(samples_per_side, seed, stream);
        let index = SurfaceIndex::new(mesh).map_err(SimError::in_mesh(role))?;
        Ok::<_, SimError>((points, index))
    };
    let (reference_side, candidate_side) = rayon::join(
        || prepare(reference, "reference", REFERENCE_STREAM),
        || prepare(candidate, "candidate", CANDIDATE_STREAM),
    );
    let (on_reference, reference_index) = reference_side?;
    let (on_candidate, candidate_index) = candidate_side?;

    let reference_to_candidate = Summary::of(&candidate_index.distances(&on_reference));
    let candidate_to_reference = Summary::of(&reference_index.distances(&on_candidate));

    let n = samples_per_side as f64;
    let mean_reference_to_candidate_m = reference_to_candidate.sum_m / n;
    let mean_candidate_to_reference_m = candidate_to_reference.sum_m / n;
    Ok(MeshDistance {
        mhe_m: 0.5 * (mean_reference_to_candidate_m + mean_candidate_to_reference_m),
        mean_reference_to_candidate_m,
        mean_candidate_to_reference_m,
        hausdorff_m: reference_to_candidate
            .max_m
            .max(candidate_to_reference.max_m),
        max_reference_to_candidate_m: reference_to_candidate.max_m,
        max_candidate_to_reference_m: candidate_to_reference.max_m,
        rms_m: ((reference_to_candidate.sum_sq_m2 + candidate_to_reference.sum_sq_m2) / (2.0 * n))
            .sqrt(),
        samples_per_side,
    })
}

/// The exact unsigned distance from each point to the surface of `mesh`, in metres, in the
/// order of `points`. Computed in parallel; the result does not depend on the thread count.
///
/// Fails if the mesh has no triangles, a bad index or a non-finite vertex, or if a point is
/// not finite. Zero-area triangles are fine (they count as segments or points).
pub fn point_to_mesh_distances(mesh: &TriMesh, points: &[Vec3]) -> Result<Vec<f32>, SimError> {
    let index = SurfaceIndex::new(mesh)?;
    if let Some((index, &position)) = points.iter().enumerate().find(|(_, p)| !p.is_finite()) {
        return Err(SimError::NonFinitePoint { index, position });
    }
    Ok(index.distances(points))
}

/// A mesh surface indexed for closest-point queries: parry's triangle mesh with its AABB tree.
struct SurfaceIndex {
    mesh: ParryTriMesh,
}

impl SurfaceIndex {
    fn new(mesh: &TriMesh) -> Result<Self, SimError> {
        check_mesh(mesh)?;
        // No flags: no vertex merging, no triangle removal, no topology; just the BVH. The
        // only error parry reports without flags is an empty index buffer.
        let mesh = ParryTriMesh::new(mesh.vertices.clone(), mesh.triangles.clone())
            .map_err(|_| SimError::EmptyMesh)?;
        Ok(Self { mesh })
    }

    /// Distance from each (finite) point to the nearest point of any triangle.
    fn distances(&self, points: &[Vec3]) -> Vec<f32> {
        points
            .par_iter()
            .map(|&p| {
                // `solid = false`: project onto the surface even from inside a closed mesh.
                let projection = self.mesh.project_local_point(p, false);
                projection.point.distance(p)
            })
            .collect()
    }
}

/// One side's sums, accumulated sequentially in f64 so the result is reproducible.
struct Summary {
    sum_m: f64,
    sum_sq_m2: f64,
    max_m: f64,
}

impl Summary {
    fn of(distances_m: &[f32]) -> Self {
        distances_m.iter().fold(
            Summary {
                sum_m: 0.0,
                sum_sq_m2: 0.0,
                max_m: 0.0,
            },
            |acc, &d| {
                let d = f64::from(d);
                Summary {
                    sum_m: acc.sum_m + d,
                    sum_sq_m2: acc.sum_sq_m2 + d * d,
                    max_m: acc.max_m.max(d),
                }
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use glam::DVec3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    use super::*;
    use crate::Shape;

    /// Brute-force distance from `p` to the closest point of triangle `abc`, in f64: the plane
    /// projection if it falls inside, otherwise the nearest of the three edges.
    fn brute_point_triangle(p: DVec3, [a, b, c]: [DVec3; 3]) -> f64 {
        let normal = (b - a).cross(c - a);
        if normal.length_squared() > 0.0 {
            let q = p - normal * (p - a).dot(normal) / normal.length_squared();
            let inside = [(a, b), (b, c), (c, a)]
                .iter()
                .all(|&(u, v)| normal.dot((v - u).cross(q - u)) >= 0.0);
            if inside {
                return p.distance(q);
            }
        }
        [(a, b), (b, c), (c, a)]
            .iter()
            .map(|&(u, v)| {
                let edge = v - u;
                let t = if edge.length_squared() > 0.0 {
                    ((p - u).dot(edge) / edge.length_squared()).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                p.distance(u + edge * t)
            })
            .fold(f64::MAX, f64::min)
    }

    fn brute_point_mesh(p: Vec3, mesh: &TriMesh) -> f64 {
        (0..mesh.triangles.len())
            .map(|t| brute_point_triangle(p.as_dvec3(), mesh.corners(t).map(Vec3::as_dvec3)))
            .fold(f64::MAX, f64::min)
    }

    fn random_points(n: usize, half_extent_m: f32, seed: u64) -> Vec<Vec3> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                Vec3::new(
                    rng.random_range(-half_extent_m..half_extent_m),
                    rng.random_range(-half_extent_m..half_extent_m),
                    rng.random_range(-half_extent_m..half_extent_m),
                )
            })
            .collect()
    }

    #[test]
    fn distances_match_brute_force() {
        // A degenerate mesh too: a proper triangle, a needle and a point.
        let odd = TriMesh::new(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::new(0.0, 0.0, 0.5),
                Vec3::new(0.3, 0.3, 0.8),
            ],
            vec![[0, 1, 2], [3, 4, 4], [4, 4, 4]],
        );
        for (name, mesh) in [
            ("cone", Shape::Cone.mesh()),
            ("monkey", Shape::Monkey.mesh()),
            ("degenerate", odd),
        ] {
            let mut points = random_points(2000, 0.8, 17);
            // Points on the surface as well, and the vertices themselves.
            if let Ok(sampler) = SurfaceSampler::new(&mesh) {
                points.extend(sampler.sample_points(200, 1));
            }
            points.extend(mesh.vertices.iter().copied());
            let fast = point_to_mesh_distances(&mesh, &points).expect("valid mesh");
            for (p, d) in points.iter().zip(fast) {
                let exact = brute_point_mesh(*p, &mesh);
                assert!(
                    (f64::from(d) - exact).abs() < 2e-6,
                    "{name}: {p}: parry {d}, brute force {exact}"
                );
            }
        }
    }

    #[test]
    fn identical_meshes_are_zero_apart() {
        let mesh = Shape::Monkey.mesh();
        let d = mesh_distance(&mesh, &mesh, 20_000, 4).expect("valid meshes");
        assert!(d.mhe_m < 1e-6, "{d:?}");
        assert!(d.hausdorff_m < 1e-5, "{d:?}");
        assert_eq!(d.samples_per_side, 20_000);
    }

    #[test]
    fn cube_grown_two_percent_is_a_centimetre_off() {
        // A 1 m cube against the same cube scaled by 1.02 about its centre: every face moves
        // out by 0.01 m.
        //
        // Reference side: a point on the small cube lies inside the big one, at least 0.01 m
        // from every big face, and exactly 0.01 m from the parallel one: every distance is
        // 0.01.
        //
        // Candidate side: a point on a big face (1.02 m square) is 0.01 m from the small cube
        // only over the central 1 m square. In the four 1 × 0.01 strips along the edges the
        // distance is √(0.01² + t²), t ∈ [0, 0.01], mean 0.01 (√2 + asinh 1)/2
        // = 0.01 · 1.147794; in the four 0.01 × 0.01 corner squares it is √(0.01² + s² + t²),
        // mean 0.01 · 1.280789. Weighting by area:
        // 0.01 (1 + 4·0.01·1.147794 + 4·0.0001·1.280789) / 1.0404 = 0.0100579.
        //
        // MHE = (0.01 + 0.0100579) / 2 = 0.0100290; Hausdorff ≤ 0.01 √3 (the corners).
        let small = Shape::Cube.mesh();
        let mut big = small.clone();
        big.transform(1.02, Vec3::ZERO);
        let d = mesh_distance(&small, &big, PAPER_SAMPLES, 1).expect("valid meshes");

        assert!(
            (d.mean_reference_to_candidate_m - 0.01).abs() < 1e-6,
            "{d:?}"
        );
        // Only ~4.5 % of the candidate's points vary, by at most 73 %: the Monte-Carlo error
        // of this mean is about 0.02 %.
        assert!(
            (d.mean_candidate_to_reference_m / 0.010_057_9 - 1.0).abs() < 0.002,
            "{d:?}"
        );
        assert!((d.mhe_m / 0.010_029_0 - 1.0).abs() < 0.001, "{d:?}");
        assert!(d.hausdorff_m <= 0.01 * 3f64.sqrt() + 1e-6, "{d:?}");
        assert!(d.hausdorff_m > 0.014, "{d:?}");
        // Every reference point is 0.01 m inside; the candidate's corners stray the farthest.
        assert!(
            (d.max_reference_to_candidate_m - 0.01).abs() < 1e-6,
            "{d:?}"
        );
        assert_eq!(d.max_candidate_to_reference_m, d.hausdorff_m, "{d:?}");
    }

    /// One corner of a cube pulled out along its diagonal to (0.7, 0.7, 0.7), 0.35 m from the
    /// cube: the spike shows on the candidate's side, not on the reference's, whose corner
    /// region lies inside the candidate.
    #[test]
    fn a_spike_is_the_candidates_farthest_point() {
        let reference = Shape::Cube.mesh();
        let mut candidate = reference.clone();
        let corner = candidate
            .vertices
            .iter()
            .position(|v| v.cmpgt(Vec3::ZERO).all())
            .expect("the cube has a corner in the positive octant");
        candidate.vertices[corner] *= 1.4;
        let d = mesh_distance(&reference, &candidate, PAPER_SAMPLES, 3).expect("valid meshes");
        let tip = 0.2 * 3f64.sqrt();
        assert!(
            d.max_candidate_to_reference_m > 0.2 && d.max_candidate_to_reference_m <= tip + 1e-6,
            "{d:?}"
        );
        assert!(
            d.max_candidate_to_reference_m > 2.0 * d.max_reference_to_candidate_m,
            "{d:?}"
        );
    }

    #[test]
    fn hausdorff_bounds_rms_bounds_means() {
        let d = mesh_distance(&Shape::Sphere.mesh(), &Shape::Cube.mesh(), 10_000, 2)
            .expect("valid meshes");
        assert!(d.mhe_m > 0.01, "{d:?}");
        assert!(d.hausdorff_m >= d.rms_m, "{d:?}");
        // RMS ≥ mean of all 2n distances = MHE (equal sample counts per side).
        assert!(d.rms_m >= d.mhe_m, "{d:?}");
        assert!(
            d.hausdorff_m
                >= d.mean_reference_to_candidate_m
                    .max(d.mean_candidate_to_reference_m)
        );
    }

    #[test]
    fn result_is_the_same_on_any_thread_count() {
        let (a, b) = (Shape::Torus.mesh(), Shape::Sphere.mesh());
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool")
                .install(|| mesh_distance(&a, &b, 20_000, 99).expect("valid meshes"))
        };
        let first = run(1);
        assert_eq!(first, run(1));
        assert_eq!(first, run(4));
        assert_eq!(
            first,
            mesh_distance(&a, &b, 20_000, 99).expect("valid meshes")
        );
        assert_ne!(
            first,
            mesh_distance(&a, &b, 20_000, 100).expect("valid meshes")
        );
    }

    #[test]
    fn unusable_inputs_are_rejected_and_named() {
        let cube = Shape::Cube.mesh();
        let empty = TriMesh::default();
        match mesh_distance(&cube, &empty, 100, 0) {
            Err(SimError::InMesh { role, source }) => {
                assert_eq!(role, "candidate");
                assert!(matches!(*source, SimError::EmptyMesh));
            }
            other => panic!("expected an empty candidate error, got {other:?}"),
        }
        let err = mesh_distance(&empty, &cube, 100, 0).expect_err("empty reference");
        assert!(matches!(
            err,
            SimError::InMesh {
                role: "reference",
                ..
            }
        ));
        assert!(matches!(err.root(), SimError::EmptyMesh));
        assert!(matches!(
            mesh_distance(&cube, &cube, 0, 0),
            Err(SimError::NoSamples)
        ));
        assert!(matches!(
            point_to_mesh_distances(&empty, &[Vec3::ZERO]),
            Err(SimError::EmptyMesh)
        ));
        assert!(matches!(
            point_to_mesh_distances(&cube, &[Vec3::ZERO, Vec3::splat(f32::NAN)]),
            Err(SimError::NonFinitePoint { index: 1, .. })
        ));
    }

    #[test]
    fn distances_from_inside_a_closed_mesh_go_to_its_surface() {
        // solid = false: the centre of a 1 m cube is 0.5 m from its surface, not 0.
        let d =
            point_to_mesh_distances(&Shape::Cube.mesh(), &[Vec3::ZERO, Vec3::new(0.4, 0.0, 0.0)])
                .expect("valid mesh");
        assert!(
            (d[0] - 0.5).abs() < 1e-6 && (d[1] - 0.1).abs() < 1e-6,
            "{d:?}"
        );
    }
}
