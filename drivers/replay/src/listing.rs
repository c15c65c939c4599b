//! Which files a replay plays, in which order, with which timestamps and poses.
//!
//! Entry points:
//! - [`list_depth_images`] / [`list_clouds`]: a directory's depth images or clouds, by name.
//! - [`read_association_file`]: a TUM-style `depth.txt` ("timestamp filename" per line).
//! - [`read_pose_file`]: a slambook-style `pose.txt` ("tx ty tz qx qy qz qw" per line).

use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3};

use crate::decode::{extension, is_depth_image_path};
use crate::ReplayError;

/// One depth image of a sequence, with its recorded time when known.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthFile {
    pub path: PathBuf,
    /// Seconds on the recording's clock (TUM: Unix time).
    pub timestamp_s: Option<f64>,
}

impl DepthFile {
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            timestamp_s: None,
        }
    }
}

/// Whether a path has the extension of a cloud format `tacmesh_formats::read_cloud` reads.
/// (`.txt` is left out: in a directory it is more often an association or pose file.)
pub fn is_cloud_path(path: &Path) -> bool {
    matches!(extension(path).as_str(), "ply" | "pcd" | "xyz" | "pts")
}

/// Whether a file name says it is a colour image (`1_rgb.png`, `color/…`), which a directory
/// listing of depth images skips.
fn is_colour_name(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    ["rgb", "color", "colour"].iter().any(|w| name.contains(w))
}

fn sorted_files(dir: &Path, keep: impl Fn(&Path) -> bool) -> Result<Vec<PathBuf>, ReplayError> {
    let io = |error| ReplayError::Io {
        name: dir.display().to_string(),
        action: "list the directory",
        error,
    };
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(io)? {
        let path = entry.map_err(io)?.path();
        if path.is_file() && keep(&path) {
            files.push(path);
        }
    }
    files.sort();
    Ok(files)
}

/// The depth images in a directory (`.png`, `.tif`, `.tiff`, `.pgm`, `.z16`, `.raw`), sorted
/// by file name. Files whose name contains `rgb`, `color` or `colour` are colour images of an
/// RGB-D pair and are skipped.
pub fn list_depth_images(dir: &Path) -> Result<Vec<DepthFile>, ReplayError> {
    let files = sorted_files(dir, |p| is_depth_image_path(p) && !is_colour_name(p))?;
    Ok(files.into_iter().map(DepthFile::new).collect())
}

/// The point clouds in a directory (`.ply`, `.pcd`, `.xyz`, `.pts`), sorted by file name.
pub fn list_clouds(dir: &Path) -> Result<Vec<PathBuf>, ReplayError> {
    sorted_files(dir, is_cloud_path)
}

fn read_text(path: &Path) -> Result<String, ReplayError> {
    std::fs::read_to_string(path).map_err(|error| ReplayError::Io {
        name: path.display().to_string(),
        action: "read",
        error,
    })
}

/// The data lines of a text file: numbered from 1, blank lines and `#` comments skipped.
fn data_lines(text: &str) -> impl Iterator<Item = (usize, Vec<&str>)> {
    text.lines()
        .enumerate()
        .map(|(i, line)| (i + 1, line.split_whitespace().collect::<Vec<_>>()))
        .filter(|(_, fields)| fields.first().is_some_and(|f| !f.starts_with('#')))
}

/// Reads a TUM-style association file: "timestamp filename" per line, `#` comments, file names
/// relative to the file's directory. A four-column line (`associate.py`'s "t1 f1 t2 f2")
/// contributes the pair whose file name mentions `depth`, or else the first pair.
pub fn read_association_file(path: &Path) -> Result<Vec<DepthFile>, ReplayError> {
    let base = path.parent().unwrap_or(Path::new(""));
    let bad_line = |line, reason: String| ReplayError::ListFile {
        name: path.display().to_string(),
        line,
        reason,
    };
    let mut files = Vec::new();
    for (line, fields) in data_lines(&read_text(path)?) {
        let pair = match fields.as_slice() {
            [t, f] => (*t, *f),
            [t1, f1, t2, f2] => {
                if !f1.contains("depth") && f2.contains("depth") {
                    (*t2, *f2)
                } else {
                    (*t1, *f1)
                }
            }
            _ => {
                return Err(bad_line(
                    line,
                    format!(
                        "expected \"timestamp filename\", found {} fields",
                        fields.len()
                    ),
                ))
            }
        };
        let timestamp_s: f64 = pair
            .0
            .parse()
            .ok()
            .filter(|t: &f64| t.is_finite())
            .ok_or_else(|| bad_line(line, format!("{:?} is not a timestamp in seconds", pair.0)))?;
        files.push(DepthFile {
            path: base.join(pair.1),
            timestamp_s: Some(timestamp_s),
        });
    }
    Ok(files)
}

/// Whether a text file looks like an association file: its first data line is
/// "number filename" with a depth image extension.
pub fn looks_like_association_file(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    let first = data_lines(&text).next();
    matches!(first, Some((_, fields)) if fields.len() >= 2
        && fields[0].parse::<f64>().is_ok()
        && is_depth_image_path(Path::new(fields[1])))
}

/// Reads a pose per line, "tx ty tz qx qy qz qw" (metres, unit quaternion, scalar last), as
/// `world_from_sensor` transforms (slambook's `pose.txt` holds `T_world_camera`). Quaternions
/// are normalised; a zero or non-finite one is an error.
pub fn read_pose_file(path: &Path) -> Result<Vec<Affine3A>, ReplayError> {
    let mut poses = Vec::new();
    for (line, fields) in data_lines(&read_text(path)?) {
        let pose = parse_pose(&fields).map_err(|reason| ReplayError::ListFile {
            name: path.display().to_string(),
            line,
            reason,
        })?;
        poses.push(pose);
    }
    Ok(poses)
}

/// "tx ty tz qx qy qz qw" to a transform.
pub(crate) fn parse_pose(fields: &[&str]) -> Result<Affine3A, String> {
    if fields.len() != 7 {
        return Err(format!(
            "expected 7 numbers \"tx ty tz qx qy qz qw\", found {} fields",
            fields.len()
        ));
    }
    let mut v = [0.0f32; 7];
    for (slot, field) in v.iter_mut().zip(fields) {
        *slot = field
            .parse()
            .ok()
            .filter(|x: &f32| x.is_finite())
            .ok_or_else(|| format!("{field:?} is not a finite number"))?;
    }
    let q = Quat::from_xyzw(v[3], v[4], v[5], v[6]);
    if q.length() < 1e-6 {
        return Err("the rotation quaternion is zero".to_owned());
    }
    Ok(Affine3A::from_rotation_translation(
        q.normalize(),
        Vec3::new(v[0], v[1], v[2]),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn association_file_resolves_relative_names_and_picks_depth_column() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("depth.txt");
        std::fs::write(
            &path,
            "# depth maps\n# timestamp filename\n1.5 depth/a.png\n\n\
             2.0 rgb/b.png 2.01 depth/b.png\n",
        )
        .expect("write");
        let files = read_association_file(&path).expect("parses");
        assert_eq!(
            files,
            vec![
                DepthFile {
                    path: dir.path().join("depth/a.png"),
                    timestamp_s: Some(1.5)
                },
                DepthFile {
                    path: dir.path().join("depth/b.png"),
                    timestamp_s: Some(2.01)
                },
            ]
        );
        assert!(looks_like_association_file(&path));
    }

    #[test]
    fn association_file_names_the_bad_line() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("depth.txt");
        std::fs::write(&path, "1.0 a.png\nsoon b.png\n").expect("write");
        let err = read_association_file(&path).unwrap_err().to_string();
        assert!(err.contains("depth.txt") && err.contains("line 2"), "{err}");
    }

    #[test]
    fn pose_line_is_translation_then_scalar_last_quaternion() {
        let pose = parse_pose(&["1", "2", "3", "0", "0", "0.7071068", "0.7071068"]).expect("pose");
        let p = pose.transform_point3(Vec3::X);
        assert!(p.distance(Vec3::new(1.0, 3.0, 3.0)) < 1e-6, "{p}");
        assert!(parse_pose(&["0"; 7]).is_err());
    }
}
