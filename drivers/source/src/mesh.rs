use glam::Vec3;

use crate::cloud::bounds_of;

/// An indexed triangle mesh, vertices in metres, triangles counter-clockwise seen from outside.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    pub vertices: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
}

impl TriMesh {
    pub fn new(vertices: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Self {
        Self {
            vertices,
            triangles,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The meshes as one: their vertices one after another, each mesh's triangles renumbered
    /// to its own (a union of convex hulls, as an engine collides them, for a probe).
    pub fn concatenated<'a>(meshes: impl IntoIterator<Item = &'a TriMesh>) -> TriMesh {
        let mut all = TriMesh::default();
        for mesh in meshes {
            let base = all.vertices.len() as u32;
            all.vertices.extend(&mesh.vertices);
            all.triangles
                .extend(mesh.triangles.iter().map(|t| t.map(|i| i + base)));
        }
        all
    }

    /// Axis-aligned bounds `(min, max)` of the vertices, or `None` for an empty mesh.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        bounds_of(&self.vertices)
    }

    /// The three corner positions of triangle `t`.
    pub fn corners(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.vertices[a as usize],
            self.vertices[b as usize],
            self.vertices[c as usize],
        ]
    }

    /// Total surface area in square metres.
    pub fn area(&self) -> f32 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.corners(t);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }

    /// The connected piece of each face (faces sharing a vertex are in one piece), numbered
    /// 0.. in the order of each piece's first face, and the number of pieces. A union-find
    /// over the vertices, with path halving.
    pub fn face_pieces(&self) -> (Vec<u32>, usize) {
        let mut parent: Vec<u32> = (0..self.vertices.len() as u32).collect();
        fn find(parent: &mut [u32], mut x: u32) -> u32 {
            while parent[x as usize] != x {
                parent[x as usize] = parent[parent[x as usize] as usize];
                x = parent[x as usize];
            }
            x
        }
        for &[a, b, c] in &self.triangles {
            for (u, v) in [(a, b), (b, c)] {
                let (ru, rv) = (find(&mut parent, u), find(&mut parent, v));
                if ru != rv {
                    parent[ru.max(rv) as usize] = ru.min(rv);
                }
            }
        }
        let mut piece_of_root = vec![u32::MAX; self.vertices.len()];
        let mut pieces = 0u32;
        let piece_of_face = self
            .triangles
            .iter()
            .map(|t| {
                let root = find(&mut parent, t[0]) as usize;
                if piece_of_root[root] == u32::MAX {
                    piece_of_root[root] = pieces;
                    pieces += 1;
                }
                piece_of_root[root]
            })
            .collect();
        (piece_of_face, pieces as usize)
    }

    /// How many faces use each undirected edge, one count per edge (in no meaningful order).
    fn edge_uses(&self) -> Vec<usize> {
        let mut edges: Vec<u64> = self
            .triangles
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .map(|(u, v)| u64::from(u.min(v)) << 32 | u64::from(u.max(v)))
            .collect();
        edges.sort_unstable();
        edges.chunk_by(|x, y| x == y).map(<[u64]>::len).collect()
    }

    /// Whether the mesh has faces and every edge is shared by exactly two of them.
    pub fn is_closed(&self) -> bool {
        !self.triangles.is_empty() && self.edge_uses().iter().all(|&n| n == 2)
    }

    /// Whether some edge is used by one face only: a hole or a rim.
    pub fn has_open_edge(&self) -> bool {
        self.edge_uses().contains(&1)
    }

    /// The first triangle whose index points past the vertex list, if any.
    pub fn first_bad_index(&self) -> Option<(usize, u32)> {
        let n = self.vertices.len() as u32;
        self.triangles
            .iter()
            .enumerate()
            .find_map(|(t, tri)| tri.iter().find(|&&i| i >= n).map(|&i| (t, i)))
    }

    /// Scales and translates the mesh in place: `p ↦ p * scale + offset`.
    pub fn transform(&mut self, scale: f32, offset: Vec3) {
        for v in &mut self.vertices {
            *v = *v * scale + offset;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_right_triangle_has_half_area() {
        let mesh = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        assert!((mesh.area() - 0.5).abs() < 1e-6);
    }

    #[test]
    fn a_closed_mesh_is_told_from_an_open_one() {
        let tetrahedron = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z],
            vec![[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]],
        );
        assert!(tetrahedron.is_closed() && !tetrahedron.has_open_edge());
        let open = TriMesh::new(
            tetrahedron.vertices.clone(),
            tetrahedron.triangles[..3].to_vec(),
        );
        assert!(!open.is_closed() && open.has_open_edge());
        // An edge of four faces (two tetrahedra on one edge) is neither open nor closed.
        let mut bowtie = tetrahedron.clone();
        bowtie
            .vertices
            .extend([Vec3::new(0.0, 0.0, -1.0), Vec3::new(1.0, 1.0, -1.0)]);
        bowtie.triangles.extend([[0, 4, 1], [0, 5, 4]]);
        bowtie.triangles.extend([[1, 4, 5], [0, 1, 5]]);
        assert!(!bowtie.is_closed() && !bowtie.has_open_edge());
        assert!(!TriMesh::default().is_closed() && !TriMesh::default().has_open_edge());
    }

    #[test]
    fn first_bad_index_finds_out_of_range_corner() {
        let mesh = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            vec![[0, 1, 2], [0, 3, 1]],
        );
        assert_eq!(mesh.first_bad_index(), Some((1, 3)));
    }

    #[test]
    fn faces_sharing_a_vertex_are_one_piece() {
        // Two triangles sharing vertex 2, and one apart (listed between them).
        let vertices = (0..8)
            .map(|i| Vec3::new(i as f32, (i % 2) as f32, 0.0))
            .collect();
        let mesh = TriMesh::new(vertices, vec![[0, 1, 2], [5, 6, 7], [2, 3, 4]]);
        assert_eq!(mesh.face_pieces(), (vec![0, 1, 0], 2));
        assert_eq!(TriMesh::default().face_pieces(), (vec![], 0));
    }
}
