//! The paper's test shapes (its Figure 3 and Table 1): Blender's default primitives.
//!
//! The five analytic primitives are built here the way Blender 3.4 builds them with default
//! settings (same vertex positions, same face structure), then triangulated: quads split on a
//! diagonal (every quad of these primitives is planar, so the diagonal does not change the
//! surface) and n-gon caps fan-triangulated. Suzanne cannot be built procedurally; it is
//! embedded from Blender's own OBJ export (`assets/suzanne.obj`).
//!
//! Conventions are Blender's: Z up, one unit = 1 m, triangles counter-clockwise seen from
//! outside. Around the Z axis the ring vertices start at +Y and go towards +X, as Blender's do.

use glam::{DVec3, Vec3};
use tacmesh_source::TriMesh;

/// Suzanne as exported by Blender 3.4.1 with -Z forward, Y up (see `assets/README.md`).
const SUZANNE_OBJ: &str = include_str!("../assets/suzanne.obj");

/// One of the six test shapes of the paper's Table 1.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Shape {
    Cone,
    Cube,
    Cylinder,
    /// Suzanne, Blender's monkey head.
    Monkey,
    Torus,
    /// Blender's UV sphere.
    Sphere,
}

impl Shape {
    /// All shapes in the order of the paper's Table 1.
    pub const ALL: [Shape; 6] = [
        Shape::Cone,
        Shape::Cube,
        Shape::Cylinder,
        Shape::Monkey,
        Shape::Torus,
        Shape::Sphere,
    ];

    /// The name the paper's Table 1 uses, lower case.
    pub fn name(self) -> &'static str {
        match self {
            Shape::Cone => "cone",
            Shape::Cube => "cube",
            Shape::Cylinder => "cylinder",
            Shape::Monkey => "monkey",
            Shape::Torus => "torus",
            Shape::Sphere => "sphere",
        }
    }

    /// Parses a [`name`](Self::name), ignoring ASCII case; also accepts Blender's names
    /// `suzanne` and `uv_sphere`.
    pub fn from_name(name: &str) -> Option<Shape> {
        let name = name.to_ascii_lowercase();
        match name.as_str() {
            "suzanne" => Some(Shape::Monkey),
            "uv_sphere" => Some(Shape::Sphere),
            _ => Shape::ALL.into_iter().find(|s| s.name() == name),
        }
    }

    /// Blender's default primitive, in Blender units and axes (Z up), triangulated.
    ///
    /// | shape | Blender defaults | triangles |
    /// |---|---|---|
    /// | cone | radius 1, depth 2, 32 vertices, n-gon base | 62 |
    /// | cube | size 2 | 12 |
    /// | cylinder | radius 1, depth 2, 32 vertices, n-gon caps | 124 |
    /// | monkey | Suzanne | 968 (the paper's table says 967) |
    /// | torus | major radius 1, minor 0.25, 48 × 12 segments | 1152 |
    /// | sphere | UV sphere, radius 1, 32 segments, 16 rings | 960 |
    pub fn blender_mesh(self) -> TriMesh {
        match self {
            Shape::Cone => cone(32, 1.0, 2.0),
            Shape::Cube => cube(2.0),
            Shape::Cylinder => cylinder(32, 1.0, 2.0),
            Shape::Monkey => suzanne(),
            Shape::Torus => torus(48, 12, 1.0, 0.25),
            Shape::Sphere => uv_sphere(32, 16, 1.0),
        }
    }

    /// The test mesh in metres: [`blender_mesh`](Self::blender_mesh) scaled uniformly so the
    /// largest side of its bounding box is 1 m, centred on the origin (the paper: "bounding
    /// boxes approximately 1 m wide").
    pub fn mesh(self) -> TriMesh {
        let mut mesh = self.blender_mesh();
        fit_to_extent(&mut mesh, 1.0);
        mesh
    }
}

impl std::fmt::Display for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Scales `mesh` uniformly so the largest side of its bounding box is `extent_m`, and moves
/// the centre of the bounding box to the origin.
///
/// A mesh without vertices, or with non-finite vertices, is left alone; a mesh whose vertices
/// all coincide is only moved to the origin.
pub fn fit_to_extent(mesh: &mut TriMesh, extent_m: f32) {
    let Some((lo, hi)) = mesh.bounds() else {
        return;
    };
    if !(lo.is_finite() && hi.is_finite()) {
        return;
    }
    let centre = (lo + hi) * 0.5;
    let largest_m = (hi - lo).max_element();
    let scale = if largest_m > 0.0 {
        extent_m / largest_m
    } else {
        1.0
    };
    for v in &mut mesh.vertices {
        *v = (*v - centre) * scale;
    }
}

// ---------------------------------------------------------------------------------------------
// Procedural primitives. Angles are evaluated in f64 and rounded once to f32.

/// A flat square of side `side_m` in the z = 0 plane, centred on the origin and facing +z
/// (counter-clockwise seen from above): a table top, 4 vertices, 2 triangles.
pub fn square(side_m: f32) -> TriMesh {
    let h = 0.5 * side_m;
    TriMesh::new(
        vec![
            Vec3::new(-h, -h, 0.0),
            Vec3::new(h, -h, 0.0),
            Vec3::new(h, h, 0.0),
            Vec3::new(-h, h, 0.0),
        ],
        vec![[0, 1, 2], [0, 2, 3]],
    )
}

/// Blender's cube: side `size_m`, centred on the origin, 8 vertices, 12 triangles.
pub fn cube(size_m: f32) -> TriMesh {
    let h = 0.5 * size_m;
    // Vertex i has x = +h if bit 0 is set, y = +h if bit 1, z = +h if bit 2.
    let vertices = (0..8u32)
        .map(|i| {
            let pick = |bit: u32| if i & (1 << bit) != 0 { h } else { -h };
            Vec3::new(pick(0), pick(1), pick(2))
        })
        .collect();
    // Counter-clockwise seen from outside: -X, +X, -Y, +Y, -Z, +Z.
    const FACES: [[u32; 4]; 6] = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    let mut triangles = Vec::with_capacity(12);
    for quad in FACES {
        push_quad(&mut triangles, quad);
    }
    TriMesh::new(vertices, triangles)
}

/// Blender's cylinder: `vertices` around, `radius_m`, height `depth_m` centred on the origin,
/// both caps n-gons (fan-triangulated). `4 * vertices - 4` triangles.
///
/// # Panics
/// If `vertices < 3`.
pub fn cylinder(vertices: u32, radius_m: f32, depth_m: f32) -> TriMesh {
    assert!(vertices >= 3, "a cylinder needs at least 3 vertices around");
    let n = vertices;
    let top_z = 0.5 * depth_m;
    // Top ring 0..n, bottom ring n..2n.
    let mut points = ring(n, radius_m, top_z);
    points.extend(ring(n, radius_m, -top_z));
    let top = |j: u32| j % n;
    let bottom = |j: u32| n + j % n;

    let mut triangles = Vec::with_capacity(4 * n as usize - 4);
    for j in 0..n {
        push_quad(
            &mut triangles,
            [top(j), top(j + 1), bottom(j + 1), bottom(j)],
        );
    }
    // Ring order runs clockwise seen from +Z, so the top cap goes backwards.
    push_fan(&mut triangles, (0..n).map(|j| top(n - j)));
    push_fan(&mut triangles, (0..n).map(bottom));
    TriMesh::new(points, triangles)
}

/// Blender's cone: `vertices` around the base of radius `radius_m`, apex on +Z, height
/// `depth_m` centred on the origin, base an n-gon (fan-triangulated). `2 * vertices - 2`
/// triangles.
///
/// # Panics
/// If `vertices < 3`.
pub fn cone(vertices: u32, radius_m: f32, depth_m: f32) -> TriMesh {
    assert!(vertices >= 3, "a cone needs at least 3 vertices around");
    let n = vertices;
    let mut points = ring(n, radius_m, -0.5 * depth_m);
    points.push(Vec3::new(0.0, 0.0, 0.5 * depth_m));
    let apex = n;
    let base = |j: u32| j % n;

    let mut triangles = Vec::with_capacity(2 * n as usize - 2);
    for j in 0..n {
        triangles.push([apex, base(j + 1), base(j)]);
    }
    push_fan(&mut triangles, (0..n).map(base));
    TriMesh::new(points, triangles)
}

/// Blender's UV sphere: `segments` around, `rings` from pole to pole, radius `radius_m`.
/// `2 * segments * (rings - 1)` triangles.
///
/// # Panics
/// If `segments < 3` or `rings < 2`.
pub fn uv_sphere(segments: u32, rings: u32, radius_m: f32) -> TriMesh {
    assert!(segments >= 3, "a UV sphere needs at least 3 segments");
    assert!(rings >= 2, "a UV sphere needs at least 2 rings");
    let radius = f64::from(radius_m);
    // North pole, the rings k = 1..rings-1 from north to south, south pole.
    let mut points = vec![Vec3::new(0.0, 0.0, radius_m)];
    for k in 1..rings {
        let polar = std::f64::consts::PI * f64::from(k) / f64::from(rings);
        points.extend(ring(
            segments,
            (radius * polar.sin()) as f32,
            (radius * polar.cos()) as f32,
        ));
    }
    points.push(Vec3::new(0.0, 0.0, -radius_m));
    let south = points.len() as u32 - 1;
    let at = |j: u32, k: u32| 1 + (k - 1) * segments + j % segments;

    let mut triangles = Vec::with_capacity(2 * (segments * (rings - 1)) as usize);
    for j in 0..segments {
        triangles.push([0, at(j + 1, 1), at(j, 1)]);
    }
    for k in 1..rings - 1 {
        for j in 0..segments {
            push_quad(
                &mut triangles,
                [at(j, k), at(j + 1, k), at(j + 1, k + 1), at(j, k + 1)],
            );
        }
    }
    for j in 0..segments {
        triangles.push([at(j, rings - 1), at(j + 1, rings - 1), south]);
    }
    TriMesh::new(points, triangles)
}

/// Blender's torus: `major_segments` around Z, `minor_segments` around the tube, in the XY
/// plane. `2 * major_segments * minor_segments` triangles.
///
/// # Panics
/// If either segment count is below 3.
pub fn torus(
    major_segments: u32,
    minor_segments: u32,
    major_radius_m: f32,
    minor_radius_m: f32,
) -> TriMesh {
    assert!(
        major_segments >= 3 && minor_segments >= 3,
        "a torus needs at least 3 segments each way"
    );
    let (big, small) = (f64::from(major_radius_m), f64::from(minor_radius_m));
    let mut points = Vec::with_capacity((major_segments * minor_segments) as usize);
    for i in 0..major_segments {
        let (sin_u, cos_u) =
            (std::f64::consts::TAU * f64::from(i) / f64::from(major_segments)).sin_cos();
        for k in 0..minor_segments {
            let (sin_v, cos_v) =
                (std::f64::consts::TAU * f64::from(k) / f64::from(minor_segments)).sin_cos();
            let radial = big + small * cos_v;
            points.push(DVec3::new(radial * cos_u, radial * sin_u, small * sin_v).as_vec3());
        }
    }
    let at = |i: u32, k: u32| (i % major_segments) * minor_segments + k % minor_segments;

    let mut triangles = Vec::with_capacity(2 * (major_segments * minor_segments) as usize);
    for i in 0..major_segments {
        for k in 0..minor_segments {
            push_quad(
                &mut triangles,
                [at(i, k), at(i + 1, k), at(i + 1, k + 1), at(i, k + 1)],
            );
        }
    }
    TriMesh::new(points, triangles)
}

/// Suzanne from the embedded Blender export, fan-triangulated, in Blender axes.
fn suzanne() -> TriMesh {
    let options = tobj::LoadOptions {
        triangulate: true,
        ..Default::default()
    };
    // The file has no `mtllib`, so the material loader is never called.
    let (models, _) = tobj::load_obj_buf(&mut SUZANNE_OBJ.as_bytes(), &options, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .expect("the embedded suzanne.obj is valid OBJ (checked by the tests)");

    let mut mesh = TriMesh::default();
    for model in models {
        let first = mesh.vertices.len() as u32;
        // OBJ (x, y, z) is Blender (x, z, -y), so Blender (x, y, z) is OBJ (x, -z, y).
        mesh.vertices.extend(
            model
                .mesh
                .positions
                .chunks_exact(3)
                .map(|p| Vec3::new(p[0], -p[2], p[1])),
        );
        mesh.triangles.extend(
            model
                .mesh
                .indices
                .chunks_exact(3)
                .map(|t| [first + t[0], first + t[1], first + t[2]]),
        );
    }
    mesh
}

/// `n` points on a circle of radius `radius_m` at height `z_m`, starting at +Y and going
/// towards +X (clockwise seen from +Z), as Blender places them.
fn ring(n: u32, radius_m: f32, z_m: f32) -> Vec<Vec3> {
    let radius = f64::from(radius_m);
    (0..n)
        .map(|j| {
            let (sin, cos) = (std::f64::consts::TAU * f64::from(j) / f64::from(n)).sin_cos();
            Vec3::new((radius * sin) as f32, (radius * cos) as f32, z_m)
        })
        .collect()
}

/// Splits the quad `a b c d` (counter-clockwise) on the diagonal `a c`.
fn push_quad(triangles: &mut Vec<[u32; 3]>, [a, b, c, d]: [u32; 4]) {
    triangles.push([a, b, c]);
    triangles.push([a, c, d]);
}

/// Fan-triangulates a convex polygon given counter-clockwise, from its first vertex.
fn push_fan(triangles: &mut Vec<[u32; 3]>, polygon: impl IntoIterator<Item = u32>) {
    let polygon: Vec<u32> = polygon.into_iter().collect();
    for pair in polygon.windows(2).skip(1) {
        triangles.push([polygon[0], pair[0], pair[1]]);
    }
}

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

    use super::*;

    /// Vertex positions of a Blender OBJ export (-Z forward, Y up), converted to Blender axes.
    fn obj_vertices_in_blender_axes(obj: &str) -> Vec<Vec3> {
        obj.lines()
            .filter_map(|line| line.strip_prefix("v "))
            .map(|rest| {
                let xyz: Vec<f32> = rest
                    .split_whitespace()
                    .map(|s| s.parse().expect("OBJ coordinate"))
                    .collect();
                Vec3::new(xyz[0], -xyz[2], xyz[1])
            })
            .collect()
    }

    fn blender_export(shape: Shape) -> &'static str {
        match shape {
            Shape::Cone => include_str!("../../testdata/meshes/cone.obj"),
            Shape::Cube => include_str!("../../testdata/meshes/cube.obj"),
            Shape::Cylinder => include_str!("../../testdata/meshes/cylinder.obj"),
            Shape::Monkey => SUZANNE_OBJ,
            Shape::Torus => include_str!("../../testdata/meshes/torus.obj"),
            Shape::Sphere => include_str!("../../testdata/meshes/uv_sphere.obj"),
        }
    }

    /// Signed volume by the divergence theorem; positive when triangles wind outwards.
    fn signed_volume(mesh: &TriMesh) -> f64 {
        (0..mesh.triangles.len())
            .map(|t| {
                let [a, b, c] = mesh.corners(t).map(|p| p.as_dvec3());
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// How many times each directed edge occurs.
    fn directed_edges(mesh: &TriMesh) -> HashMap<(u32, u32), usize> {
        let mut edges = HashMap::new();
        for &[a, b, c] in &mesh.triangles {
            for edge in [(a, b), (b, c), (c, a)] {
                *edges.entry(edge).or_insert(0) += 1;
            }
        }
        edges
    }

    #[test]
    fn triangle_counts_match_blender() {
        let counts: Vec<usize> = Shape::ALL
            .iter()
            .map(|s| s.blender_mesh().triangles.len())
            .collect();
        // Table 1 order: cone, cube, cylinder, monkey, torus, sphere. The paper lists the
        // monkey with 967 faces; Blender's Suzanne has 500 faces (468 quads, 32 triangles),
        // which is 968 triangles.
        assert_eq!(counts, [62, 12, 124, 968, 1152, 960]);
    }

    #[test]
    fn vertex_sets_match_blender_exports() {
        for shape in Shape::ALL {
            let ours = shape.blender_mesh().vertices;
            let blender = obj_vertices_in_blender_axes(blender_export(shape));
            assert_eq!(ours.len(), blender.len(), "{shape}: vertex count");
            // Each vertex has a partner within 1e-4 m both ways; with equal counts and no
            // duplicates (checked below) that makes the sets equal.
            for (from, to, what) in [
                (&ours, &blender, "ours→blender"),
                (&blender, &ours, "blender→ours"),
            ] {
                for p in from {
                    let nearest = to.iter().map(|q| p.distance(*q)).fold(f32::MAX, f32::min);
                    assert!(
                        nearest < 1e-4,
                        "{shape} {what}: {p} is {nearest} m from any vertex"
                    );
                }
            }
            if shape == Shape::Monkey {
                // Suzanne has two pairs of coincident, unwelded vertices (14 = 113 and
                // 15 = 114 in the OBJ's 0-based numbering); Blender ships it that way.
                continue;
            }
            let closest_pair = (0..ours.len())
                .flat_map(|i| (i + 1..ours.len()).map(move |j| (i, j)))
                .map(|(i, j)| ours[i].distance(ours[j]))
                .fold(f32::MAX, f32::min);
            assert!(closest_pair > 1e-3, "{shape}: duplicate vertices");
        }
    }

    #[test]
    fn primitives_are_closed_manifolds_wound_outwards() {
        for shape in Shape::ALL.into_iter().filter(|&s| s != Shape::Monkey) {
            let mesh = shape.blender_mesh();
            let edges = directed_edges(&mesh);
            // Every directed edge once and its reverse once: every edge is in exactly two
            // triangles, which agree on orientation.
            for (&(a, b), &count) in &edges {
                assert_eq!(count, 1, "{shape}: edge {a}->{b} used {count} times");
                assert_eq!(
                    edges.get(&(b, a)),
                    Some(&1),
                    "{shape}: edge {a}-{b} is open"
                );
            }
            let volume = signed_volume(&mesh);
            assert!(
                volume > 0.0,
                "{shape}: signed volume {volume} (inward winding)"
            );
        }
    }

    #[test]
    fn primitive_volumes_approach_the_analytic_solids() {
        use std::f64::consts::PI;
        let volume = |s: Shape| signed_volume(&s.blender_mesh());
        assert!((volume(Shape::Cube) - 8.0).abs() < 1e-6);
        // Inscribed 32-gon prisms and pyramids: area 16 sin(2π/32) = 3.1214 instead of π.
        let polygon_area = 16.0 * (2.0 * PI / 32.0).sin();
        assert!((volume(Shape::Cylinder) - 2.0 * polygon_area).abs() < 1e-5);
        assert!((volume(Shape::Cone) - 2.0 * polygon_area / 3.0).abs() < 1e-5);
        // Faceted sphere and torus sit inside the smooth ones: the sphere within 3 %, the
        // torus within 6 % (its 12-gon cross-section alone has 3/π = 95.5 % of the circle's
        // area).
        let sphere = 4.0 / 3.0 * PI;
        assert!((0.97 * sphere..sphere).contains(&volume(Shape::Sphere)));
        let torus = 2.0 * PI * PI * 1.0 * 0.25 * 0.25;
        assert!((0.94 * torus..torus).contains(&volume(Shape::Torus)));
    }

    #[test]
    fn suzanne_is_in_blender_axes_facing_minus_y() {
        let mesh = Shape::Monkey.blender_mesh();
        let (lo, hi) = mesh.bounds().expect("suzanne has vertices");
        // Blender: ears along ±X (±1.367), face forward along -Y (depth ±0.852), height along Z.
        assert!(
            (hi - Vec3::new(1.367188, 0.851562, 0.984375))
                .abs()
                .max_element()
                < 1e-5
        );
        assert!((lo + hi).abs().max_element() < 1e-5);
        // Open at the eye sockets: 42 edges have one triangle, the rest two.
        let edges = directed_edges(&mesh);
        let boundary = edges
            .keys()
            .filter(|&&(a, b)| !edges.contains_key(&(b, a)))
            .count();
        assert_eq!(boundary, 42);
        // The face looks along -Y: the chin (the lowest vertex) is at the front.
        let chin = mesh.vertices.iter().min_by(|a, b| a.z.total_cmp(&b.z));
        assert!(chin.is_some_and(|c| c.y < -0.5), "chin at {chin:?}");
        // Open, but wound outwards: the eye holes barely change the enclosed volume.
        assert!(signed_volume(&mesh) > 0.0);
    }

    #[test]
    fn meshes_fit_a_one_metre_box_centred_on_the_origin() {
        for shape in Shape::ALL {
            let (lo, hi) = shape.mesh().bounds().expect("non-empty");
            let size = hi - lo;
            assert!((size.max_element() - 1.0).abs() < 1e-6, "{shape}: {size}");
            assert!(
                (lo + hi).abs().max_element() < 1e-6,
                "{shape}: centre {}",
                (lo + hi) / 2.0
            );
        }
        // Aspect ratios survive: the torus is 1 x 1 x 0.2.
        let (lo, hi) = Shape::Torus.mesh().bounds().expect("non-empty");
        assert!(((hi - lo).z - 0.2).abs() < 1e-6);
    }

    #[test]
    fn fit_to_extent_scales_uniformly_about_the_box_centre() {
        let mut mesh = TriMesh::new(
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(5.0, 3.0, 3.5)],
            vec![],
        );
        fit_to_extent(&mut mesh, 2.0);
        assert_eq!(
            mesh.vertices,
            vec![Vec3::new(-1.0, -0.25, -0.125), Vec3::new(1.0, 0.25, 0.125)]
        );

        let mut point = TriMesh::new(vec![Vec3::splat(4.0)], vec![]);
        fit_to_extent(&mut point, 1.0);
        assert_eq!(point.vertices, vec![Vec3::ZERO]);

        let mut empty = TriMesh::default();
        fit_to_extent(&mut empty, 1.0);
        assert!(empty.vertices.is_empty());
    }

    #[test]
    fn names_round_trip_and_blender_aliases_parse() {
        for shape in Shape::ALL {
            assert_eq!(Shape::from_name(shape.name()), Some(shape));
            assert_eq!(shape.to_string(), shape.name());
        }
        assert_eq!(Shape::from_name("suzanne"), Some(Shape::Monkey));
        assert_eq!(Shape::from_name("UV_Sphere"), Some(Shape::Sphere));
        assert_eq!(Shape::from_name("Torus"), Some(Shape::Torus));
        assert_eq!(Shape::from_name("teapot"), None);
    }

    #[test]
    fn denser_primitives_stay_closed() {
        let meshes = [
            cube(1.0),
            cylinder(5, 1.0, 1.0),
            cone(3, 1.0, 1.0),
            uv_sphere(3, 2, 1.0),
            torus(3, 3, 1.0, 0.5),
        ];
        for mesh in meshes {
            let edges = directed_edges(&mesh);
            assert!(edges
                .iter()
                .all(|(&(a, b), &n)| n == 1 && edges.get(&(b, a)) == Some(&1)));
            assert!(signed_volume(&mesh) > 0.0);
        }
        assert_eq!(uv_sphere(100, 50, 1.0).triangles.len(), 2 * 100 * 49);
        assert_eq!(torus(100, 100, 1.0, 0.25).triangles.len(), 20_000);
    }
}
