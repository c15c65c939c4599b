//! Seeded views of convex shapes, so the tests read like scripts.

use std::time::Duration;

use glam::{Affine3A, Quat, Vec3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use tacmesh_track::{FrameClusters, ObjectMap, TrackConfig};

pub const FRAME: Duration = Duration::from_nanos(33_333_333);

pub fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

fn gaussian3(rng: &mut ChaCha8Rng) -> Vec3 {
    Vec3::new(
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
        rng.sample(StandardNormal),
    )
}

/// A convex shape at a pose, whose visible points a camera samples.
#[derive(Debug, Clone, Copy)]
pub enum Body {
    Sphere {
        radius_m: f32,
    },
    Cube {
        half_m: f32,
    },
    /// Its axis along the body's +z from the base (at z = 0, not sampled: it stands on
    /// something) to the apex.
    Cone {
        radius_m: f32,
        height_m: f32,
    },
}

/// `n` points on the part of `body` (placed by `world_from_body`) facing `viewpoint`, as
/// dense per projected area as a depth camera's, with isotropic Gaussian noise of `sigma_m`.
pub fn view(
    body: Body,
    world_from_body: Affine3A,
    viewpoint: Vec3,
    n: usize,
    sigma_m: f32,
    rng: &mut ChaCha8Rng,
) -> Vec<Vec3> {
    let mut points = Vec::with_capacity(n);
    let mut tries = 0;
    while points.len() < n && tries < n * 100 {
        tries += 1;
        let (p_in_body, n_in_body) = match body {
            Body::Sphere { radius_m } => {
                let dir = gaussian3(rng).normalize_or(Vec3::Z);
                (dir * radius_m, dir)
            }
            Body::Cube { half_m } => {
                let axis = rng.random_range(0..3usize);
                let sign = if rng.random::<bool>() { 1.0 } else { -1.0 };
                let mut normal = Vec3::ZERO;
                normal[axis] = sign;
                let mut p = Vec3::new(
                    rng.random_range(-half_m..half_m),
                    rng.random_range(-half_m..half_m),
                    rng.random_range(-half_m..half_m),
                );
                p[axis] = sign * half_m;
                (p, normal)
            }
            Body::Cone { radius_m, height_m } => {
                // Uniform over the side: the radius at a uniform area fraction goes as its
                // square root.
                let r = radius_m * rng.random::<f32>().sqrt();
                let angle = rng.random_range(0.0..std::f32::consts::TAU);
                let radial = Vec3::new(angle.cos(), angle.sin(), 0.0);
                let z = height_m * (1.0 - r / radius_m);
                let normal = (radial * height_m + Vec3::Z * radius_m).normalize();
                (radial * r + Vec3::Z * z, normal)
            }
        };
        let p = world_from_body.transform_point3(p_in_body);
        let normal = world_from_body.transform_vector3(n_in_body);
        // A depth camera's samples per area fall with the cosine of the viewing angle, so a
        // face turning into view gains points gradually.
        let facing = normal.dot((viewpoint - p).normalize_or_zero());
        if facing > 0.0 && rng.random::<f32>() < facing {
            points.push(p + gaussian3(rng) * sigma_m);
        }
    }
    points
}

pub fn at(x: f32, y: f32, z: f32) -> Affine3A {
    Affine3A::from_translation(Vec3::new(x, y, z))
}

pub fn posed(rotation: Quat, translation: Vec3) -> Affine3A {
    Affine3A::from_rotation_translation(rotation, translation)
}

/// Translation (m) and rotation (rad) of `a⁻¹ · b`.
pub fn pose_error(a: &Affine3A, b: &Affine3A) -> (f32, f32) {
    let d = a.inverse() * *b;
    let angle = Quat::from_mat3a(&d.matrix3).angle_between(Quat::IDENTITY);
    (Vec3::from(d.translation).length(), angle)
}

pub fn frame(index: u32, clusters: Vec<Vec<Vec3>>) -> FrameClusters {
    FrameClusters {
        capture_time: FRAME * index,
        viewpoint_m: Vec3::ZERO,
        clusters,
        free_space: None,
    }
}

pub fn map() -> ObjectMap {
    ObjectMap::new(TrackConfig::default()).expect("default config is valid")
}
