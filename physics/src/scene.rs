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
    /// With a [`SceneBody::primitive`], its tessellation.
    pub convex_parts: Vec<TriMesh>,
    /// The primitive the body is (a box, a cylinder, a sphere), in its frame: the writers
    /// collide it as the engine's own geom instead of the convex parts.
    pub primitive: Option<crate::primitive::Primitive>,
    /// Unit-density mass properties in the body's frame (of the mesh, or of its parts).
    pub mass: MassProperties,
    pub motion: Motion,
}

/// A support (a table top, the floor, a shelf) as a slab: a box whose top face is the smallest
/// rectangle around what was seen of it, grown by a margin, and `thickness_m` deep under it. A
/// finite box, not an infinite plane: an engine treats a plane as a half-space, and a desk's
/// plane then swallows the floor and what stands on it (and throws it out at 14 m/s).
#[derive(Debug, Clone, PartialEq)]
pub struct SceneSupport {
    /// A name or id; sanitised and made unique in the file.
    pub name: String,
    /// The centre of the top face, world frame, metres.
    pub top_centre_in_world: Vec3,
    /// Up: the side bodies rest on, world frame, unit.
    pub normal_in_world: Vec3,
    /// The top face's first axis, in the plane, world frame, unit.
    pub along_in_world: Vec3,
    /// Half the top face's sides: along `along_in_world`, and along `normal × along`.
    pub half_size_m: glam::Vec2,
    /// How deep the slab reaches under its top face, metres.
    pub thickness_m: f32,
}

/// How far a support's slab reaches beyond what was seen of it, metres: the fan of a table
/// ends where the segmentation stopped seeing it, a little short of its edge.
pub const SUPPORT_MARGIN_M: f32 = 0.02;

/// How deep a support's slab reaches under its top, metres: thick enough that nothing resting
/// on it pushes through in a time step, thin enough to stay clear of what stands under a desk.
pub const SUPPORT_THICKNESS_M: f32 = 0.05;

impl SceneSupport {
    /// The slab of a support whose plane passes through `point_in_world` with `normal_in_world`
    /// (unit), bounded by `outline_in_world` (what was seen of it: a fan's vertices) projected
    /// onto the plane, plus `margin_m`. `None` when the outline spans no area.
    pub fn from_outline(
        name: impl Into<String>,
        point_in_world: Vec3,
        normal_in_world: Vec3,
        outline_in_world: &[Vec3],
        margin_m: f32,
        thickness_m: f32,
    ) -> Option<SceneSupport> {
        let normal = normal_in_world.try_normalize()?;
        let u = normal.any_orthonormal_vector();
        let v = normal.cross(u);
        let flat: Vec<glam::Vec2> = outline_in_world
            .iter()
            .map(|p| glam::Vec2::new((*p - point_in_world).dot(u), (*p - point_in_world).dot(v)))
            .collect();
        let (centre, axis, half) = crate::support::min_area_rectangle(&flat)?;
        Some(SceneSupport {
            name: name.into(),
            top_centre_in_world: point_in_world + u * centre.x + v * centre.y,
            normal_in_world: normal,
            along_in_world: (u * axis.x + v * axis.y).normalize(),
            half_size_m: half + glam::Vec2::splat(margin_m.max(0.0)),
            thickness_m,
        })
    }

    /// The slab's orientation: its x along `along_in_world`, its z along the normal.
    pub fn rotation(&self) -> Quat {
        let z = self.normal_in_world.normalize_or_zero();
        let x = (self.along_in_world - z * self.along_in_world.dot(z)).normalize_or_zero();
        Quat::from_mat3(&glam::Mat3::from_cols(x, z.cross(x), z)).normalize()
    }

    /// The centre of the slab (half its thickness under the top face's centre).
    pub fn box_centre_in_world(&self) -> Vec3 {
        self.top_centre_in_world - self.normal_in_world * (0.5 * self.thickness_m)
    }

    /// Height of `p` above the top face, along the normal (negative under it).
    pub fn height(&self, p: Vec3) -> f32 {
        self.normal_in_world
            .normalize_or_zero()
            .dot(p - self.top_centre_in_world)
    }

    /// Whether `p` lies over (or under) the top face: within its rectangle seen along the
    /// normal.
    pub fn over(&self, p: Vec3) -> bool {
        let rotation = self.rotation();
        let d = p - self.top_centre_in_world;
        d.dot(rotation * Vec3::X).abs() <= self.half_size_m.x
            && d.dot(rotation * Vec3::Y).abs() <= self.half_size_m.y
    }

    /// Half the box's sides in its own frame (x, y along the top face, z through it).
    pub fn box_half_size_m(&self) -> Vec3 {
        Vec3::new(
            self.half_size_m.x,
            self.half_size_m.y,
            0.5 * self.thickness_m,
        )
    }
}

/// Which member of a scene: a support or a body, by its index in [`Scene::supports`] or
/// [`Scene::bodies`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Member {
    Support(usize),
    Body(usize),
}

impl Member {
    /// This member's entry in one list per kind (the names a writer gave them).
    pub(crate) fn of<'a, T>(self, supports: &'a [T], bodies: &'a [T]) -> &'a T {
        match self {
            Member::Support(k) => &supports[k],
            Member::Body(k) => &bodies[k],
        }
    }
}

/// Two members that start inside each other by `depth_m`: they do not collide with each other
/// (each still collides with everything else), or the engine would throw them apart.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Exclusion {
    pub a: Member,
    pub b: Member,
    pub depth_m: f32,
}

/// What a scene file holds.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Gravity in the world frame, m/s² (for example `-9.81 * up`).
    pub gravity_m_s2: Vec3,
    pub supports: Vec<SceneSupport>,
    pub bodies: Vec<SceneBody>,
    /// Pairs that do not collide with each other (see `crate::overlap::starting_overlaps`).
    pub exclusions: Vec<Exclusion>,
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
        let normal_ok = support.normal_in_world.length() > 1e-6
            && support.along_in_world.length() > 1e-6
            && support.normal_in_world.is_finite()
            && support.along_in_world.is_finite();
        let size_ok = support.half_size_m.is_finite()
            && support.half_size_m.min_element() > 0.0
            && support.thickness_m.is_finite()
            && support.thickness_m > 0.0;
        if !normal_ok || !support.top_centre_in_world.is_finite() || !size_ok {
            return Err(PhysicsError::InvalidScene(format!(
                "support {:?} needs a finite place, a non-zero normal and axis, and a positive \
                 size and thickness",
                support.name
            )));
        }
    }
    for exclusion in &scene.exclusions {
        let known = |m: Member| match m {
            Member::Support(k) => k < scene.supports.len(),
            Member::Body(k) => k < scene.bodies.len(),
        };
        if !known(exclusion.a) || !known(exclusion.b) {
            return Err(PhysicsError::InvalidScene(format!(
                "an exclusion names a member the scene does not have: {exclusion:?}"
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
            if let Some(why) = body.mass.implausible() {
                return Err(PhysicsError::InvalidScene(format!(
                    "dynamic body {:?} cannot be simulated: {why}",
                    body.name
                )));
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
