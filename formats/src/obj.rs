//! Wavefront OBJ, the geometry part: `v x y z` vertices and `f a b c ...` faces (1-based, or
//! negative for relative to the last vertex; `a/t/n` corners use only `a`), polygons
//! fan-triangulated. Texture coordinates, normals, groups, materials and lines are ignored.
//!
//! Entry points: [`parse`] (bytes to a mesh) and [`write()`].
//!
//! This is a small reader of its own rather than `tobj` 4.0.5, which (a) renumbers vertices in
//! order of first use and drops unreferenced ones, so a written mesh does not read back the
//! same, (b) gives each `o`/`g` group its own copy of shared vertices, opening seams in a
//! closed mesh, and (c) overflows (a panic in debug builds) on a negative texture or normal
//! index reaching before the first one, e.g. `f 1/-3 2/-3 3/-3` after one `vt`.
//!
//! The format has no counts, so a file cut at a line boundary reads as a smaller mesh; a cut
//! that leaves a vertex short of 3 numbers, or a face pointing past the vertices, is an error.

use std::io::{self, Write};

use glam::Vec3;
use tacmesh_source::TriMesh;

use crate::FormatError;

/// Parses OBJ text held in memory: vertices in file order, each face of n corners as the
/// n - 2 triangles of a fan from its first corner. `name` is used in error messages.
pub fn parse(bytes: &[u8], name: &str) -> Result<TriMesh, FormatError> {
    let mut vertices = Vec::new();
    let mut triangles = Vec::new();
    // Corner indices (0-based, unchecked) and the line each face came from.
    let mut corners: Vec<i64> = Vec::new();
    let mut face_lines: Vec<(usize, usize)> = Vec::new();
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_number = i + 1;
        let bad =
            |what: String| FormatError::malformed(name, format!("line {line_number}: {what}"));
        let mut words = line
            .split(|b| b.is_ascii_whitespace())
            .filter(|w| !w.is_empty());
        match words.next() {
            Some(b"v") => {
                let mut xyz = [0.0f32; 3];
                for c in &mut xyz {
                    let word = words
                        .next()
                        .ok_or_else(|| bad("a vertex needs 3 coordinates".into()))?;
                    *c = std::str::from_utf8(word)
                        .ok()
                        .and_then(|w| w.parse().ok())
                        .ok_or_else(|| {
                            bad(format!(
                                "{:?} is not a number",
                                String::from_utf8_lossy(word)
                            ))
                        })?;
                }
                vertices.push(Vec3::from(xyz));
            }
            Some(b"f") => {
                let start = corners.len();
                for word in words {
                    let index = word.split(|&b| b == b'/').next().unwrap_or_default();
                    let index: i64 = std::str::from_utf8(index)
                        .ok()
                        .and_then(|w| w.parse().ok())
                        .filter(|&i| i != 0)
                        .ok_or_else(|| {
                            bad(format!(
                                "{:?} is not a vertex reference",
                                String::from_utf8_lossy(word)
                            ))
                        })?;
                    // Negative indices count back from the vertices read so far.
                    corners.push(if index < 0 {
                        vertices.len() as i64 + index
                    } else {
                        index - 1
                    });
                }
                let count = corners.len() - start;
                if count < 3 {
                    return Err(bad(format!(
                        "a face has {count} corners; it needs at least 3"
                    )));
                }
                face_lines.push((line_number, start));
            }
            _ => {}
        }
    }

    // Faces may refer to vertices defined after them, so indices are checked at the end.
    let vertex_count = vertices.len();
    for (f, &(line_number, start)) in face_lines.iter().enumerate() {
        let end = face_lines.get(f + 1).map_or(corners.len(), |&(_, s)| s);
        let mut face = Vec::with_capacity(end - start);
        for &corner in &corners[start..end] {
            match u32::try_from(corner) {
                Ok(i) if (i as usize) < vertex_count => face.push(i),
                _ => {
                    return Err(FormatError::malformed(
                        name,
                        format!(
                            "line {line_number}: face refers to vertex {} but there are \
                             {vertex_count} vertices",
                            corner + 1
                        ),
                    ))
                }
            }
        }
        triangles.extend(face[1..].windows(2).map(|w| [face[0], w[0], w[1]]));
    }
    Ok(TriMesh::new(vertices, triangles))
}

/// Writes `v x y z` lines, then `f a b c` lines (1-based), each number in the shortest form
/// that reads back to the same `f32`.
pub fn write<W: Write>(out: &mut W, mesh: &TriMesh) -> io::Result<()> {
    for v in &mesh.vertices {
        writeln!(out, "v {} {} {}", v.x, v.y, v.z)?;
    }
    for [a, b, c] in &mesh.triangles {
        writeln!(out, "f {} {} {}", a + 1, b + 1, c + 1)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slashed_and_relative_corners_are_resolved() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
            f 1/1/1 2/1/1 3//1 4\nf -4 -2 -1\n";
        let mesh = parse(text.as_bytes(), "q.obj").unwrap();
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3], [0, 2, 3]]);
    }

    #[test]
    fn groups_share_vertices() {
        let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\no a\nf 1 2 3\no b\nf 1 3 4\n";
        let mesh = parse(text.as_bytes(), "g.obj").unwrap();
        assert_eq!(mesh.vertices.len(), 4);
        assert_eq!(mesh.triangles, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn face_past_the_vertices_is_rejected() {
        let err = parse(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "x.obj")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "x.obj: line 4: face refers to vertex 9 but there are 3 vertices"
        );
    }

    #[test]
    fn relative_index_before_the_first_vertex_is_rejected() {
        let err = parse(b"v 0 0 0\nf 1 -2 1\n", "r.obj")
            .unwrap_err()
            .to_string();
        assert!(err.contains("face refers to vertex 0"), "{err}");
    }

    #[test]
    fn short_vertex_is_rejected() {
        let err = parse(b"v 0 0\n", "s.obj").unwrap_err().to_string();
        assert_eq!(err, "s.obj: line 1: a vertex needs 3 coordinates");
    }
}
