//! Contact fidelity (issue 13): how differently a physics simulation touching the candidate mesh
//! would feel from one touching the real object, measured with probe balls.
//!
//! The operator's side of a teleoperation link simulates a fingertip or tool touching the
//! meshes tacmesh sends. What matters there is not the mean surface distance (MHE, `metric.rs`)
//! but where a probe first touches, in which direction the contact pushes back, and how deep it
//! sinks at a given push. So we move balls of a few radii (5 mm, a fingertip, to 50 mm, a
//! palm) toward both meshes along the same lines and compare what they meet.
//!
//! **The probe lines** are a uniform random field of lines through the objects, the same for
//! both meshes and for every radius: `probe_lines` approach directions on a Fibonacci sphere
//! (even in direction), turned by a seeded random rotation; each line is offset from the centre
//! by a point drawn uniformly on the disk of radius `R + r_max` across its direction (`R` the
//! radius of a sphere about the reference's bounding-box centre that holds both meshes, `r_max`
//! the largest probe), so a line meets a surface patch in proportion to its projected area, as
//! parallel beams from every side would. Lines aimed at surface points would weight grazing
//! approaches by 1/cos of their incidence instead. A probe starts on the line's plane
//! `R + r_max` (plus a small margin) behind the centre, outside both meshes, and moves along
//! the line.
//!
//! **Per probe and radius** (stages in the order they run):
//! 1. *First contact* on each mesh: an exact sweep of the ball against each triangle (the first
//!    entry of its centre into the triangle grown by the radius), the triangles taken
//!    best-first from parry's AABB tree. Triangles are two-sided, so open meshes are surfaces,
//!    and a probe starting outside can never be "inside" a mesh. The contact normal is the unit vector from the
//!    touched surface point (the closest point of the mesh to the ball's centre at contact) to
//!    the centre: the direction the contact pushes the ball back, at an edge or corner too.
//! 2. *Selection*: a probe touching neither mesh is not used. With a viewpoint (a one-view scan,
//!    whose mesh is an open shell), a probe is used only if it approaches from the viewpoint's
//!    half-space (`dot(-d, viewpoint - centre) > 0`) and touches the real object (or, if it
//!    touches only the candidate, the candidate) on a surface that faces the viewpoint
//!    (`dot(normal, viewpoint - contact) > 0`). Occlusion is not tested: a front-facing patch
//!    hidden behind another part still counts.
//! 3. *Push*: the ball is placed `push_m` past its first contact with the reference (with the
//!    candidate if only it was touched) along the line, and its penetration depth into each
//!    mesh is measured there: with `s` the distance from the centre to the surface, the depth
//!    is `r - s` while the centre is still in front of the surface and `r + s` once it is
//!    behind it. "Behind" means that the centre's path from the start crossed the surface an
//!    odd number of times (ray casts along the line), so the rule needs no orientation and
//!    works for open shells and closed solids alike; it also lets a probe that went through a
//!    part thinner than the push come out again.
//! 4. *Errors*, for a probe that touches both meshes: the first-contact error along the
//!    reference's contact normal, `|t_c - t_r| · |cos θ|` (`t` the travel to first contact,
//!    `θ` the angle between the approach and the reference's normal: the gap between the
//!    surfaces where the probe touches, so a surface 10 mm off reads 10 mm at any incidence),
//!    and also along the approach itself, `|t_c - t_r|` (when the touch comes, which grows as
//!    1/cos θ at grazing incidence); the angle between the two contact normals (degrees); and
//!    the difference of the two penetration depths. A probe that touches only one mesh is a
//!    *miss*: `missed_by_candidate` (it passes where the real object is) or
//!    `extra_in_candidate` (it is stopped where nothing is). A miss is counted and also charged
//!    in every error, so that misses cannot hide, by looking at the other mesh from the ball's
//!    first contact with the one it touched: the first-contact error is the ball's clearance
//!    from the other mesh there (how far it is from touching it), the error along the approach
//!    is the cap (the touch never comes), the normal error is the angle between the contact
//!    normal and the direction from the other mesh's closest point to the ball's centre, and
//!    the penetration error is the depth into the mesh touched (the other's is zero). So a
//!    probe grazing past a silhouette a millimetre off costs about a millimetre and a degree,
//!    as a touching one would, while one through a hole costs its distance to the rim and the
//!    full push. First-contact errors are capped at [`ContactConfig::first_contact_cap_m`]
//!    (50 mm), so that one probe meeting the far side through a hole cannot outweigh the rest.
//! 5. *Summaries*: mean, median, 95th percentile (nearest rank) and maximum of each error, per radius
//!    and over all radii, in f64 in probe order.
//!
//! The probe set is drawn sequentially from ChaCha streams of the seed, the per-probe work runs
//! in parallel (rayon) into a vector in probe order, and the summaries are sequential: the
//! result does not depend on the thread count.

use std::f64::consts::TAU;

use glam::{DQuat, DVec3, Vec3};
use parry3d::bounding_volume::Aabb;
use parry3d::query::{PointQuery, Ray, RayCast};
use parry3d::shape::TriMesh as ParryTriMesh;
use rand::Rng;
use rayon::prelude::*;
use tacmesh_source::TriMesh;

use crate::sampling::seeded_rng;
use crate::{check_mesh, SimError};

/// Probe radii, metres: a fingertip (5 mm) to a palm (50 mm).
pub const DEFAULT_PROBE_RADII_M: [f32; 4] = [0.005, 0.010, 0.020, 0.050];

/// How far past the first contact a probe is pushed to measure penetration, metres.
pub const DEFAULT_PUSH_M: f32 = 0.010;

/// Probe lines (each run with every radius). A third (the monkey) to four fifths (a sphere) of
/// them touch one of the paper's 1 m shapes, so about 1,000 to 3,000 probes per radius.
pub const DEFAULT_PROBE_LINES: usize = 4_000;

/// ChaCha stream of the probe set; distinct from those of [`sample_cloud`](crate::sample_cloud)
/// (0, 1) and of the MHE metric (2, 3), so a scan and its evaluations with one seed are
/// independent.
const PROBE_STREAM: u64 = 4;

/// Extra clearance of the start plane outside the bounding sphere: 1 mm plus 1 % of its radius.
const START_MARGIN_M: f32 = 0.001;
const START_MARGIN_FRACTION: f32 = 0.01;

/// Step past a ray hit before looking for the next crossing of a surface, metres. Far above
/// f32 resolution at a few metres (about 0.5 µm), far below any probe radius.
const CROSSING_STEP_M: f32 = 1e-5;

/// More crossings than a straight line makes through any mesh we probe before the push; the
/// count stops here (the parity is then a guess, but such a mesh is a wall of folds).
const MAX_CROSSINGS: usize = 64;

/// How [`contact_fidelity`] probes. Lengths in metres, angles in degrees.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactConfig {
    /// Radii of the probe balls, metres (each > 0).
    pub probe_radii_m: Vec<f32>,
    /// How far past its first contact with the reference a probe is pushed to compare
    /// penetration depths, metres.
    pub push_m: f32,
    /// Number of probe lines; every radius runs along all of them.
    pub probe_lines: usize,
    /// Seed of the probe set.
    pub seed: u64,
    /// The sensor's position in the meshes' frame, metres. When given, only probes that
    /// approach from its side and touch a surface facing it are used (the one-sided variant,
    /// for the open shell of a one-view scan).
    pub viewpoint_m: Option<Vec3>,
    /// The largest first-contact error counted, metres; also the error along the approach of
    /// a probe that touches only one mesh.
    pub first_contact_cap_m: f32,
}

impl Default for ContactConfig {
    fn default() -> Self {
        Self {
            probe_radii_m: DEFAULT_PROBE_RADII_M.to_vec(),
            push_m: DEFAULT_PUSH_M,
            probe_lines: DEFAULT_PROBE_LINES,
            seed: 1,
            viewpoint_m: None,
            first_contact_cap_m: 0.050,
        }
    }
}

/// Mean, median, 95th percentile (both nearest rank) and maximum of one error over the probes
/// used. The unit is in the name of the field holding it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorSummary {
    pub mean: f64,
    pub p50: f64,
    pub p95: f64,
    pub max: f64,
}

/// The contact errors of a set of probes. Lengths in metres, angles in degrees.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ContactErrors {
    /// Probes used: those that touched at least one mesh (and, with a viewpoint, were on its
    /// side).
    pub probes: usize,
    /// Probes that touched the reference but passed the candidate.
    pub missed_by_candidate: usize,
    /// Probes that touched the candidate where they passed the reference.
    pub extra_in_candidate: usize,
    /// First-contact error measured along the reference's contact normal: the gap between the
    /// surfaces where the probe touches, metres.
    pub first_contact_m: ErrorSummary,
    /// First-contact error along the approach: how much earlier or later the touch comes,
    /// metres.
    pub first_contact_along_approach_m: ErrorSummary,
    /// Angle between the two meshes' contact normals, degrees.
    pub normal_deg: ErrorSummary,
    /// Difference of the penetration depths at the push, metres.
    pub penetration_m: ErrorSummary,
}

/// The contact errors of the probes of one radius.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadiusFidelity {
    pub probe_radius_m: f32,
    pub errors: ContactErrors,
}

/// What [`contact_fidelity`] measured: per probe radius, in the order of
/// [`ContactConfig::probe_radii_m`], and over all of them.
#[derive(Debug, Clone, PartialEq)]
pub struct ContactFidelity {
    pub per_radius: Vec<RadiusFidelity>,
    pub overall: ContactErrors,
    /// The push used for the penetration depths, metres.
    pub push_m: f32,
    /// Probe lines run with each radius.
    pub probe_lines: usize,
}

/// One line of the probe field: where probes start and where they go (unit vector).
#[derive(Debug, Clone, Copy)]
struct ProbeLine {
    start: Vec3,
    direction: Vec3,
}

/// Where and how a ball first touched a mesh.
#[derive(Debug, Clone, Copy)]
struct Touch {
    /// Distance travelled from the start to first contact, metres.
    travel_m: f32,
    /// The touched point of the surface.
    point: Vec3,
    /// Unit vector from the touched point to the ball's centre.
    normal: Vec3,
}

/// Which meshes a used probe touched.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Touched {
    Both,
    /// Only the reference.
    MissedByCandidate,
    /// Only the candidate.
    ExtraInCandidate,
}

/// One probe's errors (stage 4), lengths in metres, first-contact errors capped.
#[derive(Debug, Clone, Copy, PartialEq)]
struct ProbeErrors {
    first_contact_m: f32,
    along_approach_m: f32,
    normal_deg: f32,
    penetration_m: f32,
}

/// One probe's result: `None` when it touched neither mesh or was not from the viewpoint's
/// side.
type Outcome = Option<(Touched, ProbeErrors)>;

/// The probe lines: a seeded rotation of a Fibonacci sphere of directions, each line offset
/// uniformly across the disk of radius `beam_radius_m` about `centre`, starting on the plane
/// `start_distance_m` behind `centre`.
fn probe_lines(
    count: usize,
    seed: u64,
    centre: Vec3,
    beam_radius_m: f32,
    start_distance_m: f32,
) -> Vec<ProbeLine> {
    let mut rng = seeded_rng(seed, PROBE_STREAM);
    // Shoemake's uniform random rotation.
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let rotation = DQuat::from_xyzw(
        (1.0 - u1).sqrt() * (TAU * u2).sin(),
        (1.0 - u1).sqrt() * (TAU * u2).cos(),
        u1.sqrt() * (TAU * u3).sin(),
        u1.sqrt() * (TAU * u3).cos(),
    )
    .normalize();
    let golden_angle = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    (0..count)
        .map(|k| {
            let z = 1.0 - (2.0 * k as f64 + 1.0) / count as f64;
            let ring = (1.0 - z * z).max(0.0).sqrt();
            let azimuth = golden_angle * k as f64;
            let direction = rotation * DVec3::new(ring * azimuth.cos(), ring * azimuth.sin(), z);
            let (across, across2) = direction.any_orthonormal_pair();
            let (r, phi): (f64, f64) = (rng.random(), rng.random());
            let offset = (across * (TAU * phi).cos() + across2 * (TAU * phi).sin()) * r.sqrt();
            let direction = direction.as_vec3();
            ProbeLine {
                start: centre + offset.as_vec3() * beam_radius_m - direction * start_distance_m,
                direction,
            }
        })
        .collect()
}

/// The travel, metres, after which a ball of `radius_m` moving along `line` first touches
/// the triangle `corners`, if it does before `max_travel_m`. Exact, in f64: the first entry of
/// the ball's centre into the triangle grown by the radius, whose boundary is made of the two
/// faces offset by ±r, a cylinder about each edge and a sphere about each corner.
///
/// Our own rather than parry's `cast_shapes` of a `Ball` against the `TriMesh`: parry sweeps
/// a ball against each triangle by GJK, which stops within a tolerance (about 40 µm of travel
/// in a test against a plane) and, near grazing incidence, can put the same surface's contact
/// millimetres apart in two meshes that share it, which this metric would count as error.
fn sweep_ball_triangle(
    line: &ProbeLine,
    radius_m: f64,
    corners: [DVec3; 3],
    max_travel_m: f64,
) -> Option<f64> {
    let origin = line.start.as_dvec3();
    let direction = line.direction.as_dvec3().normalize();
    let mut first: Option<f64> = None;
    let mut consider = |t: f64| {
        if (0.0..max_travel_m).contains(&t) && first.is_none_or(|f| t < f) {
            first = Some(t);
        }
    };
    let [a, b, c] = corners;
    // The two faces, offset by ±r along the normal; the hit must project inside the triangle.
    if let Some(normal) = (b - a).cross(c - a).try_normalize() {
        let approach = direction.dot(normal);
        if approach.abs() > 1e-12 {
            for side in [-1.0, 1.0] {
                let t = (a + normal * (side * radius_m) - origin).dot(normal) / approach;
                let on_plane = origin + direction * t - normal * (side * radius_m);
                let inside = [(a, b), (b, c), (c, a)]
                    .iter()
                    .all(|&(u, v)| normal.dot((v - u).cross(on_plane - u)) >= 0.0);
                if inside {
                    consider(t);
                }
            }
        }
    }
    // The edges' cylinders: entry where the centre is r from the edge's line, within the edge.
    for (u, v) in [(a, b), (b, c), (c, a)] {
        let Some(axis) = (v - u).try_normalize() else {
            continue;
        };
        let from_u = origin - u;
        let direction_across = direction - axis * direction.dot(axis);
        let from_u_across = from_u - axis * from_u.dot(axis);
        let qa = direction_across.length_squared();
        if qa < 1e-18 {
            continue; // parallel to the edge: the corner spheres meet it first
        }
        let qb = from_u_across.dot(direction_across);
        let qc = from_u_across.length_squared() - radius_m * radius_m;
        let discriminant = qb * qb - qa * qc;
        if discriminant < 0.0 {
            continue;
        }
        let t = (-qb - discriminant.sqrt()) / qa;
        let along = (from_u + direction * t).dot(axis);
        if (0.0..=u.distance(v)).contains(&along) {
            consider(t);
        }
    }
    // The corners' spheres.
    for corner in corners {
        let from_corner = origin - corner;
        let qb = from_corner.dot(direction);
        let qc = from_corner.length_squared() - radius_m * radius_m;
        let discriminant = qb * qb - qc;
        if discriminant >= 0.0 {
            consider(-qb - discriminant.sqrt());
        }
    }
    first
}

/// A mesh surface indexed for probing: parry's triangle mesh with its AABB tree.
struct ProbeTarget {
    mesh: ParryTriMesh,
}

impl ProbeTarget {
    fn new(mesh: &TriMesh) -> Result<Self, SimError> {
        check_mesh(mesh)?;
        // No flags: only the BVH (see `metric.rs`); the only error then is no triangles.
        let mesh = ParryTriMesh::new(mesh.vertices.clone(), mesh.triangles.clone())
            .map_err(|_| SimError::EmptyMesh)?;
        Ok(Self { mesh })
    }

    /// Stage 1: where a ball of `radius_m` moving along `line` first touches the surface,
    /// within `max_travel_m`: the triangle whose exact sweep ([`sweep_ball_triangle`]) comes
    /// first, found best-first in parry's AABB tree (each box grown by the radius).
    fn first_touch(&self, line: &ProbeLine, radius_m: f32, max_travel_m: f32) -> Option<Touch> {
        let ray = Ray::new(line.start, line.direction);
        let grow = Vec3::splat(radius_m);
        let (_, travel_m) = self.mesh.bvh().find_best(
            max_travel_m,
            |node, best_m| {
                Aabb::new(node.mins() - grow, node.maxs() + grow)
                    .cast_local_ray(&ray, best_m, true)
                    .unwrap_or(f32::MAX)
            },
            |triangle, best_m| {
                let corners = self.mesh.triangle(triangle);
                sweep_ball_triangle(
                    line,
                    f64::from(radius_m),
                    [corners.a, corners.b, corners.c].map(Vec3::as_dvec3),
                    f64::from(best_m),
                )
                .map(|t| t as f32)
            },
        )?;
        let centre = line.start + line.direction * travel_m;
        let point = self.mesh.project_local_point(centre, false).point;
        let normal = (centre - point).try_normalize().unwrap_or(-line.direction);
        Some(Touch {
            travel_m,
            point,
            normal,
        })
    }

    /// Stage 4, for a miss: how far a ball of `radius_m` centred at `centre` is from touching
    /// this surface, metres, and the unit vector from the surface's closest point to the centre.
    fn clearance(&self, centre: Vec3, radius_m: f32, fallback_normal: Vec3) -> (f32, Vec3) {
        let closest = self.mesh.project_local_point(centre, false).point;
        let normal = (centre - closest)
            .try_normalize()
            .unwrap_or(fallback_normal);
        ((closest.distance(centre) - radius_m).max(0.0), normal)
    }

    /// Stage 3: the penetration depth of a ball of `radius_m` whose centre has travelled
    /// `travel_m` along `line`: `r - s` in front of the surface, `r + s` behind it (an odd
    /// number of crossings of the centre's path), never below zero.
    fn penetration_m(&self, line: &ProbeLine, travel_m: f32, radius_m: f32) -> f32 {
        let centre = line.start + line.direction * travel_m;
        let distance_m = self
            .mesh
            .project_local_point(centre, false)
            .point
            .distance(centre);
        if self.crossings(line, travel_m) % 2 == 1 {
            radius_m + distance_m
        } else {
            (radius_m - distance_m).max(0.0)
        }
    }

    /// How many times the line crosses the surface between its start and `travel_m`.
    fn crossings(&self, line: &ProbeLine, travel_m: f32) -> usize {
        let mut from_m = 0.0;
        let mut count = 0;
        while count < MAX_CROSSINGS && from_m < travel_m {
            let ray = Ray::new(line.start + line.direction * from_m, line.direction);
            match self.mesh.cast_local_ray(&ray, travel_m - from_m, false) {
                Some(t) => {
                    count += 1;
                    from_m += t + CROSSING_STEP_M;
                }
                None => break,
            }
        }
        count
    }
}

/// Angle between two unit vectors in degrees, accurate near 0 (atan2 rather than acos).
fn angle_deg(a: Vec3, b: Vec3) -> f32 {
    let (a, b) = (a.as_dvec3(), b.as_dvec3());
    a.cross(b).length().atan2(a.dot(b)).to_degrees() as f32
}

/// Everything one radius's probes share.
struct ProbeRun<'a> {
    reference: &'a ProbeTarget,
    candidate: &'a ProbeTarget,
    radius_m: f32,
    push_m: f32,
    /// [`ContactConfig::first_contact_cap_m`].
    cap_m: f32,
    max_travel_m: f32,
    /// The viewpoint and the centre of the probe field.
    viewpoint: Option<(Vec3, Vec3)>,
}

impl ProbeRun<'_> {
    /// Stages 1 to 4 for one probe.
    fn probe(&self, line: &ProbeLine) -> Outcome {
        if let Some((viewpoint, centre)) = self.viewpoint {
            if (-line.direction).dot(viewpoint - centre) <= 0.0 {
                return None;
            }
        }
        let on_reference = self
            .reference
            .first_touch(line, self.radius_m, self.max_travel_m);
        let on_candidate = self
            .candidate
            .first_touch(line, self.radius_m, self.max_travel_m);
        let first = on_reference.or(on_candidate)?;
        if let Some((viewpoint, _)) = self.viewpoint {
            if first.normal.dot(viewpoint - first.point) <= 0.0 {
                return None;
            }
        }
        let pushed_m = first.travel_m + self.push_m;
        let penetration_m = (self.reference.penetration_m(line, pushed_m, self.radius_m)
            - self.candidate.penetration_m(line, pushed_m, self.radius_m))
        .abs();
        let (touched, first_contact_m, along_approach_m, normal_deg) =
            match (on_reference, on_candidate) {
                (Some(r), Some(c)) => {
                    let along_approach_m = (c.travel_m - r.travel_m).abs();
                    (
                        Touched::Both,
                        along_approach_m * r.normal.dot(line.direction).abs(),
                        along_approach_m,
                        angle_deg(r.normal, c.normal),
                    )
                }
                (Some(touch), None) | (None, Some(touch)) => {
                    let (touched, other) = if on_reference.is_some() {
                        (Touched::MissedByCandidate, self.candidate)
                    } else {
                        (Touched::ExtraInCandidate, self.reference)
                    };
                    let centre = line.start + line.direction * touch.travel_m;
                    let (clearance_m, other_normal) =
                        other.clearance(centre, self.radius_m, touch.normal);
                    (
                        touched,
                        clearance_m,
                        self.cap_m,
                        angle_deg(touch.normal, other_normal),
                    )
                }
                (None, None) => return None,
            };
        Some((
            touched,
            ProbeErrors {
                first_contact_m: first_contact_m.min(self.cap_m),
                along_approach_m: along_approach_m.min(self.cap_m),
                normal_deg,
                penetration_m,
            },
        ))
    }
}

/// Stage 5, for one error: mean in f64 in probe order, nearest-rank p50 and p95, maximum.
fn summarise(mut values: Vec<f64>) -> ErrorSummary {
    if values.is_empty() {
        return ErrorSummary {
            mean: 0.0,
            p50: 0.0,
            p95: 0.0,
            max: 0.0,
        };
    }
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    values.sort_by(f64::total_cmp);
    let nearest_rank = |q: f64| {
        let rank = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len());
        values[rank - 1]
    };
    ErrorSummary {
        mean,
        p50: nearest_rank(0.5),
        p95: nearest_rank(0.95),
        max: values[values.len() - 1],
    }
}

/// Stage 5: the errors of a set of probes.
fn summarise_outcomes<'a>(outcomes: impl Iterator<Item = &'a Outcome>) -> ContactErrors {
    let mut first_contact = Vec::new();
    let mut along_approach = Vec::new();
    let mut normal = Vec::new();
    let mut penetration = Vec::new();
    let (mut missed_by_candidate, mut extra_in_candidate) = (0, 0);
    for (touched, errors) in outcomes.flatten() {
        match touched {
            Touched::Both => {}
            Touched::MissedByCandidate => missed_by_candidate += 1,
            Touched::ExtraInCandidate => extra_in_candidate += 1,
        }
        first_contact.push(f64::from(errors.first_contact_m));
        along_approach.push(f64::from(errors.along_approach_m));
        normal.push(f64::from(errors.normal_deg));
        penetration.push(f64::from(errors.penetration_m));
    }
    ContactErrors {
        probes: first_contact.len(),
        missed_by_candidate,
        extra_in_candidate,
        first_contact_m: summarise(first_contact),
        first_contact_along_approach_m: summarise(along_approach),
        normal_deg: summarise(normal),
        penetration_m: summarise(penetration),
    }
}

/// Checks the settings before any probing, naming the first bad one.
fn check_config(config: &ContactConfig) -> Result<(), SimError> {
    if config.probe_radii_m.is_empty() {
        return Err(SimError::NoProbeRadii);
    }
    if let Some(&radius_m) = config
        .probe_radii_m
        .iter()
        .find(|r| !(r.is_finite() && **r > 0.0))
    {
        return Err(SimError::InvalidProbeRadius { radius_m });
    }
    if config.probe_lines == 0 {
        return Err(SimError::NoProbeLines);
    }
    for (name, value) in [
        ("push_m", config.push_m),
        ("first_contact_cap_m", config.first_contact_cap_m),
    ] {
        if !(value.is_finite() && value >= 0.0) {
            return Err(SimError::InvalidContactSetting { name, value });
        }
    }
    if let Some(viewpoint) = config.viewpoint_m.filter(|v| !v.is_finite()) {
        return Err(SimError::NonFiniteViewpoint { viewpoint });
    }
    Ok(())
}

/// Contact fidelity of `candidate` against `reference`: probe balls of each radius in `config`
/// moved along the same lines toward both meshes, their first contacts, contact normals and
/// penetration depths at a fixed push compared (see the module documentation for the probe set
/// and every rule). Both meshes are treated as surfaces, so an open candidate is fine; the
/// reference's orientation is not used either.
///
/// Deterministic: the same meshes, config and seed give the same result on any thread count.
///
/// Fails with [`SimError::InMesh`] naming the mesh if either has no triangles, a bad index or
/// a non-finite vertex; on a bad setting ([`SimError::InvalidProbeRadius`],
/// [`SimError::InvalidContactSetting`], [`SimError::NoProbeRadii`], [`SimError::NoProbeLines`],
/// [`SimError::NonFiniteViewpoint`]); and with [`SimError::NoContacts`] when no probe of a
/// radius touched either mesh (from the viewpoint's side).
pub fn contact_fidelity(
    reference: &TriMesh,
    candidate: &TriMesh,
    config: &ContactConfig,
) -> Result<ContactFidelity, SimError> {
    check_config(config)?;
    let reference_target = ProbeTarget::new(reference).map_err(SimError::in_mesh("reference"))?;
    let candidate_target = ProbeTarget::new(candidate).map_err(SimError::in_mesh("candidate"))?;

    let (low, high) = reference
        .bounds()
        .ok_or_else(|| SimError::in_mesh("reference")(SimError::EmptyMesh))?;
    let centre = (low + high) * 0.5;
    let bounding_radius_m = reference
        .vertices
        .iter()
        .chain(&candidate.vertices)
        .map(|v| v.distance(centre))
        .fold(0.0f32, f32::max);
    let largest_radius_m = config.probe_radii_m.iter().copied().fold(0.0, f32::max);
    let beam_radius_m = bounding_radius_m + largest_radius_m;
    let start_distance_m =
        beam_radius_m + START_MARGIN_M + START_MARGIN_FRACTION * bounding_radius_m;
    let lines = probe_lines(
        config.probe_lines,
        config.seed,
        centre,
        beam_radius_m,
        start_distance_m,
    );

    let mut per_radius = Vec::with_capacity(config.probe_radii_m.len());
    let mut all_outcomes = Vec::with_capacity(config.probe_radii_m.len() * lines.len());
    for &radius_m in &config.probe_radii_m {
        let run = ProbeRun {
            reference: &reference_target,
            candidate: &candidate_target,
            radius_m,
            push_m: config.push_m,
            cap_m: config.first_contact_cap_m,
            max_travel_m: 2.0 * start_distance_m,
            viewpoint: config.viewpoint_m.map(|v| (v, centre)),
        };
        let outcomes: Vec<Outcome> = lines.par_iter().map(|line| run.probe(line)).collect();
        let errors = summarise_outcomes(outcomes.iter());
        if errors.probes == 0 {
            return Err(SimError::NoContacts { radius_m });
        }
        per_radius.push(RadiusFidelity {
            probe_radius_m: radius_m,
            errors,
        });
        all_outcomes.extend(outcomes);
    }
    Ok(ContactFidelity {
        per_radius,
        overall: summarise_outcomes(all_outcomes.iter()),
        push_m: config.push_m,
        probe_lines: lines.len(),
    })
}

#[cfg(test)]
mod tests {
    use glam::Quat;

    use super::*;
    use crate::{cube, uv_sphere, Shape};

    /// A config with one probe radius and otherwise the defaults.
    fn one_radius(radius_m: f32) -> ContactConfig {
        ContactConfig {
            probe_radii_m: vec![radius_m],
            ..ContactConfig::default()
        }
    }

    /// A 2 m square in the plane z = 0, two triangles.
    fn square() -> TriMesh {
        TriMesh::new(
            vec![
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn ball_meets_a_plane_where_geometry_says() {
        // A 10 mm ball from (0, 0, 1) at 30° to the plane's normal touches when its centre is
        // 10 mm above the plane: after (1 - 0.01) / cos 30° of travel, normal +Z.
        let target = ProbeTarget::new(&square()).expect("valid mesh");
        let direction = Vec3::new(30f32.to_radians().sin(), 0.0, -30f32.to_radians().cos());
        let line = ProbeLine {
            start: Vec3::new(-0.3, 0.1, 1.0),
            direction,
        };
        let touch = target
            .first_touch(&line, 0.01, 3.0)
            .expect("the ball lands");
        let expected_m = 0.99 / 30f32.to_radians().cos();
        assert!((touch.travel_m - expected_m).abs() < 1e-5, "{touch:?}");
        assert!(angle_deg(touch.normal, Vec3::Z) < 0.01, "{touch:?}");
        assert!(touch.point.z.abs() < 1e-6, "{touch:?}");
        // Pushed 20 mm further, the centre is 20 cos 30° - 10 mm behind the plane.
        let depth_m = target.penetration_m(&line, touch.travel_m + 0.02, 0.01);
        assert!(
            (depth_m - 0.02 * 30f32.to_radians().cos()).abs() < 1e-5,
            "{depth_m}"
        );
        // Short of the plane, a ball overlapping it by 4 mm is 4 mm deep; clear of it, 0.
        let depth_m = target.penetration_m(&line, expected_m + 0.004 / direction.z.abs(), 0.01);
        assert!((depth_m - 0.004).abs() < 1e-5, "{depth_m}");
        assert_eq!(target.penetration_m(&line, 0.5, 0.01), 0.0);
        // Missing the square altogether.
        let past = ProbeLine {
            start: Vec3::new(5.0, 0.0, 1.0),
            direction: -Vec3::Z,
        };
        assert!(target.first_touch(&past, 0.01, 3.0).is_none());
    }

    #[test]
    fn a_probe_through_a_thin_wall_comes_out_again() {
        // Two parallel squares 5 mm apart: pushed 10 mm past the first, the centre has crossed
        // both and is 5 mm beyond the second, in front of it again: depth 10 - 5 mm.
        let mut wall = square();
        let mut back = square();
        back.transform(1.0, Vec3::new(0.0, 0.0, -0.005));
        let offset = wall.vertices.len() as u32;
        wall.vertices.extend(back.vertices);
        wall.triangles
            .extend(back.triangles.iter().map(|t| t.map(|i| i + offset)));
        let target = ProbeTarget::new(&wall).expect("valid mesh");
        let line = ProbeLine {
            start: Vec3::new(0.1, 0.2, 1.0),
            direction: -Vec3::Z,
        };
        assert_eq!(target.crossings(&line, 1.0 + 0.002), 1);
        assert_eq!(target.crossings(&line, 1.0 + 0.010), 2);
        let depth_m = target.penetration_m(&line, 1.0 + 0.010, 0.010);
        assert!((depth_m - 0.005).abs() < 1e-5, "{depth_m}");
    }

    #[test]
    fn identical_meshes_touch_identically() {
        let mesh = Shape::Monkey.mesh();
        let f = contact_fidelity(&mesh, &mesh, &ContactConfig::default()).expect("valid meshes");
        assert_eq!(f.per_radius.len(), 4);
        for errors in f.per_radius.iter().map(|r| r.errors).chain([f.overall]) {
            assert!(errors.probes > 300, "{errors:?}");
            assert_eq!(errors.missed_by_candidate + errors.extra_in_candidate, 0);
            for summary in [
                errors.first_contact_m,
                errors.first_contact_along_approach_m,
                errors.penetration_m,
            ] {
                assert!(summary.max < 1e-6, "{errors:?}");
            }
            assert!(errors.normal_deg.max < 0.01, "{errors:?}");
        }
        assert_eq!(
            f.overall.probes,
            f.per_radius.iter().map(|r| r.errors.probes).sum::<usize>()
        );
    }

    #[test]
    fn sphere_against_one_10mm_larger_is_10mm_off_along_the_normal() {
        // A fine UV sphere of radius 0.5 m against the same scaled to 0.51 m: every face moves
        // out by 10 mm (0.02 of its distance from the centre, within 0.1 mm of 0.5 m).
        let small = uv_sphere(64, 32, 0.5);
        let big = uv_sphere(64, 32, 0.51);
        for radius_m in [0.005, 0.05] {
            let config = one_radius(radius_m);
            let f = contact_fidelity(&small, &big, &config).expect("valid meshes");
            let e = f.overall;
            // Lines passing within the big sphere's reach but outside the small one's stop
            // only on the candidate: (R'+r)² - (R+r)² of (R'+r)² of the used lines.
            assert_eq!(e.missed_by_candidate, 0, "{e:?}");
            let reach = |sphere_m: f32| (sphere_m + radius_m).powi(2);
            let expected = (reach(0.51) - reach(0.5)) / reach(0.51);
            let extra = e.extra_in_candidate as f32 / e.probes as f32;
            assert!(
                (extra / expected - 1.0).abs() < 0.3,
                "{extra} vs {expected}: {e:?}"
            );
            // Along the normal, the gap is 10 mm except near grazing, where it falls to 0; the
            // extra probes graze the big sphere less than 10 mm from the small one.
            assert!((0.0085..0.0101).contains(&e.first_contact_m.mean), "{e:?}");
            assert!((0.0095..0.0101).contains(&e.first_contact_m.p50), "{e:?}");
            assert!((0.0095..0.0101).contains(&e.first_contact_m.p95), "{e:?}");
            // Along the approach it is longer, 10 mm / cos θ, and the misses count the cap.
            assert!(e.first_contact_along_approach_m.mean > 0.012, "{e:?}");
            // The normals differ where the probe meets the larger sphere earlier, at another
            // point: by asin(b/(R+r)) - asin(b/(R'+r)) at impact parameter b, whose mean over
            // lines uniform in b² is about π/2 · (1 - (R+r)/(R'+r)) rad = 1.6-1.8°.
            assert!((1.2..2.3).contains(&e.normal_deg.mean), "{e:?}");
            assert!(e.normal_deg.p50 < 1.5, "{e:?}");
            // Pushed 10 mm past the small sphere, the ball is 20 mm into the big one (less
            // away from normal incidence).
            assert!((0.0085..0.0101).contains(&e.penetration_m.p50), "{e:?}");
        }
    }

    #[test]
    fn cube_turned_5_degrees_turns_contact_normals_by_that() {
        // A 5° turn about (1, 1, 1) turns every face normal by 2 asin(sin 2.5° · √(2/3)) =
        // 4.08°: the median contact. Near the edges, which the turn moves by up to 4 cm, one
        // mesh is touched on a face and the other on an edge or the next face, at up to 90°.
        let reference = Shape::Cube.mesh();
        let mut turned = reference.clone();
        let rotation = Quat::from_axis_angle(Vec3::ONE.normalize(), 5f32.to_radians());
        for v in &mut turned.vertices {
            *v = rotation * *v;
        }
        let f = contact_fidelity(&reference, &turned, &one_radius(0.005)).expect("valid meshes");
        let e = f.overall;
        let face_turn_deg = 2.0 * ((2.5f64).to_radians().sin() * (2.0f64 / 3.0).sqrt()).asin();
        let face_turn_deg = face_turn_deg.to_degrees();
        assert!(
            (e.normal_deg.p50 - face_turn_deg).abs() < 0.05,
            "{} vs {face_turn_deg}: {e:?}",
            e.normal_deg.p50
        );
        assert!(e.normal_deg.mean > face_turn_deg, "{e:?}");
        // Turned corners stick out (extra) and leave gaps (missed) at the silhouette.
        assert!(
            e.missed_by_candidate > 0 && e.extra_in_candidate > 0,
            "{e:?}"
        );
    }

    #[test]
    fn a_half_open_candidate_lets_probes_through() {
        // The upper half of the sphere's faces removed: probes that would touch only the upper
        // half pass the candidate.
        let reference = uv_sphere(32, 16, 0.5);
        let mut open = reference.clone();
        open.triangles.retain(|t| {
            t.iter()
                .map(|&i| reference.vertices[i as usize].z)
                .sum::<f32>()
                < 0.0
        });
        let f = contact_fidelity(&reference, &open, &ContactConfig::default()).expect("valid");
        let e = f.overall;
        assert!(
            e.missed_by_candidate as f32 > 0.1 * e.probes as f32,
            "{e:?}"
        );
        assert_eq!(e.extra_in_candidate, 0, "{e:?}");
        // Through the open top, the ball is far from the candidate's rim.
        assert!(e.first_contact_m.p95 >= 0.049, "{e:?}");
        assert!(e.penetration_m.p95 >= 0.009, "{e:?}");

        // Seen from below, the open shell is what the sensor saw: the one-sided variant uses
        // only probes from below that touch the lower half, and finds it exact there.
        let from_below = ContactConfig {
            viewpoint_m: Some(Vec3::new(0.3, -0.2, -2.0)),
            ..ContactConfig::default()
        };
        let seen = contact_fidelity(&reference, &open, &from_below).expect("valid");
        let e = seen.overall;
        assert!(e.probes > 1000, "{e:?}");
        assert_eq!(e.missed_by_candidate + e.extra_in_candidate, 0, "{e:?}");
        assert!(e.first_contact_m.max < 1e-6, "{e:?}");
        assert!(e.normal_deg.max < 0.01, "{e:?}");
    }

    #[test]
    fn result_is_the_same_on_any_thread_count() {
        let (a, b) = (Shape::Torus.mesh(), Shape::Sphere.mesh());
        let config = ContactConfig {
            probe_lines: 500,
            ..ContactConfig::default()
        };
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .expect("thread pool")
                .install(|| contact_fidelity(&a, &b, &config).expect("valid meshes"))
        };
        let first = run(1);
        assert_eq!(first, run(3));
        assert_eq!(
            first,
            contact_fidelity(&a, &b, &config).expect("valid meshes")
        );
        let other_seed = ContactConfig {
            seed: 2,
            ..config.clone()
        };
        assert_ne!(
            first,
            contact_fidelity(&a, &b, &other_seed).expect("valid meshes")
        );
    }

    #[test]
    fn bad_settings_and_meshes_are_named() {
        let cube = cube(1.0);
        let with = |config: ContactConfig| contact_fidelity(&cube, &cube, &config);
        assert!(matches!(
            with(ContactConfig { probe_radii_m: vec![0.01, -0.005], ..ContactConfig::default() }),
            Err(SimError::InvalidProbeRadius { radius_m }) if radius_m == -0.005
        ));
        assert!(matches!(
            with(ContactConfig {
                probe_radii_m: vec![],
                ..ContactConfig::default()
            }),
            Err(SimError::NoProbeRadii)
        ));
        assert!(matches!(
            with(ContactConfig {
                push_m: f32::NAN,
                ..ContactConfig::default()
            }),
            Err(SimError::InvalidContactSetting { name: "push_m", .. })
        ));
        assert!(matches!(
            with(ContactConfig {
                probe_lines: 0,
                ..ContactConfig::default()
            }),
            Err(SimError::NoProbeLines)
        ));
        assert!(matches!(
            with(ContactConfig {
                viewpoint_m: Some(Vec3::splat(f32::INFINITY)),
                ..ContactConfig::default()
            }),
            Err(SimError::NonFiniteViewpoint { .. })
        ));
        let err = contact_fidelity(&cube, &TriMesh::default(), &ContactConfig::default())
            .expect_err("empty candidate");
        assert!(
            matches!(
                err,
                SimError::InMesh {
                    role: "candidate",
                    ..
                }
            ),
            "{err:?}"
        );
    }
}
