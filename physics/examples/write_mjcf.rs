//! Writes a demo MuJoCo scene: a 10 cm cube resting on the floor and a 5 cm sphere dropped
//! beside it, each with its convex parts and mass properties, a static box, and a desk top
//! 0.4 m up with a cube on it and another on the floor under it (where an infinite plane of the
//! desk would swallow it). Each support is a finite slab.
//!
//! `cargo run -p tacmesh-physics --example write_mjcf -- DIR [--up z|y] [--sdf]`
//!
//! `--up y` builds the same scene in a world whose up is +Y (gravity along -Y, the plane's
//! normal +Y), as a camera's frame might be. `python/tests/test_mjcf.py` loads and steps it.
//! `--sdf` writes the same scene as an SDF world (DIR/scene.sdf) instead, which
//! `python/tests/test_sdf.py` loads in PyBullet.

use std::path::PathBuf;
use std::process::ExitCode;

use glam::{Quat, Vec3};
use tacmesh_physics::{
    convex_parts, write_mjcf, write_sdf, ConvexConfig, MjcfConfig, Motion, PhysicsError, Primitive,
    PrimitiveShape, Scene, SceneBody, SceneSupport, SdfConfig, TriMesh, WorldFromBody,
};
use tacmesh_sim::{cube, uv_sphere};

/// A body whose collision parts and inertia come from its mesh.
fn body(
    name: &str,
    mesh: TriMesh,
    world_from_body: WorldFromBody,
    motion: Motion,
) -> Result<SceneBody, PhysicsError> {
    let parts = convex_parts(&mesh, &ConvexConfig::default())?;
    Ok(SceneBody {
        name: name.into(),
        world_from_body,
        visual: mesh,
        convex_parts: parts.hulls,
        primitive: None,
        mass: parts.mesh_mass,
        motion,
    })
}

/// A body that is a primitive: a standing cylinder 16 cm tall, 5 cm in radius, written as the
/// engine's own cylinder.
fn drum(world_from_body: WorldFromBody) -> SceneBody {
    let primitive = Primitive {
        shape: PrimitiveShape::Cylinder {
            radius_m: 0.05,
            half_height_m: 0.08,
        },
        rotation: Quat::IDENTITY,
        centre: Vec3::ZERO,
        residual_m: 0.0,
    };
    SceneBody {
        name: "drum".into(),
        world_from_body,
        visual: primitive.mesh(),
        convex_parts: vec![primitive.mesh()],
        primitive: Some(primitive),
        mass: primitive.mass(),
        motion: Motion::Dynamic,
    }
}

fn demo_scene(up: Vec3) -> Result<Scene, PhysicsError> {
    // Turns the z-up layout into the requested up.
    let world_from_layout = Quat::from_rotation_arc(Vec3::Z, up);
    let at = |p: Vec3, yaw: f32| WorldFromBody {
        rotation: world_from_layout * Quat::from_rotation_z(yaw),
        translation_m: world_from_layout * p,
    };
    let slab = |name: &str, centre: Vec3, half: glam::Vec2| SceneSupport {
        name: name.into(),
        top_centre_in_world: world_from_layout * centre,
        normal_in_world: up,
        along_in_world: world_from_layout * Vec3::X,
        half_size_m: half,
        thickness_m: 0.05,
    };
    Ok(Scene {
        gravity_m_s2: -9.81 * up,
        supports: vec![
            slab("table", Vec3::ZERO, glam::Vec2::splat(1.0)),
            slab(
                "desk",
                Vec3::new(0.6, 0.0, 0.4),
                glam::Vec2::new(0.25, 0.15),
            ),
        ],
        exclusions: vec![],
        bodies: vec![
            // Resting: its lowest face on the plane.
            body(
                "cube",
                cube(0.1),
                at(Vec3::new(0.0, 0.0, 0.05), 0.4),
                Motion::Dynamic,
            )?,
            body(
                "sphere",
                uv_sphere(16, 8, 0.05),
                at(Vec3::new(0.0, 0.3, 0.2), 0.0),
                Motion::Dynamic,
            )?,
            body(
                "on_desk",
                cube(0.1),
                at(Vec3::new(0.6, 0.0, 0.45), 0.2),
                Motion::Dynamic,
            )?,
            drum(at(Vec3::new(-0.2, -0.3, 0.08), 0.0)),
            body(
                "under_desk",
                cube(0.1),
                at(Vec3::new(0.6, 0.0, 0.05), -0.3),
                Motion::Dynamic,
            )?,
            body(
                "wall",
                cube(0.2),
                at(Vec3::new(-0.5, 0.0, 0.1), 0.0),
                Motion::Static,
            )?,
        ],
    })
}

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let sdf = args.iter().any(|a| a == "--sdf");
    args.retain(|a| a != "--sdf");
    let (dir, up) = match args.as_slice() {
        [dir] => (PathBuf::from(dir), Vec3::Z),
        [dir, flag, axis] if flag == "--up" && axis == "z" => (PathBuf::from(dir), Vec3::Z),
        [dir, flag, axis] if flag == "--up" && axis == "y" => (PathBuf::from(dir), Vec3::Y),
        _ => {
            eprintln!("usage: write_mjcf DIR [--up z|y] [--sdf]");
            return ExitCode::from(2);
        }
    };
    let written = demo_scene(up).and_then(|scene| {
        if sdf {
            write_sdf(&dir, &scene, &SdfConfig::default())
        } else {
            write_mjcf(&dir, &scene, &MjcfConfig::default())
        }
    });
    match written {
        Ok(written) => {
            println!("{}", written.scene_file.display());
            ExitCode::SUCCESS
        }
        Err(e) => {
            eprintln!("write_mjcf: {e}");
            ExitCode::FAILURE
        }
    }
}
