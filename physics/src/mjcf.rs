//! A MuJoCo scene (MJCF) of tacmesh's objects: `scene.xml` and one binary STL per mesh,
//! which `mujoco.MjModel.from_xml_path` loads and steps.
//!
//! What each body becomes (MJCF reference: <https://mujoco.readthedocs.io/en/stable/XMLreference.html>):
//! - a `<body>` at its pose in the world (`pos`, `quat` as w x y z);
//! - one collision `<geom type="mesh">` per convex part: MuJoCo collides the convex hull of
//!   any mesh, so a concave visual mesh would collide as its hull; the parts are the
//!   decomposition (`crate::convex`);
//! - collision geoms do not collide with other bodies' unless [`MjcfConfig::bodies_collide`]
//!   (they still do with the supports and with whatever the user adds);
//! - the visual mesh as a `<geom>` of class `visual`: `contype="0" conaffinity="0"` (never
//!   collides), `group="1"`, no mass;
//! - a dynamic body also gets a `<freejoint>` and an explicit `<inertial>` (`pos` = centre of
//!   mass, `mass`, `fullinertia` = Ixx Iyy Izz Ixy Ixz Iyz) from its unit-density mass
//!   properties times [`MjcfConfig::density_kg_m3`], so MuJoCo never infers inertia from the
//!   hulls (which over-approximate); a static body has neither and is welded to the world.
//!
//! Supports are `<geom type="plane">` in the world body: MuJoCo's plane is the local XY plane
//! with +Z its normal, so the geom's quaternion turns +Z onto the support's normal. Gravity
//! is a vector (`<option gravity>`): the world's Z need not be up.
//!
//! Names are sanitised to `[A-Za-z0-9_.-]` (anything else becomes `_`) and made unique with a
//! numeric suffix, so they are safe both as XML attribute values and as file names.
//!
//! Entry points: [`write_mjcf`] (files), [`mjcf_document`] (the XML and the meshes it names,
//! without touching the disk).

use std::collections::HashSet;
use std::fmt::Write as _;
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

/// How to write a scene.
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfConfig {
    /// Density of every dynamic body, kg/m³ (default 500: between foam and water, a fair
    /// guess for household objects, hollow or solid; a real value belongs with the object).
    pub density_kg_m3: f32,
    /// Simulation time step in seconds (default 0.002, MuJoCo's own default).
    pub timestep_s: f32,
    /// The `<mujoco model>` name.
    pub model_name: String,
    /// Whether the bodies collide with each other (default no). A tacmesh body is a
    /// conservative collision proxy: a one-view object's proxy takes in the unseen space behind
    /// it, where another object's may reach too (on the milk carton recording two proxies start
    /// 89 mm into each other, and MuJoCo threw the lighter one 0.4 m). Each still collides with
    /// the supports and with anything the user adds (a probe, a robot's fingers: MuJoCo's
    /// default `contype` and `conaffinity` of 1).
    pub bodies_collide: bool,
}

impl Default for MjcfConfig {
    fn default() -> Self {
        Self {
            density_kg_m3: 500.0,
            timestep_s: 0.002,
            model_name: "tacmesh".into(),
            bodies_collide: false,
        }
    }
}

/// A scene as text and the meshes its `file` attributes name (paths relative to the XML).
#[derive(Debug, Clone, PartialEq)]
pub struct MjcfDocument {
    pub xml: String,
    /// `(relative path, mesh)` for each mesh asset, written as binary STL.
    pub meshes: Vec<(String, TriMesh)>,
}

/// What [`write_mjcf`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenScene {
    pub scene_xml: PathBuf,
    pub mesh_files: Vec<PathBuf>,
}

/// The folder beside `scene.xml` that holds the meshes.
pub const MESH_FOLDER: &str = "meshes";

// ---- names ----------------------------------------------------------------------------------

/// Keeps `[A-Za-z0-9_.-]`, replaces anything else with `_`; never empty, never starting with
/// a dot (a hidden file).
fn sanitise(name: &str) -> String {
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
struct UniqueNames {
    taken: HashSet<String>,
}

impl UniqueNames {
    fn claim(&mut self, wanted: &str) -> String {
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
fn number(v: f32) -> String {
    let v = v + 0.0; // -0 + 0 = +0
    let magnitude = v.abs();
    if v == 0.0 || (1e-4..1e7).contains(&magnitude) {
        format!("{v}")
    } else {
        format!("{v:e}")
    }
}

/// Space-separated numbers.
fn numbers(values: &[f32]) -> String {
    values
        .iter()
        .map(|&v| number(v))
        .collect::<Vec<_>>()
        .join(" ")
}

fn mjcf_quat(q: Quat) -> String {
    let q = q.normalize();
    numbers(&[q.w, q.x, q.y, q.z])
}

// ---- checks ---------------------------------------------------------------------------------

fn check_scene(scene: &Scene, config: &MjcfConfig) -> Result<(), PhysicsError> {
    let density_ok = config.density_kg_m3.is_finite() && config.density_kg_m3 > 0.0;
    if !density_ok {
        return Err(PhysicsError::BadDensity {
            density_kg_m3: config.density_kg_m3,
        });
    }
    let step_ok = config.timestep_s.is_finite() && config.timestep_s > 0.0;
    if !step_ok {
        return Err(PhysicsError::InvalidScene(format!(
            "time step {} s is not a positive number",
            config.timestep_s
        )));
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

// ---- document -------------------------------------------------------------------------------

/// The MJCF text of `scene` and the meshes it refers to, without writing anything.
pub fn mjcf_document(scene: &Scene, config: &MjcfConfig) -> Result<MjcfDocument, PhysicsError> {
    check_scene(scene, config)?;
    let mut names = UniqueNames::default();
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    let mut assets = String::new();
    let mut world = String::new();

    // `write!` to a String cannot fail; the results are ignored on purpose below.
    for support in &scene.supports {
        let name = names.claim(&support.name);
        let normal = support.normal_in_world.normalize();
        let quat = Quat::from_rotation_arc(Vec3::Z, normal);
        let half = support.drawn_half_size_m.max(0.0);
        let _ = writeln!(
            world,
            r#"    <geom name="{name}" class="support" type="plane" pos="{}" quat="{}" size="{} {} 0.05"/>"#,
            numbers(&support.point_in_world.to_array()),
            mjcf_quat(quat),
            number(half),
            number(half),
        );
    }

    for body in &scene.bodies {
        let name = names.claim(&body.name);
        let pose = body.world_from_body;
        let _ = writeln!(
            world,
            r#"    <body name="{name}" pos="{}" quat="{}">"#,
            numbers(&pose.translation_m.to_array()),
            mjcf_quat(pose.rotation),
        );
        if body.motion == Motion::Dynamic {
            let density = config.density_kg_m3;
            let i = body.mass.inertia_kg_m2(density);
            let _ = writeln!(world, r#"      <freejoint name="{name}_free"/>"#);
            let _ = writeln!(
                world,
                r#"      <inertial pos="{}" mass="{}" fullinertia="{}"/>"#,
                numbers(&body.mass.centre_of_mass.to_array()),
                number(body.mass.mass_kg(density)),
                numbers(&[i[0][0], i[1][1], i[2][2], i[0][1], i[0][2], i[1][2]]),
            );
        }
        if !body.visual.is_empty() {
            let mesh_name = names.claim(&format!("{name}_visual"));
            let file = format!("{MESH_FOLDER}/{mesh_name}.stl");
            // `shell`: a visual mesh may be an open one-view shell, which has no volume.
            let _ = writeln!(
                assets,
                r#"    <mesh name="{mesh_name}" file="{file}" inertia="shell"/>"#
            );
            let _ = writeln!(
                world,
                r#"      <geom name="{mesh_name}" class="visual" type="mesh" mesh="{mesh_name}"/>"#
            );
            meshes.push((file, body.visual.clone()));
        }
        for (k, part) in body.convex_parts.iter().enumerate() {
            let mesh_name = names.claim(&format!("{name}_part{k}"));
            let file = format!("{MESH_FOLDER}/{mesh_name}.stl");
            let _ = writeln!(
                assets,
                r#"    <mesh name="{mesh_name}" file="{file}" inertia="convex"/>"#
            );
            let _ = writeln!(
                world,
                r#"      <geom name="{mesh_name}" class="collision" type="mesh" mesh="{mesh_name}"/>"#
            );
            meshes.push((file, part.clone()));
        }
        let _ = writeln!(world, "    </body>");
    }

    let collision_bits = if config.bodies_collide {
        ""
    } else {
        // contype 2 & conaffinity 1: two such geoms never collide (2 & 1 = 0 both ways); with
        // a plane or a user's geom (1, 1) they do (1 & 1).
        r#"contype="2" conaffinity="1" "#
    };
    let mut xml = String::new();
    let _ = writeln!(
        xml,
        r#"<mujoco model="{}">
  <!-- Written by tacmesh: bodies at their poses, collision from convex parts, inertia from
       the meshes at {} kg/m3. -->
  <compiler angle="radian" inertiafromgeom="false" balanceinertia="true"/>
  <option timestep="{}" gravity="{}"/>
  <default>
    <default class="visual">
      <geom contype="0" conaffinity="0" group="1" density="0" rgba="0.7 0.7 0.75 1"/>
    </default>
    <default class="collision">
      <geom {collision_bits}group="3" density="0" rgba="0.3 0.6 0.9 0.4"/>
    </default>
    <default class="support">
      <geom group="2" rgba="0.5 0.45 0.4 1"/>
    </default>
  </default>
  <asset>
{assets}  </asset>
  <worldbody>
    <light name="tacmesh_light" directional="true" dir="{}" pos="{}"/>
{world}  </worldbody>
</mujoco>"#,
        sanitise(&config.model_name),
        config.density_kg_m3,
        config.timestep_s,
        numbers(&scene.gravity_m_s2.to_array()),
        numbers(&light_direction(scene.gravity_m_s2).to_array()),
        numbers(&(-3.0 * light_direction(scene.gravity_m_s2)).to_array()),
    );
    Ok(MjcfDocument { xml, meshes })
}

/// Light from above: along gravity, or straight down -Z without gravity.
fn light_direction(gravity_m_s2: Vec3) -> Vec3 {
    gravity_m_s2.try_normalize().unwrap_or(Vec3::NEG_Z)
}

// ---- files ----------------------------------------------------------------------------------

/// Writes `bytes` to `path` whole: into a temporary file beside it, then renamed over it, so
/// a reader never sees half a file.
fn write_whole(path: &Path, bytes: &[u8]) -> Result<(), PhysicsError> {
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

/// Writes `dir/scene.xml` and `dir/meshes/*.stl` for `scene` (creating the folders), meshes
/// first, so a reader that sees the new `scene.xml` finds every mesh it names.
pub fn write_mjcf(
    dir: &Path,
    scene: &Scene,
    config: &MjcfConfig,
) -> Result<WrittenScene, PhysicsError> {
    let document = mjcf_document(scene, config)?;
    let mesh_dir = dir.join(MESH_FOLDER);
    std::fs::create_dir_all(&mesh_dir).map_err(|source| PhysicsError::Write {
        path: mesh_dir.clone(),
        source,
    })?;
    let mut mesh_files = Vec::with_capacity(document.meshes.len());
    for (relative, mesh) in &document.meshes {
        let path = dir.join(relative);
        let mut bytes = Vec::new();
        write_binary_stl(&mut bytes, mesh).map_err(|source| PhysicsError::Write {
            path: path.clone(),
            source,
        })?;
        write_whole(&path, &bytes)?;
        mesh_files.push(path);
    }
    let scene_xml = dir.join("scene.xml");
    write_whole(&scene_xml, document.xml.as_bytes())?;
    Ok(WrittenScene {
        scene_xml,
        mesh_files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convex::{convex_parts, ConvexConfig};
    use tacmesh_sim::cube;

    fn body(name: &str, motion: Motion, z: f32) -> SceneBody {
        let mesh = cube(0.1);
        let parts = convex_parts(&mesh, &ConvexConfig::default()).unwrap();
        SceneBody {
            name: name.into(),
            world_from_body: WorldFromBody {
                rotation: Quat::from_rotation_z(0.3),
                translation_m: Vec3::new(0.0, 0.0, z),
            },
            visual: mesh,
            convex_parts: parts.hulls,
            mass: parts.mesh_mass,
            motion,
        }
    }

    fn two_body_scene() -> Scene {
        Scene {
            gravity_m_s2: Vec3::new(0.0, 0.0, -9.81),
            supports: vec![ScenePlane {
                name: "table".into(),
                point_in_world: Vec3::ZERO,
                normal_in_world: Vec3::Z,
                drawn_half_size_m: 1.0,
            }],
            bodies: vec![
                body("box <1>", Motion::Dynamic, 0.05),
                body("shelf", Motion::Static, 0.5),
            ],
        }
    }

    #[test]
    fn two_body_scene_is_written_with_its_meshes() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_mjcf(dir.path(), &two_body_scene(), &MjcfConfig::default()).unwrap();
        let xml = std::fs::read_to_string(&written.scene_xml).unwrap();
        assert!(xml.starts_with("<mujoco model=\"tacmesh\">"));
        assert!(xml.trim_end().ends_with("</mujoco>"));
        assert_eq!(xml.matches("<body ").count(), 2);
        assert_eq!(xml.matches("</body>").count(), 2);
        // Only the dynamic body moves and has an inertia: 0.001 m³ at 500 kg/m³.
        assert_eq!(xml.matches("<freejoint").count(), 1);
        assert_eq!(xml.matches("<inertial").count(), 1);
        assert!(xml.contains(r#"mass="0.5""#), "{xml}");
        // The name is sanitised and the quaternion is w x y z.
        assert!(
            xml.contains(r#"<body name="box__1_" pos="0 0 0.05" quat="0.9887711 0 0 0.14943814">"#),
            "{xml}"
        );
        assert!(
            xml.contains(r#"type="plane" pos="0 0 0" quat="1 0 0 0""#),
            "{xml}"
        );
        // A visual and a collision mesh per body, every one written.
        assert_eq!(xml.matches(r#"class="visual" type="mesh""#).count(), 2);
        assert_eq!(xml.matches(r#"class="collision" type="mesh""#).count(), 2);
        assert_eq!(written.mesh_files.len(), 4);
        for file in &written.mesh_files {
            let relative = file.strip_prefix(dir.path()).unwrap().to_str().unwrap();
            assert!(xml.contains(&format!(r#"file="{relative}""#)), "{relative}");
            // 12 triangles of a cube: 84 + 12 × 50 bytes.
            assert_eq!(std::fs::metadata(file).unwrap().len(), 684);
        }
    }

    /// Bodies collide with the supports and a user's geoms, not with each other, unless asked.
    #[test]
    fn bodies_do_not_collide_with_each_other_unless_asked() {
        let apart = mjcf_document(&two_body_scene(), &MjcfConfig::default())
            .unwrap()
            .xml;
        assert!(
            apart.contains(r#"<geom contype="2" conaffinity="1" group="3""#),
            "{apart}"
        );
        let together = MjcfConfig {
            bodies_collide: true,
            ..MjcfConfig::default()
        };
        let xml = mjcf_document(&two_body_scene(), &together).unwrap().xml;
        assert!(!xml.contains(r#"contype="2""#), "{xml}");
    }

    #[test]
    fn plane_quaternion_turns_z_onto_the_normal() {
        let mut scene = two_body_scene();
        scene.supports[0].normal_in_world = Vec3::new(0.0, 2.0, 0.0);
        let xml = mjcf_document(&scene, &MjcfConfig::default()).unwrap().xml;
        // A quarter turn about -X takes +Z to +Y: w = cos 45°, x = -sin 45°.
        assert!(xml.contains(r#"quat="0.7071068 -0.7071068 0 0""#), "{xml}");
    }

    #[test]
    fn names_are_sanitised_and_unique() {
        let mut names = UniqueNames::default();
        assert_eq!(names.claim("cup"), "cup");
        assert_eq!(names.claim("cup"), "cup_2");
        assert_eq!(names.claim("a\"b<c>&"), "a_b_c__");
        assert_eq!(names.claim(""), "_");
        assert_eq!(names.claim("../x"), "_.._x");
    }

    #[test]
    fn dynamic_body_without_parts_is_refused() {
        let mut scene = two_body_scene();
        scene.bodies[0].convex_parts.clear();
        let error = mjcf_document(&scene, &MjcfConfig::default()).unwrap_err();
        assert!(matches!(error, PhysicsError::InvalidScene(_)), "{error}");
    }

    #[test]
    fn zero_density_is_refused() {
        let config = MjcfConfig {
            density_kg_m3: 0.0,
            ..MjcfConfig::default()
        };
        let error = mjcf_document(&two_body_scene(), &config).unwrap_err();
        assert!(matches!(error, PhysicsError::BadDensity { .. }), "{error}");
    }
}
