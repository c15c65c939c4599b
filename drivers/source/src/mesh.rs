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
    fn first_bad_index_finds_out_of_range_corner() {
        let mesh = TriMesh::new(
            vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            vec![[0, 1, 2], [0, 3, 1]],
        );
        assert_eq!(mesh.first_bad_index(), Some((1, 3)));
    }
}
