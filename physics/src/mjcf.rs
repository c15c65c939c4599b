//! A MuJoCo scene (MJCF) of tacmesh's objects: `scene.xml` and one binary STL per mesh,
//! which `mujoco.MjModel.from_xml_path` loads and steps.
//!
//! What each body becomes (MJCF reference: <https://mujoco.readthedocs.io/en/stable/XMLreference.html>):
//! - a `<body>` at its pose in the world (`pos`, `quat` as w x y z);
//! - a body that is a primitive ([`SceneBody::primitive`]) collides as MuJoCo's own `box`,
//!   `cylinder` or `sphere` geom; any other has one collision `<geom type="mesh">` per convex part: MuJoCo collides the convex hull of
//!   any mesh, so a concave visual mesh would collide as its hull; the parts are the
//!   decomposition (`crate::convex`);
//! - bodies collide with each other and with the supports, except the pairs the scene lists in
//!   [`Scene::exclusions`] (they start inside each other), each a `<contact><exclude>`; with
//!   [`MjcfConfig::bodies_collide`] off they collide only with the supports and what the user
//!   adds;
//! - the visual mesh as a `<geom>` of class `visual`: `contype="0" conaffinity="0"` (never
//!   collides), `group="1"`, no mass;
//! - a dynamic body also gets a `<freejoint>` and an explicit `<inertial>` (`pos` = centre of
//!   mass, `mass`, `fullinertia` = Ixx Iyy Izz Ixy Ixz Iyz) from its unit-density mass
//!   properties times [`MjcfConfig::density_kg_m3`], so MuJoCo never infers inertia from the
//!   hulls (which over-approximate); a static body has neither and is welded to the world.
//!
//! A support is a static `<body>` (no joint: welded to the world) holding one `<geom
//! type="box">`, the slab of [`SceneSupport`]: a finite box, because MuJoCo's plane is an
//! infinite half-space and a desk's would swallow the floor under it. Gravity is a vector
//! (`<option gravity>`): the world's Z need not be up.
//!
//! Names are sanitised to `[A-Za-z0-9_.-]` (anything else becomes `_`) and made unique with a
//! numeric suffix, so they are safe both as XML attribute values and as file names.
//!
//! Entry points: [`write_mjcf`] (files), [`mjcf_document`] (the XML and the meshes it names,
//! without touching the disk).

use std::fmt::Write as _;
use std::path::Path;

use glam::{Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;
use crate::primitive::PrimitiveShape;
use crate::scene::{check_scene, number, numbers, sanitise, write_scene_files, UniqueNames};
// The scene's types, here too: the MJCF writer's callers name them through this module.
pub use crate::scene::{
    Exclusion, Member, Motion, Scene, SceneBody, SceneSupport, WorldFromBody, WrittenScene,
    MESH_FOLDER,
};

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
    /// Whether the bodies collide with each other (default yes). Pairs that start inside each
    /// other (a one-view object's proxy takes in the unseen space behind it, where another
    /// object's may reach too) are kept apart by [`Scene::exclusions`] instead. Off, each
    /// body collides only with the supports and with anything the user adds (a probe, a
    /// robot's fingers: MuJoCo's default `contype` and `conaffinity` of 1).
    pub bodies_collide: bool,
}

impl Default for MjcfConfig {
    fn default() -> Self {
        Self {
            density_kg_m3: 500.0,
            timestep_s: 0.002,
            model_name: "tacmesh".into(),
            bodies_collide: true,
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

fn mjcf_quat(q: Quat) -> String {
    // q and −q are the same rotation: the one with w ≥ 0 is written.
    let q = if q.w < 0.0 { -q } else { q }.normalize();
    numbers(&[q.w, q.x, q.y, q.z])
}

// ---- checks ---------------------------------------------------------------------------------

fn check_config(scene: &Scene, config: &MjcfConfig) -> Result<(), PhysicsError> {
    let step_ok = config.timestep_s.is_finite() && config.timestep_s > 0.0;
    if !step_ok {
        return Err(PhysicsError::InvalidScene(format!(
            "time step {} s is not a positive number",
            config.timestep_s
        )));
    }
    check_scene(scene, config.density_kg_m3)
}

// ---- document -------------------------------------------------------------------------------

/// The MJCF text of `scene` and the meshes it refers to, without writing anything.
pub fn mjcf_document(scene: &Scene, config: &MjcfConfig) -> Result<MjcfDocument, PhysicsError> {
    check_config(scene, config)?;
    let mut names = UniqueNames::default();
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    let mut assets = String::new();
    let mut world = String::new();

    // `write!` to a String cannot fail; the results are ignored on purpose below.
    let mut support_names = Vec::with_capacity(scene.supports.len());
    for support in &scene.supports {
        let name = names.claim(&support.name);
        let half = support.box_half_size_m();
        // The body sits at the slab's centre, turned so its z is the support's normal.
        let _ = writeln!(
            world,
            r#"    <body name="{name}" pos="{}" quat="{}">
      <geom name="{name}_slab" class="support" type="box" size="{}"/>
    </body>"#,
            numbers(&support.box_centre_in_world().to_array()),
            mjcf_quat(support.rotation()),
            numbers(&half.to_array()),
        );
        support_names.push(name);
    }

    let mut body_names = Vec::with_capacity(scene.bodies.len());
    for body in &scene.bodies {
        let name = names.claim(&body.name);
        body_names.push(name.clone());
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
        if let Some(primitive) = &body.primitive {
            // The engine's own geom: exact contact, true normals.
            let geom_name = names.claim(&format!("{name}_{}", primitive.shape.name()));
            let (kind, size) = match primitive.shape {
                PrimitiveShape::Box { half_m } => ("box", half_m.to_array().to_vec()),
                PrimitiveShape::Cylinder {
                    radius_m,
                    half_height_m,
                } => ("cylinder", vec![radius_m, half_height_m]),
                PrimitiveShape::Sphere { radius_m } => ("sphere", vec![radius_m]),
                PrimitiveShape::Capsule {
                    radius_m,
                    half_height_m,
                } => ("capsule", vec![radius_m, half_height_m]),
            };
            let _ = writeln!(
                world,
                r#"      <geom name="{geom_name}" class="collision" type="{kind}" size="{}" pos="{}" quat="{}"/>"#,
                numbers(&size),
                numbers(&primitive.centre.to_array()),
                mjcf_quat(primitive.rotation),
            );
        }
        let parts = if body.primitive.is_some() {
            &[][..]
        } else {
            &body.convex_parts[..]
        };
        for (k, part) in parts.iter().enumerate() {
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

    let mut contact = String::new();
    for exclusion in &scene.exclusions {
        let name = |m: Member| m.of(&support_names, &body_names);
        let _ = writeln!(
            contact,
            r#"    <exclude body1="{}" body2="{}"/> <!-- {} mm inside each other at the start -->"#,
            name(exclusion.a),
            name(exclusion.b),
            number((exclusion.depth_m * 1e3).round()),
        );
    }
    let contact = if contact.is_empty() {
        String::new()
    } else {
        format!("  <contact>\n{contact}  </contact>\n")
    };
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
{contact}</mujoco>"#,
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

/// Writes `dir/scene.xml` and `dir/meshes/*.stl` for `scene` (creating the folders), meshes
/// first, so a reader that sees the new `scene.xml` finds every mesh it names.
pub fn write_mjcf(
    dir: &Path,
    scene: &Scene,
    config: &MjcfConfig,
) -> Result<WrittenScene, PhysicsError> {
    let document = mjcf_document(scene, config)?;
    write_scene_files(dir, "scene.xml", &document.xml, &document.meshes)
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
            primitive: None,
            mass: parts.mesh_mass,
            motion,
        }
    }

    fn two_body_scene() -> Scene {
        Scene {
            gravity_m_s2: Vec3::new(0.0, 0.0, -9.81),
            supports: vec![SceneSupport {
                name: "table".into(),
                top_centre_in_world: Vec3::ZERO,
                normal_in_world: Vec3::Z,
                along_in_world: Vec3::X,
                half_size_m: glam::Vec2::splat(1.0),
                thickness_m: 0.05,
            }],
            bodies: vec![
                body("box <1>", Motion::Dynamic, 0.05),
                body("shelf", Motion::Static, 0.5),
            ],
            exclusions: vec![],
        }
    }

    #[test]
    fn two_body_scene_is_written_with_its_meshes() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_mjcf(dir.path(), &two_body_scene(), &MjcfConfig::default()).unwrap();
        let xml = std::fs::read_to_string(&written.scene_file).unwrap();
        assert!(xml.starts_with("<mujoco model=\"tacmesh\">"));
        assert!(xml.trim_end().ends_with("</mujoco>"));
        // The two bodies and the table's slab, a static body of its own.
        assert_eq!(xml.matches("<body ").count(), 3);
        assert_eq!(xml.matches("</body>").count(), 3);
        // Only the dynamic body moves and has an inertia: 0.001 m³ at 500 kg/m³.
        assert_eq!(xml.matches("<freejoint").count(), 1);
        assert_eq!(xml.matches("<inertial").count(), 1);
        assert!(xml.contains(r#"mass="0.5""#), "{xml}");
        // The name is sanitised and the quaternion is w x y z.
        assert!(
            xml.contains(r#"<body name="box__1_" pos="0 0 0.05" quat="0.9887711 0 0 0.14943814">"#),
            "{xml}"
        );
        // The table is a finite slab, 5 cm thick under its top at z = 0.
        assert!(
            xml.contains(r#"<body name="table" pos="0 0 -0.025" quat="1 0 0 0">"#),
            "{xml}"
        );
        assert!(
            xml.contains(r#"class="support" type="box" size="1 1 0.025""#),
            "{xml}"
        );
        assert!(!xml.contains(r#"type="plane""#), "{xml}");
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

    /// Bodies collide with each other, except the pairs that start inside each other; asked
    /// to, they collide only with the supports and a user's geoms.
    #[test]
    fn bodies_collide_with_each_other_but_for_the_excluded_pairs() {
        let mut scene = two_body_scene();
        scene.exclusions.push(Exclusion {
            a: Member::Body(0),
            b: Member::Support(0),
            depth_m: 0.0123,
        });
        let xml = mjcf_document(&scene, &MjcfConfig::default()).unwrap().xml;
        assert!(!xml.contains(r#"contype="2""#), "{xml}");
        assert!(
            xml.contains(
                r#"<contact>
    <exclude body1="box__1_" body2="table"/> <!-- 12 mm inside each other at the start -->
  </contact>"#
            ),
            "{xml}"
        );
        let apart = MjcfConfig {
            bodies_collide: false,
            ..MjcfConfig::default()
        };
        let xml = mjcf_document(&two_body_scene(), &apart).unwrap().xml;
        assert!(
            xml.contains(r#"<geom contype="2" conaffinity="1" group="3""#),
            "{xml}"
        );
        assert!(!xml.contains("<contact>"), "{xml}");
    }

    #[test]
    fn a_primitive_body_collides_as_the_engines_own_geom() {
        let mut scene = two_body_scene();
        let primitive = crate::primitive::Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.05,
                half_height_m: 0.08,
            },
            rotation: Quat::IDENTITY,
            centre: Vec3::new(0.0, 0.0, 0.01),
            residual_m: 0.002,
        };
        scene.bodies[0].primitive = Some(primitive);
        scene.bodies[0].mass = primitive.mass();
        let document = mjcf_document(&scene, &MjcfConfig::default()).unwrap();
        assert!(
            document.xml.contains(
                r#"class="collision" type="cylinder" size="0.05 0.08" pos="0 0 0.01" quat="1 0 0 0"/>"#
            ),
            "{}",
            document.xml
        );
        // Its parts are not written: the other body's are.
        assert_eq!(
            document
                .xml
                .matches(r#"class="collision" type="mesh""#)
                .count(),
            1
        );
        // A capsule is MuJoCo's own capsule too: radius, then half the axis.
        let capsule = crate::primitive::Primitive {
            shape: PrimitiveShape::Capsule {
                radius_m: 0.03,
                half_height_m: 0.07,
            },
            ..primitive
        };
        scene.bodies[0].primitive = Some(capsule);
        scene.bodies[0].mass = capsule.mass();
        let xml = mjcf_document(&scene, &MjcfConfig::default()).unwrap().xml;
        assert!(
            xml.contains(r#"class="collision" type="capsule" size="0.03 0.07""#),
            "{xml}"
        );
    }

    #[test]
    fn a_slab_is_turned_so_its_z_is_the_normal() {
        let mut scene = two_body_scene();
        scene.supports[0].normal_in_world = Vec3::new(0.0, 1.0, 0.0);
        let xml = mjcf_document(&scene, &MjcfConfig::default()).unwrap().xml;
        // A quarter turn about -X takes +Z to +Y: w = cos 45°, x = -sin 45°.
        assert!(xml.contains(r#"quat="0.7071068 -0.7071068 0 0""#), "{xml}");
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
