//! One tracked object: its fused moments in its own frame, its pose and motion, and what
//! changed since it was last meshed.
//!
//! Why point moments rather than a TSDF: moments are additive, so fusing a frame is one
//! addition per point (cost follows the cluster, never the history) and the state is one fixed
//! record per voxel (memory follows the surface area); a plane fitted to summed moments is the
//! exact least-squares plane of every point ever seen there, at any neighbourhood size, with no
//! truncation band or weighting ramp to choose; and it is what the offline pipeline
//! (`tacmesh_reconstruct::surface::mesh_moment_grid`) already meshes, so a live object and a
//! file give the same surface. A TSDF would need rays from the sensor per point, a band and a
//! weight cap, and would smear sub-voxel planes.
//!
//! Pose: each frame the cluster is aligned to the fused model (see `icp`), starting from the
//! last pose moved on by a constant body-frame velocity, if the last two measured motions agree
//! (a steady motion; a shaken camera's jolts back and forth are not carried on).
//! `world_from_object` changes only when the aligned pose differs from it by more than the
//! move thresholds (a dead band), so a static object seen from a static camera keeps its pose
//! exactly and noise never accumulates; slow motion adds up against the kept pose until it
//! crosses a threshold. Points are always fused with the published pose; below the thresholds
//! that smears the model by less than half a voxel. The object frame starts axis-aligned with its origin at the first cluster's
//! centroid, which keeps the alignment well conditioned.
//!
//! Failure: if the cluster cannot be aligned (too few points near the fused surface, or too
//! large a residual), the fused state restarts from the cluster, keeping the id.

use std::time::Duration;

use glam::{Affine3A, IVec3, Quat, Vec3};
use tacmesh_reconstruct::moment_grid::MomentGrid;
use tacmesh_reconstruct::moments::PointMoments;
use tracing::{debug, info};

use crate::change::ChangeTracker;
use crate::config::TrackConfig;
use crate::free_space::FreeSpace;
use crate::icp::{
    align_to_grids, truncated_cost, Alignment, CentroidAnchor, IcpFailure, IcpLevel, IcpScratch,
    IcpSettings,
};

/// Fraction of a cluster's points that must find the fused surface for a fine-only alignment
/// to stand.
const FAMILIAR_FRACTION: f32 = 0.8;

/// Weight of the newest cluster in the smoothed centroid: about ten frames' memory, which
/// averages out the centroid's jitter from frame to frame (a random sample of the visible
/// surface) while still following a visible part that changes as the object turns.
const CENTROID_SMOOTHING: f32 = 0.1;

/// [`TrackedObject::coverage`] tests at most this many of a cluster's points: the fraction to
/// within about 3 %.
const COVERAGE_SAMPLE: usize = 1000;

/// Lines of sight this far apart see different sides of an object (45°).
const ANOTHER_SIDE_RAD: f32 = std::f32::consts::FRAC_PI_4;

/// What [`TrackedObject::carve`] did to the fused state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Carved {
    /// Voxels the frame saw through, which lost weight.
    pub weakened: usize,
    /// Of those, voxels left with less than a point's weight, now dropped.
    pub dropped: usize,
}

/// Slack of [`BodyVelocity::steady_with`].
const STEADY_SLACK_RAD_S: f32 = 0.05;
const STEADY_SLACK_M_S: f32 = 0.01;

/// Rigid velocity in the object's own frame, about its origin.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct BodyVelocity {
    /// Rotation vector per second, rad/s.
    pub angular_rad_s: Vec3,
    pub linear_m_s: Vec3,
}

impl BodyVelocity {
    /// The body-frame motion `before⁻¹ · after` spread over `dt`.
    fn between(before: &Affine3A, after: &Affine3A, dt: Duration) -> Self {
        let seconds = dt.as_secs_f32();
        if seconds <= 0.0 {
            return Self::default();
        }
        let delta = before.inverse() * *after;
        Self {
            angular_rad_s: Quat::from_mat3a(&delta.matrix3).to_scaled_axis() / seconds,
            linear_m_s: Vec3::from(delta.translation) / seconds,
        }
    }

    /// Whether two measured velocities describe one steady motion: each part (turn and shift)
    /// differs by at most the larger (a jolt back is twice as large), or both are slow (under
    /// [`STEADY_SLACK_RAD_S`], [`STEADY_SLACK_M_S`]: a tenth of a degree and a third of a
    /// millimetre a frame at 30 fps).
    fn steady_with(&self, other: &Self) -> bool {
        let close =
            |a: Vec3, b: Vec3, slack: f32| (a - b).length() <= a.length().max(b.length()) + slack;
        close(self.angular_rad_s, other.angular_rad_s, STEADY_SLACK_RAD_S)
            && close(self.linear_m_s, other.linear_m_s, STEADY_SLACK_M_S)
    }

    /// The body-frame motion over `dt`.
    fn over(&self, dt: Duration) -> Affine3A {
        let seconds = dt.as_secs_f32();
        Affine3A::from_rotation_translation(
            Quat::from_scaled_axis(self.angular_rad_s * seconds),
            self.linear_m_s * seconds,
        )
    }
}

/// What fusing one cluster did to the object.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Observed {
    /// Pose kept (any motion was below the thresholds).
    Still,
    /// The object moved; the new `world_from_object`.
    Moved(Affine3A),
    /// Alignment failed; the fused state now holds only the new cluster.
    Reset(IcpFailure),
}

/// Why a leftover cluster was taken for a piece of an object ([`TrackedObject::fuse_fragment`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fragment {
    /// Most of it lies on the object's fused surface.
    OnSurface,
    /// Seen from another side than the object's last view, most of it lies in the object's
    /// box: its far side.
    FarSide,
}

/// One object's state.
#[derive(Debug, Clone)]
pub struct TrackedObject {
    pub id: u64,
    /// The fused moments, object frame.
    pub grid: MomentGrid,
    /// The same points in voxels `icp_coarse_factor` times wider, for coarse alignment.
    coarse: MomentGrid,
    pub change: ChangeTracker,
    pub world_from_object: Affine3A,
    object_from_world: Affine3A,
    /// The velocity the next pose is predicted with: the last measured one, if it agrees with
    /// the one measured before it (`measured_velocity`); otherwise none.
    velocity: BodyVelocity,
    /// The motion measured between the last two pose changes.
    measured_velocity: BodyVelocity,
    /// When the pose last changed (or the object was created or reset), capture time.
    last_pose_change: Duration,
    pub last_seen: Duration,
    pub frames_seen: u32,
    /// Centroid of the recent clusters, object frame, smoothed over frames: association
    /// predicts it, and alignment anchors the motion the surface cannot show to it.
    centroid_in_object: Vec3,
    pub viewpoint_in_object: Vec3,
    pub points_fused: u64,
    pub meshing_runs: u64,
    pub last_meshed: Option<Duration>,
    /// Box of the fused points, object frame (empty: min > max).
    bounds_in_object: (Vec3, Vec3),
    /// Alignment failures since the last success (a burst of resets is logged once).
    pub resets_in_a_row: u32,
    /// Poses the object recently moved away from, with when it left each (see
    /// [`ROCK_HOLD`]).
    left_poses: Vec<(Affine3A, Duration)>,
    /// When an alignment last put the object where it is (within the dead band).
    pose_confirmed: Duration,
    /// The fused weight when a frame last saw the object (measured when carving touched it;
    /// see `ObjectMap::integrate`): carving that takes most of it from an object no cluster
    /// matches any more means the object is gone.
    pub weight_when_seen: f64,
}

/// An accepted alignment: the new `world_from_object`, how far it is from the current pose,
/// and the alignment it came from.
struct Judged {
    estimate: Affine3A,
    shift_m: f32,
    turn_rad: f32,
    fit: Alignment,
    /// The left poses the estimate goes back to ([`TrackedObject::left_poses_returned_to`]).
    returns_to: Vec<usize>,
}

/// Whether a change of pose (`shift_m`, `turn_rad`) is beyond the dead band
/// ([`TrackConfig::move_threshold_m`], [`TrackConfig::move_threshold_rad`]).
fn beyond_band(shift_m: f32, turn_rad: f32, config: &TrackConfig) -> bool {
    shift_m > config.move_threshold_m || turn_rad > config.move_threshold_rad
}

/// How far `after` is from `before` (both `world_from_object`): the shift of the object's
/// origin and the turn, in the object's frame.
fn pose_change(before: &Affine3A, after: &Affine3A) -> (f32, f32) {
    let delta = before.inverse() * *after;
    let shift_m = Vec3::from(delta.translation).length();
    let turn_rad = Quat::from_mat3a(&delta.matrix3).angle_between(Quat::IDENTITY);
    (shift_m, turn_rad)
}

/// An object that has not moved for [`STILL_BEFORE_JUMP`] and whose next alignment moves it
/// by more than [`JUMP_M`] or [`JUMP_RAD`] with fewer than [`FAMILIAR_FRACTION`] of the
/// cluster's points on its surface is taken to be another object standing where it stood
/// (the cluttered mOSD scene put a similar object where the last scene's stood; the old
/// model was turned 18 degrees to take half its points), and restarts from the cluster. A
/// still object that is really pushed or picked up keeps its shape, and nearly all of the
/// cluster lands on it.
const STILL_BEFORE_JUMP: Duration = Duration::from_millis(500);
const JUMP_M: f32 = 0.005;
const JUMP_RAD: f32 = 0.05; // about 3 degrees

/// An object that rocks: a move back to a pose the object left less than [`ROCK_MEMORY`] ago
/// waits until no alignment has put it where it is for [`ROCK_HOLD`]. Two views of an object
/// from either side of a turn (a camera going back and forth, or shaking) each align it a few
/// millimetres and degrees differently (the fused model holds both, each view's points having
/// been fused where its frame put the object, and each view keeps finding its own): on the TUM
/// desk's two views, a third of the objects moved in every frame, 2–10 mm and 1.5–7.5° each
/// way. A held frame is not fused (the view the object is held at builds the model), and the
/// left pose it matched is remembered afresh. A move to a new pose is never held (steady motion
/// moves on at once), and an object really put back where it was follows [`ROCK_HOLD`] after
/// the pose it was held at was last confirmed.
const ROCK_HOLD: Duration = Duration::from_millis(200);
const ROCK_MEMORY: Duration = Duration::from_secs(1);
/// A move goes back to a left pose when it lands within the dead band of it, or nearer it
/// than this share of the move itself (surface displacement, [`TrackedObject::surface_move_m`]).
/// The second is for alignments that are not repeatable: a 5 cm shiny caster at the PCL
/// Kinect image's edge, seen differently in each of the three looped frames, turned 6–39°
/// and shifted 1–8 mm every frame (never back within the 1° band), and a leafy cluster on the
/// TUM desk 1.8 m away went 20–27 mm one way and the other at each of the two views; both
/// were re-meshed two to three times a second. Steady motion only ever moves away from where
/// the object was.
const ROCK_BACK_SHARE: f32 = 0.5;

/// How far outside an object's box the centroid of a cluster that is the object seen
/// differently may be (see [`TrackedObject::seen_differently_again`]).
const SEEN_DIFFERENTLY_MARGIN_M: f32 = 0.02;

/// At most this many left poses are remembered.
const ROCK_POSES: usize = 4;

/// A move beyond the dead band is taken only when the cluster fits the model at the new pose
/// better than at the held one by more than this many times the residual variance per point
/// (an F-test of the six pose parameters: noise alone lowers the truncated cost by about six
/// variances, and 24 is its 0.1 % tail for hundreds of points). Along directions the surface
/// leaves loose (a partly seen object's slide and turn at the image's edge) ICP wanders with
/// hardly any gain: on the PCL Kinect floor the clutter 1.2–1.7 m away, cut by the image's
/// edges, moved every other frame by millimetres to centimetres and up to 0.4 rad, each move
/// fusing the frame where it put the object: in a minute a cart piece grew 13.5 % and a
/// cardboard box had 6.5 % of its area over 3 cm from the data.
const MOVE_EVIDENCE: f64 = 24.0;

/// An alignment that puts more than this share of the fused surface where the camera sees
/// through is refused (see [`TrackedObject::observe`]). A right alignment has a few per cent
/// there at most: silhouette voxels, and what carving is about to take.
const SEEN_THROUGH_MAX: f32 = 0.25;

/// At most this many voxels are projected for [`TrackedObject::observe`]'s check.
const SEEN_THROUGH_SAMPLE: usize = 500;

impl TrackedObject {
    /// A new object from its first cluster (finite points, centroid given); its frame is
    /// axis-aligned with the world with its origin at the centroid, which keeps alignment
    /// well conditioned (rotations act about the object, not about a far world origin).
    pub fn new(
        id: u64,
        points_in_world: &[Vec3],
        centroid_in_world: Vec3,
        capture_time: Duration,
        viewpoint_in_world: Vec3,
        config: &TrackConfig,
    ) -> Self {
        let mut object = Self {
            id,
            grid: MomentGrid::new(config.voxel_size_m),
            coarse: MomentGrid::new(config.voxel_size_m),
            change: ChangeTracker::new(config.occupied_cell_points, config.saturated_cell_points),
            world_from_object: Affine3A::IDENTITY,
            object_from_world: Affine3A::IDENTITY,
            velocity: BodyVelocity::default(),
            measured_velocity: BodyVelocity::default(),
            last_pose_change: capture_time,
            last_seen: capture_time,
            frames_seen: 0,
            centroid_in_object: Vec3::ZERO,
            viewpoint_in_object: Vec3::ZERO,
            points_fused: 0,
            meshing_runs: 0,
            last_meshed: None,
            bounds_in_object: (Vec3::INFINITY, Vec3::NEG_INFINITY),
            resets_in_a_row: 0,
            left_poses: Vec::new(),
            pose_confirmed: capture_time,
            weight_when_seen: points_in_world.len() as f64,
        };
        let range_m = centroid_in_world.distance(viewpoint_in_world);
        object.restart(
            Quat::IDENTITY,
            centroid_in_world,
            capture_time,
            range_m,
            config,
        );
        object.fuse(
            points_in_world,
            centroid_in_world,
            capture_time,
            viewpoint_in_world,
            config,
        );
        object
    }

    /// Where the object is expected at `capture_time`: the last pose moved on by its velocity.
    pub fn predicted_world_from_object(&self, capture_time: Duration) -> Affine3A {
        let dt = capture_time.saturating_sub(self.last_seen);
        self.world_from_object * self.velocity.over(dt)
    }

    /// Where the next cluster's centroid is expected, world frame.
    pub fn predicted_centroid(&self, capture_time: Duration) -> Vec3 {
        self.predicted_world_from_object(capture_time)
            .transform_point3(self.centroid_in_object)
    }

    /// Aligns a new cluster (finite points) to the fused model, updates the pose, fuses it.
    ///
    /// With the frame's free space, an alignment is accepted only if the camera does not see
    /// through much of the fused surface at the new pose ([`SEEN_THROUGH_MAX`]): when one
    /// object is replaced by a similar one in the same place, the new cluster can align to the
    /// old model with a turn that lands half its points on it, and would carry the old shape
    /// on under a wrong pose. The free space tells: at that pose much of the old surface lies
    /// where the camera now sees the table behind it. Such an object restarts from the
    /// cluster instead.
    #[allow(clippy::too_many_arguments)] // the frame's facts, each needed once
    pub fn observe(
        &mut self,
        points_in_world: &[Vec3],
        centroid_in_world: Vec3,
        capture_time: Duration,
        viewpoint_in_world: Vec3,
        free: Option<&FreeSpace>,
        config: &TrackConfig,
        scratch: &mut IcpScratch,
    ) -> Observed {
        self.left_poses
            .retain(|&(_, left)| capture_time.saturating_sub(left) <= ROCK_MEMORY);
        let predicted = self.predicted_world_from_object(capture_time);
        let stride = points_in_world.len().div_ceil(config.icp_max_points).max(1);
        let sample: Vec<Vec3> = points_in_world.iter().step_by(stride).copied().collect();
        let range_m = centroid_in_world.distance(viewpoint_in_world);
        let noise_m = config.depth_noise_per_m2 * range_m * range_m;
        let aligned = self
            .align(
                &sample,
                centroid_in_world,
                predicted,
                noise_m,
                config,
                scratch,
            )
            .and_then(|fit| {
                let inlier_share = fit.inliers as f32 / sample.len().max(1) as f32;
                self.judge_alignment(fit, inlier_share, capture_time, free, config)
            });
        let outcome = match aligned {
            Ok(Judged {
                estimate,
                shift_m,
                turn_rad,
                fit,
                returns_to,
            }) => {
                if self.resets_in_a_row > 1 {
                    info!(
                        id = self.id,
                        resets = self.resets_in_a_row,
                        "object aligned again after a burst of resets"
                    );
                }
                self.resets_in_a_row = 0;
                // A move the cluster barely prefers is noise: the object stays where it is
                // held (see `MOVE_EVIDENCE`).
                let moves = beyond_band(shift_m, turn_rad, config)
                    && self.move_is_evident(&sample, &fit, config, scratch);
                let returned_to = if moves { returns_to } else { Vec::new() };
                let rocking_back = !returned_to.is_empty();
                if rocking_back {
                    // Not fused either: fused at the held pose, the cluster would put a copy
                    // of the object where it is held, and confirm the hold for ever.
                    tracing::trace!(id = self.id, shift_m, turn_rad, "object rocks back: held");
                    for k in returned_to {
                        self.left_poses[k].1 = capture_time;
                    }
                    self.velocity = BodyVelocity::default();
                    self.measured_velocity = BodyVelocity::default();
                    self.last_seen = capture_time;
                    self.frames_seen = self.frames_seen.saturating_add(1);
                    return Observed::Still;
                } else if moves {
                    let dt = capture_time.saturating_sub(self.last_pose_change);
                    // Only a steady motion is carried on: a shaken camera moves every object
                    // back and forth, and carrying each jolt into the next frame's prediction
                    // started alignments a jolt off, from where a flat face (a laptop lid on
                    // the PCL Kinect frames) slid along itself, differently every run.
                    let measured = BodyVelocity::between(&self.world_from_object, &estimate, dt);
                    self.velocity = if measured.steady_with(&self.measured_velocity) {
                        measured
                    } else {
                        BodyVelocity::default()
                    };
                    self.measured_velocity = measured;
                    self.left_poses
                        .insert(0, (self.world_from_object, capture_time));
                    self.left_poses.truncate(ROCK_POSES);
                    self.set_pose(estimate);
                    self.last_pose_change = capture_time;
                    self.pose_confirmed = capture_time;
                    debug!(id = self.id, shift_m, turn_rad, "object moved");
                    Observed::Moved(estimate)
                } else {
                    // Below the dead band: keep the pose and predict no motion, so noise
                    // never accumulates into drift while slow motion still adds up against
                    // the kept pose until it crosses a threshold.
                    self.pose_confirmed = capture_time;
                    self.velocity = BodyVelocity::default();
                    self.measured_velocity = BodyVelocity::default();
                    Observed::Still
                }
            }
            Err(failure) if self.seen_differently_again(&failure, centroid_in_world) => {
                self.resets_in_a_row = self.resets_in_a_row.saturating_add(1);
                debug!(
                    id = self.id,
                    %failure,
                    resets = self.resets_in_a_row,
                    "object seen differently again where it stands: fused where it is held"
                );
                self.velocity = BodyVelocity::default();
                self.measured_velocity = BodyVelocity::default();
                Observed::Still
            }
            Err(failure) => {
                self.resets_in_a_row = self.resets_in_a_row.saturating_add(1);
                let rotation = Quat::from_mat3a(&self.world_from_object.matrix3);
                self.restart(rotation, centroid_in_world, capture_time, range_m, config);
                Observed::Reset(failure)
            }
        };
        self.fuse(
            points_in_world,
            centroid_in_world,
            capture_time,
            viewpoint_in_world,
            config,
        );
        outcome
    }

    /// Accepts an alignment (`fit`, with `inlier_share` of the cluster on the fused surface)
    /// or refuses it: a still object that would jump with a cluster only partly on it (see
    /// [`JUMP_M`]), or a pose that puts much of the fused surface where the camera
    /// sees through (see [`SEEN_THROUGH_MAX`]). An accepted one comes with its motion from the
    /// current pose.
    fn judge_alignment(
        &self,
        fit: Alignment,
        inlier_share: f32,
        capture_time: Duration,
        free: Option<&FreeSpace>,
        config: &TrackConfig,
    ) -> Result<Judged, IcpFailure> {
        // What the surface cannot show is not measured: the step from the held pose loses its
        // turns about axes the surface leaves free, so that neither the pose nor the velocity
        // (nor the next prediction) spins a cone or a cylinder about its own axis.
        let step = fit.object_from_world * self.world_from_object;
        let estimate = (fit.unseen_turns.removed_from(&step) * self.object_from_world).inverse();
        let (shift_m, turn_rad) = pose_change(&self.world_from_object, &estimate);
        let still_for = capture_time.saturating_sub(self.last_pose_change);
        if still_for >= STILL_BEFORE_JUMP
            && (shift_m > JUMP_M || turn_rad > JUMP_RAD)
            && inlier_share < FAMILIAR_FRACTION
        {
            return Err(IcpFailure::JumpedWhileStill {
                shift_mm: 1e3 * shift_m,
                turn_deg: turn_rad.to_degrees(),
                percent: 100.0 * inlier_share,
            });
        }
        // A pose the object is about to be held against (it goes back to one it left) is
        // not taken, so what the camera sees through there does not matter: on the TUM desk's
        // two views, an object each view aligns 25 mm apart was reset at every other frame.
        let returns_to = self.left_poses_returned_to(&estimate, capture_time, config);
        if let (Some(free), true) = (free, returns_to.is_empty()) {
            let fraction = self.seen_through_fraction(free, estimate, config);
            if fraction > SEEN_THROUGH_MAX {
                return Err(IcpFailure::SeenThrough {
                    percent: 100.0 * fraction,
                });
            }
        }
        Ok(Judged {
            estimate,
            shift_m,
            turn_rad,
            fit,
            returns_to,
        })
    }

    /// Aligns, cheapest first: the fine level alone from the prediction, kept if nearly all
    /// points land on the fused surface (a static or steadily moving object); else coarse then
    /// fine from the prediction; else coarse then fine from the prediction shifted so the
    /// centroids agree (a sudden start or stop the velocity did not foresee). The coarse
    /// level's planes, fitted over boxes centimetres wide, round off edges and corners, so it
    /// runs only when the fine level cannot reach.
    ///
    /// `noise_m` is the sensor's depth noise (σ) at the object's range: far away, and with a
    /// noisy sensor, it widens the rejection distance and the accepted residual (see
    /// [`TrackConfig::depth_noise_per_m2`]), so that noise alone does not reset an object.
    fn align(
        &self,
        points_in_world: &[Vec3],
        centroid_in_world: Vec3,
        predicted: Affine3A,
        noise_m: f32,
        config: &TrackConfig,
        scratch: &mut IcpScratch,
    ) -> Result<Alignment, IcpFailure> {
        let share = |a: &Alignment| a.inliers as f32 / points_in_world.len().max(1) as f32;
        let levels = self.icp_levels(config);
        let settings = IcpSettings {
            max_rms_m: config.icp_max_rms_m.max(1.5 * noise_m),
            ..config.icp_settings()
        };
        let anchor = Some(CentroidAnchor {
            centroid_in_world,
            expected_in_object: self.centroid_in_object,
        });
        scratch.start_object();
        let guess = predicted.inverse();
        let fine_only = align_to_grids(
            &levels[1..],
            points_in_world,
            guess,
            anchor,
            &settings,
            scratch,
        );
        if let Ok(a) = fine_only {
            if share(&a) >= FAMILIAR_FRACTION {
                return Ok(a);
            }
        }
        let offset = centroid_in_world - predicted.transform_point3(self.centroid_in_object);
        let mut starts = vec![guess];
        if offset.length() > levels[1].reject_m {
            starts.push((Affine3A::from_translation(offset) * predicted).inverse());
        }
        let mut last = fine_only;
        for start in starts {
            last = align_to_grids(&levels, points_in_world, start, anchor, &settings, scratch);
            if last.is_ok() {
                break;
            }
        }
        last
    }

    /// Whether the cluster (`sample`, world, the points `fit` aligned) fits the fused model at
    /// the alignment's pose so much better than where the object is held that the move is more
    /// than noise: the truncated cost falls by more than [`MOVE_EVIDENCE`] residual variances.
    fn move_is_evident(
        &self,
        sample: &[Vec3],
        fit: &Alignment,
        config: &TrackConfig,
        scratch: &mut IcpScratch,
    ) -> bool {
        let levels = self.icp_levels(config);
        let held = truncated_cost(&levels[1], sample, &self.object_from_world, scratch);
        let moved = fit.truncated_cost;
        let n = sample.len() as f64;
        // Per point, the residual variance left at the estimate (at least a tenth of a
        // voxel's, so an exact synthetic fit does not make every nudge evident).
        let floor = (0.1 * f64::from(self.grid.voxel_size_m())).powi(2);
        let variance = (moved / (n - 6.0).max(1.0)).max(floor);
        held - moved > MOVE_EVIDENCE * variance
    }

    /// The fused grids as alignment levels, coarse then fine.
    pub(crate) fn icp_levels(&self, config: &TrackConfig) -> [IcpLevel<'_>; 2] {
        [
            IcpLevel {
                grid: &self.coarse,
                iterations: config.icp_coarse_iterations,
                reject_m: config.icp_reject_voxels * self.coarse.voxel_size_m(),
            },
            IcpLevel {
                grid: &self.grid,
                iterations: config.icp_fine_iterations,
                reject_m: config.icp_reject_voxels * self.grid.voxel_size_m(),
            },
        ]
    }

    /// Whether a failed alignment (`failure`, of a cluster centred at `centroid_in_world`) is
    /// the same object seen differently rather than a new one: the cluster does not fit the
    /// fused surface, again right after a reset, and stands inside the object's box. Then the
    /// cluster is fused where the object is held instead of restarting it once more. On the
    /// PCL Kinect floor the clutter at the back, cut by the image's edge, gives a different
    /// cluster in each of the three looped frames (503, 595 and 756 points, a quarter to a
    /// third of each on the last one's surface): it was reset twice every three frames and
    /// re-meshed four times a second for as long as it was watched. A first failure still
    /// restarts the object (another object put where it stood, a sudden move), and one that
    /// aligns again after it never comes here.
    fn seen_differently_again(&self, failure: &IcpFailure, centroid_in_world: Vec3) -> bool {
        matches!(failure, IcpFailure::TooFewInliers { .. })
            && self.resets_in_a_row >= 1
            && self
                .world_bounds(SEEN_DIFFERENTLY_MARGIN_M)
                .is_some_and(|(lo, hi)| {
                    centroid_in_world.cmpge(lo).all() && centroid_in_world.cmple(hi).all()
                })
    }

    /// The left poses (those remembered, see [`ROCK_MEMORY`]) that a move to `estimate` goes
    /// back to while the held pose is still being confirmed (see [`ROCK_HOLD`],
    /// [`ROCK_BACK_SHARE`]).
    fn left_poses_returned_to(
        &self,
        estimate: &Affine3A,
        capture_time: Duration,
        config: &TrackConfig,
    ) -> Vec<usize> {
        if capture_time.saturating_sub(self.pose_confirmed) >= ROCK_HOLD {
            return Vec::new();
        }
        let to_here = self.surface_move_m(&self.world_from_object, estimate);
        (0..self.left_poses.len())
            .filter(|&k| {
                let left = &self.left_poses[k].0;
                let (shift_m, turn_rad) = pose_change(left, estimate);
                !beyond_band(shift_m, turn_rad, config)
                    || self.surface_move_m(left, estimate) <= ROCK_BACK_SHARE * to_here
            })
            .collect()
    }

    /// How far the move from `before` to `after` (both `world_from_object`) carries the fused
    /// surface at most: the shift of the object's origin plus the turn times the radius of the
    /// fused box about it.
    fn surface_move_m(&self, before: &Affine3A, after: &Affine3A) -> f32 {
        let (shift_m, turn_rad) = pose_change(before, after);
        let (lo, hi) = self.bounds_in_object;
        let radius_m = if lo.cmple(hi).all() {
            lo.abs().max(hi.abs()).length()
        } else {
            0.0
        };
        shift_m + turn_rad * radius_m
    }

    fn set_pose(&mut self, world_from_object: Affine3A) {
        self.world_from_object = world_from_object;
        self.object_from_world = world_from_object.inverse();
    }

    /// Empties the fused state and puts the object origin at `centroid_in_world`, `range_m`
    /// from the sensor, which sets the voxel size ([`TrackConfig::voxel_at_range`]).
    fn restart(
        &mut self,
        rotation: Quat,
        centroid_in_world: Vec3,
        capture_time: Duration,
        range_m: f32,
        config: &TrackConfig,
    ) {
        let voxel_m = config.voxel_at_range(range_m);
        self.grid = MomentGrid::new(voxel_m);
        self.coarse = MomentGrid::new(voxel_m * config.icp_coarse_factor as f32);
        self.change = ChangeTracker::new(config.occupied_cell_points, config.saturated_cell_points);
        self.velocity = BodyVelocity::default();
        self.measured_velocity = BodyVelocity::default();
        self.points_fused = 0;
        self.bounds_in_object = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        self.last_pose_change = capture_time;
        self.pose_confirmed = capture_time;
        self.left_poses.clear();
        self.set_pose(Affine3A::from_rotation_translation(
            rotation,
            centroid_in_world,
        ));
    }

    /// The fraction of `points_in_world` that land in or beside (3×3×3) a voxel of the fused
    /// model at the current pose: how much of a cluster is a piece of this object.
    pub fn coverage(&self, points_in_world: &[Vec3]) -> f32 {
        if points_in_world.is_empty() {
            return 0.0;
        }
        // An even sample of at most COVERAGE_SAMPLE points: the fraction is all that is asked,
        // and it is asked of every leftover cluster beside every object it overlaps, each
        // point costing up to 27 look-ups (the largest part of a frame's fusion on the looped
        // PCL Kinect frames when every point was tested).
        let stride = points_in_world.len().div_ceil(COVERAGE_SAMPLE);
        let sample = points_in_world.iter().step_by(stride);
        let tested = sample.len();
        let covered = sample
            .filter(|&&p| {
                let cell = self
                    .grid
                    .cell_of(self.object_from_world.transform_point3(p));
                self.grid.any_near(cell, 1)
            })
            .count();
        covered as f32 / tested as f32
    }

    /// Whether a sensor at `viewpoint_in_world` sees the object from another side than its
    /// last frame did: the two lines of sight to the object's centroid are more than
    /// [`ANOTHER_SIDE_RAD`] apart.
    pub fn seen_from_another_side(&self, viewpoint_in_world: Vec3) -> bool {
        let centroid = self
            .world_from_object
            .transform_point3(self.centroid_in_object);
        let last = self
            .world_from_object
            .transform_point3(self.viewpoint_in_object)
            - centroid;
        let now = viewpoint_in_world - centroid;
        last.angle_between(now) > ANOTHER_SIDE_RAD
    }

    /// The box of the fused points in the world at the current pose, grown by `margin_m`;
    /// `None` before any point.
    pub fn world_bounds(&self, margin_m: f32) -> Option<(Vec3, Vec3)> {
        let (lo, hi) = self.bounds_in_object;
        if lo.cmpgt(hi).any() {
            return None;
        }
        let mut world = (Vec3::INFINITY, Vec3::NEG_INFINITY);
        for corner in 0..8 {
            let pick = |bit: u32, a: f32, b: f32| if corner & bit == 0 { a } else { b };
            let c = Vec3::new(
                pick(1, lo.x, hi.x),
                pick(2, lo.y, hi.y),
                pick(4, lo.z, hi.z),
            );
            let w = self.world_from_object.transform_point3(c);
            world = (world.0.min(w), world.1.max(w));
        }
        Some((
            world.0 - Vec3::splat(margin_m),
            world.1 + Vec3::splat(margin_m),
        ))
    }

    /// Fuses a fragment of this object (a piece of it that segmentation split off, such as a
    /// side face seen at a grazing angle, or its far side seen by a second camera) at the
    /// current pose, and counts the object as seen. Pose, velocity and centroid are left to
    /// the main cluster.
    ///
    /// A fragment taken for lying on the fused surface ([`Fragment::OnSurface`]) only
    /// refreshes the cells it falls in that are already occupied: it is fused unaligned, and
    /// its points a cell off the surface (the flying pixels along a silhouette, which the
    /// demo's cube gave as a 300-point cluster every few seconds) would each time have grown
    /// the surface by a cell on the side the camera never sees, where nothing carves it
    /// back: the cube's model grew 10-15 mm on its hidden faces in five minutes. A far side
    /// seen from another viewpoint ([`Fragment::FarSide`]) is what the model lacks, and is
    /// fused whole.
    pub fn fuse_fragment(
        &mut self,
        points_in_world: &[Vec3],
        fragment: Fragment,
        capture_time: Duration,
        config: &TrackConfig,
    ) {
        self.last_seen = self.last_seen.max(capture_time);
        match fragment {
            Fragment::FarSide => {
                self.add_points(points_in_world, config);
            }
            Fragment::OnSurface => {
                let occupied = f64::from(config.occupied_cell_points);
                let on_surface: Vec<Vec3> = points_in_world
                    .iter()
                    .copied()
                    .filter(|&p| {
                        let cell = self
                            .grid
                            .cell_of(self.object_from_world.transform_point3(p));
                        self.grid.get(cell).is_some_and(|m| m.count >= occupied)
                    })
                    .collect();
                self.add_points(&on_surface, config);
            }
        }
    }

    /// Adds world points to the fused grids at the current pose (with their change
    /// accounting and the fused box); returns how many were finite and added.
    ///
    /// A voxel holding `max_cell_points` first forgets one point's worth of its weight
    /// ([`MomentGrid::add_point_capped`]; the coarse grid loses the same share): a running
    /// average over about that many of its newest points. The fused state thus follows the recent data, and
    /// camera jitter or slow drift cannot pile up in it for ever (nvblox caps and decays
    /// weights for the same reason).
    fn add_points(&mut self, points_in_world: &[Vec3], config: &TrackConfig) -> u64 {
        let mut added = 0;
        let cap = f64::from(config.max_cell_points);
        for &p_in_world in points_in_world {
            let p_in_object = self.object_from_world.transform_point3(p_in_world);
            if let Some((cell, moments, forgotten)) = self.grid.add_point_capped(p_in_object, cap) {
                let count = moments.count as u32;
                self.change.note_point(&self.grid, cell, count);
                if forgotten.count > 0.0 {
                    self.coarse
                        .subtract(self.coarse_cell(cell), &forgotten, 0.0);
                }
                self.coarse.add_point(p_in_object);
                self.points_fused += 1;
                self.bounds_in_object.0 = self.bounds_in_object.0.min(p_in_object);
                self.bounds_in_object.1 = self.bounds_in_object.1.max(p_in_object);
                added += 1;
            }
        }
        added
    }

    /// Takes `share` (a scaled copy of the voxel's moments) out of fused voxel `cell` and
    /// out of the coarse voxel holding it, so both grids keep the same points; the fused
    /// voxel is dropped below `min_count` points (the coarse one below half that: its
    /// emptiness follows its finer voxels, and rounding can leave a speck of weight behind).
    /// Returns whether the fused voxel is gone.
    fn forget(&mut self, cell: IVec3, share: &PointMoments, min_count: f64) -> bool {
        self.coarse
            .subtract(self.coarse_cell(cell), share, 0.5 * min_count);
        self.grid.subtract(cell, share, min_count)
    }

    /// The coarse voxel holding fused voxel `cell` (the grids share their origin).
    fn coarse_cell(&self, cell: IVec3) -> IVec3 {
        let factor = (self.coarse.voxel_size_m() / self.grid.voxel_size_m()).round() as i32;
        cell.div_euclid(IVec3::splat(factor))
    }

    /// Forgets what the frame saw through (see `crate::free_space`): each fused voxel whose
    /// centroid the sensor now sees past loses `carve_fraction` of its weight, and is dropped
    /// once it weighs less than one point. A removed or replaced object is thus erased within
    /// a few frames (at 0.3, a voxel of 256 points is gone in 16 frames, half a second at 30
    /// fps), and a voxel that one noisy frame contradicts loses little.
    ///
    /// Voxels hidden under a support the object stands on (most of its weight lies on the
    /// sensor's side of the plane; see `FreeSpace::hidden_under_support`) are forgotten the
    /// same way: nothing standing on a table reaches under its top. On the PCL Kinect frames
    /// (camera shake of up to a centimetre and a degree between frames) the laptop lid, a flat
    /// face whose slide along itself alignment can barely see, crept a little each frame, and
    /// the part that crept under the desk stayed: 18–25 % of its published area lay over 3 cm
    /// from any measured point, in most runs.
    pub fn carve(&mut self, free: &FreeSpace, config: &TrackConfig) -> Carved {
        let mut carved = Carved::default();
        if config.carve_fraction <= 0.0 {
            return carved;
        }
        let margin = config.carve_margin();
        let voxels: Vec<(IVec3, PointMoments, Vec3)> = self
            .grid
            .iter()
            .filter_map(|(cell, m)| {
                let centroid = m.centroid()?;
                Some((cell, *m, self.world_from_object.transform_point3(centroid)))
            })
            .collect();
        let standing_on: Vec<usize> = free
            .supports()
            .iter()
            .enumerate()
            .filter(|(_, &(normal, offset))| {
                let (above, below) = voxels.iter().fold((0.0, 0.0), |(a, b), (_, m, p)| {
                    if normal.dot(*p) - offset >= -config.carve_margin_m {
                        (a + m.count, b)
                    } else {
                        (a, b + m.count)
                    }
                });
                above > below
            })
            .map(|(index, _)| index)
            .collect();
        let seen_through: Vec<(IVec3, PointMoments)> = voxels
            .into_iter()
            .filter(|(_, _, p)| {
                free.seen_through(*p, &margin)
                    || standing_on
                        .iter()
                        .any(|&support| free.hidden_under_support(*p, support, &margin))
            })
            .map(|(cell, m, _)| (cell, m))
            .collect();
        carved.weakened = seen_through.len();
        for (cell, moments) in seen_through {
            let share = if moments.count * (1.0 - f64::from(config.carve_fraction)) < 1.0 {
                moments
            } else {
                moments.scaled(f64::from(config.carve_fraction))
            };
            if self.forget(cell, &share, 1.0) {
                self.change.note_removed(cell);
                carved.dropped += 1;
            }
        }
        if carved.dropped > 0 {
            self.bounds_in_object = self
                .grid
                .iter()
                .filter_map(|(_, m)| m.centroid())
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), c| {
                    (lo.min(c), hi.max(c))
                });
        }
        carved
    }

    /// The share of the fused weight (over at most [`SEEN_THROUGH_SAMPLE`] voxels, an even
    /// stride) that the camera sees through with the object at `world_from_object`.
    fn seen_through_fraction(
        &self,
        free: &FreeSpace,
        world_from_object: Affine3A,
        config: &TrackConfig,
    ) -> f32 {
        let margin = config.carve_margin();
        let stride = self.grid.len().div_ceil(SEEN_THROUGH_SAMPLE).max(1);
        let (mut through, mut total) = (0.0f64, 0.0f64);
        for (_, m) in self.grid.iter().step_by(stride) {
            let Some(centroid) = m.centroid() else {
                continue;
            };
            let weight = m.count.min(f64::from(config.saturated_cell_points));
            total += weight;
            if free.seen_through(world_from_object.transform_point3(centroid), &margin) {
                through += weight;
            }
        }
        if total > 0.0 {
            (through / total) as f32
        } else {
            0.0
        }
    }

    /// The points' worth of weight the fused state holds.
    pub fn fused_weight(&self) -> f64 {
        self.grid.iter().map(|(_, m)| m.count).sum()
    }

    /// Adds the cluster to the fused state with the current pose.
    fn fuse(
        &mut self,
        points_in_world: &[Vec3],
        centroid_in_world: Vec3,
        capture_time: Duration,
        viewpoint_in_world: Vec3,
        config: &TrackConfig,
    ) {
        let points_added = self.add_points(points_in_world, config);
        let centroid_in_object = self.object_from_world.transform_point3(centroid_in_world);
        self.centroid_in_object = if self.points_fused == points_added {
            centroid_in_object
        } else {
            self.centroid_in_object
                .lerp(centroid_in_object, CENTROID_SMOOTHING)
        };
        self.viewpoint_in_object = self.object_from_world.transform_point3(viewpoint_in_world);
        self.last_seen = capture_time;
        self.frames_seen = self.frames_seen.saturating_add(1);
    }
}
