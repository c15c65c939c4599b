//! The object map: every tracked object, updated frame by frame, in pipeline order: clean the
//! clusters → associate → align and fuse → create tracks → expire tracks → (later, on the
//! mesher's schedule) hand out mesh jobs.

use std::collections::BTreeMap;
use std::time::Duration;

use glam::{Affine3A, Vec3};
use tacmesh_reconstruct::moment_grid::MomentGrid;
use tracing::{debug, info};

use crate::associate::associate_greedy;
use crate::camera_error::CameraError;
use crate::config::{TrackConfig, TrackError};
use crate::free_space::FreeSpace;
use crate::icp::IcpScratch;
use crate::object::{Fragment, Observed, TrackedObject};

/// A cluster no track claimed joins the object whose fused surface (or box) holds at least
/// this fraction of its points, instead of becoming a new object.
const FRAGMENT_COVERAGE: f32 = 0.5;

/// An object's box, for the fragment test, grown by this much (metres): a far side seen by
/// another camera sticks out of the near side's box by the depth the near side could not see.
const FRAGMENT_BOX_MARGIN_M: f32 = 0.03;

/// One frame's segmentation: world points per object seen.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameClusters {
    /// Capture time of the frame (the sensor's clock).
    pub capture_time: Duration,
    /// Sensor position, world frame, metres.
    pub viewpoint_m: Vec3,
    /// World points of each segmented object, metres. Non-finite points are skipped.
    pub clusters: Vec<Vec<Vec3>>,
    /// What the frame saw through ([`FreeSpace::from_depth`] or [`FreeSpace::from_points`] of
    /// all its points, planes and background included): fused voxels it sees past are
    /// forgotten. `None` forgets nothing (a sensor whose rays are unknown).
    pub free_space: Option<FreeSpace>,
}

/// What one frame did to the map.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct FrameReport {
    /// Clusters that matched no object and were beyond `max_birth_range_m`: not objects.
    pub too_far: usize,
    /// New objects, by id.
    pub created: Vec<u64>,
    /// Objects gone: not seen for `leave_after`, or seen through (their fused state carved
    /// away, see `TrackedObject::carve`).
    pub removed: Vec<u64>,
    /// Fused voxels forgotten this frame because the frame saw through them.
    pub carved_cells: usize,
    /// Objects that moved, with their new `world_from_object` (republish the last mesh there;
    /// no re-meshing needed).
    pub moved: Vec<(u64, Affine3A)>,
    /// Objects whose alignment failed: their fused state restarted from this frame's cluster
    /// (same id; their next mesh replaces the old one).
    pub reset: Vec<u64>,
    /// The object each input cluster went to, in input order; `None` for clusters ignored
    /// (fewer than `min_cluster_points` finite points, or too far to start an object).
    pub cluster_ids: Vec<Option<u64>>,
    /// The correction of the camera's pose the frame was fused with: maps the frame's world
    /// (as its pose put it) onto the map's (see `crate::camera_error`). Identity while no
    /// error was found.
    pub camera_correction: Affine3A,
}

/// One object to mesh: its fused state, a copy the mesher owns.
#[derive(Debug, Clone)]
pub struct MeshJob {
    pub object_id: u64,
    /// Fused moments, object frame; mesh with `tacmesh_reconstruct::surface::mesh_moment_grid`.
    pub grid: MomentGrid,
    pub world_from_object: Affine3A,
    /// The newest frame's sensor position, object frame (for viewpoint orientation; an object
    /// turned far from its first view has been seen from several sides and is better oriented
    /// by propagation).
    pub viewpoint_in_object: Vec3,
    /// Capture time of the newest points in `grid`.
    pub newest_capture: Duration,
    /// Released by [`ObjectMap::flush_mesh_jobs`] when the stream ended: no later frame will
    /// bring another chance, so a failure to mesh it is worth a warning.
    pub end_of_stream: bool,
}

/// Why an object's latest fused state had not been meshed when its stream ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HeldBack {
    /// Seen in fewer frames than `confirm_frames` (it could have been noise or a passing hand).
    Unconfirmed {
        frames_seen: u32,
        confirm_frames: u32,
    },
    /// Changed enough to re-mesh, but meshed less than `remesh_interval` before its last frame.
    RateLimited,
    /// Changed since its last meshing, by less than `remesh_min_change`.
    SmallChange { changed_fraction: f32 },
}

impl std::fmt::Display for HeldBack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            HeldBack::Unconfirmed {
                frames_seen,
                confirm_frames,
            } => write!(
                f,
                "seen in {frames_seen} frame{}, fewer than the {confirm_frames} that confirm an \
                 object",
                if *frames_seen == 1 { "" } else { "s" }
            ),
            HeldBack::RateLimited => write!(f, "its re-mesh was waiting for the rate limit"),
            HeldBack::SmallChange { changed_fraction } => write!(
                f,
                "{:.1} % changed since its last mesh, below the re-mesh threshold",
                changed_fraction * 100.0
            ),
        }
    }
}

/// One object, as the daemon and its logs see it.
#[derive(Debug, Clone, PartialEq)]
pub struct ObjectSummary {
    pub id: u64,
    pub world_from_object: Affine3A,
    /// Points fused since the object was created or last reset.
    pub points_fused: u64,
    /// Voxels of the fused grid holding any point (memory follows this, not the frame count).
    pub cells: usize,
    pub meshing_runs: u64,
    /// How much of the fused state changed since the last meshing (see `remesh_min_change`).
    pub changed_fraction: f32,
    pub frames_seen: u32,
    pub last_seen: Duration,
    /// Seen in `confirm_frames` frames, so offered for meshing (or meshed at the end of its
    /// stream, see [`ObjectMap::flush_mesh_jobs`]).
    pub confirmed: bool,
}

/// Every tracked object; ids start at 1 and are never reused.
#[derive(Debug)]
pub struct ObjectMap {
    config: TrackConfig,
    objects: BTreeMap<u64, TrackedObject>,
    next_id: u64,
    meshing_runs: u64,
    scratch: IcpScratch,
    camera: CameraError,
}

/// A cluster's finite points and centroid, or `None` if too few.
fn clean_cluster(points: &[Vec3], min_points: usize) -> Option<(Vec<Vec3>, Vec3)> {
    let finite: Vec<Vec3> = points.iter().copied().filter(|p| p.is_finite()).collect();
    if finite.is_empty() || finite.len() < min_points {
        return None;
    }
    let sum = finite
        .iter()
        .fold(glam::DVec3::ZERO, |s, p| s + p.as_dvec3());
    let centroid = (sum / finite.len() as f64).as_vec3();
    Some((finite, centroid))
}

/// An object no cluster matches that has lost more than half its weight to carving since a
/// frame last saw it is gone ([`ObjectMap::integrate`]).
const CARVED_AWAY: f64 = 0.5;

impl ObjectMap {
    /// An empty map; fails on an invalid config.
    pub fn new(config: TrackConfig) -> Result<Self, TrackError> {
        config.validate()?;
        Ok(Self {
            config,
            objects: BTreeMap::new(),
            next_id: 1,
            meshing_runs: 0,
            scratch: IcpScratch::default(),
            camera: CameraError::default(),
        })
    }

    pub fn config(&self) -> &TrackConfig {
        &self.config
    }

    /// Associates the frame's clusters with tracks, aligns and fuses each matched cluster into
    /// its object (cost proportional to the cluster, not the object's history), creates tracks
    /// for the rest and removes tracks not seen for `leave_after`.
    pub fn integrate(&mut self, frame: &FrameClusters) -> FrameReport {
        let now = frame.capture_time;
        let mut report = FrameReport {
            cluster_ids: vec![None; frame.clusters.len()],
            ..Default::default()
        };

        let mut cleaned: Vec<Option<(Vec<Vec3>, Vec3)>> = frame
            .clusters
            .iter()
            .map(|c| clean_cluster(c, self.config.min_cluster_points))
            .collect();

        // The camera's error first: every later step works in the map's world.
        let correction = if self.config.estimate_camera_error {
            self.camera
                .estimate(&cleaned, &self.objects, now, &self.config)
        } else {
            Affine3A::IDENTITY
        };
        report.camera_correction = correction;
        let corrected = correction != Affine3A::IDENTITY;
        if corrected {
            for (points, centroid) in cleaned.iter_mut().flatten() {
                for p in points.iter_mut() {
                    *p = correction.transform_point3(*p);
                }
                *centroid = correction.transform_point3(*centroid);
            }
        }
        let viewpoint = correction.transform_point3(frame.viewpoint_m);
        let moved_free = frame
            .free_space
            .as_ref()
            .filter(|_| corrected)
            .map(|free| free.moved(&correction));
        let free_space = moved_free.as_ref().or(frame.free_space.as_ref());

        let ids: Vec<u64> = self.objects.keys().copied().collect();
        let predicted: Vec<Vec3> = self
            .objects
            .values()
            .map(|o| o.predicted_centroid(now))
            .collect();
        let centroids: Vec<Option<Vec3>> = cleaned
            .iter()
            .map(|c| c.as_ref().map(|(_, centroid)| *centroid))
            .collect();
        let pairs = associate_greedy(&centroids, &predicted, self.config.match_distance_m);

        for &(ci, ti) in &pairs {
            let id = ids[ti];
            let (Some((points, centroid)), Some(object)) =
                (cleaned[ci].as_ref(), self.objects.get_mut(&id))
            else {
                continue;
            };
            report.cluster_ids[ci] = Some(id);
            tracing::trace!(id, points = points.len(), centroid = %centroid, "cluster matched");
            match object.observe(
                points,
                *centroid,
                now,
                viewpoint,
                free_space,
                &self.config,
                &mut self.scratch,
            ) {
                Observed::Still => {}
                Observed::Moved(world_from_object) => report.moved.push((id, world_from_object)),
                Observed::Reset(why) => {
                    // Once per burst: an object that cannot be aligned fails frame after
                    // frame (120 lines a second on the ONI recording before this).
                    if object.resets_in_a_row == 1 {
                        info!(
                            id,
                            %why,
                            "object reset: its fused state restarts from this frame (logged \
                             once per burst)"
                        );
                    } else {
                        debug!(id, %why, resets = object.resets_in_a_row, "object reset again");
                    }
                    report.reset.push(id);
                }
            }
        }

        for (ci, cluster) in cleaned.iter().enumerate() {
            let Some((points, centroid)) = cluster else {
                continue;
            };
            if report.cluster_ids[ci].is_some() {
                continue;
            }
            // Segmentation sometimes splits a piece off an object (a side face seen at a
            // grazing angle, sampled too sparsely to bridge the gap), and a second camera sees
            // an object's far side, whose centroid is far from the near side's. A leftover
            // cluster that mostly lies on an object's fused surface, or mostly inside its box,
            // is part of that object, not a new one.
            // Objects whose (grown) box misses the cluster's box are skipped before any
            // per-point work: a room scene has dozens of clusters and objects.
            let (cluster_lo, cluster_hi) = points
                .iter()
                .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(lo, hi), &p| {
                    (lo.min(p), hi.max(p))
                });
            let host = self
                .objects
                .values()
                .filter_map(|o| {
                    let (lo, hi) = o.world_bounds(FRAGMENT_BOX_MARGIN_M)?;
                    if cluster_hi.cmplt(lo).any() || cluster_lo.cmpgt(hi).any() {
                        return None;
                    }
                    // The box test is for a far side, which only another viewpoint sees: from
                    // the object's last viewpoint, a separate cluster inside the box is
                    // another object beside or on top of it (taking those in merged
                    // stacked objects and grew a box that then took in the next scene's).
                    let inside = if o.seen_from_another_side(viewpoint) {
                        points
                            .iter()
                            .filter(|p| p.cmpge(lo).all() && p.cmple(hi).all())
                            .count() as f32
                            / points.len().max(1) as f32
                    } else {
                        0.0
                    };
                    let (share, fragment) = if inside >= FRAGMENT_COVERAGE {
                        (inside, Fragment::FarSide)
                    } else {
                        (o.coverage(points), Fragment::OnSurface)
                    };
                    Some((share, o.id, fragment))
                })
                .filter(|&(share, _, _)| share >= FRAGMENT_COVERAGE)
                .max_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((share, id, fragment)) = host {
                if let Some(object) = self.objects.get_mut(&id) {
                    object.fuse_fragment(points, fragment, now, &self.config);
                    debug!(
                        id,
                        points = points.len(),
                        share,
                        "fragment fused into object"
                    );
                    report.cluster_ids[ci] = Some(id);
                    continue;
                }
            }
            // Far away a cluster adds to an object seen from nearer, never starts one.
            let nearest_m = points
                .iter()
                .map(|p| p.distance(viewpoint))
                .fold(f32::INFINITY, f32::min);
            if nearest_m > self.config.max_birth_range_m {
                debug!(
                    points = points.len(),
                    nearest_m, "cluster beyond the birth range: no new object"
                );
                report.too_far += 1;
                continue;
            }
            let id = self.next_id;
            self.next_id += 1;
            let object = TrackedObject::new(id, points, *centroid, now, viewpoint, &self.config);
            info!(id, points = points.len(), centroid = %centroid, "object appeared");
            self.objects.insert(id, object);
            report.created.push(id);
            report.cluster_ids[ci] = Some(id);
        }

        // Forget what the frame saw through, after fusing it (its own points are never seen
        // through: they are the nearest surface in their direction). An object left with less
        // than a cluster's worth of weight was taken away, or was never there (a smear of a
        // bad alignment): it is gone now, not `leave_after` later.
        if let Some(free) = free_space {
            let mut vanished = Vec::new();
            for object in self.objects.values_mut() {
                let carved = object.carve(free, &self.config);
                report.carved_cells += carved.dropped;
                let seen_now = object.last_seen == now;
                // Only carving lowers the weight: an object it left alone keeps what it had.
                if carved.weakened == 0 && !seen_now {
                    continue;
                }
                let weight = object.fused_weight();
                if seen_now {
                    object.weight_when_seen = weight;
                    continue;
                }
                // Gone: too little left to be a cluster, or, with no cluster seen where it is,
                // most of what it had when last seen is seen through (the rest is hidden behind
                // something, where waiting `leave_after` would keep a stale mesh published).
                if weight < self.config.min_cluster_points as f64
                    || (!seen_now && weight < CARVED_AWAY * object.weight_when_seen)
                {
                    vanished.push(object.id);
                }
            }
            for id in vanished {
                self.objects.remove(&id);
                info!(id, "object gone: the camera sees through where it was");
                report.removed.push(id);
            }
        }

        // Expired only after matching: a track this frame saw is not gone, however long the
        // sensor was silent before it (expiring first wiped the whole map after any outage
        // longer than `leave_after`, and every object came back under a new id).
        let leave_after = self.config.leave_after;
        let expired: Vec<u64> = self
            .objects
            .values()
            .filter(|o| now.saturating_sub(o.last_seen) > leave_after)
            .map(|o| o.id)
            .collect();
        for id in expired {
            self.objects.remove(&id);
            info!(id, "object left");
            report.removed.push(id);
        }

        debug!(
            capture_s = now.as_secs_f64(),
            clusters = frame.clusters.len(),
            carved = report.carved_cells,
            objects = self.objects.len(),
            moved = report.moved.len(),
            "frame integrated"
        );
        report
    }

    /// The confirmed objects whose fused state changed enough since their last meshing
    /// (`remesh_min_change`) and whose last meshing is at least `remesh_interval` before
    /// `now_capture`; each is marked clean and counted as a meshing run.
    pub fn take_mesh_jobs(&mut self, now_capture: Duration) -> Vec<MeshJob> {
        let mut jobs = Vec::new();
        for object in self.objects.values_mut() {
            if object.frames_seen < self.config.confirm_frames || object.change.changed_cells() == 0
            {
                continue;
            }
            let due = object
                .last_meshed
                .is_none_or(|at| now_capture.saturating_sub(at) >= self.config.remesh_interval);
            let changed = !object.change.meshed()
                || object.change.changed_fraction() >= self.config.remesh_min_change;
            if !(due && changed) {
                continue;
            }
            debug!(
                id = object.id,
                changed_fraction = object.change.changed_fraction(),
                cells = object.grid.len(),
                "mesh job"
            );
            jobs.push(Self::mesh_job(object, now_capture, false));
        }
        self.meshing_runs += jobs.len() as u64;
        jobs
    }

    /// At the end of the stream (a recording played once): a job for every object whose
    /// latest state was not meshed, whatever held it back (confirmation, rate limit, change
    /// threshold), with the reason; each is marked clean and counted as a meshing run. No
    /// later frame would release them, and a one-shot recording must still mesh what it saw.
    pub fn flush_mesh_jobs(&mut self) -> Vec<(MeshJob, HeldBack)> {
        let config = &self.config;
        let mut jobs = Vec::new();
        for object in self.objects.values_mut() {
            if object.change.meshed() && object.change.changed_cells() == 0 {
                continue;
            }
            let held_back = if object.frames_seen < config.confirm_frames {
                HeldBack::Unconfirmed {
                    frames_seen: object.frames_seen,
                    confirm_frames: config.confirm_frames,
                }
            } else if !object.change.meshed()
                || object.change.changed_fraction() >= config.remesh_min_change
            {
                HeldBack::RateLimited
            } else {
                HeldBack::SmallChange {
                    changed_fraction: object.change.changed_fraction(),
                }
            };
            let at = object.last_seen;
            jobs.push((Self::mesh_job(object, at, true), held_back));
        }
        self.meshing_runs += jobs.len() as u64;
        jobs
    }

    /// A job of `object`'s current state, which is marked meshed at `at` and counted as one of
    /// its meshing runs.
    fn mesh_job(object: &mut TrackedObject, at: Duration, end_of_stream: bool) -> MeshJob {
        object.change.mark_meshed(&object.grid);
        object.meshing_runs += 1;
        object.last_meshed = Some(at);
        MeshJob {
            object_id: object.id,
            grid: object.grid.clone(),
            world_from_object: object.world_from_object,
            viewpoint_in_object: object.viewpoint_in_object,
            newest_capture: object.last_seen,
            end_of_stream,
        }
    }

    /// The object's `world_from_object`, if it is tracked.
    pub fn world_from_object(&self, id: u64) -> Option<Affine3A> {
        self.objects.get(&id).map(|o| o.world_from_object)
    }

    /// Every object, by id.
    pub fn objects(&self) -> impl Iterator<Item = ObjectSummary> + '_ {
        self.objects.values().map(|o| ObjectSummary {
            id: o.id,
            world_from_object: o.world_from_object,
            points_fused: o.points_fused,
            cells: o.grid.len(),
            meshing_runs: o.meshing_runs,
            changed_fraction: o.change.changed_fraction(),
            frames_seen: o.frames_seen,
            last_seen: o.last_seen,
            confirmed: o.frames_seen >= self.config.confirm_frames || o.meshing_runs > 0,
        })
    }

    /// Meshing runs handed out over the map's life.
    pub fn meshing_runs(&self) -> u64 {
        self.meshing_runs
    }

    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }
}
