//! Point-cloud and mesh files: PLY, PCD, XYZ and OBJ.
//!
//! Entry points, each choosing the format by the file's extension:
//! - [`read_cloud_file`]: `.ply`, `.pcd`, `.xyz`/`.txt`/`.pts` to a [`CloudFile`]: the points,
//!   how many had a NaN or infinite coordinate (dropped or kept, one rule for every format),
//!   the sensor pose when the file records one, and the pixel grid of an organised PCD.
//!   [`read_cloud`] is its finite points.
//! - [`read_mesh`]: `.obj`, `.ply` to a [`TriMesh`] (polygons fan-triangulated).
//! - [`write_cloud`]: `.ply` (binary little-endian) or `.xyz` (text).
//! - [`write_mesh`]: `.ply` (binary little-endian) or `.obj` (text).
//!
//! One module per format, each with a parser over bytes that needs no file
//! ([`ply::parse_cloud`], [`pcd::parse`], [`xyz::parse`], [`obj::parse`]) and, where the format
//! is written, a writer to any `io::Write`. [`pcd::read_pcd`] keeps what a PCD has beyond a
//! cloud: the organised grid with its invalid points, per-point labels and colours.
//!
//! Every error names the file and says what is wrong with it; no input makes a reader panic.

pub mod obj;
pub mod pcd;
pub mod ply;
pub mod xyz;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use glam::Affine3A;
use tacmesh_source::{CloudGrid, PointCloud, TriMesh};

/// Why a file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum FormatError {
    /// The operating system refused: missing file, no permission, full disk.
    #[error("{name}: cannot {action}: {error}")]
    Io {
        name: String,
        action: &'static str,
        error: std::io::Error,
    },
    /// The extension does not name a format this crate handles in this direction.
    #[error("{name}: unsupported extension; {what} can be {supported}")]
    UnsupportedExtension {
        name: String,
        what: &'static str,
        supported: &'static str,
    },
    /// The contents are not a valid file of the format its extension names.
    #[error("{name}: {reason}")]
    Malformed { name: String, reason: String },
    /// The data handed to a writer cannot be written as a valid file.
    #[error("{name}: cannot write: {reason}")]
    Unwritable { name: String, reason: String },
}

impl FormatError {
    pub(crate) fn malformed(name: &str, reason: impl Into<String>) -> Self {
        Self::Malformed {
            name: name.to_owned(),
            reason: reason.into(),
        }
    }
}

const CLOUD_READ_EXTENSIONS: &str = ".ply, .pcd, .xyz, .txt or .pts";
const MESH_READ_EXTENSIONS: &str = ".obj or .ply";
const CLOUD_WRITE_EXTENSIONS: &str = ".ply or .xyz";
const MESH_WRITE_EXTENSIONS: &str = ".ply or .obj";

/// What to do with the points of a file that have a NaN or infinite coordinate (an organised
/// PCD's invalid pixels, a scanner's misses written as `nan`). Every format follows the same
/// rule: such a point is read, never an error, and is counted.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NonFinite {
    /// Leave them out (what meshing wants).
    Drop,
    /// Keep them in place, so that per-point results (labels) line up with the file.
    Keep,
}

/// A point cloud file as read by [`read_cloud_file`].
#[derive(Debug, Clone, PartialEq)]
pub struct CloudFile {
    /// The points (with normals when the file has them), in file order.
    pub cloud: PointCloud,
    /// Points with a NaN or infinite coordinate: dropped or kept, as asked.
    pub non_finite: usize,
    /// The sensor's pose in the cloud's frame, when the file records one (PCD `VIEWPOINT`);
    /// its translation is where the scan was seen from.
    pub cloud_from_sensor: Option<Affine3A>,
    /// The pixel grid of an organised file (a PCD with `HEIGHT` > 1), when `cloud` still lies
    /// on it: non-finite points kept, or none to drop. `None` for unorganised files and for an
    /// organised one whose non-finite points were dropped.
    pub grid: Option<CloudGrid>,
}

/// Reads a point cloud, choosing the format by extension: `.ply`, `.pcd`, or `.xyz` (also
/// read from `.txt` and `.pts`). Normals are kept when the file has them: PLY `nx ny nz`, PCD
/// `normal_x normal_y normal_z`, XYZ's 6-column form. Points with a non-finite coordinate are
/// dropped or kept as `non_finite` says, and counted either way.
pub fn read_cloud_file(path: &Path, non_finite: NonFinite) -> Result<CloudFile, FormatError> {
    let name = path.display().to_string();
    // Only PCD records a sensor pose; PLY and XYZ have no standard place for one.
    // Only PCD is organised: its parser has checked that WIDTH * HEIGHT is the point count.
    let (mut cloud, cloud_from_sensor, grid) = match extension(path).as_str() {
        "ply" => (ply::parse_cloud(&read_bytes(path)?, &name)?, None, None),
        "pcd" => {
            let pcd = pcd::parse(&read_bytes(path)?, &name)?;
            let pose = pcd.cloud_from_sensor;
            let grid = (pcd.height > 1).then_some(CloudGrid {
                width: pcd.width,
                height: pcd.height,
            });
            (pcd.into_cloud(), pose, grid)
        }
        "xyz" | "txt" | "pts" => (xyz::parse(&read_bytes(path)?, &name)?, None, None),
        _ => {
            return Err(FormatError::UnsupportedExtension {
                name,
                what: "point clouds",
                supported: CLOUD_READ_EXTENSIONS,
            })
        }
    };
    let count = match non_finite {
        NonFinite::Drop => cloud.retain_finite(),
        NonFinite::Keep => cloud.points.iter().filter(|p| !p.is_finite()).count(),
    };
    let on_grid = non_finite == NonFinite::Keep || count == 0;
    Ok(CloudFile {
        cloud,
        non_finite: count,
        cloud_from_sensor,
        grid: grid.filter(|_| on_grid),
    })
}

/// [`read_cloud_file`]'s points without those with a non-finite coordinate.
pub fn read_cloud(path: &Path) -> Result<PointCloud, FormatError> {
    let file = read_cloud_file(path, NonFinite::Drop)?;
    if file.non_finite > 0 {
        tracing::debug!(
            "{}: dropped {} points with a NaN or infinite coordinate",
            path.display(),
            file.non_finite
        );
    }
    Ok(file.cloud)
}

/// [`read_cloud_file`]'s points, every one of the file in its order, non-finite ones
/// included, so that per-point results (labels) line up with the file.
pub fn read_cloud_in_file_order(path: &Path) -> Result<PointCloud, FormatError> {
    read_cloud_file(path, NonFinite::Keep).map(|file| file.cloud)
}

/// Reads a triangle mesh, choosing the format by extension. Vertices keep the file's order.
pub fn read_mesh(path: &Path) -> Result<TriMesh, FormatError> {
    let name = path.display().to_string();
    let parse: fn(&[u8], &str) -> Result<TriMesh, FormatError> = match extension(path).as_str() {
        "obj" => obj::parse,
        "ply" => ply::parse_mesh,
        _ => {
            return Err(FormatError::UnsupportedExtension {
                name,
                what: "meshes",
                supported: MESH_READ_EXTENSIONS,
            })
        }
    };
    parse(&read_bytes(path)?, &name)
}

/// Writes a mesh as binary little-endian `.ply` or as text `.obj`, by extension.
pub fn write_mesh(path: &Path, mesh: &TriMesh) -> Result<(), FormatError> {
    let name = path.display().to_string();
    check_mesh_path(path)?;
    let write: fn(&mut BufWriter<File>, &TriMesh) -> std::io::Result<()> =
        match extension(path).as_str() {
            "obj" => obj::write,
            _ => ply::write_mesh,
        };
    if let Some((triangle, vertex)) = mesh.first_bad_index() {
        return Err(FormatError::Unwritable {
            name,
            reason: format!(
                "triangle {triangle} refers to vertex {vertex} but there are {} vertices",
                mesh.vertices.len()
            ),
        });
    }
    write_file(path, &name, |out| write(out, mesh))
}

/// Writes a cloud as binary little-endian `.ply` (x y z, plus nx ny nz when it has normals) or
/// as text `.xyz`, by extension.
pub fn write_cloud(path: &Path, cloud: &PointCloud) -> Result<(), FormatError> {
    let name = path.display().to_string();
    let write: fn(&mut BufWriter<File>, &PointCloud) -> std::io::Result<()> =
        match extension(path).as_str() {
            "ply" => ply::write_cloud,
            "xyz" => xyz::write,
            _ => {
                return Err(FormatError::UnsupportedExtension {
                    name,
                    what: "point clouds",
                    supported: CLOUD_WRITE_EXTENSIONS,
                })
            }
        };
    if let Some(normals) = &cloud.normals {
        if normals.len() != cloud.points.len() {
            return Err(FormatError::Unwritable {
                name,
                reason: format!(
                    "the cloud has {} points but {} normals",
                    cloud.points.len(),
                    normals.len()
                ),
            });
        }
    }
    write_file(path, &name, |out| write(out, cloud))
}

/// The extension in lower case, or "" when there is none.
/// Whether [`write_mesh`] can write `path` (by its extension): a command can say so before it
/// does the work whose result would go there.
pub fn check_mesh_path(path: &Path) -> Result<(), FormatError> {
    match extension(path).as_str() {
        "ply" | "obj" => Ok(()),
        _ => Err(FormatError::UnsupportedExtension {
            name: path.display().to_string(),
            what: "meshes",
            supported: MESH_WRITE_EXTENSIONS,
        }),
    }
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
}

/// The largest cloud or mesh file read, bytes: 2 GiB (a 100-million-point binary PLY is
/// 1.2 GB; a depth camera's frame is a few MB).
pub const MAX_FILE_BYTES: u64 = 2 << 30;

fn read_bytes(path: &Path) -> Result<Vec<u8>, FormatError> {
    tacmesh_source::read_regular_file(path, MAX_FILE_BYTES).map_err(|error| FormatError::Io {
        name: path.display().to_string(),
        action: "read",
        error,
    })
}

fn write_file(
    path: &Path,
    name: &str,
    write: impl FnOnce(&mut BufWriter<File>) -> std::io::Result<()>,
) -> Result<(), FormatError> {
    let io_error = |error| FormatError::Io {
        name: name.to_owned(),
        action: "write",
        error,
    };
    let mut out = BufWriter::new(File::create(path).map_err(io_error)?);
    write(&mut out).and_then(|()| out.flush()).map_err(io_error)
}
