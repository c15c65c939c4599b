//! A closed collision proxy for every mesh: what a physics engine can give mass to, and what a
//! probe from any direction stops on at or before the real object.
//!
//! A closed visual mesh is its own proxy. A one-view object is an open shell: the surface the
//! sensor saw. Everything behind that surface, along the sensor's rays, is space the sensor has
//! not seen (its rays ended on the shell), and everything beside it the rays passed through on
//! their way to the support (the table seen around the object) is free. So the largest solid
//! the observations allow is the shell's *shadow volume*: the shell swept away from the sensor
//! along its rays until they meet the support plane. The real object lies inside it (up to the
//! noise of the visible surface), which makes contact with the proxy conservative: a probe
//! from the seen side meets the visible surface, one from behind meets the shadow's walls or
//! cap before it could meet the object.
//!
//! The proxy is the shell, its copy on the support (the cap, wound the other way), and a wall
//! of two triangles along each boundary edge: closed wherever the shell is a consistently wound
//! surface. A ray that never meets the support (one running level with it or away from it,
//! above the horizon of a camera looking across a room) or a scene with no support is cut at
//! `max_depth_of_extent` times the shell's extent behind its surface, and so is a ray that
//! grazes the support and would meet it metres away (then goes straight down to the
//! support): an assumption (objects at most twice as deep as they are wide) where the
//! observations bound nothing or next to nothing; the proxy's [`Proxy::capped_vertices`] say
//! how many rays it applied to.
//!
//! How conservative: the shadow of a box seen from 45° above is the box plus the wedge of table
//! it hides, about 1.5–2 times its volume; a camera low over the table casts long shadows and
//! a larger proxy (the tests and BENCHMARKS.md give figures on the simulated scenes).

use std::collections::HashMap;

use glam::Vec3;
use tacmesh_source::TriMesh;

use crate::orientation::{orientation, signed_volume_m3};

/// A plane the object stands on: points `p` with `normal·p = offset`, the unit normal pointing
/// to the side the object is on (up, towards the sensor).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SupportPlane {
    pub normal: Vec3,
    pub offset: f32,
}

impl SupportPlane {
    /// Height of `p` above the plane, metres (negative below it).
    pub fn height(&self, p: Vec3) -> f32 {
        self.normal.dot(p) - self.offset
    }
}

/// Settings of [`collision_proxy`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ProxyConfig {
    /// How far behind the visible surface a ray is cut when it meets no support or meets it
    /// farther, as a multiple of the shell's extent (the largest side of its bounding box).
    pub max_depth_of_extent: f32,
    /// How far the proxy of an open shell is grown outward, metres: the visible surface is the
    /// reconstruction's, within its error of the true one on either side, and it ends short of
    /// the true silhouette where the data thins out; growing by about that error makes contact
    /// stop at or before the real object there too. A closed visual mesh is not grown.
    pub margin_m: f32,
    /// Vertices lower than this over the support, as a fraction of the shell's extent, drop
    /// straight down onto it instead of along their ray: the visible surface stops short of
    /// the table (the data thins out where the object meets it), and a ray from that low rim
    /// runs under the object, leaving the strip of its front between the rim and the table
    /// outside the proxy; straight down covers it.
    pub drop_height_of_extent: f32,
}

impl Default for ProxyConfig {
    fn default() -> Self {
        Self {
            max_depth_of_extent: 2.0,
            margin_m: 0.0,
            drop_height_of_extent: 0.1,
        }
    }
}

/// How a proxy was made.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ProxyKind {
    /// The visual mesh, already closed.
    Surface,
    /// An open shell swept away from the sensor along its rays to the support plane.
    ShadowVolume,
    /// An open shell with no sensor position, swept straight down onto the support plane.
    Extrusion,
    /// An open shell with neither a sensor position nor a support: nothing bounds its back, and
    /// the proxy is the open shell itself.
    OpenShell,
}

impl ProxyKind {
    pub fn as_str(self) -> &'static str {
        match self {
            ProxyKind::Surface => "surface",
            ProxyKind::ShadowVolume => "shadow volume",
            ProxyKind::Extrusion => "extrusion",
            ProxyKind::OpenShell => "open shell",
        }
    }
}

/// A collision proxy and how it was made.
#[derive(Debug, Clone, PartialEq)]
pub struct Proxy {
    pub mesh: TriMesh,
    pub kind: ProxyKind,
    /// Whether `mesh` is closed and consistently wound.
    pub closed: bool,
    /// Its signed volume, m³ (positive when closed).
    pub volume_m3: f64,
    /// Shell vertices whose ray was cut at the depth limit instead of meeting the support.
    pub capped_vertices: usize,
}

/// The closed collision proxy of `visual` (which faces out: see
/// [`orient_outward`](crate::orientation::orient_outward)), given the sensor position and the
/// support plane in the mesh's frame when known.
pub fn collision_proxy(
    visual: &TriMesh,
    viewpoint: Option<Vec3>,
    support: Option<SupportPlane>,
    config: &ProxyConfig,
) -> Proxy {
    let faced = orientation(visual);
    if faced.is_closed() || visual.triangles.is_empty() {
        // A closed surface that encloses a negative volume faces in (a small blob whose
        // orientation the mesher got backwards): turned inside out, it is its own proxy.
        let inward = faced.is_closed() && faced.signed_volume_m3 < 0.0;
        let mesh = if inward {
            TriMesh::new(
                visual.vertices.clone(),
                visual
                    .triangles
                    .iter()
                    .map(|&[a, b, c]| [a, c, b])
                    .collect(),
            )
        } else {
            visual.clone()
        };
        return Proxy {
            mesh,
            kind: ProxyKind::Surface,
            closed: faced.is_closed(),
            volume_m3: faced.signed_volume_m3.abs(),
            capped_vertices: 0,
        };
    }
    let support = support.filter(|s| s.normal.is_finite() && s.offset.is_finite());
    let (kind, direction_of): (ProxyKind, Box<dyn Fn(Vec3) -> Vec3>) = match (viewpoint, support) {
        (Some(eye), _) if eye.is_finite() => (
            ProxyKind::ShadowVolume,
            Box::new(move |v: Vec3| (v - eye).normalize_or_zero()),
        ),
        (_, Some(plane)) => (
            ProxyKind::Extrusion,
            Box::new(move |_| -plane.normal.normalize_or_zero()),
        ),
        _ => {
            return Proxy {
                mesh: visual.clone(),
                kind: ProxyKind::OpenShell,
                closed: false,
                volume_m3: faced.signed_volume_m3,
                capped_vertices: 0,
            }
        }
    };

    // Not empty: an empty mesh returned above as its own (closed) proxy.
    let extent = visual
        .bounds()
        .map_or(0.0, |(lo, hi)| (hi - lo).max_element());
    let max_depth = config.max_depth_of_extent * extent;
    let drop_height = config.drop_height_of_extent * extent;
    let mut capped_vertices = 0;
    let swept: Vec<Vec3> = visual
        .vertices
        .iter()
        .map(|&v| {
            if let Some(plane) = support {
                let height = plane.height(v);
                if height < drop_height {
                    return v - plane.normal * height.max(0.0);
                }
            }
            let along = direction_of(v);
            let to_support = support.and_then(|plane| {
                let descent = plane.normal.dot(along);
                // Only a ray heading down meets the support; a vertex under it (noise) stays.
                (descent < -1e-6).then(|| (plane.height(v) / -descent).max(0.0))
            });
            match (to_support, support) {
                (Some(depth), _) if depth <= max_depth => v + along * depth,
                // Cut short of the support: on down to it from there, so that the cap lies on
                // the support whenever there is one (a cap hanging in the air behind the object
                // would cut back through the object's far, low side on its way to the rim).
                (_, Some(plane)) => {
                    capped_vertices += 1;
                    let cut = v + along * max_depth;
                    cut - plane.normal * plane.height(cut).max(0.0)
                }
                (_, None) => {
                    capped_vertices += 1;
                    v + along * max_depth
                }
            }
        })
        .collect();

    let n = visual.vertices.len() as u32;
    let mut mesh = TriMesh {
        vertices: visual.vertices.iter().chain(&swept).copied().collect(),
        triangles: Vec::with_capacity(visual.triangles.len() * 2 + 64),
    };
    mesh.triangles.extend_from_slice(&visual.triangles);
    // The cap faces away from the sensor: the shell's faces, wound the other way.
    mesh.triangles.extend(
        visual
            .triangles
            .iter()
            .map(|&[a, b, c]| [a + n, c + n, b + n]),
    );
    // A wall along each boundary edge a→b (as its one face winds it), facing away from that
    // face: the quad a, a′, b′, b.
    for (a, b) in boundary_edges(visual) {
        mesh.triangles.push([a, a + n, b + n]);
        mesh.triangles.push([a, b + n, b]);
    }
    if config.margin_m > 0.0 && config.margin_m.is_finite() {
        grow(&mut mesh, config.margin_m);
        // The object cannot be under its support: growing must not push the cap into it
        // (a simulation would lift the body by the margin).
        if let Some(plane) = support {
            for v in &mut mesh.vertices {
                let height = plane.height(*v);
                if height < 0.0 {
                    *v -= plane.normal * height;
                }
            }
        }
    }
    let closed = orientation(&mesh).is_closed();
    let volume_m3 = signed_volume_m3(&mesh);
    Proxy {
        mesh,
        kind,
        closed,
        volume_m3,
        capped_vertices,
    }
}

/// Moves every vertex `margin_m` along its outward normal (the area-weighted mean of its
/// faces' normals): a closed surface grows by about the margin, and a vertex on a crease or
/// corner moves along the mean of its faces, so the faces there move a little less.
fn grow(mesh: &mut TriMesh, margin_m: f32) {
    let mut normals = vec![Vec3::ZERO; mesh.vertices.len()];
    for &[a, b, c] in &mesh.triangles {
        let [pa, pb, pc] = [a, b, c].map(|i| mesh.vertices[i as usize]);
        let area_normal = (pb - pa).cross(pc - pa);
        for i in [a, b, c] {
            normals[i as usize] += area_normal;
        }
    }
    for (v, n) in mesh.vertices.iter_mut().zip(normals) {
        *v += n.normalize_or_zero() * margin_m;
    }
}

/// The edges one face uses, directed as that face winds them.
fn boundary_edges(mesh: &TriMesh) -> Vec<(u32, u32)> {
    let mut uses: HashMap<(u32, u32), (u32, (u32, u32))> = HashMap::new();
    for &[a, b, c] in &mesh.triangles {
        for (u, v) in [(a, b), (b, c), (c, a)] {
            uses.entry((u.min(v), u.max(v))).or_insert((0, (u, v))).0 += 1;
        }
    }
    let mut edges: Vec<(u32, u32)> = uses
        .into_values()
        .filter(|&(count, _)| count == 1)
        .map(|(_, edge)| edge)
        .collect();
    edges.sort_unstable();
    edges
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::orientation::orient_outward;

    /// A grid of `n`×`n` quads over the unit square at height `z`, facing +z.
    fn square(n: u32, z: f32) -> TriMesh {
        let vertices = (0..=n)
            .flat_map(|j| {
                (0..=n).map(move |i| Vec3::new(i as f32 / n as f32, j as f32 / n as f32, z))
            })
            .collect();
        let at = |i: u32, j: u32| j * (n + 1) + i;
        let triangles = (0..n)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .flat_map(|(i, j)| {
                [
                    [at(i, j), at(i + 1, j), at(i + 1, j + 1)],
                    [at(i, j), at(i + 1, j + 1), at(i, j + 1)],
                ]
            })
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    const TABLE: SupportPlane = SupportPlane {
        normal: Vec3::Z,
        offset: 0.0,
    };

    #[test]
    fn a_closed_surface_facing_in_is_turned_out() {
        let cube = tacmesh_sim::cube(0.1);
        let inward = TriMesh::new(
            cube.vertices.clone(),
            cube.triangles.iter().map(|&[a, b, c]| [a, c, b]).collect(),
        );
        let proxy = collision_proxy(&inward, None, Some(TABLE), &ProxyConfig::default());
        assert_eq!(proxy.kind, ProxyKind::Surface);
        assert!(proxy.closed);
        assert!(
            (proxy.volume_m3 - 0.001).abs() < 1e-6,
            "{}",
            proxy.volume_m3
        );
        let mass = crate::mass::MassProperties::of_closed_mesh(&proxy.mesh).expect("outward");
        assert!((mass.volume_m3 - 0.001).abs() < 1e-6);
    }

    #[test]
    fn a_top_seen_from_straight_above_closes_into_its_box() {
        // The top of a unit cube standing on the table, the camera far above its centre: the
        // rays are nearly vertical, and the shadow is nearly the cube.
        let top = square(4, 1.0);
        let proxy = collision_proxy(
            &top,
            Some(Vec3::new(0.5, 0.5, 1000.0)),
            Some(TABLE),
            &ProxyConfig::default(),
        );
        assert_eq!(proxy.kind, ProxyKind::ShadowVolume);
        assert!(proxy.closed);
        assert!((proxy.volume_m3 - 1.0).abs() < 0.01, "{}", proxy.volume_m3);
        assert_eq!(proxy.capped_vertices, 0);
    }

    #[test]
    fn an_oblique_view_casts_the_shadow_the_camera_cannot_see_into() {
        // The top and the near side of a unit cube, seen from 45° above its +x side: the
        // shadow holds the cube and the wedge of table behind it (a prism of volume ½, from
        // the top's far edge down to the table one unit farther away).
        let mut shell = square(4, 1.0);
        let side = square(4, 0.0);
        let base = shell.vertices.len() as u32;
        // The side x = 1, facing +x: (u, v) ↦ (1, u, v) is wound to face +x.
        shell
            .vertices
            .extend(side.vertices.iter().map(|v| Vec3::new(1.0, v.x, v.y)));
        shell
            .triangles
            .extend(side.triangles.iter().map(|t| t.map(|i| i + base)));
        // Far away along (1, 0, 1): the rays are parallel.
        let eye = Vec3::new(0.5, 0.5, 0.5) + Vec3::new(1.0, 0.0, 1.0) * 1e4;
        orient_outward(&mut shell, Some(eye));
        let proxy = collision_proxy(&shell, Some(eye), Some(TABLE), &ProxyConfig::default());
        assert!(proxy.closed, "{proxy:?}");
        assert!((proxy.volume_m3 - 1.5).abs() < 0.02, "{}", proxy.volume_m3);
    }

    #[test]
    fn rays_that_miss_the_support_are_cut_at_the_depth_limit() {
        let top = square(2, 1.0);
        let proxy = collision_proxy(
            &top,
            Some(Vec3::new(0.5, 0.5, 1000.0)),
            None,
            &ProxyConfig {
                max_depth_of_extent: 0.5,
                ..ProxyConfig::default()
            },
        );
        assert!(proxy.closed);
        assert_eq!(proxy.capped_vertices, top.vertices.len());
        assert!((proxy.volume_m3 - 0.5).abs() < 0.01, "{}", proxy.volume_m3);
    }

    #[test]
    fn without_a_viewpoint_the_shell_is_extruded_down_and_without_anything_left_open() {
        let top = square(2, 0.3);
        let extruded = collision_proxy(&top, None, Some(TABLE), &ProxyConfig::default());
        assert_eq!(extruded.kind, ProxyKind::Extrusion);
        assert!((extruded.volume_m3 - 0.3).abs() < 1e-4);
        let open = collision_proxy(&top, None, None, &ProxyConfig::default());
        assert_eq!(open.kind, ProxyKind::OpenShell);
        assert!(!open.closed);
    }

    #[test]
    fn a_closed_mesh_is_its_own_proxy() {
        let eye = Vec3::new(0.5, 0.5, 1000.0);
        let closed = collision_proxy(&square(2, 1.0), Some(eye), Some(TABLE), &Default::default());
        let again = collision_proxy(&closed.mesh, Some(eye), Some(TABLE), &Default::default());
        assert_eq!(again.kind, ProxyKind::Surface);
        assert_eq!(again.mesh, closed.mesh);
        assert!(again.closed);
    }

    #[test]
    fn a_margin_grows_the_proxy_all_round() {
        let eye = Vec3::new(0.5, 0.5, 1000.0);
        let config = ProxyConfig {
            margin_m: 0.01,
            ..ProxyConfig::default()
        };
        let grown = collision_proxy(&square(4, 1.0), Some(eye), Some(TABLE), &config);
        assert!(grown.closed);
        // A unit cube grown by 1 cm on its sides and top but not under the table (less at
        // its corners and edges, where the vertices move along the mean normal): between 1
        // and 1.02² · 1.01.
        assert!(
            (1.0..1.0507).contains(&grown.volume_m3),
            "{}",
            grown.volume_m3
        );
        assert!(grown.volume_m3 > 1.03, "{}", grown.volume_m3);
        let lowest = grown
            .mesh
            .vertices
            .iter()
            .map(|v| v.z)
            .fold(f32::INFINITY, f32::min);
        assert!(lowest >= 0.0, "{lowest}");
    }
}
