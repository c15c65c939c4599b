//! Behaviour of `tacmesh_simplify::simplify` on small hand-built meshes.

mod util;

use tacmesh_simplify::{
    simplify, simplify_near_points, SimplifyConfig, SimplifyError, SimplifyReport,
};
use tacmesh_source::glam::Vec3;
use tacmesh_source::TriMesh;
use util::*;

#[test]
fn simplify_keeps_tetrahedron() {
    let mesh = tetrahedron();
    let (out, report) = run(&mesh, f32::INFINITY);
    assert_eq!(out.triangles.len(), 4);
    assert_eq!(out.vertices.len(), 4);
    assert_eq!(report.collapses, 0);
    assert_manifold(&out);
    assert!(boundary_edges(&out).is_empty());
}

#[test]
fn flat_grid_collapses_to_few_triangles_and_keeps_boundary() {
    let mesh = grid(20, 1.0);
    let (out, report) = run(&mesh, 0.01);
    assert!(
        out.triangles.len() <= 8,
        "{} triangles: {report:?}",
        out.triangles.len()
    );
    assert_manifold(&out);
    assert_no_degenerate_or_duplicate(&out);
    assert!((out.area() - 1.0).abs() < 1e-4, "area {}", out.area());
    let boundary = boundary_edges(&out);
    let on_square = |p: Vec3| {
        p.z.abs() < 1e-6
            && (p.x.abs() < 1e-6
                || (p.x - 1.0).abs() < 1e-6
                || p.y.abs() < 1e-6
                || (p.y - 1.0).abs() < 1e-6)
    };
    for &(a, b) in &boundary {
        assert!(on_square(out.vertices[a as usize]) && on_square(out.vertices[b as usize]));
    }
    for corner in [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(1.0, 1.0, 0.0)] {
        assert!(
            out.vertices.iter().any(|&v| v.distance(corner) < 1e-6),
            "lost corner {corner}"
        );
    }
    for t in 0..out.triangles.len() {
        assert!(normal(&out, t).z > 0.999);
    }
}

#[test]
fn no_collapse_flips_a_face() {
    let mut noise = Noise::new(7);
    let mesh = icosphere(4, 0.5, |_| 0.008 * noise.next());
    let (out, report) = run(&mesh, 0.01);
    assert!(report.collapses > 0);
    for t in 0..out.triangles.len() {
        let [a, b, c] = out.corners(t);
        let centroid = (a + b + c) / 3.0;
        let n = normal(&out, t);
        assert!(n.dot(centroid.normalize()) > 0.0, "face {t} points inward");
        // The input face nearest to the centroid must agree.
        let nearest = (0..mesh.triangles.len())
            .min_by(|&x, &y| {
                let [xa, xb, xc] = mesh.corners(x);
                let [ya, yb, yc] = mesh.corners(y);
                point_triangle_distance(centroid, xa, xb, xc)
                    .total_cmp(&point_triangle_distance(centroid, ya, yb, yc))
            })
            .expect("input has faces");
        assert!(
            n.dot(normal(&mesh, nearest)) > 0.0,
            "face {t} flipped against the input"
        );
    }
    assert_manifold(&out);
    assert_no_degenerate_or_duplicate(&out);
}

#[test]
fn collapses_create_no_needles() {
    // Inputs without needles: every output triangle keeps quality 4√3·area/Σedge² ≥ 0.1.
    let mut noise = Noise::new(13);
    let mut bumpy = grid(24, 1.0);
    for v in &mut bumpy.vertices {
        v.z = 0.05 * (6.0 * v.x).sin() * (4.0 * v.y).cos();
    }
    for mesh in [
        icosphere(4, 0.5, |_| 0.006 * noise.next()),
        bumpy,
        grid(20, 1.0),
    ] {
        for max_residual_m in [0.005, 0.02, 0.1] {
            let (out, _) = run(&mesh, max_residual_m);
            for t in 0..out.triangles.len() {
                let [a, b, c] = out.corners(t);
                let sum =
                    (b - a).length_squared() + (c - b).length_squared() + (a - c).length_squared();
                let quality = 4.0 * 3f32.sqrt() * 0.5 * (b - a).cross(c - a).length() / sum;
                assert!(
                    quality >= 0.1,
                    "triangle {t} is a needle: quality {quality}"
                );
            }
        }
    }
}

#[test]
fn closed_input_stays_closed() {
    let mut noise = Noise::new(3);
    for mesh in [
        icosphere(3, 0.5, |_| 0.01 * noise.next()),
        rounded_cube(12, 0.5, 0.01),
        tetrahedron(),
    ] {
        for max_residual_m in [0.002, 0.02, 0.2, f32::INFINITY] {
            let (out, _) = run(&mesh, max_residual_m);
            assert!(boundary_edges(&mesh).is_empty());
            assert!(
                boundary_edges(&out).is_empty(),
                "residual {max_residual_m} opened the mesh"
            );
            assert_manifold(&out);
            assert_no_degenerate_or_duplicate(&out);
            assert!(out.triangles.len() >= 4);
        }
    }
}

#[test]
fn residual_bound_holds() {
    let mut noise = Noise::new(11);
    let sphere = icosphere(3, 0.5, |_| 0.01 * noise.next());
    let mut bumpy_grid = grid(24, 1.0);
    for v in &mut bumpy_grid.vertices {
        v.z = 0.05 * (6.0 * v.x).sin() * (4.0 * v.y).cos();
    }
    for mesh in [sphere, bumpy_grid, rounded_cube(10, 0.5, 0.03)] {
        for max_residual_m in [0.003, 0.01, 0.03] {
            let (out, report) = run(&mesh, max_residual_m);
            assert!(report.max_residual_m <= max_residual_m);
            let worst = max_vertex_distance(&mesh, &out);
            assert!(
                worst <= max_residual_m * 1.0001 + 1e-6,
                "input vertex {worst} m from output, bound {max_residual_m}"
            );
            assert!(worst <= report.max_residual_m * 1.0001 + 1e-6);
        }
    }
}

#[test]
fn open_boundary_stays_on_input_boundary() {
    // A bumpy open patch: output boundary vertices must lie on the input boundary polyline.
    let mut mesh = grid(24, 1.0);
    for v in &mut mesh.vertices {
        v.z = 0.08 * (5.0 * v.x).sin() * (3.0 * v.y).cos();
    }
    let (out, report) = run(&mesh, 0.01);
    assert!(report.collapses > 0);
    assert_manifold(&out);
    assert_no_degenerate_or_duplicate(&out);
    let input_boundary = boundary_edges(&mesh);
    for (a, b) in boundary_edges(&out) {
        for v in [a, b] {
            let p = out.vertices[v as usize];
            let d = input_boundary
                .iter()
                .map(|&(x, y)| {
                    let (x, y) = (mesh.vertices[x as usize], mesh.vertices[y as usize]);
                    point_triangle_distance(p, x, y, y)
                })
                .fold(f32::INFINITY, f32::min);
            assert!(
                d <= 0.01,
                "boundary vertex {p} is {d} m off the input boundary"
            );
        }
    }
    // One boundary loop, as in the input.
    assert_eq!(
        boundary_edges(&out).len(),
        out.vertices
            .iter()
            .enumerate()
            .filter(|&(v, _)| boundary_edges(&out)
                .iter()
                .any(|&(a, b)| a == v as u32 || b == v as u32))
            .count()
    );
    assert!(max_vertex_distance(&mesh, &out) <= 0.01 + 1e-6);
}

#[test]
fn tighter_residual_keeps_more_faces() {
    let mut noise = Noise::new(5);
    let mesh = icosphere(4, 0.5, |_| 0.002 * noise.next());
    let counts: Vec<usize> = [0.003, 0.01, 0.03]
        .iter()
        .map(|&r| run(&mesh, r).0.triangles.len())
        .collect();
    assert!(counts[0] > counts[1] && counts[1] > counts[2], "{counts:?}");
}

#[test]
fn sphere_reduces_to_about_a_hundred_faces() {
    let mesh = icosphere(5, 0.5, |_| 0.0);
    assert_eq!(mesh.triangles.len(), 20480);
    let (out, report) = run(&mesh, 0.012);
    let faces = out.triangles.len();
    assert!((60..=250).contains(&faces), "{faces} faces: {report:?}");
    assert!(boundary_edges(&out).is_empty());
    assert_manifold(&out);
    assert_no_degenerate_or_duplicate(&out);
    let worst = max_vertex_distance(&mesh, &out);
    assert!(worst <= 0.012 + 1e-6, "input vertex {worst} m from output");
}

#[test]
fn cube_recovers_sharp_corners() {
    let mesh = rounded_cube(24, 0.5, 0.01);
    let (out, report) = run(&mesh, 0.01);
    let faces = out.triangles.len();
    assert!((12..=40).contains(&faces), "{faces} faces: {report:?}");
    for x in [-0.5f32, 0.5] {
        for y in [-0.5f32, 0.5] {
            for z in [-0.5f32, 0.5] {
                let corner = Vec3::new(x, y, z);
                let nearest = out
                    .vertices
                    .iter()
                    .map(|v| v.distance(corner))
                    .fold(f32::INFINITY, f32::min);
                assert!(
                    nearest < 0.015,
                    "no vertex near corner {corner}: {nearest} m"
                );
            }
        }
    }
    assert!(boundary_edges(&out).is_empty());
    assert_manifold(&out);
    assert!(max_vertex_distance(&mesh, &out) <= 0.01 + 1e-6);
}

#[test]
fn marching_tetrahedra_sphere_simplifies_cleanly() {
    let mesh = marching_tetrahedra(|p| p.length() - 0.5, Vec3::splat(-0.5713), 0.05, 24);
    assert!(boundary_edges(&mesh).is_empty());
    assert_manifold(&mesh);
    let (out, report) = run(&mesh, 0.012);
    assert!(report.collapses > 0);
    assert!(boundary_edges(&out).is_empty());
    assert_manifold(&out);
    assert_no_degenerate_or_duplicate(&out);
    assert!(max_vertex_distance(&mesh, &out) <= 0.012 + 1e-6);
}

#[test]
fn rejects_out_of_range_index() {
    let mesh = TriMesh::new(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        vec![[0, 1, 2], [0, 3, 1]],
    );
    let err = simplify(&mesh, &SimplifyConfig::default()).unwrap_err();
    assert_eq!(
        err,
        SimplifyError::IndexOutOfRange {
            triangle: 1,
            index: 3,
            vertex_count: 3
        }
    );
}

#[test]
fn rejects_non_finite_vertex_and_bad_residual() {
    let mesh = TriMesh::new(
        vec![Vec3::ZERO, Vec3::X, Vec3::new(0.0, f32::NAN, 0.0)],
        vec![[0, 1, 2]],
    );
    let err = simplify(&mesh, &SimplifyConfig::default()).unwrap_err();
    assert!(
        matches!(err, SimplifyError::NonFiniteVertex { index: 2, .. }),
        "{err}"
    );
    for bad in [-0.1, f32::NAN] {
        let config = SimplifyConfig {
            max_residual_m: bad,
            ..SimplifyConfig::default()
        };
        assert!(matches!(
            simplify(&tetrahedron(), &config),
            Err(SimplifyError::InvalidMaxResidual { .. })
        ));
    }
}

#[test]
fn keeps_nonmanifold_input_intact() {
    let mut mesh = grid(10, 1.0);
    // A fin on the interior edge (v, v+1) of the grid: that edge now has three faces.
    let (v0, v1) = (5 * 11 + 5, 5 * 11 + 6);
    let apex = mesh.vertices.len() as u32;
    mesh.vertices.push(Vec3::new(0.55, 0.5, 0.3));
    mesh.triangles.push([v0, v1, apex]);
    // A bow-tie: a second patch touching the grid at its corner vertex 0 only.
    let base = mesh.vertices.len() as u32;
    mesh.vertices
        .extend([Vec3::new(-0.3, -0.1, 0.0), Vec3::new(-0.1, -0.3, 0.0)]);
    mesh.triangles.push([0, base, base + 1]);
    // Junk: a degenerate triangle and an unreferenced vertex.
    mesh.triangles.push([1, 1, 2]);
    mesh.vertices.push(Vec3::splat(9.0));
    let (out, report) = run(&mesh, 0.01);
    assert!(report.collapses > 0);
    let has = |p: Vec3| out.vertices.iter().position(|&v| v == p);
    let fin: Vec<Option<usize>> = [v0, v1, apex]
        .iter()
        .map(|&v| has(mesh.vertices[v as usize]))
        .collect();
    assert!(fin.iter().all(Option::is_some), "fin vertices lost");
    let fin: Vec<u32> = fin
        .into_iter()
        .map(|v| v.unwrap_or_default() as u32)
        .collect();
    assert!(
        out.triangles.contains(&[fin[0], fin[1], fin[2]]),
        "fin triangle lost"
    );
    assert!(has(Vec3::splat(9.0)).is_none(), "unreferenced vertex kept");
    assert!(has(Vec3::new(-0.3, -0.1, 0.0)).is_some());
    assert!(out
        .triangles
        .iter()
        .all(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0]));
    assert!(max_vertex_distance(&mesh, &out) <= 0.01 + 1e-6);
}

#[test]
fn output_is_deterministic() {
    let mut noise = Noise::new(9);
    let mesh = icosphere(4, 0.5, |_| 0.005 * noise.next());
    let first = run(&mesh, 0.01);
    for _ in 0..3 {
        assert_eq!(run(&mesh.clone(), 0.01), first);
    }
}

#[test]
fn empty_and_degenerate_input_is_fine() {
    let (out, report) = run(&TriMesh::default(), 0.01);
    assert!(out.is_empty() && report.faces_out == 0);
    let junk = TriMesh::new(vec![Vec3::ZERO, Vec3::X], vec![[0, 0, 1], [1, 1, 1]]);
    let (out, report) = run(&junk, 0.01);
    assert!(out.is_empty() && out.vertices.is_empty());
    assert_eq!(report.faces_in, 2);
}

#[test]
fn min_faces_is_respected() {
    let mesh = icosphere(3, 0.5, |_| 0.0);
    let config = SimplifyConfig {
        max_residual_m: f32::INFINITY,
        min_faces: 200,
    };
    let (out, _) = simplify(&mesh, &config).expect("simplifies");
    assert!(
        (200..=201).contains(&out.triangles.len()),
        "{}",
        out.triangles.len()
    );
}

#[test]
fn random_soups_never_panic_and_keep_the_bound() {
    let mut noise = Noise::new(21);
    for round in 0..90 {
        let mesh = if round % 3 == 2 {
            // A noisy closed sphere with a few vertices welded together (pinches, fins) and a
            // few faces removed.
            let mut mesh = icosphere(2, 0.5, |_| 0.02 * noise.next());
            let n = mesh.vertices.len() as f32;
            for _ in 0..3 {
                let from = ((noise.next() + 1.0) * 0.4999 * n) as u32;
                let to = ((noise.next() + 1.0) * 0.4999 * n) as u32;
                for t in &mut mesh.triangles {
                    for i in t.iter_mut().filter(|i| **i == from) {
                        *i = to;
                    }
                }
            }
            mesh.triangles.retain(|_| noise.next() > -0.9);
            mesh
        } else if round % 3 == 0 {
            // A free triangle soup over few vertices: non-manifold almost everywhere.
            let vertices: Vec<Vec3> = (0..12)
                .map(|_| Vec3::new(noise.next(), noise.next(), noise.next()) * 0.3)
                .collect();
            let triangles = (0..30)
                .map(|_| [(); 3].map(|_| ((noise.next() + 1.0) * 5.99) as u32))
                .collect();
            TriMesh::new(vertices, triangles)
        } else {
            // A bumpy grid with random holes, flipped triangles and pinched corners.
            let mut mesh = grid(8, 1.0);
            for v in &mut mesh.vertices {
                v.z = 0.03 * noise.next();
            }
            mesh.triangles.retain(|_| noise.next() > -0.6);
            for t in &mut mesh.triangles {
                if noise.next() > 0.8 {
                    t.swap(1, 2);
                }
            }
            mesh
        };
        for max_residual_m in [0.0, 0.02, f32::INFINITY] {
            let (out, report) = run(&mesh, max_residual_m);
            assert!(out
                .triangles
                .iter()
                .flatten()
                .all(|&i| (i as usize) < out.vertices.len()));
            assert_eq!(report.faces_out, out.triangles.len());
            if is_manifold(&mesh) {
                assert_manifold(&out);
                assert_eq!(
                    boundary_edges(&mesh).is_empty(),
                    boundary_edges(&out).is_empty()
                );
            }
            if max_residual_m.is_finite() {
                let worst = max_vertex_distance_of_kept(&mesh, &out);
                assert!(worst <= max_residual_m + 1e-5, "round {round}: {worst}");
            }
        }
    }
}

fn run_near(mesh: &TriMesh, points: &[Vec3], max_residual_m: f32) -> (TriMesh, SimplifyReport) {
    simplify_near_points(
        mesh,
        points,
        &SimplifyConfig {
            max_residual_m,
            ..SimplifyConfig::default()
        },
    )
    .expect("valid input simplifies")
}

/// A bumpy patch whose plain simplification leans up to the bound away from its vertices.
fn bumpy_grid() -> TriMesh {
    let mut mesh = grid(24, 1.0);
    for v in &mut mesh.vertices {
        v.z = 0.05 * (6.0 * v.x).sin() * (4.0 * v.y).cos();
    }
    mesh
}

#[test]
fn extra_points_are_held_to_the_bound_and_cost_faces() {
    let mesh = bumpy_grid();
    let bound = 0.03;
    // Points 2 cm above every vertex: within the bound of the input, but on one side of it,
    // so the output may no longer lean the other way by up to the bound.
    let above: Vec<Vec3> = mesh.vertices.iter().map(|&v| v + 0.02 * Vec3::Z).collect();
    let (plain, _) = run(&mesh, bound);
    let (held, report) = run_near(&mesh, &above, bound);
    assert_eq!(report.points_beyond_bound, 0);
    assert!(
        held.triangles.len() > plain.triangles.len(),
        "held {} faces, plain {}",
        held.triangles.len(),
        plain.triangles.len()
    );
    let worst_point = above
        .iter()
        .map(|&p| point_mesh_distance(p, &held))
        .fold(0.0, f32::max);
    assert!(worst_point <= bound * 1.0001 + 1e-6, "{worst_point}");
    assert!(max_vertex_distance(&mesh, &held) <= bound * 1.0001 + 1e-6);
    assert!(report.max_residual_m <= bound);
    assert!(worst_point <= report.max_residual_m * 1.0001 + 1e-6);
    assert_manifold(&held);
    assert_no_degenerate_or_duplicate(&held);
}

#[test]
fn extra_points_beyond_the_bound_are_left_out_and_counted() {
    let mesh = bumpy_grid();
    let bound = 0.03;
    let far = [
        Vec3::new(0.5, 0.5, 1.0),
        Vec3::new(0.2, 0.7, -0.5),
        Vec3::NAN,
        Vec3::INFINITY,
    ];
    let (plain, _) = run(&mesh, bound);
    let (out, report) = run_near(&mesh, &far, bound);
    assert_eq!(report.points_beyond_bound, far.len());
    assert_eq!(out, plain, "points left out change nothing");
    let (none, report) = run_near(&mesh, &[], bound);
    assert_eq!(report.points_beyond_bound, 0);
    assert_eq!(none, plain);
}

#[test]
fn extra_points_keep_the_checks_on_a_closed_mesh() {
    // A sphere held to the vertices of a finer sphere, both within 4 mm of radius 0.5: closed,
    // manifold, and every point that was within the bound still is; the others are counted.
    let mut noise = Noise::new(5);
    let sphere = icosphere(3, 0.5, |_| 0.004 * noise.next());
    let points: Vec<Vec3> = icosphere(4, 0.5, |_| 0.004 * noise.next()).vertices;
    for bound in [0.005, 0.02] {
        let (out, report) = run_near(&sphere, &points, bound);
        assert_manifold(&out);
        assert!(boundary_edges(&out).is_empty());
        let beyond = |factor: f32| {
            points
                .iter()
                .filter(|&&p| point_mesh_distance(p, &sphere) > factor * bound)
                .count()
        };
        let left_out = report.points_beyond_bound;
        assert!(
            (beyond(1.001)..=beyond(0.999)).contains(&left_out),
            "bound {bound}: {left_out} left out"
        );
        let worst = points
            .iter()
            .filter(|&&p| point_mesh_distance(p, &sphere) <= bound * 0.999)
            .map(|&p| point_mesh_distance(p, &out))
            .fold(0.0, f32::max);
        assert!(worst <= bound * 1.0001 + 1e-6, "bound {bound}: {worst}");
    }
}

#[test]
fn components_are_found_whatever_the_order_of_indices() {
    // A 2×2 grid of the unit square, its vertices and corners shuffled: the union of a
    // triangle's corners used to link a root that the first union had already hung under
    // another, which cut vertex 1 off its component and left it no faces on record (an overflow
    // in debug builds, a component simplified below its floor in release; a real scan's second
    // pass hit it).
    let at = |x: f32, y: f32| Vec3::new(x, y, 0.0);
    let vertices = vec![
        at(0.5, 0.0),
        at(0.0, 1.0),
        at(1.0, 0.0),
        at(0.5, 1.0),
        at(1.0, 1.0),
        at(0.5, 0.5),
        at(0.0, 0.5),
        at(0.0, 0.0),
        at(1.0, 0.5),
    ];
    let triangles = vec![
        [7, 0, 5],
        [5, 6, 7],
        [8, 0, 2],
        [5, 0, 8],
        [6, 5, 3],
        [1, 6, 3],
        [5, 8, 4],
        [4, 3, 5],
    ];
    let mesh = TriMesh::new(vertices, triangles);
    let (out, _) = run(&mesh, f32::INFINITY);
    assert!(!out.triangles.is_empty());
    assert_manifold(&out);
    assert!((out.area() - 1.0).abs() < 1e-4, "area {}", out.area());
}

#[test]
fn the_work_counts_add_up() {
    let mesh = marching_tetrahedra(|p| p.length() - 0.5, Vec3::splat(-0.5713), 0.05, 24);
    let (_, report) = run(&mesh, 0.012);
    let work = report.work;
    let refused =
        report.rejected_by_residual + report.rejected_by_topology + report.rejected_by_geometry;
    // Every collapse and every refusal was an evaluation, and every evaluation a pop; a
    // collapse checks at least the support points of the faces it removes.
    assert!(work.evaluations >= report.collapses + refused, "{report:?}");
    assert!(work.queue_pops >= work.evaluations, "{report:?}");
    assert!(work.support_checks >= report.collapses, "{report:?}");
    assert!(work.support_searches <= work.support_checks, "{report:?}");
    assert!(work.support_searches > 0, "{report:?}");
    // Nothing to collapse, nothing counted but the pops that find it so.
    let (_, still) = run(&tetrahedron(), f32::INFINITY);
    assert_eq!(
        still.work.evaluations, still.rejected_by_topology,
        "{still:?}"
    );
    assert_eq!(still.work.support_checks, 0, "{still:?}");
}
