//! Primitives where an object is one: a box, a cylinder or a capsule (standing or lying) or a
//! sphere fitted
//! to what was seen of it. A physics engine collides primitives exactly and cheaply, with true
//! contact normals, and their mass properties are those of the whole object, where a one-view
//! shell's shadow volume weighs two to twenty times the truth.
//!
//! A fit is accepted only when every part of what was seen is explained: the 95th percentile
//! of the seen points' distances from the primitive's surface within the caller's bound (the
//! shape's residual bound and the sensor's noise, and, for fused points, their own scatter
//! about their surface: [`FusedPoints`]), and the primitive resting on the support the object
//! stands on. A box is fitted only when its top was seen (else its depth is a guess),
//! a standing cylinder only when its wall was.
//!
//! The fits are this project's own (no crate fits primitives to partial, one-sided views with a
//! support): algebraic circle and sphere fits (Kåsa 1976) refined by a few Gauss–Newton steps,
//! and the footprint's smallest rectangle ([`crate::min_area_rectangle`]).

use glam::{DMat3, DVec3, Mat3, Quat, Vec2, Vec3};
use parry3d::shape::{Ball, Capsule, Cuboid, Cylinder};
use tacmesh_source::TriMesh;

use crate::mass::MassProperties;
use crate::proxy::SupportPlane;

/// What kind of primitive, with its sizes (in its own frame: a box's sides along x, y, z; a
/// cylinder's and a capsule's axis along z, centred on its origin; a sphere about its origin).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PrimitiveShape {
    Box {
        half_m: Vec3,
    },
    Cylinder {
        radius_m: f32,
        half_height_m: f32,
    },
    Sphere {
        radius_m: f32,
    },
    /// The segment from −`half_height_m` to `half_height_m` on z, grown by `radius_m`
    /// (MuJoCo's and Bullet's capsule).
    Capsule {
        radius_m: f32,
        half_height_m: f32,
    },
}

/// A primitive placed in an object's frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Primitive {
    pub shape: PrimitiveShape,
    /// From the primitive's frame to the object's.
    pub rotation: Quat,
    pub centre: Vec3,
    /// The 95th percentile of the seen points' distances from its surface, metres.
    pub residual_m: f32,
}

impl PrimitiveShape {
    /// A short name: `box`, `cylinder`, `sphere`, `capsule`.
    pub fn name(&self) -> &'static str {
        match self {
            PrimitiveShape::Box { .. } => "box",
            PrimitiveShape::Cylinder { .. } => "cylinder",
            PrimitiveShape::Sphere { .. } => "sphere",
            PrimitiveShape::Capsule { .. } => "capsule",
        }
    }

    /// How far the shape reaches along the unit direction `n` (its own frame) from its centre:
    /// its support function.
    pub fn reach(&self, n: Vec3) -> f32 {
        match *self {
            PrimitiveShape::Sphere { radius_m } => radius_m,
            PrimitiveShape::Box { half_m } => (n.abs() * half_m).element_sum(),
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            } => n.z.abs() * half_height_m + radius_m * Vec2::new(n.x, n.y).length(),
            PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => n.z.abs() * half_height_m + radius_m,
        }
    }

    /// Signed distance of `q` (the primitive's frame) from its surface: negative inside.
    pub fn signed_distance(&self, q: Vec3) -> f32 {
        match *self {
            PrimitiveShape::Sphere { radius_m } => q.length() - radius_m,
            PrimitiveShape::Box { half_m } => {
                let d = q.abs() - half_m;
                d.max(Vec3::ZERO).length() + d.max_element().min(0.0)
            }
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            } => {
                let d = Vec2::new(
                    Vec2::new(q.x, q.y).length() - radius_m,
                    q.z.abs() - half_height_m,
                );
                d.max(Vec2::ZERO).length() + d.max_element().min(0.0)
            }
            PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => {
                let on_axis = Vec3::new(0.0, 0.0, q.z.clamp(-half_height_m, half_height_m));
                q.distance(on_axis) - radius_m
            }
        }
    }

    /// Volume, m³.
    pub fn volume_m3(&self) -> f32 {
        match *self {
            PrimitiveShape::Sphere { radius_m: r } => 4.0 / 3.0 * std::f32::consts::PI * r.powi(3),
            PrimitiveShape::Box { half_m } => 8.0 * half_m.x * half_m.y * half_m.z,
            PrimitiveShape::Cylinder {
                radius_m: r,
                half_height_m: h,
            } => std::f32::consts::PI * r * r * 2.0 * h,
            PrimitiveShape::Capsule {
                radius_m: r,
                half_height_m: h,
            } => std::f32::consts::PI * r * r * (2.0 * h + 4.0 / 3.0 * r),
        }
    }

    /// Principal moments of inertia about the centre at unit density (m⁵), along x, y, z.
    fn principal_moments(&self) -> Vec3 {
        let v = self.volume_m3();
        match *self {
            PrimitiveShape::Sphere { radius_m: r } => Vec3::splat(0.4 * v * r * r),
            PrimitiveShape::Box { half_m } => {
                let s = 2.0 * half_m;
                let (x2, y2, z2) = (s.x * s.x, s.y * s.y, s.z * s.z);
                Vec3::new(y2 + z2, x2 + z2, x2 + y2) * (v / 12.0)
            }
            PrimitiveShape::Cylinder {
                radius_m: r,
                half_height_m: h,
            } => {
                let across = v * (3.0 * r * r + 4.0 * h * h) / 12.0;
                Vec3::new(across, across, 0.5 * v * r * r)
            }
            PrimitiveShape::Capsule {
                radius_m: r,
                half_height_m: h,
            } => {
                // The cylinder between the caps, and the two hemispheres: each of half the
                // ball's volume, its own moment across 83/320 m r² about its centroid, 3r/8
                // from its flat face (at ±h).
                let cylinder = std::f32::consts::PI * r * r * 2.0 * h;
                let ball = 4.0 / 3.0 * std::f32::consts::PI * r.powi(3);
                let across = cylinder * (r * r / 4.0 + h * h / 3.0)
                    + ball * (83.0 / 320.0 * r * r + (h + 3.0 * r / 8.0).powi(2));
                Vec3::new(across, across, cylinder * r * r / 2.0 + ball * 0.4 * r * r)
            }
        }
    }
}

impl Primitive {
    /// Distance of `p` (the object's frame) from the surface, signed: negative inside.
    pub fn signed_distance(&self, p: Vec3) -> f32 {
        self.shape
            .signed_distance(self.rotation.inverse() * (p - self.centre))
    }

    /// A closed, outward tessellation in the object's frame (a box's 8 corners, a cylinder of
    /// 24 sides, a sphere of 16 × 8), for what needs a mesh: the convex parts an engine without
    /// the primitive collides with, the overlap and footprint checks.
    pub fn mesh(&self) -> TriMesh {
        self.mesh_with(24, 8)
    }

    /// As [`Primitive::mesh`], with `around` sides to a cylinder and a sphere, and `rings`
    /// rings to a sphere (fine enough to measure contact against: 128 × 64 is within 0.03 %
    /// of the radius).
    pub fn mesh_with(&self, around: u32, rings: u32) -> TriMesh {
        let (around, rings) = (around.max(3), rings.max(2));
        // Parry's tessellations (its cylinder stands along y: turned onto z here).
        let (vertices, triangles, turn) = match self.shape {
            PrimitiveShape::Box { half_m } => {
                let (v, t) = Cuboid::new(half_m).to_trimesh();
                (v, t, Quat::IDENTITY)
            }
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            } => {
                let (v, t) = Cylinder::new(half_height_m, radius_m).to_trimesh(around);
                (v, t, Quat::from_rotation_x(std::f32::consts::FRAC_PI_2))
            }
            PrimitiveShape::Sphere { radius_m } => {
                let (v, t) = Ball::new(radius_m).to_trimesh(2 * rings, rings);
                (v, t, Quat::IDENTITY)
            }
            PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => {
                let (v, t) = Capsule::new_z(half_height_m, radius_m).to_trimesh(around, rings);
                (v, t, Quat::IDENTITY)
            }
        };
        let to_object = self.rotation * turn;
        TriMesh::new(
            vertices
                .iter()
                .map(|&v| to_object * v + self.centre)
                .collect(),
            triangles,
        )
    }

    /// A convex tessellation that contains the primitive (as [`Primitive::mesh`], its round
    /// sides pushed out until every face's plane is at or beyond the true surface): the hull
    /// an engine without the primitive collides, conservative as the protocol's hulls are.
    pub fn covering_mesh(&self) -> TriMesh {
        let round = |scale: f32| match self.shape {
            PrimitiveShape::Box { .. } => self.shape,
            PrimitiveShape::Sphere { radius_m } => PrimitiveShape::Sphere {
                radius_m: radius_m * scale,
            },
            PrimitiveShape::Cylinder {
                radius_m,
                half_height_m,
            } => PrimitiveShape::Cylinder {
                radius_m: radius_m * scale,
                half_height_m,
            },
            PrimitiveShape::Capsule {
                radius_m,
                half_height_m,
            } => PrimitiveShape::Capsule {
                radius_m: radius_m * scale,
                half_height_m,
            },
        };
        let placed = |shape: PrimitiveShape| Primitive { shape, ..*self };
        // The faces' planes are inside the round surface by 1 − cos of half a facet's angle;
        // a few rounds of growing by the worst face's shortfall settle it.
        let mut scale = 1.0f32;
        for _ in 0..6 {
            let mesh = placed(round(scale)).mesh();
            let shortfall = mesh
                .triangles
                .iter()
                .filter_map(|t| {
                    let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                    let n = (b - a).cross(c - a).try_normalize()?;
                    let offset = n.dot(a - self.centre);
                    let needed = self.shape.reach(self.rotation.inverse() * n);
                    (offset > 0.0).then_some(needed / offset)
                })
                .fold(1.0f32, f32::max);
            if shortfall <= 1.0 + 1e-6 {
                return mesh;
            }
            scale *= shortfall * (1.0 + 1e-6);
        }
        placed(round(scale)).mesh()
    }

    /// Mass properties at unit density, in the object's frame.
    pub fn mass(&self) -> MassProperties {
        let r = Mat3::from_quat(self.rotation);
        let inertia = r * Mat3::from_diagonal(self.shape.principal_moments()) * r.transpose();
        MassProperties {
            volume_m3: self.shape.volume_m3(),
            centre_of_mass: self.centre,
            inertia: [
                inertia.row(0).to_array(),
                inertia.row(1).to_array(),
                inertia.row(2).to_array(),
            ],
        }
    }
}

/// Points to judge a fit by: a mesh's vertices, edge midpoints and triangle centroids (a
/// simplified mesh has few vertices on large flat triangles).
pub fn surface_points(mesh: &TriMesh) -> Vec<Vec3> {
    let mut points = mesh.vertices.clone();
    for t in &mesh.triangles {
        let corner = |k: usize| mesh.vertices.get(t[k] as usize).copied();
        let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
            continue;
        };
        points.extend([
            (a + b) * 0.5,
            (b + c) * 0.5,
            (c + a) * 0.5,
            (a + b + c) / 3.0,
        ]);
    }
    points
}

/// The `per_cent`th percentile of `values` (nearest rank, reordering them); `None` if empty.
pub(crate) fn percentile(values: &mut [f32], per_cent: usize) -> Option<f32> {
    let k = (values.len() * per_cent / 100).min(values.len().checked_sub(1)?);
    Some(*values.select_nth_unstable_by(k, f32::total_cmp).1)
}

/// The 95th percentile of the points' distances from `primitive`'s surface.
fn residual(primitive: &Primitive, points: &[Vec3]) -> f32 {
    let mut d: Vec<f32> = points
        .iter()
        .map(|&p| primitive.signed_distance(p).abs())
        .collect();
    percentile(&mut d, 95).unwrap_or(f32::INFINITY)
}

/// Two unit vectors spanning the support's plane.
fn plane_axes(normal: Vec3) -> (Vec3, Vec3) {
    let u = normal.any_orthonormal_vector();
    (u, normal.cross(u))
}

/// A circle through 2-D points: Kåsa's algebraic fit, then Gauss–Newton on the geometric
/// distances. `None` for fewer than three points or a degenerate arc.
fn fit_circle(points: &[Vec2]) -> Option<(Vec2, f32)> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().copied().sum::<Vec2>() / points.len() as f32;
    // x² + y² + D x + E y + F = 0, least squares, about the mean for conditioning.
    let (mut m, mut rhs) = (DMat3::ZERO, DVec3::ZERO);
    for p in points {
        let q = (*p - mean).as_dvec2();
        let row = DVec3::new(q.x, q.y, 1.0);
        m += DMat3::from_cols(row * row.x, row * row.y, row * row.z);
        rhs -= row * q.length_squared();
    }
    if m.determinant().abs() < 1e-18 {
        return None;
    }
    let s = m.inverse() * rhs;
    let mut centre = glam::DVec2::new(-s.x / 2.0, -s.y / 2.0);
    let mut radius = (centre.length_squared() - s.z).max(0.0).sqrt();
    for _ in 0..10 {
        // Residual r_i = |q_i − c| − R; Jacobian [−(q−c)/|q−c|, −1].
        let (mut h, mut g) = (DMat3::ZERO, DVec3::ZERO);
        for p in points {
            let d = (*p - mean).as_dvec2() - centre;
            let len = d.length().max(1e-12);
            let row = DVec3::new(-d.x / len, -d.y / len, -1.0);
            let r = len - radius;
            h += DMat3::from_cols(row * row.x, row * row.y, row * row.z);
            g += row * r;
        }
        if h.determinant().abs() < 1e-18 {
            break;
        }
        let step = -(h.inverse() * g);
        centre += glam::DVec2::new(step.x, step.y);
        radius += step.z;
        if step.length() < 1e-9 {
            break;
        }
    }
    (radius.is_finite() && radius > 0.0).then(|| (centre.as_vec2() + mean, radius as f32))
}

/// A sphere through 3-D points (algebraic fit, then Gauss–Newton).
fn fit_sphere(points: &[Vec3]) -> Option<(Vec3, f32)> {
    if points.len() < 4 {
        return None;
    }
    let mean = points.iter().copied().sum::<Vec3>() / points.len() as f32;
    // x² + y² + z² + D x + E y + F z + G = 0 in four unknowns: solved as a 4×4 system.
    let mut a = [[0.0f64; 4]; 4];
    let mut b = [0.0f64; 4];
    for p in points {
        let q = (*p - mean).as_dvec3();
        let row = [q.x, q.y, q.z, 1.0];
        for i in 0..4 {
            for j in 0..4 {
                a[i][j] += row[i] * row[j];
            }
            b[i] -= row[i] * q.length_squared();
        }
    }
    let s = solve(a, b)?;
    let mut centre = DVec3::new(-s[0] / 2.0, -s[1] / 2.0, -s[2] / 2.0);
    let mut radius = (centre.length_squared() - s[3]).max(0.0).sqrt();
    for _ in 0..10 {
        let mut h = [[0.0f64; 4]; 4];
        let mut g = [0.0f64; 4];
        for p in points {
            let d = (*p - mean).as_dvec3() - centre;
            let len = d.length().max(1e-12);
            let row = [-d.x / len, -d.y / len, -d.z / len, -1.0];
            let r = len - radius;
            for i in 0..4 {
                for j in 0..4 {
                    h[i][j] += row[i] * row[j];
                }
                g[i] -= row[i] * r;
            }
        }
        let Some(step) = solve(h, g) else { break };
        centre += DVec3::new(step[0], step[1], step[2]);
        radius += step[3];
        if step.iter().map(|v| v * v).sum::<f64>() < 1e-18 {
            break;
        }
    }
    (radius.is_finite() && radius > 0.0).then(|| (centre.as_vec3() + mean, radius as f32))
}

/// Gaussian elimination with partial pivoting on an N×N system.
#[allow(clippy::needless_range_loop)] // index loops read like the elimination they are
fn solve<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-18 {
            return None;
        }
        a.swap(col, pivot);
        b.swap(col, pivot);
        for row in col + 1..N {
            let f = a[row][col] / a[col][col];
            for k in col..N {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0f64; N];
    for row in (0..N).rev() {
        let tail: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - tail) / a[row][row];
    }
    Some(x)
}

/// Gauss–Newton on the points' signed distances from a primitive made from `N` parameters
/// (`make`), with forward-difference derivatives: fits what an algebraic first guess left a
/// few millimetres off (a box's footprint from the extreme points of noisy faces).
fn refine<const N: usize>(
    start: [f32; N],
    points: &[Vec3],
    make: impl Fn(&[f32; N]) -> Option<Primitive>,
) -> Option<[f32; N]> {
    let mut x = start;
    for _ in 0..8 {
        let here = make(&x)?;
        let r: Vec<f64> = points
            .iter()
            .map(|&p| f64::from(here.signed_distance(p)))
            .collect();
        let mut jacobian = vec![[0.0f64; N]; points.len()];
        for k in 0..N {
            let h = 1e-4f32.max(1e-3 * x[k].abs());
            let mut moved = x;
            moved[k] += h;
            let there = make(&moved)?;
            for ((row, &p), r) in jacobian.iter_mut().zip(points).zip(&r) {
                row[k] = (f64::from(there.signed_distance(p)) - r) / f64::from(h);
            }
        }
        let (mut a, mut b) = ([[0.0f64; N]; N], [0.0f64; N]);
        for (row, r) in jacobian.iter().zip(&r) {
            for i in 0..N {
                for j in 0..N {
                    a[i][j] += row[i] * row[j];
                }
                b[i] -= row[i] * r;
            }
        }
        for (i, row) in a.iter_mut().enumerate() {
            row[i] += 1e-9;
        }
        let step = solve(a, b)?;
        for (x, s) in x.iter_mut().zip(step) {
            *x += s as f32;
        }
        if step.iter().map(|s| s * s).sum::<f64>() < 1e-12 {
            break;
        }
    }
    Some(x)
}

/// The shortest axis segment a capsule has, over its radius.
const MIN_CAPSULE_AXIS_OVER_RADIUS: f32 = 0.5;

/// The round primitives with an axis: a cylinder, or a capsule (a cylinder with a
/// hemisphere on each end), fitted the same ways.
#[derive(Debug, Clone, Copy)]
enum Round {
    Cylinder,
    Capsule,
}

impl Round {
    /// The shape of this kind with `radius_m` and half its whole length along its axis, if
    /// both are positive (and a capsule is longer than its ball).
    fn shape(self, radius_m: f32, half_length_m: f32) -> Option<PrimitiveShape> {
        if !(radius_m > 0.0 && half_length_m > 0.0) {
            return None;
        }
        match self {
            Round::Cylinder => Some(PrimitiveShape::Cylinder {
                radius_m,
                half_height_m: half_length_m,
            }),
            // An axis shorter than half the radius is a ball to within a quarter of it: a
            // sphere says so more simply (and a ball's fit once drifted to such a capsule).
            Round::Capsule => (half_length_m - radius_m
                >= MIN_CAPSULE_AXIS_OVER_RADIUS * 0.5 * radius_m)
                .then_some(PrimitiveShape::Capsule {
                    radius_m,
                    half_height_m: half_length_m - radius_m,
                }),
        }
    }
}

/// A sphere resting on the support (or free, without one).
fn sphere(points: &[Vec3], support: Option<SupportPlane>) -> Option<Primitive> {
    let (centre, radius) = fit_sphere(points)?;
    let primitive = Primitive {
        shape: PrimitiveShape::Sphere { radius_m: radius },
        rotation: Quat::IDENTITY,
        centre,
        residual_m: 0.0,
    };
    rests(&primitive, support).then_some(primitive)
}

/// How high the points reach above the support: the 99th percentile of their heights (the
/// highest point is the noise's, not the object's).
fn top_height(points: &[Vec3], support: SupportPlane) -> f32 {
    let mut heights: Vec<f32> = points.iter().map(|&p| support.height(p)).collect();
    percentile(&mut heights, 99).unwrap_or(f32::NAN)
}

/// A box standing on the support: its footprint the smallest rectangle around the points
/// seen from above, its top the highest points. Needs its top seen.
fn standing_box(points: &[Vec3], support: SupportPlane, bound_m: f32) -> Option<Primitive> {
    let normal = support.normal.normalize_or_zero();
    let (u, v) = plane_axes(normal);
    let top = top_height(points, support);
    let on_top = points
        .iter()
        .filter(|&&p| support.height(p) > top - 2.0 * bound_m)
        .count();
    if top.is_nan() || top <= 2.0 * bound_m || on_top * 5 < points.len() {
        return None;
    }
    let flat: Vec<Vec2> = points
        .iter()
        .map(|p| Vec2::new(p.dot(u), p.dot(v)))
        .collect();
    let (centre, axis, half) = crate::min_area_rectangle(&flat)?;
    let base = normal * support.offset;
    // Footprint centre, its turn in the plane, its half sides and the height: standing on the
    // support, so the box's bottom stays on it.
    let make = |p: &[f32; 6]| {
        let x = u * p[2].cos() + v * p[2].sin();
        let (half_x, half_y, height) = (p[3], p[4], p[5]);
        (half_x > 0.0 && half_y > 0.0 && height > 0.0).then(|| Primitive {
            shape: PrimitiveShape::Box {
                half_m: Vec3::new(half_x, half_y, 0.5 * height),
            },
            rotation: Quat::from_mat3(&Mat3::from_cols(x, normal.cross(x), normal)).normalize(),
            centre: base + u * p[0] + v * p[1] + normal * (0.5 * height),
            residual_m: 0.0,
        })
    };
    let start = [
        centre.x,
        centre.y,
        axis.y.atan2(axis.x),
        half.x,
        half.y,
        top,
    ];
    let best = refine(start, points, make).unwrap_or(start);
    make(&best)
}

/// A cylinder or a capsule standing on the support: its wall a circle fitted to the points
/// below its top, its top the highest points. Needs its wall seen.
fn standing_round(
    points: &[Vec3],
    support: SupportPlane,
    bound_m: f32,
    kind: Round,
) -> Option<Primitive> {
    let normal = support.normal.normalize_or_zero();
    let (u, v) = plane_axes(normal);
    let top = top_height(points, support);
    let wall: Vec<Vec2> = points
        .iter()
        .filter(|&&p| support.height(p) < top - 2.0 * bound_m)
        .map(|p| Vec2::new(p.dot(u), p.dot(v)))
        .collect();
    if top.is_nan() || top <= 2.0 * bound_m || wall.len() * 5 < points.len() {
        return None;
    }
    let (centre, radius) = fit_circle(&wall)?;
    let base = normal * support.offset;
    // Then all the points at once (wall and top), standing on the support: the circle of the
    // wall alone is pulled by a rounded rim and by where the wall and the top were told apart.
    let make = |p: &[f32; 4]| {
        Some(Primitive {
            shape: kind.shape(p[2], 0.5 * p[3])?,
            rotation: Quat::from_rotation_arc(Vec3::Z, normal),
            centre: base + u * p[0] + v * p[1] + normal * (0.5 * p[3]),
            residual_m: 0.0,
        })
    };
    let start = [centre.x, centre.y, radius, top];
    let best = refine(start, points, make).unwrap_or(start);
    make(&best)
}

/// A cylinder or a capsule lying on the support: its axis the longest direction of the
/// points in the plane, its section a circle fitted across it, touching the support; then all
/// the points at once.
fn lying_round(
    points: &[Vec3],
    support: SupportPlane,
    bound_m: f32,
    kind: Round,
) -> Option<Primitive> {
    let normal = support.normal.normalize_or_zero();
    let (u, v) = plane_axes(normal);
    let flat: Vec<Vec2> = points
        .iter()
        .map(|p| Vec2::new(p.dot(u), p.dot(v)))
        .collect();
    // The footprint of a lying cylinder is a rectangle: its long side is the axis.
    let (_, side, half) = crate::min_area_rectangle(&flat)?;
    let along2 = if half.x >= half.y { side } else { side.perp() };
    let axis = (u * along2.x + v * along2.y).normalize();
    let across = normal.cross(axis);
    let (lo, hi) = points
        .iter()
        .map(|p| p.dot(axis))
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t), hi.max(t))
        });
    // The section, across the axis and up from the support, of the wall: an end cap's points
    // (at either end along the axis) would fill the circle in.
    let section: Vec<Vec2> = points
        .iter()
        .filter(|p| (lo + 2.0 * bound_m..hi - 2.0 * bound_m).contains(&p.dot(axis)))
        .map(|&p| Vec2::new(p.dot(across), support.height(p)))
        .collect();
    let (centre, radius) = fit_circle(&section)?;
    // It lies on the support: the circle's lowest point on the plane. Across, along, radius,
    // half length.
    let make = |p: &[f32; 4]| {
        Some(Primitive {
            shape: kind.shape(p[2], p[3])?,
            rotation: Quat::from_mat3(&Mat3::from_cols(across, normal, axis)).normalize(),
            centre: axis * p[1] + across * p[0] + normal * (support.offset + p[2]),
            residual_m: 0.0,
        })
    };
    let start = [centre.x, 0.5 * (lo + hi), radius, 0.5 * (hi - lo)];
    let best = refine(start, points, make).unwrap_or(start);
    let primitive = make(&best)?;
    rests(&primitive, Some(support)).then_some(primitive)
}

/// Whether a primitive stands on the support (its lowest point within a centimetre of the
/// plane), or there is no support to stand on.
fn rests(primitive: &Primitive, support: Option<SupportPlane>) -> bool {
    let Some(support) = support else {
        return true;
    };
    let normal = support.normal.normalize_or_zero();
    // The lowest point of the primitive along the normal.
    let reach = primitive
        .shape
        .reach(primitive.rotation.inverse() * -normal);
    (support.height(primitive.centre) - reach).abs() <= 0.01
}

/// The principal axes of `points` (unit, columns of a rotation) and their mean.
fn principal_axes(points: &[Vec3]) -> (Vec3, [Vec3; 3]) {
    let mean = points.iter().copied().sum::<Vec3>() / points.len().max(1) as f32;
    let mut covariance = Mat3::ZERO;
    for p in points {
        let d = *p - mean;
        covariance += Mat3::from_cols(d * d.x, d * d.y, d * d.z);
    }
    let eigen = parry3d::math::SymmetricEigen3::new(covariance);
    let v = eigen.eigenvectors;
    let (a, b) = (
        v.x_axis.normalize_or(Vec3::X),
        v.y_axis.normalize_or(Vec3::Y),
    );
    (mean, [a, b, a.cross(b).normalize_or(Vec3::Z)])
}

/// A box in any orientation: the points' principal axes and extents, refined (centre, turn,
/// half sides).
fn free_box(points: &[Vec3]) -> Option<Primitive> {
    let (mean, [x, y, z]) = principal_axes(points);
    let base = Quat::from_mat3(&Mat3::from_cols(x, y, z)).normalize();
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for p in points {
        let q = base.inverse() * (*p - mean);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    let centre = mean + base * (0.5 * (lo + hi));
    let half = 0.5 * (hi - lo);
    let make = |p: &[f32; 9]| {
        let half_m = Vec3::new(p[6], p[7], p[8]);
        (half_m.min_element() > 0.0).then(|| Primitive {
            shape: PrimitiveShape::Box { half_m },
            rotation: (base * Quat::from_scaled_axis(Vec3::new(p[3], p[4], p[5]))).normalize(),
            centre: Vec3::new(p[0], p[1], p[2]),
            residual_m: 0.0,
        })
    };
    let start = [
        centre.x, centre.y, centre.z, 0.0, 0.0, 0.0, half.x, half.y, half.z,
    ];
    let best = refine(start, points, make).unwrap_or(start);
    make(&best)
}

/// A cylinder or a capsule in any orientation: its axis one of the points' principal axes
/// (whichever fits best), refined (centre, axis, radius, half length).
fn free_round(points: &[Vec3], kind: Round) -> Option<Primitive> {
    let (mean, axes) = principal_axes(points);
    axes.iter()
        .filter_map(|&axis| {
            let turn = Quat::from_rotation_arc(Vec3::Z, axis);
            let (mut lo, mut hi, mut radius) = (f32::INFINITY, f32::NEG_INFINITY, 0.0f32);
            for p in points {
                let q = turn.inverse() * (*p - mean);
                lo = lo.min(q.z);
                hi = hi.max(q.z);
                radius += Vec2::new(q.x, q.y).length();
            }
            radius /= points.len() as f32;
            let centre = mean + axis * (0.5 * (lo + hi));
            let make = |p: &[f32; 7]| {
                Some(Primitive {
                    shape: kind.shape(p[5], p[6])?,
                    rotation: (turn * Quat::from_scaled_axis(Vec3::new(p[3], p[4], 0.0)))
                        .normalize(),
                    centre: Vec3::new(p[0], p[1], p[2]),
                    residual_m: 0.0,
                })
            };
            let start = [
                centre.x,
                centre.y,
                centre.z,
                0.0,
                0.0,
                radius,
                0.5 * (hi - lo),
            ];
            let best = refine(start, points, make).unwrap_or(start);
            make(&best).map(|c| Primitive {
                residual_m: residual(&c, points),
                ..c
            })
        })
        .min_by(|a, b| a.residual_m.total_cmp(&b.residual_m))
}

/// As [`fit_primitive`], for the points of a closed surface that stands on nothing known (a
/// multi-view object, an offline cloud): a sphere, or a box, a cylinder or a capsule in any orientation.
/// Only for closed surfaces: on a one-view shell a box as deep as what was seen fits as well
/// as the true one.
pub fn fit_closed_primitive(points: &[Vec3], bound_m: f32) -> Option<Primitive> {
    let points: Vec<Vec3> = points.iter().copied().filter(|p| p.is_finite()).collect();
    if points.len() < 8 || bound_m.is_nan() || bound_m <= 0.0 {
        return None;
    }
    let candidates = [
        sphere(&points, None),
        free_box(&points),
        free_round(&points, Round::Cylinder),
        free_round(&points, Round::Capsule),
    ];
    candidates
        .into_iter()
        .flatten()
        .filter(|c| c.shape.volume_m3().is_finite() && c.shape.volume_m3() > 0.0)
        .map(|c| Primitive {
            residual_m: residual(&c, &points),
            ..c
        })
        .filter(|c| c.residual_m <= bound_m)
        .min_by(|a, b| a.residual_m.total_cmp(&b.residual_m))
}

/// The points a shape was made from, fused (a voxel's mean each), and how far they scatter
/// about their own surface (the 95th percentile of their distances from local planes; NaN or
/// negative counts as none), metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FusedPoints<'a> {
    pub points: &'a [Vec3],
    pub roughness_m: f32,
}

/// How much a fit may stray for data that scatter `roughness_m` about their surface: that
/// much, up to a metre; NaN or negative counts as none.
pub(crate) fn scatter_allowance_m(roughness_m: f32) -> f32 {
    if roughness_m > 0.0 {
        roughness_m.min(1.0)
    } else {
        0.0
    }
}

/// What a primitive may be off a shape beyond the shape's own residual bound, metres: the
/// sensor's noise at a metre or two, which the fused surface keeps some of.
pub const PRIMITIVE_NOISE_M: f32 = 0.003;

/// The primitive a published shape is, if one explains it: the points it was made from within
/// its residual bound and the sensor's noise ([`PRIMITIVE_NOISE_M`]), resting on `support`
/// (the plane it stands on, in its frame) when there is one; a closed shape on nothing known
/// in any orientation. The daemon's bodies and a subscriber's scene both fit this way.
///
/// `fused` are the points the shape was made from, fused (each voxel's mean: the sensor's
/// noise averaged out), when the caller has them: the daemon does. Fitted to those, a box's
/// sides and a cylinder's radius come to within millimetres even where the mesh, simplified to
/// its residual bound, is off by that bound, and a box does not run on past its top's unseen
/// edges as the mesh does. Empty: the mesh's surface points (a subscriber has only the mesh).
///
/// `container` is a closed solid known to hold the object: the shape itself when it is closed,
/// else its conservative proxy (the space behind what was seen). A fit must lie within it (see
/// [`lies_within`]): a flat patch of carpet is explained, to a few millimetres, by a slice of
/// a cylinder a hundred metres wide lying on the floor, which the space behind the patch
/// refuses.
pub fn primitive_of_shape(
    mesh: &TriMesh,
    fused: Option<FusedPoints<'_>>,
    support: Option<SupportPlane>,
    residual_bound_m: f32,
    container: &TriMesh,
) -> Option<Primitive> {
    let bound_m = residual_bound_m.max(0.0) + PRIMITIVE_NOISE_M;
    // The fused points scatter about the surface by their roughness: a primitive explains
    // them when it is off them by no more than that and the bound.
    let (points, fit_bound_m) = match fused.filter(|f| !f.points.is_empty()) {
        Some(fused) => (
            fused.points.to_vec(),
            bound_m + scatter_allowance_m(fused.roughness_m),
        ),
        None => (surface_points(mesh), bound_m),
    };
    let fit = match support {
        None if mesh.is_closed() => fit_closed_primitive(&points, fit_bound_m),
        _ => fit_primitive(&points, support, fit_bound_m),
    }?;
    match lies_within(&fit, container, support, bound_m) {
        Ok(()) => Some(fit),
        Err(why) => {
            tracing::debug!("a {} fits the shape but {why}", fit.shape.name());
            None
        }
    }
}

/// Whether `primitive` lies within the closed `solid` up to `bound_m`: its volume at most
/// [`MAX_VOLUME_OVER_CONTAINER`] of the solid's, and at least 95 % of its surface, pulled
/// `bound_m` inward, inside the solid (by the generalised winding number). Its surface within
/// [`SUPPORT_BAND_M`] of the `support` is not judged: segmentation cuts what was seen of an
/// object off above the table, so a shadow volume does not reach the foot of the object's
/// near side. `Err` says why not.
pub fn lies_within(
    primitive: &Primitive,
    solid: &TriMesh,
    support: Option<SupportPlane>,
    bound_m: f32,
) -> Result<(), String> {
    let surface = surface_points(&primitive.mesh_with(16, 8));
    // Inward along the direction to the primitive's centre: the surface normal of a round
    // primitive, near enough for a box's.
    let centre = primitive.centre;
    let surface: Vec<(Vec3, Vec3)> = surface
        .into_iter()
        .map(|p| (p, (centre - p).normalize_or_zero()))
        .collect();
    within(
        primitive.shape.volume_m3(),
        &surface,
        solid,
        support,
        bound_m,
    )
}

/// [`lies_within`] for any completed solid: its volume, and points of its surface with the
/// way into it from each.
pub(crate) fn within(
    volume_m3: f32,
    surface: &[(Vec3, Vec3)],
    solid: &TriMesh,
    support: Option<SupportPlane>,
    bound_m: f32,
) -> Result<(), String> {
    let held = MassProperties::of_closed_mesh(solid)
        .map_err(|e| format!("the solid that holds it has no volume ({e})"))?;
    let ratio = volume_m3 / held.volume_m3;
    if ratio.is_nan() || ratio > MAX_VOLUME_OVER_CONTAINER {
        return Err(format!(
            "is {ratio:.2}× the volume of the space that holds the object"
        ));
    }
    let probes: Vec<Vec3> = surface
        .iter()
        .filter(|(p, _)| support.is_none_or(|s| s.height(*p) > SUPPORT_BAND_M))
        .map(|&(p, inward)| p + inward * bound_m)
        .collect();
    // Each probe's winding number costs a pass over the solid's triangles: a few hundred,
    // evenly spread, tell 95 % inside as well as thousands do.
    let step = probes.len().div_ceil(MAX_WITHIN_PROBES).max(1);
    let probes: Vec<Vec3> = probes.into_iter().step_by(step).collect();
    let inside = probes
        .iter()
        .filter(|&&p| winding_number(solid, p) > 0.5)
        .count();
    if inside * 100 >= probes.len() * 95 {
        Ok(())
    } else {
        Err(format!(
            "{:.0} % of its surface is outside the space that holds the object",
            100.0 * (1.0 - inside as f32 / probes.len().max(1) as f32)
        ))
    }
}

/// The most points of a completed solid's or a primitive's surface [`lies_within`] judges.
const MAX_WITHIN_PROBES: usize = 600;

/// How far above its support a primitive's surface is not judged by [`lies_within`], metres.
pub const SUPPORT_BAND_M: f32 = 0.015;

/// The most a primitive may weigh over the solid that holds it: a shape's own volume and
/// the primitive differ by the fit's residual over the surface.
pub const MAX_VOLUME_OVER_CONTAINER: f32 = 1.25;

/// The generalised winding number of a closed, outward mesh about `p`: 1 inside, 0 outside
/// (Jacobson et al. 2013: the solid angles of its triangles, by van Oosterom and Strackee's
/// formula, over 4π).
fn winding_number(mesh: &TriMesh, p: Vec3) -> f32 {
    let mut total = 0.0f64;
    for t in &mesh.triangles {
        let corner = |k: usize| {
            mesh.vertices
                .get(t[k] as usize)
                .map(|&v| (v - p).as_dvec3())
        };
        let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
            continue;
        };
        let (la, lb, lc) = (a.length(), b.length(), c.length());
        let numerator = a.dot(b.cross(c));
        let denominator = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
        total += 2.0 * numerator.atan2(denominator);
    }
    (total / (4.0 * std::f64::consts::PI)) as f32
}

/// The primitive that explains `points` (what was seen of an object, in its frame) best, if
/// one explains them within `bound_m` (95th percentile of the distances): of a box, a standing
/// or lying cylinder or capsule and a sphere, each resting on `support` when there is one.
pub fn fit_primitive(
    points: &[Vec3],
    support: Option<SupportPlane>,
    bound_m: f32,
) -> Option<Primitive> {
    let points: Vec<Vec3> = points.iter().copied().filter(|p| p.is_finite()).collect();
    if points.len() < 8 || bound_m.is_nan() || bound_m <= 0.0 {
        return None;
    }
    let mut fits: Vec<CandidateFit> = vec![Box::new(move |p: &[Vec3]| sphere(p, support))];
    if let Some(support) = support.filter(|s| s.normal.length() > 0.5) {
        fits.push(Box::new(move |p: &[Vec3]| {
            standing_box(p, support, bound_m)
        }));
        for kind in [Round::Cylinder, Round::Capsule] {
            fits.push(Box::new(move |p: &[Vec3]| {
                standing_round(p, support, bound_m, kind)
            }));
            fits.push(Box::new(move |p: &[Vec3]| {
                lying_round(p, support, bound_m, kind)
            }));
        }
    }
    best_fit(&points, bound_m, &fits)
}

/// One kind of primitive fitted to points.
type CandidateFit = Box<dyn Fn(&[Vec3]) -> Option<Primitive>>;

/// The most points each candidate is fitted to: the candidates are fitted to an even
/// thinning of the points, and only the best of them again to all of them (a fit's cost is
/// its points times its iterations; a thousand points tell the candidates apart).
const CANDIDATE_FIT_POINTS: usize = 1024;

/// The candidate of `fits` whose 95th percentile distance from `points` is least, if that
/// is within `bound_m` (see [`CANDIDATE_FIT_POINTS`]): the candidates in the order of their
/// fit to the thinned points, each fitted again to all of them until one is within the bound.
fn best_fit(points: &[Vec3], bound_m: f32, fits: &[CandidateFit]) -> Option<Primitive> {
    let scored = |fit: &dyn Fn(&[Vec3]) -> Option<Primitive>, on: &[Vec3]| {
        fit(on)
            .filter(|c| c.shape.volume_m3().is_finite() && c.shape.volume_m3() > 0.0)
            .map(|c| Primitive {
                residual_m: residual(&c, on),
                ..c
            })
    };
    let step = points.len().div_ceil(CANDIDATE_FIT_POINTS).max(1);
    if step == 1 {
        return fits
            .iter()
            .filter_map(|fit| scored(fit.as_ref(), points))
            .filter(|c| c.residual_m <= bound_m)
            .min_by(|a, b| a.residual_m.total_cmp(&b.residual_m));
    }
    // One point from each run of `step`, at a scrambled place in it: points that come in a
    // pattern (a scan's rows, faces in turn) are not thinned to one part of the pattern.
    let thinned: Vec<Vec3> = (0..points.len() / step)
        .map(|i| points[i * step + (i.wrapping_mul(2_654_435_761) >> 7) % step])
        .collect();
    let mut ranked: Vec<(f32, &CandidateFit)> = fits
        .iter()
        .filter_map(|fit| scored(fit.as_ref(), &thinned).map(|c| (c.residual_m, fit)))
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0));
    ranked
        .into_iter()
        .filter_map(|(_, fit)| scored(fit.as_ref(), points))
        .find(|c| c.residual_m <= bound_m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A low-discrepancy sequence in [0, 1)² and a small deterministic noise, so that the
    /// tests need no random generator.
    fn unit2(i: usize) -> Vec2 {
        let golden = 0.618_034_f64;
        let plastic = 0.754_877_7_f64;
        Vec2::new(
            ((i as f64 * golden).fract()) as f32,
            ((i as f64 * plastic).fract()) as f32,
        )
    }

    fn noise(i: usize, sigma: f32) -> Vec3 {
        let h = |k: f32| ((i as f32 * 12.9898 + k * 78.233).sin() * 43_758.547).fract() - 0.5;
        Vec3::new(h(1.0), h(2.0), h(3.0)) * (2.0 * sigma)
    }

    /// Points of `primitive`'s surface that a camera at `eye` sees (it is convex: a point is
    /// seen when its normal faces the eye), with noise.
    fn seen(primitive: &Primitive, eye: Vec3, n: usize, sigma: f32) -> Vec<Vec3> {
        let mut points = Vec::new();
        let mut i = 0;
        while points.len() < n && i < 100 * n {
            i += 1;
            let s = unit2(i);
            let (q, normal) = match primitive.shape {
                PrimitiveShape::Sphere { radius_m } => {
                    let z = 2.0 * s.x - 1.0;
                    let a = std::f32::consts::TAU * s.y;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let d = Vec3::new(r * a.cos(), r * a.sin(), z);
                    (d * radius_m, d)
                }
                PrimitiveShape::Box { half_m } => {
                    let face = i % 6;
                    let axis = face / 2;
                    let sign = if face % 2 == 0 { 1.0 } else { -1.0 };
                    let (a, b) = (2.0 * s.x - 1.0, 2.0 * s.y - 1.0);
                    let q = match axis {
                        0 => Vec3::new(sign, a, b),
                        1 => Vec3::new(a, sign, b),
                        _ => Vec3::new(a, b, sign),
                    } * half_m;
                    let mut normal = Vec3::ZERO;
                    normal[axis] = sign;
                    (q, normal)
                }
                PrimitiveShape::Cylinder {
                    radius_m,
                    half_height_m,
                } => {
                    let a = std::f32::consts::TAU * s.y;
                    if i % 3 == 0 {
                        let sign = if i % 2 == 0 { 1.0 } else { -1.0 };
                        let r = radius_m * s.x.sqrt();
                        (
                            Vec3::new(r * a.cos(), r * a.sin(), sign * half_height_m),
                            Vec3::Z * sign,
                        )
                    } else {
                        let d = Vec3::new(a.cos(), a.sin(), 0.0);
                        (
                            d * radius_m + Vec3::Z * (2.0 * s.x - 1.0) * half_height_m,
                            d,
                        )
                    }
                }
                PrimitiveShape::Capsule {
                    radius_m,
                    half_height_m,
                } => {
                    // The wall and the two caps in proportion to their areas, about.
                    let a = std::f32::consts::TAU * s.y;
                    if i % 4 == 0 {
                        let z = s.x;
                        let r = (1.0 - z * z).max(0.0).sqrt();
                        let sign = if i % 8 == 0 { 1.0 } else { -1.0 };
                        let d = Vec3::new(r * a.cos(), r * a.sin(), sign * z);
                        (d * radius_m + Vec3::Z * sign * half_height_m, d)
                    } else {
                        let d = Vec3::new(a.cos(), a.sin(), 0.0);
                        (
                            d * radius_m + Vec3::Z * (2.0 * s.x - 1.0) * half_height_m,
                            d,
                        )
                    }
                }
            };
            let p = primitive.rotation * q + primitive.centre;
            let normal = primitive.rotation * normal;
            if normal.dot(eye - p) > 0.0 {
                points.push(p + noise(i, sigma));
            }
        }
        points
    }

    const TABLE: SupportPlane = SupportPlane {
        normal: Vec3::Z,
        offset: 0.0,
    };
    /// A camera 45° above the table, 0.8 m away, as in the demo.
    const EYE: Vec3 = Vec3::new(0.0, -0.6, 0.6);
    const BOUND_M: f32 = 0.004;

    fn check(truth: Primitive, expected: &str) -> Primitive {
        let points = seen(&truth, EYE, 3000, 0.001);
        let fit = fit_primitive(&points, Some(TABLE), BOUND_M)
            .unwrap_or_else(|| panic!("no primitive fits a one-view {expected}"));
        assert_eq!(fit.shape.name(), expected, "{fit:?}");
        let (mass, true_mass) = (fit.mass(), truth.mass());
        let ratio = mass.volume_m3 / true_mass.volume_m3;
        assert!(
            (0.9..1.1).contains(&ratio),
            "{expected}: mass {ratio}× the truth, {fit:?}"
        );
        let off = mass.centre_of_mass.distance(true_mass.centre_of_mass);
        assert!(
            off < 0.01,
            "{expected}: centre of mass {off} m off, {fit:?}"
        );
        fit
    }

    #[test]
    fn a_one_view_box_is_a_box_of_the_right_mass() {
        let truth = Primitive {
            shape: PrimitiveShape::Box {
                half_m: Vec3::new(0.1, 0.06, 0.08),
            },
            rotation: Quat::from_rotation_z(0.5),
            centre: Vec3::new(0.1, 0.2, 0.08),
            residual_m: 0.0,
        };
        check(truth, "box");
    }

    #[test]
    fn a_standing_cylinder_is_a_cylinder() {
        let truth = Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.05,
                half_height_m: 0.09,
            },
            rotation: Quat::IDENTITY,
            centre: Vec3::new(-0.1, 0.1, 0.09),
            residual_m: 0.0,
        };
        check(truth, "cylinder");
    }

    #[test]
    fn a_lying_cylinder_is_a_cylinder_along_its_axis() {
        let truth = Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.04,
                half_height_m: 0.12,
            },
            // Its axis along the table, 30° off the x axis.
            rotation: Quat::from_rotation_z(0.52)
                * Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            centre: Vec3::new(0.0, 0.1, 0.04),
            residual_m: 0.0,
        };
        let fit = check(truth, "cylinder");
        let axis = fit.rotation * Vec3::Z;
        assert!(axis.z.abs() < 0.05, "lying: axis {axis}");
    }

    #[test]
    fn a_lying_capsule_is_a_capsule_and_a_standing_one_too() {
        let lying = Primitive {
            shape: PrimitiveShape::Capsule {
                radius_m: 0.03,
                half_height_m: 0.07,
            },
            rotation: Quat::from_rotation_z(-0.4)
                * Quat::from_rotation_y(std::f32::consts::FRAC_PI_2),
            centre: Vec3::new(0.05, 0.0, 0.03),
            residual_m: 0.0,
        };
        let fit = check(lying, "capsule");
        assert!((fit.rotation * Vec3::Z).z.abs() < 0.05, "lying: {fit:?}");
        let standing = Primitive {
            shape: PrimitiveShape::Capsule {
                radius_m: 0.04,
                half_height_m: 0.06,
            },
            rotation: Quat::IDENTITY,
            centre: Vec3::new(0.0, 0.1, 0.1),
            residual_m: 0.0,
        };
        check(standing, "capsule");
    }

    #[test]
    fn a_ball_on_the_table_is_a_sphere() {
        let truth = Primitive {
            shape: PrimitiveShape::Sphere { radius_m: 0.07 },
            rotation: Quat::IDENTITY,
            centre: Vec3::new(0.05, 0.0, 0.07),
            residual_m: 0.0,
        };
        check(truth, "sphere");
    }

    /// Points all over a primitive's surface (a closed, multi-view object), with noise.
    fn all_round(primitive: &Primitive, n: usize, sigma: f32) -> Vec<Vec3> {
        // Seen from six sides far away: every face.
        [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z]
            .iter()
            .flat_map(|&d| seen(primitive, primitive.centre + d * 100.0, n / 6, sigma))
            .collect()
    }

    #[test]
    fn closed_objects_standing_on_nothing_known_are_fitted_in_any_orientation() {
        let turn = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.5, 0.9);
        for truth in [
            Primitive {
                shape: PrimitiveShape::Box {
                    half_m: Vec3::new(0.2, 0.1, 0.05),
                },
                rotation: turn,
                centre: Vec3::new(1.0, -0.5, 0.2),
                residual_m: 0.0,
            },
            Primitive {
                shape: PrimitiveShape::Cylinder {
                    radius_m: 0.25,
                    half_height_m: 0.5,
                },
                rotation: turn,
                centre: Vec3::new(0.0, 0.2, 0.3),
                residual_m: 0.0,
            },
            Primitive {
                shape: PrimitiveShape::Capsule {
                    radius_m: 0.1,
                    half_height_m: 0.2,
                },
                rotation: turn,
                centre: Vec3::new(0.0, 0.2, 0.3),
                residual_m: 0.0,
            },
        ] {
            let points = all_round(&truth, 6000, 0.002);
            let fit = fit_closed_primitive(&points, 0.006).expect("a primitive");
            assert_eq!(fit.shape.name(), truth.shape.name(), "{fit:?}");
            let ratio = fit.mass().volume_m3 / truth.mass().volume_m3;
            assert!((0.95..1.05).contains(&ratio), "{ratio}: {fit:?}");
        }
    }

    #[test]
    fn what_is_no_primitive_gets_none() {
        // A cone's one-view shell: its side is neither a wall nor a box's face.
        let mut points = Vec::new();
        for i in 0..3000 {
            let s = unit2(i + 1);
            let a = std::f32::consts::TAU * s.y;
            let h = 0.2 * s.x;
            let r = 0.08 * (1.0 - h / 0.2);
            let p = Vec3::new(r * a.cos(), r * a.sin(), h);
            let normal = Vec3::new(a.cos() * 0.2, a.sin() * 0.2, 0.08).normalize();
            if normal.dot(EYE - p) > 0.0 {
                points.push(p + noise(i, 0.001));
            }
        }
        assert_eq!(fit_primitive(&points, Some(TABLE), BOUND_M), None);
        assert_eq!(fit_primitive(&[], Some(TABLE), BOUND_M), None);
    }

    /// A patch of carpet a few millimetres over the floor, seen from above, is explained
    /// within the bound by a cylinder tens of metres wide lying on the floor (as on the milk
    /// scan); the space behind the patch (its extrusion to the floor) refuses it. A box is a
    /// box, and a box twice as long is not within it.
    #[test]
    fn a_primitive_must_lie_within_the_space_that_holds_the_object() {
        let (n, lift) = (12u32, 0.005f32);
        let mut vertices = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (0.3 * i as f32 / n as f32, 0.25 * j as f32 / n as f32);
                // A gentle bulge, as a real patch has, and no more than the noise.
                let z = lift + 0.002 * (std::f32::consts::PI * x / 0.3).sin();
                vertices.push(Vec3::new(x, y, z));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let k = j * (n + 1) + i;
                triangles.push([k, k + 1, k + n + 2]);
                triangles.push([k, k + n + 2, k + n + 1]);
            }
        }
        let patch = TriMesh::new(vertices, triangles);
        let held = crate::proxy::collision_proxy(
            &patch,
            None,
            Some(TABLE),
            &crate::proxy::ProxyConfig {
                margin_m: BOUND_M,
                ..crate::proxy::ProxyConfig::default()
            },
        );
        assert!(held.closed);
        let unchecked = fit_primitive(&surface_points(&patch), Some(TABLE), BOUND_M + 0.003);
        assert!(
            unchecked.is_some_and(|p| p.shape.volume_m3() > 0.01),
            "the fit alone takes a huge primitive: {unchecked:?}"
        );
        let refused = primitive_of_shape(&patch, None, Some(TABLE), BOUND_M, &held.mesh);
        assert_eq!(refused, None, "a flat patch is no primitive");

        let truth = Primitive {
            shape: PrimitiveShape::Box {
                half_m: Vec3::new(0.1, 0.06, 0.08),
            },
            rotation: Quat::from_rotation_z(0.5),
            centre: Vec3::new(0.1, 0.2, 0.08),
            residual_m: 0.0,
        };
        let whole = truth.mesh();
        let fit = primitive_of_shape(&whole, None, Some(TABLE), BOUND_M, &whole).expect("a box");
        assert_eq!(fit.shape.name(), "box");
        assert_eq!(lies_within(&truth, &whole, Some(TABLE), BOUND_M), Ok(()));
        let twice = Primitive {
            shape: PrimitiveShape::Box {
                half_m: Vec3::new(0.2, 0.06, 0.08),
            },
            ..truth
        };
        assert!(
            lies_within(&twice, &whole, Some(TABLE), BOUND_M).is_err(),
            "twice as long"
        );
    }

    #[test]
    fn primitive_meshes_are_closed_outward_and_weigh_about_as_much() {
        for shape in [
            PrimitiveShape::Box {
                half_m: Vec3::new(0.1, 0.2, 0.3),
            },
            PrimitiveShape::Cylinder {
                radius_m: 0.1,
                half_height_m: 0.2,
            },
            PrimitiveShape::Sphere { radius_m: 0.1 },
            PrimitiveShape::Capsule {
                radius_m: 0.1,
                half_height_m: 0.15,
            },
        ] {
            let primitive = Primitive {
                shape,
                rotation: Quat::from_rotation_y(0.7),
                centre: Vec3::new(0.3, -0.2, 0.1),
                residual_m: 0.0,
            };
            let mesh = MassProperties::of_closed_mesh(&primitive.mesh()).expect("closed");
            let exact = primitive.mass();
            let ratio = mesh.volume_m3 / exact.volume_m3;
            assert!((0.9..=1.0001).contains(&ratio), "{}: {ratio}", shape.name());
            assert!(mesh.centre_of_mass.distance(exact.centre_of_mass) < 1e-4);
            // A fine tessellation's inertia is the closed form's.
            let fine =
                MassProperties::of_closed_mesh(&primitive.mesh_with(128, 64)).expect("closed");
            for (row, exact_row) in fine.inertia.iter().zip(&exact.inertia) {
                for (a, b) in row.iter().zip(exact_row) {
                    let scale = exact.inertia[0][0].abs().max(exact.inertia[2][2].abs());
                    assert!((a - b).abs() < 0.01 * scale, "{}: {a} vs {b}", shape.name());
                }
            }
            // The covering hull is convex and holds the primitive, by little.
            let cover = primitive.covering_mesh();
            assert!(cover.is_closed(), "{}", shape.name());
            let planes: Vec<(Vec3, f32)> = cover
                .triangles
                .iter()
                .filter_map(|t| {
                    let [a, b, c] = t.map(|i| cover.vertices[i as usize]);
                    let n = (b - a).cross(c - a).try_normalize()?;
                    Some((n, n.dot(a)))
                })
                .collect();
            let surface = primitive.mesh_with(128, 64);
            for &p in &surface.vertices {
                let outside = planes
                    .iter()
                    .map(|&(n, d)| n.dot(p) - d)
                    .fold(f32::NEG_INFINITY, f32::max);
                assert!(
                    outside <= 1e-5,
                    "{}: {p} is {outside} m outside",
                    shape.name()
                );
            }
            let grown = MassProperties::of_closed_mesh(&cover)
                .expect("closed")
                .volume_m3;
            assert!(
                (0.9999..1.06).contains(&(grown / exact.volume_m3)),
                "{}: the cover is {}× the primitive",
                shape.name(),
                grown / exact.volume_m3
            );
        }
    }

    #[test]
    fn primitive_mass_properties_match_their_meshes() {
        // A box's inertia about its axes, turned: the same as the closed form turned.
        let b = Primitive {
            shape: PrimitiveShape::Box {
                half_m: Vec3::new(0.1, 0.2, 0.3),
            },
            rotation: Quat::from_rotation_x(0.3),
            centre: Vec3::new(1.0, 2.0, 3.0),
            residual_m: 0.0,
        };
        let m = b.mass();
        assert!((m.volume_m3 - 0.048).abs() < 1e-6);
        assert_eq!(m.implausible(), None);
        let c = Primitive {
            shape: PrimitiveShape::Cylinder {
                radius_m: 0.1,
                half_height_m: 0.2,
            },
            ..b
        };
        assert_eq!(c.mass().implausible(), None);
        assert!(b.signed_distance(b.centre) < 0.0);
        assert!(
            (b.signed_distance(b.centre + b.rotation * Vec3::new(0.0, 0.0, 0.4)) - 0.1).abs()
                < 1e-5
        );
    }
}
