//! The per-frame path: deproject, segment, track and fuse, then hand dirty objects to the
//! mesher. Two threads in a pipeline: the segmenting half (deproject, segment) takes frames
//! from the ring and hands each frame's clusters to the fusing half (planes, track and fuse,
//! the board, mesh jobs) through a one-slot channel, so that frame N+1 is segmented while
//! frame N is fused. On two cores that raises the frame rate from 1 / (segment + fuse) to
//! 1 / max(segment, fuse); a slow half holds the other back (the channel is full), and the
//! ring drops frames as before. The fusing half owns the tracker and the plane tracker.

use std::sync::atomic::Ordering;
use std::time::{Duration, Instant};

use glam::{Affine3A, Vec3};
use tacmesh_segment::{segment_scan, FlyingPixels, SegmentConfig, SupportPlane};
use tacmesh_source::{FrameError, Observation};
use tacmesh_track::{FrameClusters, FreeSpace, ObjectMap, TrackConfig};

use super::config::{DaemonConfig, WorkspaceSection};

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
        max_birth_range_m: config.track.max_birth_range_m,
        estimate_camera_error: config.track.correct_camera,
        ..TrackConfig::default()
    }
}

/// The per-frame path, both halves.
pub struct Perception {
    segmenting: Segmenting,
    fusing: Fusing,
}

/// The segmenting half's state between frames.
struct Segmenting {
    /// Last frame's planes (supports, background, object faces): segmentation refines them
    /// instead of searching anew.
    plane_hints: Vec<SupportPlane>,
    malformed_logged: bool,
    /// A frame with no usable depth was explained in the log (once until one has some).
    empty_frame_logged: bool,
    /// The end of every stream was passed on (once).
    end_sent: bool,
}

/// The fusing half's state between frames.
struct Fusing {
    objects: ObjectMap,
    planes: PlaneTracker,
    /// Support planes in the last frame, for the end-of-stream message.
    supports_last_frame: usize,
}

/// What the segmenting half hands the fusing half.
enum Segmented {
    Frame(Box<FrameWork>),
    /// Every stream ended and the ring is empty: mesh what was held back.
    EndOfStream,
}

/// One segmented frame.
struct FrameWork {
    capture_time: Duration,
    viewpoint: Vec3,
    /// What the frame saw through, from all its points (planes and background included).
    free_space: FreeSpace,
    clusters: Vec<Vec<Vec3>>,
    supports: Vec<SupportPlane>,
}

/// The segmentation settings the daemon uses on a frame whose sensor is at
/// `world_from_sensor`, within `workspace`.
pub fn segment_config(workspace: &WorkspaceSection, world_from_sensor: Affine3A) -> SegmentConfig {
    SegmentConfig {
        max_object_size_m: workspace.max_object_size_m,
        ..SegmentConfig::live().seen_from(world_from_sensor)
    }
}

/// The points the daemon segments of a frame's world `points`: those outside a bounded
/// `workspace` box as no reading (the picture keeps its pixel grid); `None` for an unbounded
/// one, which takes them all.
pub fn points_in_workspace(workspace: &WorkspaceSection, points: &[Vec3]) -> Option<Vec<Vec3>> {
    workspace.is_bounded().then(|| {
        points
            .iter()
            .map(|&p| if workspace.contains(p) { p } else { Vec3::NAN })
            .collect()
    })
}

impl Perception {
    /// The object map is built by the caller, so that a bad track config fails at start.
    pub fn new(objects: ObjectMap) -> Self {
        Self {
            segmenting: Segmenting {
                plane_hints: Vec::new(),
                malformed_logged: false,
                empty_frame_logged: false,
                end_sent: false,
            },
            fusing: Fusing {
                objects,
                planes: PlaneTracker::new(),
                supports_last_frame: 0,
            },
        }
    }

    /// Takes frames from the ring until it is closed and drained, segmenting on this thread
    /// and fusing on a second one. When every sensor's stream has ended and the ring is empty,
    /// meshes what was held back ([`Fusing::end_of_stream`]).
    pub fn run(self, shared: &Shared) {
        let Self {
            mut segmenting,
            mut fusing,
        } = self;
        let (to_fusing, from_segmenting) = std::sync::mpsc::sync_channel::<Segmented>(1);
        std::thread::scope(|scope| {
            let fuser = std::thread::Builder::new()
                .name("fusion".into())
                .spawn_scoped(scope, || {
                    // Ends when the segmenting half drops its sender.
                    for work in from_segmenting {
                        match work {
                            Segmented::Frame(frame) => fusing.process(shared, *frame),
                            Segmented::EndOfStream => fusing.end_of_stream(shared),
                        }
                    }
                });
            if let Err(err) = fuser {
                tracing::error!("cannot start the fusion thread: {err}; no frame is processed");
                return;
            }
            loop {
                let work = match shared.ring.pop_timeout(Duration::from_millis(200)) {
                    Pop::Item(observation) => segmenting
                        .process(shared, observation)
                        .map(|frame| Segmented::Frame(Box::new(frame))),
                    Pop::TimedOut if shared.every_stream_ended() && !segmenting.end_sent => {
                        segmenting.end_sent = true;
                        Some(Segmented::EndOfStream)
                    }
                    Pop::TimedOut => None,
                    Pop::Closed => break,
                };
                if let Some(work) = work {
                    if to_fusing.send(work).is_err() {
                        tracing::error!("the fusion thread is gone; no frame is processed");
                        break;
                    }
                }
            }
            drop(to_fusing);
        });
    }
}

impl Fusing {
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
                 least {} points was left once the support planes ({} in the last frame) and \
                 the background were taken out; is the sensor pose right, and the object \
                 within {} m?",
                if frames == 1 { "" } else { "s" },
                self.objects.config().min_cluster_points,
                self.supports_last_frame,
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
}

/// Why a depth frame gave no point, for an operator: no reading at all, or every reading
/// beyond the range (most often a depth scale in other units: TUM RGB-D's 1/5000 taken for
/// millimetres puts a 1 m wall at 5 m).
fn why_no_depth(depth_m: &[f32], max_range_m: f32) -> String {
    let mut beyond: Vec<f32> = depth_m
        .iter()
        .copied()
        .filter(|&z| z.is_finite() && z > max_range_m)
        .collect();
    if beyond.is_empty() {
        return "a depth frame has no reading at all (every pixel is 0 or not a number): is the \
                camera covered, too close, or not sending depth?"
            .to_owned();
    }
    let middle = beyond.len() / 2;
    let median = *beyond.select_nth_unstable_by(middle, f32::total_cmp).1;
    format!(
        "every depth of a frame is beyond pipeline.max_range_m = {max_range_m} m ({} pixels, \
         median {median:.2} m): is the depth scale right (replay depth_scale_m: 0.001 for \
         millimetres, 0.0002 for TUM RGB-D), or is the scene farther than the range?",
        beyond.len()
    )
}

impl Segmenting {
    /// Deprojects and segments one frame; `None` for a malformed one (counted and logged).
    fn process(&mut self, shared: &Shared, observation: Observation) -> Option<FrameWork> {
        let counters = &shared.counters;
        let started = Instant::now();
        let (points, organised, capture_time, world_from_sensor, free_space) = match observation {
            Observation::Depth(frame) => {
                if let Err(err) = frame.check() {
                    self.malformed(shared, &err);
                    return None;
                }
                self.malformed_logged = false;
                let max_range_m = shared.config.pipeline.max_range_m;
                let deprojection = frame.deproject_organised(max_range_m);
                Counters::add(&counters.invalid_pixels, deprojection.invalid_pixels as u64);
                if deprojection.invalid_pixels < deprojection.points_in_world.len() {
                    self.empty_frame_logged = false;
                } else if !self.empty_frame_logged {
                    self.empty_frame_logged = true;
                    tracing::warn!(
                        "{} (logged once until a frame has depth)",
                        why_no_depth(&frame.depth_m, max_range_m)
                    );
                }
                (
                    deprojection.points_in_world,
                    Some((frame.intrinsics.width, frame.intrinsics.height)),
                    frame.capture_time,
                    frame.world_from_sensor,
                    FreeSpace::from_depth(&frame, max_range_m),
                )
            }
            Observation::Cloud {
                cloud,
                grid,
                world_from_sensor,
                capture_time,
            } => {
                // An organised cloud (a recorded organised PCD) is a depth image already
                // deprojected: it takes the strided path below as a depth frame does.
                if let Some(grid) = grid {
                    if let Err(err) = grid.check(&cloud) {
                        self.malformed(shared, &err);
                        return None;
                    }
                }
                self.malformed_logged = false;
                let points: Vec<Vec3> = cloud
                    .points
                    .iter()
                    .map(|&p| world_from_sensor.transform_point3(p))
                    .collect();
                if grid.is_some() {
                    let missing = points.iter().filter(|p| !p.is_finite()).count();
                    Counters::add(&counters.invalid_pixels, missing as u64);
                }
                let organised = grid.map(|g| (g.width, g.height));
                let free_space = FreeSpace::from_points(&points, world_from_sensor);
                (
                    points,
                    organised,
                    capture_time,
                    world_from_sensor,
                    free_space,
                )
            }
        };
        let viewpoint = Vec3::from(world_from_sensor.translation);
        // Outside the workspace box nothing is segmented; the free space still sees it all.
        let workspace = &shared.config.workspace;
        let in_workspace = points_in_workspace(workspace, &points);
        let segment_points = in_workspace.as_deref().unwrap_or(&points);
        counters.record(Stage::Deproject, started.elapsed());

        let started = Instant::now();
        let stride = shared.config.pipeline.segment_stride.max(1);
        let config = segment_config(workspace, world_from_sensor);
        // `tacmesh mesh --objects` makes this same call on a scan.
        let scan = segment_scan(
            segment_points,
            organised,
            stride,
            &config,
            &self.plane_hints,
        );
        // Flying pixels stay out of fusion (see `FlyingPixels`): fused where the object is
        // held, they grew its hidden faces, where nothing carves them back.
        let flying =
            organised.map(|(width, _)| FlyingPixels::new(&points, width as usize, &config));
        let mut flying_pixels = 0usize;
        let clusters: Vec<Vec<Vec3>> = scan
            .objects
            .iter()
            .map(|indices| {
                let kept: Vec<Vec3> = indices
                    .iter()
                    .filter(|&&i| !flying.is_some_and(|f| f.flies(i as usize)))
                    .map(|&i| points[i as usize])
                    .collect();
                flying_pixels += indices.len() - kept.len();
                kept
            })
            .collect();
        let segmentation = scan.strided;
        counters.record(Stage::Segment, started.elapsed());
        tracing::debug!(
            flying_pixels,
            supports = segmentation.planes.len(),
            background_planes = segmentation.background.len(),
            object_faces = segmentation.object_faces.len(),
            background_clusters = segmentation.background_clusters,
            clusters = ?clusters.iter().map(Vec::len).collect::<Vec<_>>(),
            "segmented"
        );

        self.plane_hints = segmentation.plane_hints();
        Some(FrameWork {
            capture_time,
            viewpoint,
            free_space,
            clusters,
            supports: segmentation.planes,
        })
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

impl Fusing {
    /// Tracks and fuses one segmented frame, publishes what changed on the board, and hands
    /// out the mesh jobs it makes due.
    fn process(&mut self, shared: &Shared, frame: FrameWork) {
        let counters = &shared.counters;
        let FrameWork {
            capture_time,
            viewpoint,
            free_space,
            clusters,
            supports,
        } = frame;
        let started = Instant::now();
        let report = self.objects.integrate(&FrameClusters {
            capture_time,
            viewpoint_m: viewpoint,
            clusters,
            free_space: Some(
                free_space.with_supports(supports.iter().map(|s| (s.normal, s.offset_m))),
            ),
        });
        counters.record(Stage::Integrate, started.elapsed());
        Counters::add(&counters.frames_processed, 1);
        // The supports in the map's world, as the objects are (the tracker corrected the frame
        // for the camera's error).
        let supports: Vec<SupportPlane> = if report.camera_correction == glam::Affine3A::IDENTITY {
            supports
        } else {
            supports
                .iter()
                .map(|s| s.moved(&report.camera_correction))
                .collect()
        };
        let plane_update = self.planes.update(&supports);
        self.supports_last_frame = supports.len();

        {
            let mut board = crate::lock(&shared.board);
            for (id, mesh) in plane_update.upserts {
                board.create(id, glam::Affine3A::IDENTITY, capture_time);
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
                    board.create(id, pose, capture_time);
                }
            }
            for &id in &report.reset {
                if let Some(pose) = self.objects.world_from_object(id) {
                    board.reframe(id, pose);
                }
            }
            for &id in &report.removed {
                shared.mesh_queue.cancel(id);
                shared.body_queue.cancel(id);
                board.remove(id, &shared.publisher);
            }
            for &id in report.cluster_ids.iter().flatten() {
                board.seen(id, capture_time);
            }
            for &(id, pose) in &report.moved {
                board.move_to(id, pose, capture_time, &shared.publisher, counters);
            }
            board.report_sightings(&shared.publisher, counters);
            self.count_confirmed(shared);
        }
        for job in self.objects.take_mesh_jobs(capture_time) {
            shared.mesh_queue.submit(job);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame with no point says why: nothing read, or everything beyond the range with its
    /// median (TUM depth read as millimetres).
    #[test]
    fn a_frame_without_depth_says_whether_the_scale_is_suspect() {
        let nothing = why_no_depth(&[0.0, f32::NAN, 0.0], 4.0);
        assert!(nothing.contains("no reading at all"), "{nothing}");
        let far = why_no_depth(&[0.0, 5.5, 6.0, 9.0], 4.0);
        assert!(far.contains("beyond pipeline.max_range_m = 4 m"), "{far}");
        assert!(
            far.contains("median 6.00 m") && far.contains("depth scale"),
            "{far}"
        );
    }
}
