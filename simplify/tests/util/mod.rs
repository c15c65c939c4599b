//! Hand-built meshes and brute-force checks that make the simplifier tests read like scripts.

#![allow(dead_code)] // each test binary uses a different subset

use std::collections::{BTreeMap, BTreeSet, HashMap};

use tacmesh_simplify::{simplify, SimplifyConfig, SimplifyReport};
use tacmesh_source::glam::Vec3;
use tacmesh_source::TriMesh;

/// Small deterministic noise source (xorshift32), values in [-1, 1].
pub struct Noise(u32);

impl Noise {
    pub fn new(seed: u32) -> Self {
        Self(seed.max(1))
    }
    pub fn next(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 17;
        self.0 ^= self.0 << 5;
        (self.0 as f64 / u32::MAX as f64 * 2.0 - 1.0) as f32
    }
}

pub fn run(mesh: &TriMesh, max_residual_m: f32) -> (TriMesh, SimplifyReport) {
    simplify(
        mesh,
        &SimplifyConfig {
            max_residual_m,
            ..SimplifyConfig::default()
        },
    )
    .expect("valid input simplifies")
}

pub fn tetrahedron() -> TriMesh {
    TriMesh::new(
        vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
        ],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
}

/// An `n`×`n`-quad grid over `[0, size]²` at z = 0, facing +z.
pub fn grid(n: u32, size: f32) -> TriMesh {
    let mut vertices = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            vertices.push(Vec3::new(
                size * i as f32 / n as f32,
                size * j as f32 / n as f32,
                0.0,
            ));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut triangles = Vec::new();
    for j in 0..n {
        for i in 0..n {
            triangles.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            triangles.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    TriMesh::new(vertices, triangles)
}

/// An icosahedron subdivided `levels` times (20·4^levels faces) on a sphere of `radius`, each
/// vertex then moved radially by `radial(unit direction)`.
pub fn icosphere(levels: u32, radius: f32, mut radial: impl FnMut(Vec3) -> f32) -> TriMesh {
    let t = (1.0 + 5f32.sqrt()) / 2.0;
    let mut vertices: Vec<Vec3> = [
        (-1.0, t, 0.0),
        (1.0, t, 0.0),
        (-1.0, -t, 0.0),
        (1.0, -t, 0.0),
        (0.0, -1.0, t),
        (0.0, 1.0, t),
        (0.0, -1.0, -t),
        (0.0, 1.0, -t),
        (t, 0.0, -1.0),
        (t, 0.0, 1.0),
        (-t, 0.0, -1.0),
        (-t, 0.0, 1.0),
    ]
    .iter()
    .map(|&(x, y, z)| Vec3::new(x, y, z).normalize())
    .collect();
    let mut triangles: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut midpoint: HashMap<(u32, u32), u32> = HashMap::new();
        let mut mid = |a: u32, b: u32, vertices: &mut Vec<Vec3>| {
            *midpoint.entry((a.min(b), a.max(b))).or_insert_with(|| {
                vertices.push(((vertices[a as usize] + vertices[b as usize]) * 0.5).normalize());
                vertices.len() as u32 - 1
            })
        };
        let mut next = Vec::with_capacity(triangles.len() * 4);
        for [a, b, c] in triangles {
            let ab = mid(a, b, &mut vertices);
            let bc = mid(b, c, &mut vertices);
            let ca = mid(c, a, &mut vertices);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        triangles = next;
    }
    for v in &mut vertices {
        *v *= radius + radial(*v);
    }
    TriMesh::new(vertices, triangles)
}

/// A cube of half-size `half` centred at the origin whose edges and corners are rounded with
/// `radius`, built from `n`×`n` quads per side, spaced more densely toward the edges.
pub fn rounded_cube(n: u32, half: f32, radius: f32) -> TriMesh {
    let mut vertices: Vec<Vec3> = Vec::new();
    let mut index: BTreeMap<(i64, i64, i64), u32> = BTreeMap::new();
    let mut triangles = Vec::new();
    let warp = |i: u32| (std::f32::consts::FRAC_PI_2 * (2.0 * i as f32 / n as f32 - 1.0)).sin();
    let inner = half - radius;
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let mut ids = vec![0u32; ((n + 1) * (n + 1)) as usize];
            for j in 0..=n {
                for i in 0..=n {
                    let (u, v) = (warp(i) * half, warp(j) * half);
                    let mut q = [0.0f32; 3];
                    q[axis] = sign * half;
                    q[(axis + 1) % 3] = u;
                    q[(axis + 2) % 3] = v;
                    // Weld on the cube lattice position before rounding.
                    let key = (
                        (q[0] * 1e5).round() as i64,
                        (q[1] * 1e5).round() as i64,
                        (q[2] * 1e5).round() as i64,
                    );
                    let q = Vec3::from_array(q);
                    let core = q.clamp(Vec3::splat(-inner), Vec3::splat(inner));
                    let p = core + (q - core).normalize() * radius;
                    let id = *index.entry(key).or_insert_with(|| {
                        vertices.push(p);
                        vertices.len() as u32 - 1
                    });
                    ids[(j * (n + 1) + i) as usize] = id;
                }
            }
            for j in 0..n {
                for i in 0..n {
                    let c = |di: u32, dj: u32| ids[((j + dj) * (n + 1) + i + di) as usize];
                    let (t0, t1) = ([c(0, 0), c(1, 0), c(1, 1)], [c(0, 0), c(1, 1), c(0, 1)]);
                    // u × v points along +axis; flip on the negative side.
                    if sign > 0.0 {
                        triangles.extend([t0, t1]);
                    } else {
                        triangles.extend([[t0[0], t0[2], t0[1]], [t1[0], t1[2], t1[1]]]);
                    }
                }
            }
        }
    }
    TriMesh::new(vertices, triangles)
}

/// Marching tetrahedra (Kuhn split of each grid cube into six) of the zero set of `sdf`
/// (negative inside) over `[lo, lo + cells·step]³`: a marching-cubes-like mesh with the slivers
/// and irregular valences of real reconstructions. Welded, closed if the surface is inside the
/// box, counter-clockwise seen from outside.
pub fn marching_tetrahedra(sdf: impl Fn(Vec3) -> f32, lo: Vec3, step: f32, cells: u32) -> TriMesh {
    let m = cells + 1;
    let at = |i: u32, j: u32, k: u32| lo + Vec3::new(i as f32, j as f32, k as f32) * step;
    let mut value = vec![0.0f32; (m * m * m) as usize];
    let gid = |i: u32, j: u32, k: u32| ((k * m + j) * m + i) as usize;
    for k in 0..m {
        for j in 0..m {
            for i in 0..m {
                let v = sdf(at(i, j, k));
                value[gid(i, j, k)] = if v == 0.0 { 1e-7 } else { v };
            }
        }
    }
    let mut vertices = Vec::new();
    let mut edge_vertex: HashMap<(usize, usize), u32> = HashMap::new();
    let mut triangles = Vec::new();
    let perms = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
    ];
    for k in 0..cells {
        for j in 0..cells {
            for i in 0..cells {
                for perm in perms {
                    let mut corner = [i, j, k];
                    let mut tet = [(0usize, Vec3::ZERO); 4];
                    tet[0] = (
                        gid(corner[0], corner[1], corner[2]),
                        at(corner[0], corner[1], corner[2]),
                    );
                    for (s, &axis) in perm.iter().enumerate() {
                        corner[axis] += 1;
                        tet[s + 1] = (
                            gid(corner[0], corner[1], corner[2]),
                            at(corner[0], corner[1], corner[2]),
                        );
                    }
                    let inside: Vec<usize> = (0..4).filter(|&c| value[tet[c].0] < 0.0).collect();
                    let outside: Vec<usize> = (0..4).filter(|&c| value[tet[c].0] >= 0.0).collect();
                    if inside.is_empty() || outside.is_empty() {
                        continue;
                    }
                    let mut cut = |a: usize, b: usize| {
                        let (ga, gb) = (tet[a].0, tet[b].0);
                        let key = (ga.min(gb), ga.max(gb));
                        *edge_vertex.entry(key).or_insert_with(|| {
                            let (va, vb) = (value[ga], value[gb]);
                            let t = va / (va - vb);
                            vertices.push(tet[a].1 + (tet[b].1 - tet[a].1) * t);
                            vertices.len() as u32 - 1
                        })
                    };
                    let mut polygon = Vec::new();
                    if inside.len() == 2 {
                        let (i0, i1, o0, o1) = (inside[0], inside[1], outside[0], outside[1]);
                        polygon.extend([cut(i0, o0), cut(i0, o1), cut(i1, o1), cut(i1, o0)]);
                    } else {
                        let (lone, rest) = if inside.len() == 1 {
                            (inside[0], outside)
                        } else {
                            (outside[0], inside.clone())
                        };
                        polygon.extend(rest.iter().map(|&r| cut(lone, r)));
                    }
                    let centre = |set: &[usize]| {
                        set.iter().map(|&c| tet[c].1).sum::<Vec3>() / set.len() as f32
                    };
                    let outward = centre(&outside_of(&inside)) - centre(&inside);
                    let p = |v: u32| vertices[v as usize];
                    let mut tris = vec![[polygon[0], polygon[1], polygon[2]]];
                    if polygon.len() == 4 {
                        tris.push([polygon[0], polygon[2], polygon[3]]);
                    }
                    for t in tris {
                        let n = (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0]));
                        triangles.push(if n.dot(outward) >= 0.0 {
                            t
                        } else {
                            [t[0], t[2], t[1]]
                        });
                    }
                }
            }
        }
    }
    TriMesh::new(vertices, triangles)
}

fn outside_of(inside: &[usize]) -> Vec<usize> {
    (0..4).filter(|c| !inside.contains(c)).collect()
}

/// Squared distance from `p` to triangle `abc`, computed independently of the crate: projection
/// onto the plane if it falls inside, else the nearest edge segment.
pub fn point_triangle_distance(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    let n = (b - a).cross(c - a);
    if n.length_squared() > 0.0 {
        let n = n.normalize();
        let q = p - n * n.dot(p - a);
        let inside = [(a, b), (b, c), (c, a)]
            .iter()
            .all(|&(u, v)| (v - u).cross(q - u).dot(n) >= 0.0);
        if inside {
            return n.dot(p - a).abs();
        }
    }
    let segment = |u: Vec3, v: Vec3| {
        let d = v - u;
        let t = if d.length_squared() > 0.0 {
            ((p - u).dot(d) / d.length_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p - (u + d * t)).length()
    };
    segment(a, b).min(segment(b, c)).min(segment(c, a))
}

/// Distance from `p` to the nearest triangle of `mesh`, brute force.
pub fn point_mesh_distance(p: Vec3, mesh: &TriMesh) -> f32 {
    (0..mesh.triangles.len())
        .map(|t| {
            let [a, b, c] = mesh.corners(t);
            point_triangle_distance(p, a, b, c)
        })
        .fold(f32::INFINITY, f32::min)
}

/// The largest distance from an input vertex (used by some triangle) to the output surface.
pub fn max_vertex_distance(input: &TriMesh, output: &TriMesh) -> f32 {
    let used: BTreeSet<u32> = input.triangles.iter().flatten().copied().collect();
    used.iter()
        .map(|&v| point_mesh_distance(input.vertices[v as usize], output))
        .fold(0.0, f32::max)
}

/// As [`max_vertex_distance`], over the vertices of triangles with three distinct indices only
/// (the simplifier drops the others).
pub fn max_vertex_distance_of_kept(input: &TriMesh, output: &TriMesh) -> f32 {
    let used: BTreeSet<u32> = input
        .triangles
        .iter()
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0])
        .flatten()
        .copied()
        .collect();
    used.iter()
        .map(|&v| point_mesh_distance(input.vertices[v as usize], output))
        .fold(0.0, f32::max)
}

/// Undirected edges with the number of faces using them, and whether both directions occur.
fn edge_uses(mesh: &TriMesh) -> BTreeMap<(u32, u32), (u32, u32)> {
    let mut uses: BTreeMap<(u32, u32), (u32, u32)> = BTreeMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let e = uses.entry((a.min(b), a.max(b))).or_default();
            if a < b {
                e.0 += 1;
            } else {
                e.1 += 1;
            }
        }
    }
    uses
}

/// Edges used by exactly one face.
pub fn boundary_edges(mesh: &TriMesh) -> Vec<(u32, u32)> {
    edge_uses(mesh)
        .into_iter()
        .filter(|(_, (f, r))| f + r == 1)
        .map(|(e, _)| e)
        .collect()
}

/// Whether every edge is used by one face, or by two faces in opposite directions, and every
/// triangle has three distinct indices.
pub fn is_manifold(mesh: &TriMesh) -> bool {
    mesh.triangles
        .iter()
        .all(|t| t[0] != t[1] && t[1] != t[2] && t[2] != t[0])
        && edge_uses(mesh)
            .values()
            .all(|&(forward, reverse)| forward + reverse == 1 || (forward == 1 && reverse == 1))
}

/// Every edge used by one face, or by two faces in opposite directions.
pub fn assert_manifold(mesh: &TriMesh) {
    for (e, (forward, reverse)) in edge_uses(mesh) {
        assert!(
            (forward + reverse == 1) || (forward == 1 && reverse == 1),
            "edge {e:?} is non-manifold: {forward} forward, {reverse} reverse uses"
        );
    }
}

/// Three distinct indices, a non-zero area and no two triangles on the same three vertices.
pub fn assert_no_degenerate_or_duplicate(mesh: &TriMesh) {
    let mut seen = BTreeSet::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let [a, b, c] = *tri;
        assert!(
            a != b && b != c && c != a,
            "triangle {t} repeats an index: {tri:?}"
        );
        let [pa, pb, pc] = mesh.corners(t);
        assert!(
            (pb - pa).cross(pc - pa).length() > 1e-9,
            "triangle {t} has no area"
        );
        let mut key = *tri;
        key.sort_unstable();
        assert!(seen.insert(key), "triangle {t} duplicates another: {tri:?}");
    }
}

/// Unit normal of triangle `t`.
pub fn normal(mesh: &TriMesh, t: usize) -> Vec3 {
    let [a, b, c] = mesh.corners(t);
    (b - a).cross(c - a).normalize()
}
