//! An SDFormat world of tacmesh's objects (`scene.sdf` and one binary STL per mesh), for the
//! simulators that read SDF: Gazebo loads it as a world, PyBullet with `loadSDF`.
//!
//! The same [`Scene`] as the MuJoCo writer (`crate::mjcf`) and the same meshes (same names,
//! same `meshes/` folder), so both files can sit side by side. What each part becomes
//! (SDFormat 1.6, <http://sdformat.org/spec?ver=1.6>):
//! - a body is a `<model>` at its pose (`<pose>` x y z roll pitch yaw: rotation
//!   Rz(yaw)·Ry(pitch)·Rx(roll)), `<static>` 1 when it may not move (PyBullet reads `1`, not
//!   `true`), with one `<link>`;
//! - a body that is a primitive collides as SDFormat's own `<box>`, `<cylinder>` or
//!   `<sphere>`; any other has one `<collision>` per convex part (Gazebo's and Bullet's mesh collisions are convex
//!   hulls, as MuJoCo's are), and the visual mesh as a `<visual>` (never collides);
//! - a dynamic body's `<inertial>`: the centre of mass as its pose, the mass at
//!   [`SdfConfig::density_kg_m3`], the inertia tensor's six elements about the centre of mass
//!   (the same signed elements as MJCF's `fullinertia`). Gazebo takes them; PyBullet's
//!   `loadSDF` takes the mass but computes its own inertia from the collision shapes;
//! - bodies collide with each other unless [`SdfConfig::bodies_collide`] is off: then each
//!   body's collisions get a `collide_bitmask` of their own bit and the supports all bits
//!   (Gazebo collides two shapes when their masks share a bit). There are 16 bits: the 17th
//!   body shares the first one's. SDFormat has no filter for one pair, so the pairs of
//!   [`Scene::exclusions`] (they start inside each other) are listed in a comment: PyBullet
//!   does not read masks either, and its user filters those pairs with
//!   `setCollisionFilterPair`;
//! - a support is a static model with a `<box>` collision, the slab of [`SceneSupport`]
//!   (`crate::scene::SceneSupport`): finite, because an engine's plane is an infinite
//!   half-space;
//! - gravity is the world's `<gravity>` vector (its Z need not be up). Gazebo reads it;
//!   PyBullet's `loadSDF` does not (its user calls `setGravity` with the same vector, which
//!   the file's first comment gives).

use std::fmt::Write as _;
use std::path::Path;

use glam::{EulerRot, Quat, Vec3};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;
use crate::primitive::PrimitiveShape;
use crate::scene::{
    check_scene, number, numbers, sanitise, write_scene_files, Member, Motion, Scene, UniqueNames,
    WrittenScene, MESH_FOLDER,
};

/// How to write an SDF world.
#[derive(Debug, Clone, PartialEq)]
pub struct SdfConfig {
    /// Density of every dynamic body, kg/m³ (default 500, as `crate::MjcfConfig`'s).
    pub density_kg_m3: f32,
    /// The `<world name>`.
    pub world_name: String,
    /// Whether the bodies collide with each other (default yes, as
    /// `crate::MjcfConfig::bodies_collide`).
    pub bodies_collide: bool,
}

impl Default for SdfConfig {
    fn default() -> Self {
        Self {
            density_kg_m3: 500.0,
            world_name: "tacmesh".into(),
            bodies_collide: true,
        }
    }
}

/// A world as text and the meshes its `<uri>`s name (paths relative to the file).
#[derive(Debug, Clone, PartialEq)]
pub struct SdfDocument {
    pub xml: String,
    /// `(relative path, mesh)` for each mesh, written as binary STL.
    pub meshes: Vec<(String, TriMesh)>,
}

/// Bits of Gazebo's `collide_bitmask` (an unsigned 16-bit mask; 0xffff collides with all).
const MASK_BITS: usize = 16;
const ALL_BITS: u32 = 0xffff;

/// `x y z roll pitch yaw` of a rotation and a translation.
fn sdf_pose(rotation: Quat, translation_m: Vec3) -> String {
    // EulerRot::ZYX gives (yaw, pitch, roll) with rotation = Rz(yaw)·Ry(pitch)·Rx(roll), the
    // fixed-axis roll-pitch-yaw SDF means.
    let (yaw, pitch, roll) = rotation.normalize().to_euler(EulerRot::ZYX);
    let mut values = translation_m.to_array().to_vec();
    values.extend([roll, pitch, yaw]);
    numbers(&values)
}

fn mesh_geometry(uri: &str) -> String {
    format!("<geometry><mesh><uri>{uri}</uri></mesh></geometry>")
}

/// The SDF text of `scene` and the meshes it refers to, without writing anything.
pub fn sdf_document(scene: &Scene, config: &SdfConfig) -> Result<SdfDocument, PhysicsError> {
    check_scene(scene, config.density_kg_m3)?;
    let mut names = UniqueNames::default();
    let mut meshes: Vec<(String, TriMesh)> = Vec::new();
    let mut world = String::new();

    // `write!` to a String cannot fail; the results are ignored on purpose below.
    let mut support_names = Vec::with_capacity(scene.supports.len());
    for support in &scene.supports {
        let name = names.claim(&support.name);
        support_names.push(name.clone());
        let size = numbers(&(2.0 * support.box_half_size_m()).to_array());
        let plane = format!("<geometry><box><size>{size}</size></box></geometry>");
        let _ = writeln!(
            world,
            r#"    <model name="{name}">
      <static>1</static>
      <pose>{}</pose>
      <link name="{name}_link">
        <collision name="{name}_collision">{plane}</collision>
        <visual name="{name}_visual">{plane}</visual>
      </link>
    </model>"#,
            sdf_pose(support.rotation(), support.box_centre_in_world()),
        );
    }

    let mut body_names = Vec::with_capacity(scene.bodies.len());
    for (index, body) in scene.bodies.iter().enumerate() {
        let name = names.claim(&body.name);
        body_names.push(name.clone());
        let pose = body.world_from_body;
        let _ = writeln!(
            world,
            r#"    <model name="{name}">
      <static>{}</static>
      <pose>{}</pose>
      <link name="{name}_link">"#,
            u8::from(body.motion == Motion::Static),
            sdf_pose(pose.rotation, pose.translation_m),
        );
        if body.motion == Motion::Dynamic {
            let density = config.density_kg_m3;
            let i = body.mass.inertia_kg_m2(density);
            let _ = writeln!(
                world,
                r#"        <inertial>
          <pose>{}</pose>
          <mass>{}</mass>
          <inertia><ixx>{}</ixx><ixy>{}</ixy><ixz>{}</ixz><iyy>{}</iyy><iyz>{}</iyz><izz>{}</izz></inertia>
        </inertial>"#,
                sdf_pose(Quat::IDENTITY, body.mass.centre_of_mass),
                number(body.mass.mass_kg(density)),
                number(i[0][0]),
                number(i[0][1]),
                number(i[0][2]),
                number(i[1][1]),
                number(i[1][2]),
                number(i[2][2]),
            );
        }
        let surface = if config.bodies_collide {
            String::new()
        } else {
            let bit = 1u32 << (index % MASK_BITS);
            format!(
                "<surface><contact><collide_bitmask>{bit}</collide_bitmask></contact></surface>"
            )
        };
        // SDFormat has a capsule only from 1.8 on, and this world is 1.6 (what Gazebo Classic
        // and PyBullet read): a capsule goes as its covering hull, with the convex parts.
        let native = body.primitive.and_then(|primitive| {
            let geometry = match primitive.shape {
                PrimitiveShape::Box { half_m } => {
                    format!(
                        "<box><size>{}</size></box>",
                        numbers(&(2.0 * half_m).to_array())
                    )
                }
                PrimitiveShape::Cylinder {
                    radius_m,
                    half_height_m,
                } => format!(
                    "<cylinder><radius>{}</radius><length>{}</length></cylinder>",
                    number(radius_m),
                    number(2.0 * half_height_m)
                ),
                PrimitiveShape::Sphere { radius_m } => {
                    format!("<sphere><radius>{}</radius></sphere>", number(radius_m))
                }
                PrimitiveShape::Capsule { .. } => return None,
            };
            Some((primitive, geometry))
        });
        if let Some((primitive, geometry)) = &native {
            // The engine's own shape: exact contact, true normals.
            let geom_name = names.claim(&format!("{name}_{}", primitive.shape.name()));
            let _ = writeln!(
                world,
                r#"        <collision name="{geom_name}"><pose>{}</pose><geometry>{geometry}</geometry>{surface}</collision>"#,
                sdf_pose(primitive.rotation, primitive.centre),
            );
        }
        let parts = if native.is_some() {
            &[][..]
        } else {
            &body.convex_parts[..]
        };
        for (k, part) in parts.iter().enumerate() {
            let mesh_name = names.claim(&format!("{name}_part{k}"));
            let uri = format!("{MESH_FOLDER}/{mesh_name}.stl");
            let _ = writeln!(
                world,
                r#"        <collision name="{mesh_name}">{}{surface}</collision>"#,
                mesh_geometry(&uri),
            );
            meshes.push((uri, part.clone()));
        }
        if !body.visual.is_empty() {
            let mesh_name = names.claim(&format!("{name}_visual"));
            let uri = format!("{MESH_FOLDER}/{mesh_name}.stl");
            let _ = writeln!(
                world,
                r#"        <visual name="{mesh_name}">{}</visual>"#,
                mesh_geometry(&uri),
            );
            meshes.push((uri, body.visual.clone()));
        }
        let _ = writeln!(world, "      </link>\n    </model>");
    }

    let supports_mask = if config.bodies_collide {
        String::new()
    } else {
        format!(" Supports collide with every body (collide_bitmask {ALL_BITS:#x}, the default);\n       bodies not with each other (a bit each).")
    };
    let mut excluded = String::new();
    for exclusion in &scene.exclusions {
        let name = |m: Member| m.of(&support_names, &body_names);
        let _ = write!(
            excluded,
            "\n       {} and {} ({} mm)",
            name(exclusion.a),
            name(exclusion.b),
            number((exclusion.depth_m * 1e3).round()),
        );
    }
    if !excluded.is_empty() {
        excluded = format!(
            "\n       These pairs start inside each other and are not to collide with each other \
             (SDFormat\n       cannot say so; in PyBullet: setCollisionFilterPair(a, b, -1, -1, 0)):{excluded}"
        );
    }
    let mut xml = String::new();
    let _ = writeln!(
        xml,
        r#"<?xml version="1.0"?>
<sdf version="1.6">
  <!-- Written by tacmesh: bodies at their poses, collision from convex parts, inertia from
       the meshes at {} kg/m3.{supports_mask}
       Gravity {} m/s2: PyBullet's loadSDF does not read <gravity>; call setGravity({}).{excluded}
  -->
  <world name="{}">
    <gravity>{}</gravity>
{world}  </world>
</sdf>"#,
        config.density_kg_m3,
        numbers(&scene.gravity_m_s2.to_array()),
        numbers(&scene.gravity_m_s2.to_array()).replace(' ', ", "),
        sanitise(&config.world_name),
        numbers(&scene.gravity_m_s2.to_array()),
    );
    Ok(SdfDocument { xml, meshes })
}

/// Writes `dir/scene.sdf` and `dir/meshes/*.stl` for `scene` (creating the folders), meshes
/// first, so a reader that sees the new `scene.sdf` finds every mesh it names.
pub fn write_sdf(
    dir: &Path,
    scene: &Scene,
    config: &SdfConfig,
) -> Result<WrittenScene, PhysicsError> {
    let document = sdf_document(scene, config)?;
    write_scene_files(dir, "scene.sdf", &document.xml, &document.meshes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::convex::{convex_parts, ConvexConfig};
    use crate::scene::{Exclusion, SceneBody, SceneSupport, WorldFromBody};
    use tacmesh_sim::cube;

    fn scene(bodies: usize) -> Scene {
        let mesh = cube(0.1);
        let parts = convex_parts(&mesh, &ConvexConfig::default()).unwrap();
        Scene {
            gravity_m_s2: Vec3::new(0.0, -9.81, 0.0),
            supports: vec![SceneSupport {
                name: "table".into(),
                top_centre_in_world: Vec3::ZERO,
                normal_in_world: Vec3::Y,
                along_in_world: Vec3::X,
                half_size_m: glam::Vec2::splat(1.0),
                thickness_m: 0.04,
            }],
            bodies: (0..bodies)
                .map(|k| SceneBody {
                    name: format!("box {k}"),
                    world_from_body: WorldFromBody {
                        rotation: Quat::from_rotation_y(0.3),
                        translation_m: Vec3::new(0.2 * k as f32, 0.05, 0.0),
                    },
                    visual: mesh.clone(),
                    convex_parts: parts.hulls.clone(),
                    primitive: None,
                    mass: parts.mesh_mass,
                    motion: if k == 0 {
                        Motion::Static
                    } else {
                        Motion::Dynamic
                    },
                })
                .collect(),
            exclusions: vec![],
        }
    }

    #[test]
    fn world_is_written_with_its_meshes() {
        let dir = tempfile::tempdir().unwrap();
        let written = write_sdf(dir.path(), &scene(2), &SdfConfig::default()).unwrap();
        let xml = std::fs::read_to_string(&written.scene_file).unwrap();
        assert!(xml.starts_with("<?xml version=\"1.0\"?>\n<sdf version=\"1.6\">"));
        assert!(xml.trim_end().ends_with("</sdf>"));
        assert!(xml.contains("<gravity>0 -9.81 0</gravity>"), "{xml}");
        // The support and two bodies, the first static; only the dynamic one has an inertia.
        assert_eq!(xml.matches("<model ").count(), 3);
        assert_eq!(xml.matches("<static>1</static>").count(), 2);
        assert_eq!(xml.matches("<inertial>").count(), 1);
        // 0.001 m³ at 500 kg/m³; a cube's Ixx = m (a² + a²) / 12 about its centre.
        assert!(xml.contains("<mass>0.5</mass>"), "{xml}");
        // The table: a 2 m × 2 m slab 4 cm thick under its top at y = 0 (its z turned onto +y).
        assert!(
            xml.contains("<geometry><box><size>2 2 0.04</size></box></geometry>"),
            "{xml}"
        );
        assert!(
            xml.contains("<pose>0 -0.02 0 -1.5707964 0 0</pose>"),
            "{xml}"
        );
        assert!(xml.contains("call setGravity(0, -9.81, 0)"), "{xml}");
        // Names sanitised, a collision per part, a visual per body.
        assert!(xml.contains(r#"<model name="box_1">"#), "{xml}");
        assert!(!xml.contains("collide_bitmask"), "{xml}");
        assert_eq!(xml.matches("<visual name=\"box_").count(), 2);
        assert_eq!(written.mesh_files.len(), 4);
        for file in &written.mesh_files {
            let relative = file.strip_prefix(dir.path()).unwrap().to_str().unwrap();
            assert!(
                xml.contains(&format!("<uri>{relative}</uri>")),
                "{relative}"
            );
        }
    }

    /// The number between `<tag>` and `</tag>`, first occurrence.
    fn element(xml: &str, tag: &str) -> f32 {
        let open = format!("<{tag}>");
        let start = xml.find(&open).unwrap() + open.len();
        let end = start + xml[start..].find('<').unwrap();
        xml[start..end].parse().unwrap()
    }

    #[test]
    fn inertia_elements_are_the_tensor_about_the_centre_of_mass() {
        let xml = sdf_document(&scene(2), &SdfConfig::default()).unwrap().xml;
        // A 0.1 m cube of 0.5 kg: Ixx = m (a² + a²) / 12 about its centre, no products.
        let ixx = 0.5 * (0.1 * 0.1 + 0.1 * 0.1) / 12.0;
        for (tag, expected) in [
            ("ixx", ixx),
            ("iyy", ixx),
            ("izz", ixx),
            ("ixy", 0.0),
            ("ixz", 0.0),
            ("iyz", 0.0),
        ] {
            let value = element(&xml, tag);
            assert!(
                (value - expected).abs() < 1e-8,
                "{tag} = {value}, expected {expected}"
            );
        }
        assert!(
            xml.contains("<inertial>\n          <pose>0 0 0 0 0 0</pose>"),
            "{xml}"
        );
    }

    #[test]
    fn pose_is_roll_pitch_yaw_about_fixed_axes() {
        let rotation =
            Quat::from_rotation_z(0.7) * Quat::from_rotation_y(-0.4) * Quat::from_rotation_x(0.2);
        let text = sdf_pose(rotation, Vec3::new(1.0, 2.0, 3.0));
        let values: Vec<f32> = text.split(' ').map(|v| v.parse().unwrap()).collect();
        assert_eq!(&values[..3], &[1.0, 2.0, 3.0]);
        let (roll, pitch, yaw) = (values[3], values[4], values[5]);
        assert!(
            (roll - 0.2).abs() < 1e-5 && (pitch + 0.4).abs() < 1e-5 && (yaw - 0.7).abs() < 1e-5,
            "{text}"
        );
    }

    #[test]
    fn pairs_that_start_inside_each_other_are_named_and_masks_wrap_after_sixteen() {
        let mut overlapping = scene(2);
        overlapping.exclusions.push(Exclusion {
            a: Member::Body(0),
            b: Member::Body(1),
            depth_m: 0.02,
        });
        let xml = sdf_document(&overlapping, &SdfConfig::default())
            .unwrap()
            .xml;
        // Each pair ends its line, the last too: a reader matching `A and B (N mm)` to the
        // end of a line (as the Python tests and the benchmark do) once missed the last pair,
        // which ended in ` -->`, and PyBullet pushed those two bodies apart.
        assert!(xml.contains("box_0 and box_1 (20 mm)\n"), "{xml}");
        let apart = SdfConfig {
            bodies_collide: false,
            ..SdfConfig::default()
        };
        let xml = sdf_document(&scene(18), &apart).unwrap().xml;
        // Body 16 (the 17th) takes body 0's bit.
        assert!(xml.contains(&format!(
            "<collide_bitmask>{}</collide_bitmask>",
            1u32 << 15
        )));
        assert_eq!(
            xml.matches("<collide_bitmask>1</collide_bitmask>").count(),
            2
        );
    }

    #[test]
    fn a_primitive_body_collides_as_sdformats_own_shape() {
        let mut scene = scene(2);
        let primitive = crate::primitive::Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.05,
                half_height_m: 0.08,
            },
            rotation: Quat::IDENTITY,
            centre: Vec3::ZERO,
            residual_m: 0.002,
        };
        scene.bodies[1].primitive = Some(primitive);
        scene.bodies[1].mass = primitive.mass();
        let xml = sdf_document(&scene, &SdfConfig::default()).unwrap().xml;
        assert!(
            xml.contains("<geometry><cylinder><radius>0.05</radius><length>0.16</length></cylinder></geometry>"),
            "{xml}"
        );
        // A capsule goes as the body's convex parts (its covering hull): SDFormat 1.6 has none.
        scene.bodies[1].primitive = Some(crate::primitive::Primitive {
            shape: PrimitiveShape::Capsule {
                radius_m: 0.03,
                half_height_m: 0.07,
            },
            ..primitive
        });
        let xml = sdf_document(&scene, &SdfConfig::default()).unwrap().xml;
        assert!(!xml.contains("capsule>"), "{xml}");
        assert!(xml.contains(r#"<collision name="box_1_part0">"#), "{xml}");
    }

    #[test]
    fn dynamic_body_without_parts_is_refused() {
        let mut scene = scene(2);
        scene.bodies[1].convex_parts.clear();
        let error = sdf_document(&scene, &SdfConfig::default()).unwrap_err();
        assert!(matches!(error, PhysicsError::InvalidScene(_)), "{error}");
    }
}
