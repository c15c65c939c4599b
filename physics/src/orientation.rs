//! Which way a mesh faces, and making it face out.
//!
//! A physics engine takes a closed mesh's volume, centre of mass and inertia from its signed
//! tetrahedra: an inside-out mesh gives it a negative mass. An open shell (one side of an
//! object, as one camera sees it) has no inside, but its faces must face the side the sensor
//! saw, where a probe comes from.
//!
//! [`orient_outward`] decides each connected piece's side on its own: a closed piece by the
//! sign of its volume, an open one by the side its sensor was on, and an open one with no
//! sensor position by the sign of the volume it nearly encloses (a surface with small holes).
//! It only flips whole pieces: the reconstruction winds each piece consistently, and a piece
//! whose winding is not consistent is counted, not repaired.

use rustc_hash::FxHashMap;

use glam::{DVec3, Vec3};
use tacmesh_source::TriMesh;

/// How the faces of a mesh sit with respect to each other and to the outside.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Orientation {
    /// Connected pieces (faces sharing vertices).
    pub pieces: usize,
    /// Edges used by one face only (the rims of holes and of open shells).
    pub boundary_edges: usize,
    /// Edges more faces use in one direction than in the other: the faces disagree on which
    /// side is out (two faces using an edge the same way), or a rim meets a surface.
    pub inconsistent_edges: usize,
    /// Edges four or more faces use, as many each way: consistent, but where two sheets of
    /// the surface touch (a pinched rim of an open shell becomes one when it is closed).
    pub nonmanifold_edges: usize,
    /// Signed volume, m³: positive when a closed mesh faces out.
    pub signed_volume_m3: f64,
}

impl Orientation {
    /// Closed and consistently wound (each edge used as often in one direction as in the
    /// other: a closed oriented surface, whose volume an engine can take).
    pub fn is_closed(&self) -> bool {
        self.boundary_edges == 0 && self.inconsistent_edges == 0
    }
}

/// Signed volume of the mesh, m³ (the sum of the tetrahedra from its centroid to each face;
/// exact for a closed mesh, whatever the origin).
pub fn signed_volume_m3(mesh: &TriMesh) -> f64 {
    signed_volume_of(mesh, 0..mesh.triangles.len())
}

/// The volume of the faces `faces`, about their own vertex centroid (so that an open piece's
/// value does not depend on where the origin is).
fn signed_volume_of(mesh: &TriMesh, faces: impl Iterator<Item = usize> + Clone) -> f64 {
    let (sum, count) = faces
        .clone()
        .flat_map(|f| mesh.triangles[f])
        .fold((DVec3::ZERO, 0usize), |(s, n), i| {
            (s + mesh.vertices[i as usize].as_dvec3(), n + 1)
        });
    if count == 0 {
        return 0.0;
    }
    let centre = sum / count as f64;
    faces
        .map(|f| {
            let [a, b, c] = corners(mesh, f).map(|p| p - centre);
            a.dot(b.cross(c))
        })
        .sum::<f64>()
        / 6.0
}

fn corners(mesh: &TriMesh, face: usize) -> [DVec3; 3] {
    mesh.triangles[face].map(|i| mesh.vertices[i as usize].as_dvec3())
}

/// Twice the area times the unit normal of a face (counter-clockwise seen from its front).
fn area_normal(mesh: &TriMesh, face: usize) -> DVec3 {
    let [a, b, c] = corners(mesh, face);
    (b - a).cross(c - a)
}

/// How much the mesh faces `viewpoint`: the area-weighted mean over its faces of the cosine
/// between a face's normal and the direction from the face to the viewpoint; 1 when every face
/// looks straight at it, −1 when every face turns its back.
pub fn view_facing(mesh: &TriMesh, viewpoint: Vec3) -> f64 {
    view_facing_of(mesh, 0..mesh.triangles.len(), viewpoint)
}

fn view_facing_of(mesh: &TriMesh, faces: impl Iterator<Item = usize>, viewpoint: Vec3) -> f64 {
    let eye = viewpoint.as_dvec3();
    let (mut facing, mut area) = (0.0, 0.0);
    for f in faces {
        let normal = area_normal(mesh, f);
        let [a, b, c] = corners(mesh, f);
        let towards = (eye - (a + b + c) / 3.0).normalize_or_zero();
        facing += normal.dot(towards);
        area += normal.length();
    }
    if area > 0.0 {
        facing / area
    } else {
        0.0
    }
}

/// Per undirected edge: how many faces use it in each direction (lower index first or not).
/// Keyed with the Fx hash: the pipeline orients every marching-cubes mesh (thousands of
/// faces) before simplifying it, and with the standard library's SipHash the map's six look-ups
/// a face were 1.3 % of meshing a 1 m cube on one core. The keys are vertex indices of the
/// mesh, which the result does not depend on the order of.
fn edge_uses(mesh: &TriMesh) -> FxHashMap<(u32, u32), [u32; 2]> {
    let mut uses: FxHashMap<(u32, u32), [u32; 2]> = FxHashMap::default();
    uses.reserve(mesh.triangles.len() * 2);
    for &[a, b, c] in &mesh.triangles {
        for (u, v) in [(a, b), (b, c), (c, a)] {
            let entry = uses.entry((u.min(v), u.max(v))).or_default();
            entry[usize::from(u > v)] += 1;
        }
    }
    uses
}

/// Boundary and inconsistent edges, and the signed volume.
pub fn orientation(mesh: &TriMesh) -> Orientation {
    let mut boundary_edges = 0;
    let mut inconsistent_edges = 0;
    let mut nonmanifold_edges = 0;
    for [forward, backward] in edge_uses(mesh).into_values() {
        match (forward, backward) {
            (1, 1) => {}
            (1, 0) | (0, 1) => boundary_edges += 1,
            (f, b) if f == b => nonmanifold_edges += 1,
            _ => inconsistent_edges += 1,
        }
    }
    Orientation {
        pieces: mesh.face_pieces().1,
        boundary_edges,
        inconsistent_edges,
        nonmanifold_edges,
        signed_volume_m3: signed_volume_m3(mesh),
    }
}

/// What [`orient_outward`] found and did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct OrientOutcome {
    pub pieces: usize,
    /// Pieces turned inside out (their faces' windings reversed).
    pub pieces_flipped: usize,
    /// Pieces with a boundary (open shells, or surfaces with holes).
    pub open_pieces: usize,
}

/// Makes every connected piece face out: a closed piece so that its volume is positive; an
/// open piece so that it faces `viewpoint` (area-weighted) when one is given, and otherwise so
/// that the volume it nearly encloses is positive.
pub fn orient_outward(mesh: &mut TriMesh, viewpoint: Option<Vec3>) -> OrientOutcome {
    let (piece_of_face, count) = mesh.face_pieces();
    let mut faces_of: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (f, &p) in piece_of_face.iter().enumerate() {
        faces_of[p as usize].push(f);
    }
    let uses = edge_uses(mesh);
    let mut open = vec![false; count];
    for (f, &[a, b, c]) in mesh.triangles.iter().enumerate() {
        let rim = [(a, b), (b, c), (c, a)]
            .into_iter()
            .any(|(u, v)| uses[&(u.min(v), u.max(v))].iter().sum::<u32>() == 1);
        open[piece_of_face[f] as usize] |= rim;
    }
    let mut outcome = OrientOutcome {
        pieces: count,
        ..Default::default()
    };
    for (piece, faces) in faces_of.iter().enumerate() {
        let outward = match (open[piece], viewpoint) {
            (true, Some(eye)) => view_facing_of(mesh, faces.iter().copied(), eye) >= 0.0,
            _ => signed_volume_of(mesh, faces.iter().copied()) >= 0.0,
        };
        outcome.open_pieces += usize::from(open[piece]);
        if !outward {
            outcome.pieces_flipped += 1;
            for &f in faces {
                mesh.triangles[f].swap(1, 2);
            }
        }
    }
    outcome
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The unit cube [0,1]³, faces counter-clockwise seen from outside.
    fn cube() -> TriMesh {
        let vertices = (0..8)
            .map(|i| Vec3::new((i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32))
            .collect();
        let quads = [
            [0, 2, 3, 1], // z = 0, facing −z
            [4, 5, 7, 6], // z = 1
            [0, 1, 5, 4], // y = 0
            [2, 6, 7, 3], // y = 1
            [0, 4, 6, 2], // x = 0
            [1, 3, 7, 5], // x = 1
        ];
        let triangles = quads
            .iter()
            .flat_map(|&[a, b, c, d]| [[a, b, c], [a, c, d]])
            .collect();
        TriMesh {
            vertices,
            triangles,
        }
    }

    fn flipped(mut mesh: TriMesh) -> TriMesh {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
        mesh
    }

    #[test]
    fn a_closed_cube_has_its_volume_and_no_rim() {
        let o = orientation(&cube());
        assert!(o.is_closed(), "{o:?}");
        assert!((o.signed_volume_m3 - 1.0).abs() < 1e-9, "{o:?}");
        assert_eq!(o.pieces, 1);
        assert!((orientation(&flipped(cube())).signed_volume_m3 + 1.0).abs() < 1e-9);
    }

    #[test]
    fn an_inside_out_piece_is_turned_and_a_right_one_kept() {
        let mut two = cube();
        let far = flipped(cube());
        let base = two.vertices.len() as u32;
        two.vertices
            .extend(far.vertices.iter().map(|v| *v + Vec3::X * 3.0));
        two.triangles
            .extend(far.triangles.iter().map(|t| t.map(|i| i + base)));
        let outcome = orient_outward(&mut two, None);
        assert_eq!(outcome.pieces, 2);
        assert_eq!(outcome.pieces_flipped, 1);
        assert!((signed_volume_m3(&two) - 2.0).abs() < 1e-9);
    }

    #[test]
    fn an_open_shell_faces_its_viewpoint() {
        // The cube without its top: seen from above, its inside faces the viewer.
        let mut shell = cube();
        shell.triangles.drain(2..4);
        let eye = Vec3::new(0.5, 0.5, 5.0);
        let o = orientation(&shell);
        assert_eq!(o.boundary_edges, 4);
        assert!(view_facing(&shell, eye) < 0.0);
        let outcome = orient_outward(&mut shell, Some(eye));
        assert_eq!((outcome.pieces_flipped, outcome.open_pieces), (1, 1));
        assert!(view_facing(&shell, eye) > 0.0);

        // A shell as a camera sees a box: its near faces, already facing it.
        let mut near = cube();
        near.triangles.retain(|t| {
            let n = area_normal(
                &cube(),
                cube().triangles.iter().position(|u| u == t).unwrap(),
            );
            n.z > 0.0 || n.x > 0.0
        });
        let eye = Vec3::new(4.0, 0.5, 4.0);
        assert_eq!(orient_outward(&mut near, Some(eye)).pieces_flipped, 0);
    }

    #[test]
    fn inconsistent_winding_is_counted() {
        let mut mesh = cube();
        mesh.triangles[0].swap(1, 2);
        let o = orientation(&mesh);
        assert_eq!(o.boundary_edges, 0);
        assert_eq!(o.inconsistent_edges, 3);
        assert!(!o.is_closed());
    }

    #[test]
    fn an_empty_mesh_has_nothing_to_turn() {
        let mut empty = TriMesh::default();
        assert_eq!(orient_outward(&mut empty, None), OrientOutcome::default());
        assert_eq!(orientation(&empty).signed_volume_m3, 0.0);
    }
}
