//! Binary STL, the mesh file every physics engine's loader reads (MuJoCo, Bullet, Gazebo).
//!
//! Layout: an 80-byte header, a little-endian u32 triangle count, then per triangle its unit
//! normal, its three corners (twelve little-endian f32) and a zero u16.
//!
//! Entry point: [`write_binary_stl`].

use std::io::{self, Write};

use tacmesh_source::TriMesh;

/// Writes `mesh` as binary STL (metres, as given). Triangles whose normal is undefined get a
/// zero normal, which readers recompute from the corners.
pub fn write_binary_stl<W: Write>(out: &mut W, mesh: &TriMesh) -> io::Result<()> {
    let mut header = [0u8; 80];
    let label = b"tacmesh binary STL, metres";
    header[..label.len()].copy_from_slice(label);
    out.write_all(&header)?;
    let count = u32::try_from(mesh.triangles.len())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "more than 2^32 triangles"))?;
    out.write_all(&count.to_le_bytes())?;
    let mut record = Vec::with_capacity(50);
    for t in 0..mesh.triangles.len() {
        let [a, b, c] = mesh.corners(t);
        let normal = (b - a).cross(c - a).normalize_or_zero();
        record.clear();
        for v in [normal, a, b, c] {
            for x in v.to_array() {
                record.extend_from_slice(&x.to_le_bytes());
            }
        }
        record.extend_from_slice(&0u16.to_le_bytes());
        out.write_all(&record)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn stl_of_one_triangle_is_134_bytes() {
        let mesh = TriMesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
        let mut bytes = Vec::new();
        write_binary_stl(&mut bytes, &mesh).unwrap();
        assert_eq!(bytes.len(), 80 + 4 + 50);
        assert_eq!(&bytes[80..84], &1u32.to_le_bytes());
        // The normal is +Z for a counter-clockwise triangle in the XY plane.
        assert_eq!(&bytes[92..96], &1.0f32.to_le_bytes());
        // The second corner is (1, 0, 0).
        assert_eq!(&bytes[108..112], &1.0f32.to_le_bytes());
    }
}
