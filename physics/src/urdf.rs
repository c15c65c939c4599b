//! The scene as URDF, for the tools that load robots and objects from URDF (ROS, Gazebo's and
//! Isaac's importers, PyBullet's `loadURDF`): `DIR/urdf/NAME.urdf` per body and support, the
//! same meshes as the other writers (`DIR/meshes/*.stl`), and `DIR/urdf/scene.json` saying
//! where each goes.
//!
//! URDF describes one robot, not a world: it has no place for where a robot stands, and its
//! `floating` joint is read by hardly any simulator. So each object is a robot of one link,
//! placed by whoever loads it at the pose `scene.json` gives (PyBullet: `loadURDF(file,
//! basePosition, baseOrientation, useFixedBase=static)`). What each link holds
//! (<http://wiki.ros.org/urdf/XML/link>):
//! - a dynamic body's `<inertial>`: the centre of mass as its origin, the mass at
//!   [`UrdfConfig::density_kg_m3`], the inertia tensor about the centre of mass in the link's
//!   axes (the same signed elements as MJCF's `fullinertia` and SDF's `<inertia>`); a static
//!   one's mass is 0 (PyBullet fixes a base of mass 0) and `scene.json` says `"static": true`;
//! - a primitive body's one `<collision>` as URDF's own `<box>`, `<cylinder>` or `<sphere>`,
//!   any other's one per convex part, and the visual mesh as `<visual>`;
//! - a support is a robot whose link is its slab, a `<box>`, static.
//!
//! `scene.json` also gives the gravity (URDF has none) and the pairs that start inside each
//! other and must not collide with each other (PyBullet: `setCollisionFilterPair`).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use glam::{EulerRot, Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;
use crate::primitive::PrimitiveShape;
use crate::scene::{
    check_scene, number, numbers, write_scene_files, write_whole, Member, Motion, Scene,
    UniqueNames, MESH_FOLDER,
};

/// The folder beside `meshes/` that holds the URDF files and `scene.json`.
pub const URDF_FOLDER: &str = "urdf";

/// How to write the URDF files.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfConfig {
    /// Density of every dynamic body, kg/m³ (default 500, as `crate::MjcfConfig`'s).
    pub density_kg_m3: f32,
}

impl Default for UrdfConfig {
    fn default() -> Self {
        Self {
            density_kg_m3: 500.0,
        }
    }
}

/// The URDF files of a scene, their index and the meshes they name.
#[derive(Debug, Clone, PartialEq)]
pub struct UrdfDocuments {
    /// `(file name in urdf/, text)` per body and support.
    pub robots: Vec<(String, String)>,
    /// `urdf/scene.json`.
    pub index: String,
    /// `(path relative to DIR, mesh)`, written as binary STL.
    pub meshes: Vec<(String, TriMesh)>,
}

/// What [`write_urdf`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WrittenUrdf {
    pub index_file: PathBuf,
    pub robot_files: Vec<PathBuf>,
    pub mesh_files: Vec<PathBuf>,
}

/// `xyz="…" rpy="…"` of a rotation and a translation (URDF's rpy: fixed-axis roll, pitch,
/// yaw, as SDF's).
fn origin(rotation: Quat, translation: Vec3) -> String {
    let (yaw, pitch, roll) = rotation.normalize().to_euler(EulerRot::ZYX);
    format!(
        r#"<origin xyz="{}" rpy="{}"/>"#,
        numbers(&translation.to_array()),
        numbers(&[roll, pitch, yaw])
    )
}

fn mesh_geometry(file: &str) -> String {
    // Relative to the URDF file, which is in urdf/.
    format!(r#"<geometry><mesh filename="../{file}"/></geometry>"#)
}

fn robot(name: &str, link: &str) -> String {
    format!("<?xml version=\"1.0\"?>\n<robot name=\"{name}\">\n  <link name=\"{name}\">\n{link}  </link>\n</robot>\n")
}

/// A JSON string of a sanitised name (`[A-Za-z0-9_.-]`: nothing to escape).
fn json_name(name: &str) -> String {
    format!("\"{name}\"")
}

fn json_numbers(values: &[f32]) -> String {
    format!("[{}]", numbers(values).replace(' ', ", "))
}

/// The URDF text of each body and support of `scene`, the index and the meshes, without
/// writing anything.
pub fn urdf_documents(scene: &Scene, config: &UrdfConfig) -> Result<UrdfDocuments, PhysicsError> {
    check_scene(scene, config.density_kg_m3)?;
    let mut names = UniqueNames::default();
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    let mut robots = Vec::new();
    let mut entries = Vec::new();

    let mut support_names = Vec::with_capacity(scene.supports.len());
    for support in &scene.supports {
        let name = names.claim(&support.name);
        let size = numbers(&(2.0 * support.box_half_size_m()).to_array());
        let link = format!(
            "    <inertial><mass value=\"0\"/><inertia ixx=\"0\" ixy=\"0\" ixz=\"0\" iyy=\"0\" iyz=\"0\" izz=\"0\"/></inertial>\n    <collision><geometry><box size=\"{size}\"/></geometry></collision>\n    <visual><geometry><box size=\"{size}\"/></geometry></visual>\n"
        );
        robots.push((format!("{name}.urdf"), robot(&name, &link)));
        let q = support.rotation();
        entries.push(format!(
            "    {{\"name\": {}, \"file\": \"{name}.urdf\", \"position\": {}, \"orientation_xyzw\": {}, \"static\": true}}",
            json_name(&name),
            json_numbers(&support.box_centre_in_world().to_array()),
            json_numbers(&[q.x, q.y, q.z, q.w]),
        ));
        support_names.push(name);
    }

    let mut body_names = Vec::with_capacity(scene.bodies.len());
    for body in &scene.bodies {
        let name = names.claim(&body.name);
        body_names.push(name.clone());
        let mut link = String::new();
        if body.motion == Motion::Dynamic {
            let density = config.density_kg_m3;
            let i = body.mass.inertia_kg_m2(density);
            let _ = writeln!(
                link,
                r#"    <inertial>{}<mass value="{}"/><inertia ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"/></inertial>"#,
                origin(Quat::IDENTITY, body.mass.centre_of_mass),
                number(body.mass.mass_kg(density)),
                number(i[0][0]),
                number(i[0][1]),
                number(i[0][2]),
                number(i[1][1]),
                number(i[1][2]),
                number(i[2][2]),
            );
        } else {
            let _ = writeln!(
                link,
                r#"    <inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>"#
            );
        }
        // URDF has no capsule: a capsule goes as its covering hull, with the convex parts.
        let native = body.primitive.and_then(|primitive| {
            let geometry = match primitive.shape {
                PrimitiveShape::Box { half_m } => {
                    format!(r#"<box size="{}"/>"#, numbers(&(2.0 * half_m).to_array()))
                }
                PrimitiveShape::Cylinder {
                    radius_m,
                    half_height_m,
                } => format!(
                    r#"<cylinder radius="{}" length="{}"/>"#,
                    number(radius_m),
                    number(2.0 * half_height_m)
                ),
                PrimitiveShape::Sphere { radius_m } => {
                    format!(r#"<sphere radius="{}"/>"#, number(radius_m))
                }
                PrimitiveShape::Capsule { .. } => return None,
            };
            Some((primitive, geometry))
        });
        if let Some((primitive, geometry)) = &native {
            let _ = writeln!(
                link,
                "    <collision>{}<geometry>{geometry}</geometry></collision>",
                origin(primitive.rotation, primitive.centre),
            );
        } else {
            for (k, part) in body.convex_parts.iter().enumerate() {
                let mesh_name = names.claim(&format!("{name}_part{k}"));
                let file = format!("{MESH_FOLDER}/{mesh_name}.stl");
                let _ = writeln!(link, "    <collision>{}</collision>", mesh_geometry(&file));
                meshes.push((file, part.clone()));
            }
        }
        if !body.visual.is_empty() {
            let mesh_name = names.claim(&format!("{name}_visual"));
            let file = format!("{MESH_FOLDER}/{mesh_name}.stl");
            let _ = writeln!(link, "    <visual>{}</visual>", mesh_geometry(&file));
            meshes.push((file, body.visual.clone()));
        }
        robots.push((format!("{name}.urdf"), robot(&name, &link)));
        let pose = body.world_from_body;
        let q = pose.rotation.normalize();
        entries.push(format!(
            "    {{\"name\": {}, \"file\": \"{name}.urdf\", \"position\": {}, \"orientation_xyzw\": {}, \"static\": {}}}",
            json_name(&name),
            json_numbers(&pose.translation_m.to_array()),
            json_numbers(&[q.x, q.y, q.z, q.w]),
            body.motion == Motion::Static,
        ));
    }

    let name = |m: Member| m.of(&support_names, &body_names);
    let pairs: Vec<String> = scene
        .exclusions
        .iter()
        .map(|e| format!("[{}, {}]", json_name(name(e.a)), json_name(name(e.b))))
        .collect();
    let index = format!(
        "{{\n  \"density_kg_m3\": {},\n  \"gravity_m_s2\": {},\n  \"bodies\": [\n{}\n  ],\n  \"no_collision\": [{}]\n}}\n",
        number(config.density_kg_m3),
        json_numbers(&scene.gravity_m_s2.to_array()),
        entries.join(",\n"),
        pairs.join(", "),
    );
    Ok(UrdfDocuments {
        robots,
        index,
        meshes,
    })
}

/// Writes `dir/urdf/*.urdf`, `dir/urdf/scene.json` and `dir/meshes/*.stl` for `scene`: the
/// robots, then the meshes, the index last, so a reader that sees the new index finds
/// everything it names.
pub fn write_urdf(
    dir: &Path,
    scene: &Scene,
    config: &UrdfConfig,
) -> Result<WrittenUrdf, PhysicsError> {
    let documents = urdf_documents(scene, config)?;
    let urdf_dir = dir.join(URDF_FOLDER);
    std::fs::create_dir_all(&urdf_dir).map_err(|source| PhysicsError::Write {
        path: urdf_dir.clone(),
        source,
    })?;
    // The robots here; the meshes and then the index with write_scene_files.
    let mut robot_files = Vec::with_capacity(documents.robots.len());
    for (file, text) in &documents.robots {
        let path = urdf_dir.join(file);
        write_whole(&path, text.as_bytes())?;
        robot_files.push(path);
    }
    let index_name = format!("{URDF_FOLDER}/scene.json");
    let written = write_scene_files(dir, &index_name, &documents.index, &documents.meshes)?;
    Ok(WrittenUrdf {
        index_file: written.scene_file,
        robot_files,
        mesh_files: written.mesh_files,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convex::{convex_parts, ConvexConfig};
    use crate::primitive::Primitive;
    use crate::scene::{Exclusion, SceneBody, SceneSupport, WorldFromBody};
    use tacmesh_sim::cube;

    fn scene() -> Scene {
        let mesh = cube(0.1);
        let parts = convex_parts(&mesh, &ConvexConfig::default()).unwrap();
        let drum = Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.05,
                half_height_m: 0.08,
            },
            rotation: Quat::IDENTITY,
            centre: Vec3::ZERO,
            residual_m: 0.0,
        };
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
                SceneBody {
                    name: "box 1".into(),
                    world_from_body: WorldFromBody {
                        rotation: Quat::from_rotation_z(0.3),
                        translation_m: Vec3::new(0.0, 0.0, 0.05),
                    },
                    visual: mesh.clone(),
                    convex_parts: parts.hulls.clone(),
                    primitive: None,
                    mass: parts.mesh_mass,
                    motion: Motion::Dynamic,
                },
                SceneBody {
                    name: "drum".into(),
                    world_from_body: WorldFromBody {
                        rotation: Quat::IDENTITY,
                        translation_m: Vec3::new(0.3, 0.0, 0.08),
                    },
                    visual: drum.mesh(),
                    convex_parts: vec![drum.mesh()],
                    primitive: Some(drum),
                    mass: drum.mass(),
                    motion: Motion::Dynamic,
                },
            ],
            exclusions: vec![Exclusion {
                a: Member::Body(0),
                b: Member::Body(1),
                depth_m: 0.01,
            }],
        }
    }

    #[test]
    fn each_body_is_a_robot_and_the_index_places_them() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_urdf(dir.path(), &scene(), &UrdfConfig::default()).unwrap();
        assert_eq!(written.robot_files.len(), 3);
        let index = std::fs::read_to_string(&written.index_file).unwrap();
        assert!(
            index.contains(r#""gravity_m_s2": [0, 0, -9.81]"#),
            "{index}"
        );
        assert!(
            index.contains(r#"{"name": "table", "file": "table.urdf", "position": [0, 0, -0.025], "orientation_xyzw": [0, 0, 0, 1], "static": true}"#),
            "{index}"
        );
        assert!(
            index.contains(r#""no_collision": [["box_1", "drum"]]"#),
            "{index}"
        );
        let drum = std::fs::read_to_string(dir.path().join("urdf/drum.urdf")).unwrap();
        assert!(
            drum.contains(r#"<geometry><cylinder radius="0.05" length="0.16"/></geometry>"#),
            "{drum}"
        );
        let boxed = std::fs::read_to_string(dir.path().join("urdf/box_1.urdf")).unwrap();
        // 0.001 m³ at 500 kg/m³, parts and visual as meshes beside the other writers'.
        assert!(boxed.contains(r#"<mass value="0.5"/>"#), "{boxed}");
        assert!(
            boxed.contains(r#"<mesh filename="../meshes/box_1_part0.stl"/>"#),
            "{boxed}"
        );
        for file in &written.mesh_files {
            assert!(file.exists(), "{}", file.display());
        }
    }
}
