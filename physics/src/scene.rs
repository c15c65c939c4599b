//! What a scene file holds, whatever simulator it is written for (`crate::mjcf` for MuJoCo,
//! `crate::sdf` for Gazebo and PyBullet): bodies at their poses with their visual mesh, convex
//! collision parts and mass properties, support planes, gravity; and what both writers share
//! (file and mesh names, numbers as text, files replaced whole).

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;
use crate::mass::MassProperties;
use crate::stl::write_binary_stl;

/// A rigid transform from a body's frame to the world: `p_in_world = rotation * p_in_body +
/// translation_m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorldFromBody {
    /// Unit quaternion (glam stores x, y, z, w; MJCF gets w x y z).
    pub rotation: Quat,
    /// Translation in metres.
    pub translation_m: Vec3,
}

impl WorldFromBody {
    pub const IDENTITY: WorldFromBody = WorldFromBody {
        rotation: Quat::IDENTITY,
        translation_m: Vec3::ZERO,
    };
}

/// Whether the simulation may move a body.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Motion {
    /// Welded to the world (a table, a wall): no joint, no mass.
    Static,
    /// Free to move under gravity and contact: a free joint and an inertia.
    Dynamic,
}

/// One object of the scene; every mesh in the body's own frame, metres.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneBody {
    /// A name or id; sanitised and made unique in the file.
    pub name: String,
    pub world_from_body: WorldFromBody,
    /// What is drawn; never collides. May be empty (no visual geom).
    pub visual: TriMesh,
    /// Closed convex parts, what collides (`crate::convex_parts`). A dynamic body needs one.
    pub convex_parts: Vec<TriMesh>,
    /// Unit-density mass properties in the body's frame (of the mesh, or of its parts).
    pub mass: MassProperties,
    pub motion: Motion,
}

/// An infinite support plane (a table top, the floor) that bodies rest on.
#[derive(Debug, Clone, PartialEq)]
pub struct ScenePlane {
    /// A name or id; sanitised and made unique in the file.
    pub name: String,
    /// A point on the plane, world frame, metres.
    pub point_in_world: Vec3,
    /// The side bodies rest on, world frame (normalised here; must not be zero).
    pub normal_in_world: Vec3,
    /// Half the side of the square drawn, metres (0: drawn infinite). Collisions are always
    /// with the infinite plane.
    pub drawn_half_size_m: f32,
}

/// What a scene file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Gravity in the world frame, m/s² (for example `-9.81 * up`).
    pub gravity_m_s2: Vec3,
    pub supports: Vec<ScenePlane>,
    pub bodies: Vec<SceneBody>,
}
/// What a writer wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenScene {
    /// The scene file (`scene.xml`, `scene.sdf`).
    pub scene_file: PathBuf,
    pub mesh_files: Vec<PathBuf>,
}

/// The folder beside `scene.xml` that holds the meshes.
pub const MESH_FOLDER: &str = "meshes";
// ---- names ----------------------------------------------------------------------------------

/// Keeps `[A-Za-z0-9_.-]`, replaces anything else with `_`; never empty, never starting with
/// a dot (a hidden file).
pub(crate) fn sanitise(name: &str) -> String {
    let mut out: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if out.is_empty() || out.starts_with('.') {
        out.insert(0, '_');
    }
    out
}

/// Hands out sanitised names, each once (`box`, `box_2`, `box_3`…).
#[derive(Default)]
pub(crate) struct UniqueNames {
    taken: HashSet<String>,
}

impl UniqueNames {
    pub(crate) fn claim(&mut self, wanted: &str) -> String {
        let base = sanitise(wanted);
        let mut name = base.clone();
        let mut n = 2;
        while !self.taken.insert(name.clone()) {
            name = format!("{base}_{n}");
            n += 1;
        }
        name
    }
}

// ---- numbers --------------------------------------------------------------------------------

/// One number in Rust's shortest round-trip form, with an exponent when very small or large
/// (MuJoCo reads numbers with `strtod`), and no negative zero.
pub(crate) fn number(v: f32) -> String {
    let v = v + 0.0; // -0 + 0 = +0
    let magnitude = v.abs();
    if v == 0.0 || (1e-4..1e7).contains(&magnitude) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Space-separated numbers.
pub(crate) fn numbers(values: &[f32]) -> String {
    values
        .iter()
        .map(|&v| number(v))
        .collect::<Vec<_>>()
        .join(" ")
}
// ---- checks ---------------------------------------------------------------------------------

/// What every writer refuses: a density that is not a positive number, a support without a
/// finite point and a normal, a body without a finite pose, a dynamic body without parts to
/// collide with or without a volume to weigh.
pub(crate) fn check_scene(scene: &Scene, density_kg_m3: f32) -> Result<(), PhysicsError> {
    let density_ok = density_kg_m3.is_finite() && density_kg_m3 > 0.0;
    if !density_ok {
        return Err(PhysicsError::BadDensity { density_kg_m3 });
    }
    for support in &scene.supports {
        let normal_ok = support.normal_in_world.length() > 1e-6;
        if !normal_ok || !support.point_in_world.is_finite() {
            return Err(PhysicsError::InvalidScene(format!(
                "support {:?} needs a finite point and a non-zero normal",
                support.name
            )));
        }
    }
    for body in &scene.bodies {
        let pose_ok = body.world_from_body.translation_m.is_finite()
            && body.world_from_body.rotation.is_finite()
            && body.world_from_body.rotation.length() > 1e-6;
        if !pose_ok {
            return Err(PhysicsError::InvalidScene(format!(
                "body {:?} has no finite pose",
                body.name
            )));
        }
        if body.motion == Motion::Dynamic {
            if body.convex_parts.is_empty() {
                return Err(PhysicsError::InvalidScene(format!(
                    "dynamic body {:?} has no convex parts to collide with: it would fall \
                     through its support",
                    body.name
                )));
            }
            let mass_ok = body.mass.volume_m3.is_finite() && body.mass.volume_m3 > 0.0;
            if !mass_ok {
                return Err(PhysicsError::NoVolume {
                    volume_m3: f64::from(body.mass.volume_m3),
                });
            }
        }
    }
    Ok(())
}

// ---- files ----------------------------------------------------------------------------------

/// Writes `bytes` to `path` whole: into a temporary file beside it, then renamed over it, so
/// a reader never sees half a file.
pub(crate) fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), PhysicsError> {
    let error = |source| PhysicsError::Write {
        path: path.to_path_buf(),
        source,
    };
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".part");
    let temporary = PathBuf::from(temporary);
    std::fs::write(&temporary, bytes).map_err(error)?;
    std::fs::rename(&temporary, path).map_err(error)
}

/// Writes each mesh as binary STL under `dir` (creating [`MESH_FOLDER`]), then the scene's
/// text as `dir/file_name`: meshes first, so a reader that sees the new scene finds every mesh
/// it names.
pub(crate) fn write_scene_files(
    dir: &Path,
    file_name: &str,
    text: &str,
    meshes: &[(String, TriMesh)],
) -> Result<WrittenScene, PhysicsError> {
    let mesh_dir = dir.join(MESH_FOLDER);
    std::fs::create_dir_all(&mesh_dir).map_err(|source| PhysicsError::Write {
        path: mesh_dir.clone(),
        source,
    })?;
    let mut mesh_files = Vec::with_capacity(meshes.len());
    for (relative, mesh) in meshes {
        let path = dir.join(relative);
        let mut bytes = Vec::new();
        write_binary_stl(&mut bytes, mesh).map_err(|source| PhysicsError::Write {
            path: path.clone(),
            source,
        })?;
        write_whole(&path, &bytes)?;
        mesh_files.push(path);
    }
    let scene_file = dir.join(file_name);
    write_whole(&scene_file, text.as_bytes())?;
    Ok(WrittenScene {
        scene_file,
        mesh_files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_sanitised_and_unique() {
        let mut names = UniqueNames::default();
        assert_eq!(names.claim("cup"), "cup");
        assert_eq!(names.claim("cup"), "cup_2");
        assert_eq!(names.claim("a\"b<c>&"), "a_b_c__");
        assert_eq!(names.claim(""), "_");
        assert_eq!(names.claim("../x"), "_.._x");
    }
}
