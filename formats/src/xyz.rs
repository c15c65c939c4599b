//! XYZ text: one point per line, `x y z` or `x y z nx ny nz`, numbers separated by whitespace
//! or commas; `#` starts a comment and blank lines are skipped. Also read from `.txt` and
//! `.pts`.
//!
//! Entry points: [`parse`] (bytes to a cloud) and [`write()`].
//!
//! The format has no point count, so a file cut at a line boundary reads as a shorter cloud;
//! a cut inside a line leaves fewer than 3 numbers there and is an error.

use std::io::{self, Write};

use glam::Vec3;
use tacmesh_source::PointCloud;

use crate::FormatError;

/// Parses XYZ text held in memory, non-finite points included. Every line must have the same
/// number of columns, 3 or 6. `name` is used in error messages.
pub fn parse(bytes: &[u8], name: &str) -> Result<PointCloud, FormatError> {
    let mut points = Vec::new();
    let mut normals = Vec::new();
    // The column count of the first data line and its line number.
    let mut columns: Option<(usize, usize)> = None;
    let mut numbers = Vec::with_capacity(6);
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line_number = i + 1;
        let bad =
            |what: String| FormatError::malformed(name, format!("line {line_number}: {what}"));
        let text = std::str::from_utf8(line).map_err(|_| bad("not text".into()))?;
        let text = text.split('#').next().unwrap_or_default();
        numbers.clear();
        for token in text
            .split(|c: char| c.is_whitespace() || c == ',')
            .filter(|t| !t.is_empty())
        {
            let value: f32 = token
                .parse()
                .map_err(|_| bad(format!("{token:?} is not a number")))?;
            numbers.push(value);
        }
        if numbers.is_empty() {
            continue;
        }
        if numbers.len() != 3 && numbers.len() != 6 {
            return Err(bad(format!(
                "has {} numbers; expected 3 (x y z) or 6 (x y z nx ny nz)",
                numbers.len()
            )));
        }
        match columns {
            None => columns = Some((numbers.len(), line_number)),
            Some((first, first_line)) if first != numbers.len() => {
                return Err(bad(format!(
                    "has {} numbers but line {first_line} had {first}",
                    numbers.len()
                )));
            }
            Some(_) => {}
        }
        points.push(Vec3::new(numbers[0], numbers[1], numbers[2]));
        if numbers.len() == 6 {
            normals.push(Vec3::new(numbers[3], numbers[4], numbers[5]));
        }
    }
    Ok(match columns {
        Some((6, _)) => PointCloud::with_normals(points, normals),
        _ => PointCloud::new(points),
    })
}

/// Writes one point per line, `x y z` or `x y z nx ny nz` when the cloud has normals, each
/// number in the shortest form that reads back to the same `f32`.
pub fn write<W: Write>(out: &mut W, cloud: &PointCloud) -> io::Result<()> {
    match &cloud.normals {
        Some(normals) => {
            for (p, n) in cloud.points.iter().zip(normals) {
                writeln!(out, "{} {} {} {} {} {}", p.x, p.y, p.z, n.x, n.y, n.z)?;
            }
        }
        None => {
            for p in &cloud.points {
                writeln!(out, "{} {} {}", p.x, p.y, p.z)?;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn comments_commas_and_blank_lines_are_accepted() {
        let text = "# scan\n\n1,2,3\n 4 5 6 # trailing\r\n7, 8, 9\n";
        let cloud = parse(text.as_bytes(), "a.xyz").unwrap();
        assert_eq!(cloud.points.len(), 3);
        assert_eq!(cloud.points[2], Vec3::new(7.0, 8.0, 9.0));
        assert_eq!(cloud.normals, None);
    }

    #[test]
    fn six_columns_carry_normals() {
        let cloud = parse(b"0 0 0 0 0 1\n1 0 0 0 1 0\n", "n.xyz").unwrap();
        assert_eq!(cloud.normals, Some(vec![Vec3::Z, Vec3::Y]));
    }

    #[test]
    fn line_with_two_numbers_is_rejected_with_its_number() {
        let err = parse(b"1 2 3\n# c\n4 5\n", "bad.xyz")
            .unwrap_err()
            .to_string();
        assert_eq!(
            err,
            "bad.xyz: line 3: has 2 numbers; expected 3 (x y z) or 6 (x y z nx ny nz)"
        );
    }

    #[test]
    fn mixed_column_counts_are_rejected() {
        let err = parse(b"1 2 3\n1 2 3 0 0 1\n", "m.xyz")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("line 2: has 6 numbers but line 1 had 3"),
            "{err}"
        );
    }

    #[test]
    fn word_is_rejected() {
        let err = parse(b"1 2 three\n", "w.xyz").unwrap_err().to_string();
        assert!(err.contains("line 1: \"three\" is not a number"), "{err}");
    }
}
