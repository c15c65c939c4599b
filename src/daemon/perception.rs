//! The per-frame path: deproject, segment, track and fuse, then hand dirty objects to the
//! mesher. Runs on one thread, which owns the tracker and the plane tracker.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use glam::Vec3;
use tacmesh_segment::{segment_with_hints, SegmentConfig, Segmentation, SupportPlane};
use tacmesh_source::{FrameError, Observation};
use tacmesh_track::{FrameClusters, FreeSpace, ObjectMap, TrackConfig};

use super::config::DaemonConfig;

use super::counters::{Counters, Stage};
use super::planes::PlaneTracker;
use super::Shared;
use crate::frame_ring::Pop;

/// The tracker's settings from the daemon's config.
pub fn track_config(config: &DaemonConfig) -> TrackConfig {
    TrackConfig {
        voxel_size_m: config.track.voxel_size_m,
        leave_after: config.leave_after(),
        remesh_interval: config.remesh_interval(),
        ..TrackConfig::default()
    }
}

/// A full-resolution point joins the object of its strided neighbour only within this
/// distance, so pixels across a depth edge do not.
const LABEL_SPREAD_M: f32 = 0.02;

/// The state the per-frame path keeps between frames.
pub struct Perception {
    objects: ObjectMap,
    planes: PlaneTracker,
    segment: SegmentConfig,
    /// Last frame's support planes: segmentation refines them instead of searching anew.
    plane_hints: Vec<SupportPlane>,
    malformed_logged: bool,
}

impl Perception {
    /// The object map is built by the caller, so that a bad track config fails at start.
    pub fn new(objects: ObjectMap) -> Self {
        Self {
            objects,
            planes: PlaneTracker::new(),
            segment: SegmentConfig::live(),
            plane_hints: Vec::new(),
            malformed_logged: false,
        }
    }

    /// Takes frames from the ring until it is closed and drained. When every sensor's stream
    /// has ended and the ring is empty, meshes what was held back ([`Self::end_of_stream`]).
    pub fn run(mut self, shared: &Shared) {
        loop {
            match shared.ring.pop_timeout(Duration::from_millis(200)) {
                Pop::Item(observation) => self.process(shared, observation),
                Pop::TimedOut
                    if shared.every_stream_ended()
                        && !shared.end_of_stream_flushed.load(Ordering::Acquire) =>
                {
                    self.end_of_stream(shared);
                }
                Pop::TimedOut => {}
                Pop::Closed => break,
            }
        }
    }

    /// No frame will come again (every sensor was a recording, played once): meshes every
    /// object whose latest state was held back (seen in fewer frames than confirm an object,
    /// its re-mesh waiting for the rate limit, a change below the threshold), so that a
    /// one-shot recording still gives meshes of what it showed, and says what it did. A
    /// failure to mesh one of these is a warning from the mesher.
    fn end_of_stream(&mut self, shared: &Shared) {
        let flushed = self.objects.flush_mesh_jobs();
        let frames = shared.counters.frames_processed.load(Ordering::Relaxed);
        if self.objects.is_empty() {
            tracing::warn!(
                "end of stream after {frames} frame{}: no object to mesh: no cluster of at \
                 least {} points was left once the support planes and background ({} planes in \
                 the last frame) were taken out; is the sensor pose right, and the object \
                 within {} m?",
                if frames == 1 { "" } else { "s" },
                self.objects.config().min_cluster_points,
                self.plane_hints.len(),
                shared.config.pipeline.max_range_m,
            );
        } else if flushed.is_empty() {
            tracing::info!("end of stream: every object's mesh is up to date");
        } else {
            let held_back: Vec<String> = flushed
                .iter()
                .map(|(job, why)| format!("object {} ({why})", job.object_id))
                .collect();
            tracing::info!(
                "end of stream after {frames} frame{}: meshing what was held back: {}",
                if frames == 1 { "" } else { "s" },
                held_back.join(", ")
            );
        }
        self.count_confirmed(shared);
        for (job, _) in flushed {
            shared.mesh_queue.submit(job);
        }
        shared.end_of_stream_flushed.store(true, Ordering::Release);
    }

    /// Confirmed objects only: a cluster seen in one or two frames (noise at long range, a
    /// passing hand) is tracked but is not yet an object anyone is told about.
    fn count_confirmed(&self, shared: &Shared) {
        let confirmed = self.objects.objects().filter(|o| o.confirmed).count();
        shared
            .counters
            .objects_tracked
            .store(confirmed as u64, Ordering::Relaxed);
    }

    fn process(&mut self, shared: &Shared, observation: Observation) {
        let counters = &shared.counters;
        let started = Instant::now();
        let (points, organised, capture_time, world_from_sensor) = match observation {
            Observation::Depth(frame) => {
                if let Err(err) = frame.check() {
                    self.malformed(shared, &err);
                    return;
                }
                self.malformed_logged = false;
                let deprojection = frame.deproject_organised(shared.config.pipeline.max_range_m);
                Counters::add(&counters.invalid_pixels, deprojection.invalid_pixels as u64);
                (
                    deprojection.points_in_world,
                    Some((frame.intrinsics.width, frame.intrinsics.height)),
                    frame.capture_time,
                    frame.world_from_sensor,
                )
            }
            Observation::Cloud {
                cloud,
                world_from_sensor,
                capture_time,
            } => {
                let points = cloud
                    .points
                    .iter()
                    .map(|&p| world_from_sensor.transform_point3(p))
                    .collect();
                (points, None, capture_time, world_from_sensor)
            }
        };
        let viewpoint = Vec3::from(world_from_sensor.translation);
        // Outside the workspace box nothing is segmented; the free space still sees it all.
        let workspace = &shared.config.workspace;
        let in_workspace: Option<Vec<Vec3>> = workspace.is_bounded().then(|| {
            points
                .iter()
                .map(|&p| if workspace.contains(p) { p } else { Vec3::NAN })
                .collect()
        });
        let segment_points = in_workspace.as_deref().unwrap_or(&points);
        counters.record(Stage::Deproject, started.elapsed());

        let started = Instant::now();
        let stride = shared.config.pipeline.segment_stride.max(1);
        let strided = organised.is_some() && stride > 1;
        let config = SegmentConfig {
            // Cluster sizes count segmented points: one in stride² of an organised frame.
            min_cluster_points: if strided {
                (self.segment.min_cluster_points / (stride * stride) as usize).max(20)
            } else {
                self.segment.min_cluster_points
            },
            // The same for the largest: walls and furniture are background, not objects, at
            // any stride (unscaled, a stride-2 wall passed as a 400,000-point "object").
            max_cluster_points: if strided {
                (self.segment.max_cluster_points / (stride * stride) as usize).max(20)
            } else {
                self.segment.max_cluster_points
            },
            max_object_size_m: workspace.max_object_size_m,
            ..self.segment.clone().seen_from(world_from_sensor)
        };
        let clusters = match organised {
            Some((width, height)) if stride > 1 => strided_clusters(
                segment_points,
                width,
                height,
                stride,
                &config,
                &self.plane_hints,
            ),
            _ => {
                let segmentation = segment_with_hints(segment_points, &config, &self.plane_hints);
                let clusters = segmentation
                    .objects
                    .iter()
                    .map(|indices| indices.iter().map(|&i| points[i as usize]).collect())
                    .collect();
                (segmentation, clusters)
            }
        };
        let (segmentation, clusters) = clusters;
        counters.record(Stage::Segment, started.elapsed());
        tracing::debug!(
            supports = segmentation.planes.len(),
            background_planes = segmentation.background.len(),
            object_faces = segmentation.object_faces.len(),
            background_clusters = segmentation.background_clusters,
            clusters = ?clusters.iter().map(Vec::len).collect::<Vec<_>>(),
            "segmented"
        );

        let plane_update = self.planes.update(&segmentation.planes);
        self.plane_hints = segmentation.plane_hints();

        let started = Instant::now();
        let report = self.objects.integrate(&FrameClusters {
            capture_time,
            viewpoint_m: viewpoint,
            clusters,
            free_space: Some(FreeSpace::from_points(&points, world_from_sensor)),
        });
        counters.record(Stage::Integrate, started.elapsed());
        Counters::add(&counters.frames_processed, 1);

        {
            let mut board = crate::lock(&shared.board);
            for (id, mesh) in plane_update.upserts {
                board.create(id, glam::Affine3A::IDENTITY);
                let faces = mesh.triangles.len() as u32;
                let stats = tacmesh_protocol::SimplifyStats {
                    faces_in: faces,
                    faces_out: faces,
                    max_residual_m: 0.0,
                };
                board.new_mesh(id, mesh, stats, capture_time, &shared.publisher, counters);
            }
            for id in plane_update.removed {
                board.remove(id, &shared.publisher);
            }
            counters.record_births(report.created.len());
            Counters::add(&counters.objects_removed, report.removed.len() as u64);
            for &id in &report.created {
                if let Some(pose) = self.objects.world_from_object(id) {
                    board.create(id, pose);
                }
            }
            for &id in &report.reset {
                if let Some(pose) = self.objects.world_from_object(id) {
                    board.reframe(id, pose);
                }
            }
            for &id in &report.removed {
                shared.mesh_queue.cancel(id);
                board.remove(id, &shared.publisher);
            }
            for &(id, pose) in &report.moved {
                board.move_to(id, pose, capture_time, &shared.publisher, counters);
            }
            self.count_confirmed(shared);
        }
        for job in self.objects.take_mesh_jobs(capture_time) {
            shared.mesh_queue.submit(job);
        }
    }

    fn malformed(&mut self, shared: &Shared, err: &FrameError) {
        Counters::add(&shared.counters.malformed_frames, 1);
        // Once per burst: a source that sends bad frames sends many.
        if !self.malformed_logged {
            tracing::warn!(
                "dropping a malformed frame: {err} (logged once per burst; see the \
                 malformed-frame counter)"
            );
        }
        self.malformed_logged = true;
    }
}

/// Segments every `stride`-th pixel of an organised cloud, then gives each remaining
/// point the object of its strided neighbour (the top-left pixel of its stride × stride
/// block) when the two are within [`LABEL_SPREAD_M`] and the point is not on a support plane.
fn strided_clusters(
    points: &[Vec3],
    width: u32,
    height: u32,
    stride: u32,
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> (Segmentation, Vec<Vec<Vec3>>) {
    let (width, height, stride) = (width as usize, height as usize, stride as usize);
    let sub_width = width.div_ceil(stride);
    let sub: Vec<Vec3> = (0..height)
        .step_by(stride)
        .flat_map(|v| {
            (0..width)
                .step_by(stride)
                .map(move |u| points[v * width + u])
        })
        .collect();
    let segmentation = segment_with_hints(&sub, config, hints);

    let mut clusters = vec![Vec::new(); segmentation.objects.len()];
    for v in 0..height {
        for u in 0..width {
            let p = points[v * width + u];
            if !p.is_finite() {
                continue;
            }
            let j = (v / stride) * sub_width + u / stride;
            let label = segmentation.labels[j] as usize;
            if label == 0 || p.distance(sub[j]) > LABEL_SPREAD_M {
                continue;
            }
            let band_m = config.plane_distance_at(p);
            if segmentation
                .planes
                .iter()
                .any(|plane| plane.signed_distance_m(p) <= band_m + config.plane_margin_m)
                || segmentation
                    .background
                    .iter()
                    .any(|plane| plane.signed_distance_m(p).abs() <= band_m)
            {
                continue;
            }
            clusters[label - 1].push(p);
        }
    }
    (segmentation, clusters)
}
