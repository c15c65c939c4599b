//! Rigid alignment of a new cluster to an object's fused moments: point-to-plane ICP (Chen &
//! Medioni 1992) with the small-angle linearisation of Low 2004 ("Linear least-squares
//! optimization for point-to-plane ICP surface registration"), coarse to fine.
//!
//! The model needs no points, normals or k-d tree: a new point's correspondence is the plane of
//! the moments summed over the 3×3×3 voxels around the voxel it falls in (centroid and
//! least-spread direction, see `tacmesh_reconstruct::moments`), so a look-up replaces a nearest
//! neighbour search. Planes are fitted once per voxel per frame and cached. Two levels: the
//! fused grid coarsened by an integer factor (kept up to date by the object, not rebuilt)
//! brings points from a few centimetres away into the fine grid's capture range of about one
//! fine voxel.
//!
//! Each Gauss–Newton step solves `(JᵀJ + Λ)·x = −(Jᵀr + Λ·x_so_far)` for `x = (ω, t)`, the
//! rotation vector and translation applied in the object frame, where each inlier contributes
//! the row `J = [q × n, n]` and residual `r = n·(q − c)`. `Λ` is a weak prior on the total
//! change from the starting pose. Directions the surface cannot observe (a sphere spinning
//! about its centre, a box seen from two faces sliding along their edge) are taken from the
//! cluster's centroid instead, or left at the prediction, never from noise.
//!
//! Entry points: [`IcpScratch`] (plane caches, reused across frames), [`align_to_grids`].

use glam::{Affine3A, DVec3, IVec3, Quat, Vec3};
use rustc_hash::FxHashMap;
use tacmesh_reconstruct::moment_grid::MomentGrid;
use tacmesh_reconstruct::moments::Plane;

use crate::solve6::{solve_spd6, symmetric_eigen6};

/// Fewest points in a voxel's 3×3×3 neighbourhood for it to offer a plane.
const MIN_PLANE_POINTS: f64 = 6.0;
/// The anchor is used only while at least this fraction of the cluster lies on the fused
/// surface: when a face turns into view (points with no model yet) the centroid jumps by
/// centimetres, and the free directions then stay at the prediction for that frame.
const ANCHOR_MIN_INLIER_FRACTION: f64 = 0.9;
/// An increment this small (radians, metres) ends a level's iterations.
const CONVERGED_STEP: f64 = 1e-5;

/// One level of the coarse-to-fine schedule, in the object frame.
#[derive(Clone, Copy)]
pub struct IcpLevel<'a> {
    pub grid: &'a MomentGrid,
    pub iterations: u32,
    /// Correspondences farther than this from their plane are outliers, metres.
    pub reject_m: f32,
}

/// When an alignment counts as a failure, and the prior's weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IcpSettings {
    pub min_inliers: usize,
    pub min_inlier_fraction: f32,
    pub max_rms_m: f32,
    /// Per-point weight of the prior on the change from the starting pose (translation in
    /// metres; rotation scaled by the points' RMS distance from the object origin).
    pub prior_weight: f32,
    /// Step directions whose curvature is below this fraction of the largest are not moved
    /// along (see `gauss_newton_step`).
    pub degenerate_ratio: f32,
}

/// A successful alignment.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Alignment {
    /// Maps the cluster's world points onto the fused model.
    pub object_from_world: Affine3A,
    /// Points within the last level's rejection distance of their plane.
    pub inliers: usize,
    /// RMS point-to-plane distance of the inliers, metres.
    pub rms_m: f32,
    /// The last level's [`truncated_cost`] at the result, from the same pass that counted the
    /// inliers.
    pub truncated_cost: f64,
    /// Turns the surface does not show at the result (a cone's or a cylinder's spin about its
    /// axis, a sphere's about its centre): the alignment left them at the guess.
    pub unseen_turns: UnseenTurns,
}

/// Turns the surface cannot show, each about an axis line in the object frame: a cone's or a
/// cylinder's spin about its own axis, a sphere's about its centre.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct UnseenTurns {
    /// Unit direction of each axis and the point of it nearest the object origin.
    axes: [(Vec3, Vec3); 3],
    count: usize,
}

impl UnseenTurns {
    /// `step` without its turn about the axis, when there is exactly one (a surface of
    /// revolution: a cone, a cylinder, a torus, a bowl). `step` maps object coordinates at one
    /// pose to those at another (`object_from_world' = step · object_from_world`); the axis
    /// moves as before, so an object that slides without turning gets back a pure slide
    /// however its spin was guessed. (Removing the free eigen-direction of the step instead
    /// would not do: in the step's coordinates a pure slide has a part along it.)
    ///
    /// Two or three (a sphere's cap) are left alone: their lines, from nearly equal small
    /// eigenvalues, miss the centre by millimetres, and taking a sphere's spin out about that
    /// pivot moved its centre 5 mm off in three frames (`moving_objects_keep_ids_and_poses_follow`).
    pub fn removed_from(&self, step: &Affine3A) -> Affine3A {
        let [(axis, point)] = self.axes[..self.count] else {
            return *step;
        };
        let rotation = Quat::from_mat3a(&step.matrix3);
        // The swing: what is left of the rotation after its twist about the axis.
        let kept = rotation * twist_about(rotation, axis).inverse();
        let moved = step.transform_point3(point);
        Affine3A::from_rotation_translation(kept, moved - kept * point)
    }
}

/// The part of `rotation` about `axis` (unit): the twist of its swing–twist decomposition.
fn twist_about(rotation: Quat, axis: Vec3) -> Quat {
    let along = axis * Vec3::new(rotation.x, rotation.y, rotation.z).dot(axis);
    let twist = Quat::from_xyzw(along.x, along.y, along.z, rotation.w);
    if twist.length_squared() < 1e-12 {
        Quat::IDENTITY
    } else {
        twist.normalize()
    }
}

/// At least this much of an unseen direction's length (squared, in the step's scaled
/// coordinates `(ω·ρ, t)`) is turn for it to count as a turn; the rest are slides, which the
/// centroid follows.
const TURN_SHARE: f64 = 0.5;

/// The directions of `eq` the surface cannot show (curvature below `degenerate_ratio` times
/// the largest) that are mostly turns, as axis lines.
fn unseen_turns(eq: &NormalEquations, degenerate_ratio: f32) -> UnseenTurns {
    let n = eq.inliers.max(1) as f64;
    let rho = (eq.sum_q2 / n).sqrt().max(1e-3);
    let scale = [1.0 / rho, 1.0 / rho, 1.0 / rho, 1.0, 1.0, 1.0];
    let (values, vectors) = symmetric_eigen6(&scaled_full(&eq.h, &scale));
    let largest = values.iter().copied().fold(0.0f64, f64::max);
    let mut turns = UnseenTurns::default();
    for (value, v) in values.iter().zip(&vectors) {
        let turn: f64 = v[..3].iter().map(|v| v * v).sum();
        if *value >= f64::from(degenerate_ratio) * largest
            || turn < TURN_SHARE
            || turns.count == turns.axes.len()
        {
            continue;
        }
        // The direction is the twist (ω, t) = (v₀₋₂ / ρ, v₃₋₅): a turn about the line through
        // ω × t / |ω|² along ω (t = −ω × p for a point p of it).
        let omega = DVec3::new(v[0], v[1], v[2]) / rho;
        let t = DVec3::new(v[3], v[4], v[5]);
        let point = omega.cross(t) / omega.length_squared();
        turns.axes[turns.count] = (omega.normalize().as_vec3(), point.as_vec3());
        turns.count += 1;
    }
    turns
}

/// Why the cluster could not be aligned to the model (the tracker then resets the object).
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
pub enum IcpFailure {
    #[error("only {inliers} of {points} points lie near the fused surface")]
    TooFewInliers { inliers: usize, points: usize },
    #[error("the aligned points lie {rms_m} m (RMS) from the fused surface, over {max_rms_m} m")]
    LargeResidual { rms_m: f32, max_rms_m: f32 },
    #[error("the normal equations are singular (no points near the fused surface)")]
    Degenerate,
    /// Not the solver's own verdict: the tracker's check of an alignment against the frame's
    /// free space (`TrackedObject::observe`).
    #[error(
        "the camera sees through {percent:.0} % of the fused surface at the aligned pose \
         (something else stands there now)"
    )]
    SeenThrough { percent: f32 },
    /// Also the tracker's: a still object would have jumped, with a cluster that lands on it
    /// only in part (`TrackedObject::observe`).
    #[error(
        "a still object would have jumped by {shift_mm:.0} mm and {turn_deg:.0} degrees with \
         only {percent:.0} % of the cluster on it (another object stands there now)"
    )]
    JumpedWhileStill {
        shift_mm: f32,
        turn_deg: f32,
        percent: f32,
    },
}

/// Plane caches, one per grid (told apart by voxel size); clear with
/// [`IcpScratch::start_object`] before aligning to another object (or to the same object after
/// it changed). Kept by the caller so its allocations are reused frame after frame.
#[derive(Debug, Default)]
pub struct IcpScratch {
    /// A cache per grid, by the bits of its voxel size.
    planes: Vec<(u32, FxHashMap<IVec3, Option<Plane>>)>,
}

impl IcpScratch {
    pub fn start_object(&mut self) {
        for (_, cache) in &mut self.planes {
            cache.clear();
        }
    }

    fn cache_for(&mut self, grid: &MomentGrid) -> &mut FxHashMap<IVec3, Option<Plane>> {
        let key = grid.voxel_size_m().to_bits();
        let index = match self.planes.iter().position(|(k, _)| *k == key) {
            Some(index) => index,
            None => {
                self.planes.push((key, FxHashMap::default()));
                self.planes.len() - 1
            }
        };
        &mut self.planes[index].1
    }
}

/// The plane of the moments around `cell`, if `cell` itself holds model points and its
/// neighbourhood enough of them. A point in an empty voxel gets no plane even beside the
/// surface: it is most likely on a part of the object the model has not seen yet (a face
/// turning into view), and the plane of the face next to it would drag the pose.
fn plane_near(grid: &MomentGrid, cell: IVec3) -> Option<Plane> {
    grid.get(cell)?;
    let around = grid.neighbourhood(cell, 1);
    if around.count < MIN_PLANE_POINTS {
        return None;
    }
    around.plane()
}

/// Adds one linearised residual `r + dir·(ω × q + t)` to `h`, `g` (lower triangle of `h`).
fn add_row(h: &mut [[f64; 6]; 6], g: &mut [f64; 6], q: DVec3, dir: DVec3, r: f64, weight: f64) {
    let qd = q.cross(dir);
    let j = [qd.x, qd.y, qd.z, dir.x, dir.y, dir.z];
    for a in 0..6 {
        for b in 0..=a {
            h[a][b] += weight * j[a] * j[b];
        }
        g[a] += weight * j[a] * r;
    }
}

/// Normal equations of one Gauss–Newton step, accumulated in f64 (lower triangles).
#[derive(Default)]
struct NormalEquations {
    h: [[f64; 6]; 6],
    g: [f64; 6],
    inliers: usize,
    sum_r2: f64,
    sum_q2: f64,
}

impl NormalEquations {
    fn add(&mut self, q: DVec3, plane_point: DVec3, normal: DVec3) {
        self.add_inlier(q, normal, normal.dot(q - plane_point));
    }

    /// One inlier's row: residual `r` along `dir`, rotations acting through `lever` (the
    /// point relative to the centre the step turns about).
    fn add_inlier(&mut self, lever: DVec3, dir: DVec3, r: f64) {
        add_row(&mut self.h, &mut self.g, lever, dir, r, 1.0);
        self.inliers += 1;
        self.sum_r2 += r * r;
        self.sum_q2 += lever.length_squared();
    }

    fn rms_m(&self) -> f32 {
        (self.sum_r2 / self.inliers.max(1) as f64).sqrt() as f32
    }
}

/// The plane `level` offers a point at `q` (object frame), looked up once per voxel.
fn cached_plane(
    level: &IcpLevel,
    cache: &mut FxHashMap<IVec3, Option<Plane>>,
    q: Vec3,
) -> Option<Plane> {
    let cell = level.grid.cell_of(q);
    *cache
        .entry(cell)
        .or_insert_with(|| plane_near(level.grid, cell))
}

/// Accumulates the inliers of `points` (world) under `object_from_world` against one level.
fn accumulate(
    level: &IcpLevel,
    cache: &mut FxHashMap<IVec3, Option<Plane>>,
    points_in_world: &[Vec3],
    object_from_world: &Affine3A,
) -> NormalEquations {
    let mut eq = NormalEquations::default();
    let reject = f64::from(level.reject_m);
    for &p_in_world in points_in_world {
        let q = object_from_world.transform_point3(p_in_world);
        let Some(plane) = cached_plane(level, cache, q) else {
            continue;
        };
        let (q, normal, point) = (
            q.as_dvec3(),
            plane.normal.as_dvec3(),
            plane.point.as_dvec3(),
        );
        if normal.dot(q - point).abs() <= reject {
            eq.add(q, point, normal);
        }
    }
    eq
}

/// Symmetric copy of a lower triangle, scaled as `D·h·D`.
fn scaled_full(lower: &[[f64; 6]; 6], scale: &[f64; 6]) -> [[f64; 6]; 6] {
    let mut h = [[0.0f64; 6]; 6];
    for a in 0..6 {
        for b in 0..=a {
            let v = lower[a][b] * scale[a] * scale[b];
            h[a][b] = v;
            h[b][a] = v;
        }
    }
    h
}

fn mat_vec(m: &[[f64; 6]; 6], v: &[f64; 6]) -> [f64; 6] {
    m.map(|row| row.iter().zip(v).map(|(a, b)| a * b).sum())
}

fn dot6(a: &[f64; 6], b: &[f64; 6]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

/// One step `x = (ω, t)` from the normal equations, with the prior on the total change
/// `moved` so far.
///
/// Rotations are scaled by the points' RMS distance `ρ` from the object origin (`ω·ρ` is the
/// displacement a rotation causes), so all six unknowns are lengths and the eigenvalues
/// compare. Directions whose point-to-plane curvature is below `degenerate_ratio` times the
/// largest are unobservable from the planes (a sphere's spin about its centre, a slide along
/// the edge of a box seen from two faces): there the prior alone would let noise push the pose
/// as far as the weak curvature allows (Zhang, Kaess & Singh 2016, "On degeneracy of
/// optimization-based state estimation problems"), so they get no step from the planes. Those
/// that move the centroid (mostly shifts) are solved from the `anchor` instead, if any: the
/// cluster's centroid should land where the last cluster's did. Centroids follow the visible
/// part, so they are trusted only where the surface gives nothing: a box's edge is seen whole,
/// so its centroid fixes the slide. Free turns about the centroid (a sphere's spin, harmless
/// since it changes nothing seen) and, without an anchor, all free directions stay at the
/// prediction.
fn gauss_newton_step(
    eq: &NormalEquations,
    anchor: Option<(DVec3, DVec3)>,
    moved: &[f64; 6],
    settings: &IcpSettings,
) -> Result<[f64; 6], IcpFailure> {
    let n = eq.inliers as f64;
    let rho = (eq.sum_q2 / n).sqrt().max(1e-3);
    let scale = [1.0 / rho, 1.0 / rho, 1.0 / rho, 1.0, 1.0, 1.0];
    let h = scaled_full(&eq.h, &scale);
    let (values, vectors) = symmetric_eigen6(&h);
    let largest = values.iter().copied().fold(0.0f64, f64::max);
    let lambda = f64::from(settings.prior_weight) * n;
    let prior: [f64; 6] = std::array::from_fn(|i| lambda * moved[i] / scale[i]);

    let mut damped = h;
    for (i, row) in damped.iter_mut().enumerate() {
        row[i] += lambda;
    }
    let rhs: [f64; 6] = std::array::from_fn(|i| -(eq.g[i] * scale[i] + prior[i]));
    let mut y = solve_spd6(&damped, &rhs).ok_or(IcpFailure::Degenerate)?;

    let free: Vec<&[f64; 6]> = values
        .iter()
        .zip(&vectors)
        .filter(|(value, _)| **value < f64::from(settings.degenerate_ratio) * largest)
        .map(|(_, vector)| vector)
        .collect();
    for v in &free {
        let along = dot6(v, &y);
        for (y, v) in y.iter_mut().zip(v.iter()) {
            *y -= along * v;
        }
    }
    let Some((centroid, expected)) = anchor.filter(|_| !free.is_empty()) else {
        return Ok(std::array::from_fn(|i| y[i] * scale[i]));
    };
    // The anchor as three rows weighing as much as all the points.
    let (mut h_anchor, mut g_anchor) = ([[0.0f64; 6]; 6], [0.0f64; 6]);
    for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
        let r = axis.dot(centroid - expected);
        add_row(&mut h_anchor, &mut g_anchor, centroid, axis, r, n);
    }
    let h_anchor = scaled_full(&h_anchor, &scale);
    // Only free directions that are (nearly) pure shifts follow the centroid: along a turn the
    // centroid moves by the turn times a lever arm of centimetres (a sphere's spin about its
    // centre) or not at all (a face's spin about its middle), so the centroid's sampling noise
    // of a fraction of a millimetre would become degrees. Those stay at the prediction.
    let free: Vec<&[f64; 6]> = free
        .into_iter()
        .filter(|v| dot6(v, &mat_vec(&h_anchor, v)) >= 0.9 * n)
        .collect();
    if free.is_empty() {
        return Ok(std::array::from_fn(|i| y[i] * scale[i]));
    }

    // Minimise planes + anchor + prior over `y + V·z`, V the free directions the anchor sees:
    // (Vᵀ·H·V + λ)·z = −Vᵀ·(H·y + g + prior). Solved in the 6×6 solver with the unused rows
    // padded by the identity.
    let mut both = h_anchor;
    for (a, row) in both.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate() {
            *v += h[a][b];
        }
    }
    let gradient: [f64; 6] = {
        let hy = mat_vec(&both, &y);
        std::array::from_fn(|i| hy[i] + (eq.g[i] + g_anchor[i]) * scale[i] + prior[i])
    };
    let mut reduced = [[0.0f64; 6]; 6];
    let mut reduced_rhs = [0.0f64; 6];
    for (a, row) in reduced.iter_mut().enumerate() {
        if a >= free.len() {
            row[a] = 1.0;
            continue;
        }
        let hv = mat_vec(&both, free[a]);
        for (b, v) in row.iter_mut().enumerate().take(free.len()) {
            *v = dot6(free[b], &hv);
        }
        row[a] += lambda;
        reduced_rhs[a] = -dot6(free[a], &gradient);
    }
    let z = solve_spd6(&reduced, &reduced_rhs).ok_or(IcpFailure::Degenerate)?;
    for (v, z) in free.iter().zip(z) {
        for (y, v) in y.iter_mut().zip(v.iter()) {
            *y += z * v;
        }
    }
    Ok(std::array::from_fn(|i| y[i] * scale[i]))
}

/// Where the cluster's centroid is expected in the object frame; decides the motion along the
/// directions the surface leaves free (see `gauss_newton_step`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CentroidAnchor {
    pub centroid_in_world: Vec3,
    pub expected_in_object: Vec3,
}

/// Aligns `points_in_world` to the fused model, level by level, starting from `guess`
/// (object_from_world). `points_in_world` must be finite. Without an `anchor`, motion the
/// surface cannot show stays at the guess.
pub fn align_to_grids(
    levels: &[IcpLevel],
    points_in_world: &[Vec3],
    guess: Affine3A,
    anchor: Option<CentroidAnchor>,
    settings: &IcpSettings,
    scratch: &mut IcpScratch,
) -> Result<Alignment, IcpFailure> {
    let mut object_from_world = guess;
    // Total change from the guess, for the prior (rotation vector, translation).
    let mut moved = [0.0f64; 6];
    for level in levels {
        let cache = scratch.cache_for(level.grid);
        for _ in 0..level.iterations {
            let eq = accumulate(level, cache, points_in_world, &object_from_world);
            if eq.inliers < 6 {
                break;
            }
            let familiar =
                eq.inliers as f64 >= ANCHOR_MIN_INLIER_FRACTION * points_in_world.len() as f64;
            let anchor_now = anchor.filter(|_| familiar).map(|a| {
                (
                    object_from_world
                        .transform_point3(a.centroid_in_world)
                        .as_dvec3(),
                    a.expected_in_object.as_dvec3(),
                )
            });
            let x = gauss_newton_step(&eq, anchor_now, &moved, settings)?;
            for (m, v) in moved.iter_mut().zip(x) {
                *m += v;
            }
            let omega = DVec3::new(x[0], x[1], x[2]);
            let t = DVec3::new(x[3], x[4], x[5]);
            let step = Affine3A::from_rotation_translation(
                Quat::from_scaled_axis(omega.as_vec3()),
                t.as_vec3(),
            );
            object_from_world = step * object_from_world;
            if omega.length() < CONVERGED_STEP && t.length() < CONVERGED_STEP {
                break;
            }
        }
    }

    let Some(last) = levels.last() else {
        return Err(IcpFailure::Degenerate);
    };
    let cache = scratch.cache_for(last.grid);
    let eq = accumulate(last, cache, points_in_world, &object_from_world);
    let needed = settings
        .min_inliers
        .max((settings.min_inlier_fraction * points_in_world.len() as f32).ceil() as usize);
    if eq.inliers < needed {
        return Err(IcpFailure::TooFewInliers {
            inliers: eq.inliers,
            points: points_in_world.len(),
        });
    }
    let rms_m = eq.rms_m();
    if rms_m > settings.max_rms_m {
        return Err(IcpFailure::LargeResidual {
            rms_m,
            max_rms_m: settings.max_rms_m,
        });
    }
    let outliers = (points_in_world.len() - eq.inliers) as f64;
    Ok(Alignment {
        object_from_world,
        inliers: eq.inliers,
        rms_m,
        truncated_cost: eq.sum_r2 + outliers * f64::from(last.reject_m).powi(2),
        unseen_turns: unseen_turns(&eq, settings.degenerate_ratio),
    })
}

/// How well `points_in_world` lie on one level's model under `object_from_world`: the sum
/// of their squared point-to-plane distances, each capped at the level's rejection distance
/// (a point with no plane, or farther, counts as that distance: a truncated least-squares
/// cost, so that a pose is not rewarded for pushing points off the model).
pub fn truncated_cost(
    level: &IcpLevel,
    points_in_world: &[Vec3],
    object_from_world: &Affine3A,
    scratch: &mut IcpScratch,
) -> f64 {
    let cache = scratch.cache_for(level.grid);
    let cap = f64::from(level.reject_m).powi(2);
    points_in_world
        .iter()
        .map(|&p| {
            let q = object_from_world.transform_point3(p);
            cached_plane(level, cache, q).map_or(cap, |plane| {
                let r = f64::from(plane.normal.dot(q - plane.point));
                (r * r).min(cap)
            })
        })
        .sum()
}

/// [`align_jointly`] runs this many times each level's iterations: it starts farther from
/// the answer than an object's own alignment (a camera's error of centimetres, or a motion
/// guessed from centroids), and stops early once the steps are small.
const JOINT_ITERATIONS_FACTOR: u32 = 3;

/// One object's share of a joint alignment: its grids (coarse to fine, as in
/// [`align_to_grids`]), where it stands, and a sample of this frame's points of it (world).
pub struct JointPart<'a> {
    pub levels: [IcpLevel<'a>; 2],
    pub object_from_world: Affine3A,
    pub points_in_world: Vec<Vec3>,
}

/// The outcome of [`align_jointly`].
#[derive(Debug, Clone, PartialEq)]
pub struct JointAlignment {
    /// Maps the frame's world points onto every part's model at once.
    pub corrected_from_world: Affine3A,
    /// Per part, the share of its points within the fine level's rejection distance of its
    /// model.
    pub shares: Vec<f32>,
}

/// One rigid motion of the whole frame that lands every part's points on its own model at
/// that model's current pose: point-to-plane ICP as in [`align_to_grids`], with every part's
/// correspondences in one set of normal equations. A camera whose pose is off moves every
/// still object by the same motion; each object alone sees only its own surface (a sphere
/// cannot tell a turn, a box seen from one face a slide), all of them together see the
/// camera's error in every direction.
///
/// The rows are written in the world frame about the parts' common centroid (so rotations are
/// conditioned as in a single object): a model plane `(c, n)` in object frame `i` is the
/// world plane `(R_iᵀ(c − t_i), R_iᵀ n)`. Directions no part constrains stay at the guess.
pub fn align_jointly(
    parts: &[JointPart],
    guess: Affine3A,
    settings: &IcpSettings,
) -> Result<JointAlignment, IcpFailure> {
    let total: usize = parts.iter().map(|p| p.points_in_world.len()).sum();
    if total == 0 {
        return Err(IcpFailure::Degenerate);
    }
    let centre = parts
        .iter()
        .flat_map(|p| &p.points_in_world)
        .fold(DVec3::ZERO, |s, p| s + p.as_dvec3())
        / total as f64;
    // One plane cache per part and level: parts are different objects.
    let mut caches: Vec<[FxHashMap<IVec3, Option<Plane>>; 2]> =
        parts.iter().map(|_| Default::default()).collect();
    let mut corrected_from_world = guess;
    let mut moved = [0.0f64; 6];
    let rounds = parts.first().map_or([0, 0], |p| {
        p.levels.map(|l| l.iterations * JOINT_ITERATIONS_FACTOR)
    });
    for (level, &iterations) in rounds.iter().enumerate() {
        for _ in 0..iterations {
            let mut eq = NormalEquations::default();
            for (part, cache) in parts.iter().zip(&mut caches) {
                accumulate_joint(
                    &part.levels[level],
                    &mut cache[level],
                    part,
                    &corrected_from_world,
                    centre,
                    &mut eq,
                );
            }
            if eq.inliers < 6 {
                break;
            }
            let x = gauss_newton_step(&eq, None, &moved, settings)?;
            for (m, v) in moved.iter_mut().zip(x) {
                *m += v;
            }
            let omega = DVec3::new(x[0], x[1], x[2]);
            let t = DVec3::new(x[3], x[4], x[5]);
            // p ↦ centre + R(ω)·(p − centre) + t
            let step = Affine3A::from_translation((centre + t).as_vec3())
                * Affine3A::from_quat(Quat::from_scaled_axis(omega.as_vec3()))
                * Affine3A::from_translation(-centre.as_vec3());
            corrected_from_world = step * corrected_from_world;
            if omega.length() < CONVERGED_STEP && t.length() < CONVERGED_STEP {
                break;
            }
        }
    }
    let shares = parts
        .iter()
        .zip(&mut caches)
        .map(|(part, cache)| fine_share(part, &mut cache[1], &corrected_from_world))
        .collect();
    Ok(JointAlignment {
        corrected_from_world,
        shares,
    })
}

/// Per part, the share of its points within the fine level's rejection distance of its model
/// with the frame moved by `corrected_from_world` (as [`JointAlignment::shares`]).
pub fn joint_shares(parts: &[JointPart], corrected_from_world: &Affine3A) -> Vec<f32> {
    parts
        .iter()
        .map(|part| fine_share(part, &mut FxHashMap::default(), corrected_from_world))
        .collect()
}

fn fine_share(
    part: &JointPart,
    cache: &mut FxHashMap<IVec3, Option<Plane>>,
    corrected_from_world: &Affine3A,
) -> f32 {
    let mut eq = NormalEquations::default();
    accumulate_joint(
        &part.levels[1],
        cache,
        part,
        corrected_from_world,
        DVec3::ZERO,
        &mut eq,
    );
    eq.inliers as f32 / part.points_in_world.len().max(1) as f32
}

/// Adds one part's inliers under `corrected_from_world` to `eq`, as world-frame rows about
/// `centre` (see [`align_jointly`]).
fn accumulate_joint(
    level: &IcpLevel,
    cache: &mut FxHashMap<IVec3, Option<Plane>>,
    part: &JointPart,
    corrected_from_world: &Affine3A,
    centre: DVec3,
    eq: &mut NormalEquations,
) {
    let reject = f64::from(level.reject_m);
    let world_from_object = part.object_from_world.inverse();
    for &p in &part.points_in_world {
        let corrected = corrected_from_world.transform_point3(p);
        let q = part.object_from_world.transform_point3(corrected);
        let Some(plane) = cached_plane(level, cache, q) else {
            continue;
        };
        let r = f64::from(plane.normal.dot(q - plane.point));
        if r.abs() > reject {
            continue;
        }
        let normal = world_from_object.transform_vector3(plane.normal).as_dvec3();
        eq.add_inlier(corrected.as_dvec3() - centre, normal, r);
    }
}
