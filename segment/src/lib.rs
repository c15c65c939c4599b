//! Segmentation of one point cloud into support planes and objects: the tabletop pipeline of
//! Rusu ("Semantic 3D object maps for everyday manipulation in human living environments", 2009,
//! §6) and PCL's tabletop tutorials, without tracking across frames.
//!
//! Entry points:
//! - [`segment`]: points (non-finite ones allowed) and a [`SegmentConfig`] to a
//!   [`Segmentation`]: the support planes, the objects, and one label per input point.
//! - [`segment_with_hints`]: the same, starting from known planes (the previous frame's), which
//!   skips the RANSAC search while they still fit; [`segment_timed`] also returns
//!   [`StageTimes`].
//! - [`segment_cloud`]: [`segment`] for a [`PointCloud`].
//! - [`segment_organised`]: an organised cloud (a depth image) segmented on every 2nd or
//!   `stride`-th pixel, each pixel then labelled from its strided neighbour: the daemon's path
//!   ([`segment_organised_timed`] with the stage times).
//! - [`segment_scan`]: what the daemon and `tacmesh mesh --objects` call on a frame or a scan:
//!   [`segment_organised`] on an organised cloud, [`segment_with_hints`] on any other.
//! - [`SegmentConfig::live`]: the daemon's settings for a 30 fps stream, and `tacmesh mesh
//!   --objects`'.
//! - [`FlyingPixels`]: the pixels of an organised cloud read at a depth edge between its two
//!   surfaces and on neither, which the daemon keeps out of fusion (`veils.rs`).
//! - [`SupportPlane::outline`]: a plane's extent as a convex polygon, to publish as triangles.
//! - [`grid::VoxelGrid`]: the voxel hash grid the stages search neighbours in, for other
//!   neighbour queries over a cloud (the offline pipeline's point-spacing estimate).
//!
//! Pipeline, one file per stage, in order:
//! 1. `planes.rs`: hinted planes refined, or RANSAC for the largest plane and least-squares
//!    refinement, repeated while planes are large enough; on a sample of the points if
//!    [`SegmentConfig::plane_sample_points`] says so.
//! 2. Here (`lib.rs`, `classify`): every point to the first plane it is within
//!    [`SegmentConfig::plane_distance_m`] of; points just above a plane (within
//!    [`SegmentConfig::plane_margin_m`]) go with it, points below it (the far side from the
//!    sensor) are dropped.
//! 3. `voxels.rs`, if [`SegmentConfig::voxel_size_m`] > 0: the remaining points downsampled to
//!    cell centroids, on which stages 4 and 5 run; each point then takes its cell's object.
//! 4. `creases.rs`: each remaining point's depth below its local plane (PCA); points in concave
//!    creases, where one object stands on or leans against another, are set aside.
//! 5. `clusters.rs`: Euclidean clustering of the rest, linked on voxel hash grids
//!    (`links.rs`; on cells the links are kept for stage 7), clusters outside a size range
//!    dropped; then each set-aside point joins the object of its nearest neighbour.
//! 6. `scene.rs`: clusters that are background (walls, furniture, slices of far depth,
//!    strips of floor) dropped.
//! 7. `convexity.rs`, on the cells (stage 3 on): each cluster split where its surface folds
//!    concavely into touching or stacked objects (LCCP on surface patches).
//! 8. `occlusion.rs`, on an organised cloud only (the image tells what is in front of what):
//!    pieces of one object that an occluder or the object's own near wall cut apart are
//!    joined, and a container's inner bottom is taken back from the support.
//!
//! [`labelled`] scores a segmentation against a scan's per-point labels (mOSD's scheme).

mod clusters;
mod convexity;
mod creases;
pub mod grid;
pub mod labelled;
mod links;
mod occlusion;
mod organised;
mod planes;
mod range;
mod scene;
mod sets;
mod veils;
mod voxels;

use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;
use tacmesh_source::PointCloud;

pub use organised::{
    segment_organised, segment_organised_timed, segment_scan, OrganisedSegmentation,
};
pub use planes::{convex_outline, SupportPlane};
pub use veils::FlyingPixels;

/// Parameters of [`segment`]. The defaults suit Kinect-class (PrimeSense, Xtion, RealSense)
/// tabletop scans at 0.5–2 m in the sensor frame; they were tuned on the labelled mOSD scans
/// (see `tests/real_data.rs`).
#[derive(Debug, Clone, PartialEq)]
pub struct SegmentConfig {
    /// RANSAC inlier distance from a plane, in metres. Default 0.012: Kinect depth noise is
    /// about 1.5 mm × z², so a table at 2 m is ±6 mm thick, and tilt residue of a slightly
    /// warped table adds a little.
    pub plane_distance_m: f32,
    /// Points above a plane by up to this many metres (beyond `plane_distance_m`) also go with
    /// the plane rather than with objects: the noisy fringe of the table. Default 0.015.
    pub plane_margin_m: f32,
    /// At most this many planes are searched for (supports, walls and large object faces; see
    /// the `scene` module). Default 6: a floor, a table, two or three walls, a ceiling.
    pub max_planes: usize,
    /// A plane must hold at least this fraction of the finite points. Default 0.03: a wall
    /// seen at a slant at 3 m holds 5–10 % of a Kinect frame.
    pub min_plane_fraction: f32,
    /// Points closer than this, in metres, belong to the same object (unless a concave crease
    /// separates them, see `max_valley_depth_m`). Default 0.015: about five Kinect pixel
    /// footprints at 1.5 m, enough to bridge the depth steps of a 0.5–2 m scan. Farther away it
    /// grows to 1.5 depth steps (`range_step_per_m2`), so that one depth level of a far
    /// surface links to the next.
    pub cluster_tolerance_m: f32,
    /// Radius of the neighbourhood a point's local plane is fitted to (for the valley depth), in
    /// metres; zero turns the crease test off. Default 0.025.
    pub crease_radius_m: f32,
    /// Points lying deeper than this, in metres, below the plane fitted to their neighbours
    /// (within `crease_radius_m`) sit in a concave crease, such as where one object stands on
    /// another; they do not link clusters and afterwards join their nearest object. Infinity
    /// turns this off. Default 0.001, tuned on the mOSD stacked cylinders (see
    /// `tests/real_data.rs`: 0.0007 and 0.0013 already fail there).
    pub max_valley_depth_m: f32,
    /// Smaller clusters are noise and are dropped. Default 300 (a 5 cm object at 2 m).
    pub min_cluster_points: usize,
    /// Larger clusters are background (walls, furniture) and are dropped. Default 100 000.
    pub max_cluster_points: usize,
    /// The depth sensor's depth step per square metre of depth, in metres: a structured-light or
    /// stereo camera's disparity step grows with z² (see the `range` module). Plane bands widen
    /// to ¾ of a step and cluster links to 1.5 steps where that is more than their fixed
    /// distances, and a cluster no deeper than one step is a slice, not an object. Default
    /// 0.0035, a Kinect v1 / Xtion / RealSense D4xx class sensor (the PrimeSense recording's
    /// wall steps are 40–45 mm at 3.3–3.9 m); 0 for a fixed resolution (a simulated or lidar
    /// scan).
    pub range_step_per_m2: f32,
    /// Up, in the points' frame (a unit vector): supports face it. Default −y, up in a camera's
    /// optical frame (x right, y down, z forward) held upright.
    pub up: Vec3,
    /// The sensor's optical axis in the points' frame (a unit vector), along which depth is
    /// measured. Default +z (the optical frame).
    pub forward: Vec3,
    /// A plane facing up within this angle of `up`, in degrees, can be a support. Default 60: a
    /// camera held upright looks down on a table by up to 50°, and walls are 80–100° from up.
    pub max_support_tilt_deg: f32,
    /// A plane facing up must be at least this large across to be a support, in metres;
    /// smaller ones are the tops of objects. Default 0.5.
    pub min_support_size_m: f32,
    /// The largest object, in metres (twice the farthest distance of a cluster's points from
    /// its centroid); larger clusters, and planes facing sideways or down that are larger, are
    /// background. Default 1.2, a chair.
    pub max_object_size_m: f32,
    /// The sensor position in the points' frame, in metres; plane normals are turned towards
    /// it. Default the origin (points in the sensor frame).
    pub viewpoint_m: Vec3,
    /// Seed of the RANSAC sampling: equal inputs and seeds give equal results. Default 0.
    pub seed: u64,
    /// Planes are searched for and fitted on at most about this many points (an even stride
    /// through the finite points); all points are then assigned to the fitted planes. Default
    /// `usize::MAX` (all points); [`SegmentConfig::live`] uses 20 000, which fits a table as
    /// well as 300 000 points do.
    pub plane_sample_points: usize,
    /// Side of the voxel cells the object candidates are downsampled to, in metres: the crease
    /// test and clustering run on the cells' centroids and each point takes its cell's object
    /// (plane membership stays per point). Zero (the default) works point by point.
    pub voxel_size_m: f32,
    /// Size of the surface patches whose convexity splits touching objects, in metres (see
    /// the `convexity` module); far away it grows to three cells and sixteen depth steps
    /// (`range_step_per_m2`) across, so that noise does not decide a patch's normal. Zero
    /// turns the split off; it also needs `voxel_size_m` > 0 (it works on the cells).
    /// Default 0.03: a patch is flat enough to have one normal on a 10 cm object, and large
    /// enough that Kinect noise at up to 1 m does not turn its normal.
    pub patch_size_m: f32,
    /// A concave connection between two patches whose normals differ by less than this, in
    /// degrees, is noise on a smooth surface, not a crease between objects. Default 20: on
    /// the mOSD scans 10 (LCCP's default) cut boxes on their faces, 20–30 scored alike.
    pub concave_tolerance_deg: f32,
}

impl Default for SegmentConfig {
    fn default() -> Self {
        Self {
            plane_distance_m: 0.012,
            plane_margin_m: 0.015,
            max_planes: 6,
            min_plane_fraction: 0.03,
            cluster_tolerance_m: 0.015,
            crease_radius_m: 0.025,
            max_valley_depth_m: 0.001,
            min_cluster_points: 300,
            max_cluster_points: 100_000,
            range_step_per_m2: 0.0035,
            up: Vec3::NEG_Y,
            forward: Vec3::Z,
            max_support_tilt_deg: 60.0,
            min_support_size_m: 0.5,
            max_object_size_m: 1.2,
            viewpoint_m: Vec3::ZERO,
            seed: 0,
            plane_sample_points: usize::MAX,
            voxel_size_m: 0.0,
            patch_size_m: 0.03,
            concave_tolerance_deg: 20.0,
        }
    }
}

impl SegmentConfig {
    /// The daemon's settings for a live depth stream (a 640×480 frame every 33 ms on one
    /// core), which `tacmesh mesh --objects` uses too: the defaults, except planes fitted on
    /// 20 000 sampled points, object candidates downsampled to 8 mm voxels (on which the
    /// convexity split works), a thinner plane band (8 mm + 6 mm margin instead of 12 + 15 mm)
    /// so that low objects keep their bottoms (the simulated tabletop's torus is 4 cm tall),
    /// and a valley depth of 1.2 mm for the crease test on the cells' centroids (1.0 mm, the
    /// point-wise setting, cut PCL's stereo mug at its rim; 1.5 mm merged mOSD test45's flat
    /// box with the box it lies on). On the mOSD scans this scores 0.92 mean IoU against the
    /// defaults' 0.65 (see `tests/real_data.rs`); 7–8 mm voxels were as good as 5 mm there,
    /// 5 mm cost 3× more in the crease test. For world-frame points, place the sensor with
    /// [`SegmentConfig::seen_from`], and pass the previous frame's planes
    /// ([`Segmentation::plane_hints`]) to [`segment_with_hints`], which skips RANSAC
    /// (`cargo bench -p tacmesh-segment` prints the stage times).
    pub fn live() -> Self {
        Self {
            plane_distance_m: 0.008,
            plane_margin_m: 0.006,
            plane_sample_points: 20_000,
            voxel_size_m: 0.008,
            max_valley_depth_m: 0.0012,
            ..Self::default()
        }
    }
}

impl SegmentConfig {
    /// These settings for points in a world frame where the sensor is at `world_from_sensor`
    /// (an optical frame: x right, y down, z forward): the viewpoint is the sensor's position,
    /// forward its optical axis, and up its −y axis (a camera held upright, see
    /// [`SegmentConfig::max_support_tilt_deg`]). to a plane (and within [`SegmentConfig::plane_margin_m`] more above
    /// a support) is on it: [`SegmentConfig::plane_distance_m`], widened far away to ¾ of a
    /// depth step ([`SegmentConfig::range_step_per_m2`]).
    pub fn plane_distance_at(&self, p: Vec3) -> f32 {
        plane_band(self).at(p)
    }

    pub fn seen_from(self, world_from_sensor: glam::Affine3A) -> Self {
        Self {
            viewpoint_m: Vec3::from(world_from_sensor.translation),
            up: world_from_sensor
                .transform_vector3(Vec3::NEG_Y)
                .normalize_or_zero(),
            forward: world_from_sensor
                .transform_vector3(Vec3::Z)
                .normalize_or_zero(),
            ..self
        }
    }
}

/// The result of [`segment`].
#[derive(Debug, Clone, PartialEq)]
pub struct Segmentation {
    /// Support planes, largest first; each lists its points (RANSAC inliers plus the margin).
    pub planes: Vec<SupportPlane>,
    /// Background planes (walls, ceilings), each with the points dropped as on it.
    pub background: Vec<SupportPlane>,
    /// Planes found on objects (a box's side): their points stay with the objects, and the
    /// plane is only kept as a hint for the next frame (no inliers listed).
    pub object_faces: Vec<SupportPlane>,
    /// Clusters dropped as background (too large, or one depth step deep).
    pub background_clusters: usize,
    /// Point indices of each object (ascending), largest object first.
    pub objects: Vec<Vec<u32>>,
    /// One label per input point: `k` (1-based) for points of `objects[k - 1]`, 0 for plane
    /// points, unassigned points and non-finite points.
    pub labels: Vec<u32>,
}

impl Segmentation {
    /// Every plane found (supports, background planes, object faces), without their inliers:
    /// the hints for the next frame ([`segment_with_hints`]).
    pub fn plane_hints(&self) -> Vec<SupportPlane> {
        self.planes
            .iter()
            .chain(&self.background)
            .chain(&self.object_faces)
            .map(|plane| SupportPlane {
                inliers: Vec::new(),
                ..plane.clone()
            })
            .collect()
    }
}

/// How long each stage of one [`segment_timed`] call took (wall-clock), for per-frame logs and
/// benchmarks.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct StageTimes {
    /// Finite points, plane search (hints or RANSAC) and refinement.
    pub planes: Duration,
    /// Every point to a plane, below a plane (dropped), or candidate.
    pub classify: Duration,
    /// Voxel downsampling of the candidates (zero if off).
    pub voxels: Duration,
    /// The crease test (zero if off).
    pub creases: Duration,
    /// Euclidean clustering, creases joining their objects, background clusters, labels.
    pub clusters: Duration,
    /// Clusters split at their concave creases (zero if off).
    pub convexity: Duration,
    /// Picking the strided pixels of an organised cloud, joining hidden pieces and labelling
    /// every pixel from its strided neighbour ([`segment_organised_timed`]; zero otherwise).
    pub organised: Duration,
}

impl StageTimes {
    /// The sum of the stages.
    pub fn total(&self) -> Duration {
        self.planes
            + self.classify
            + self.voxels
            + self.creases
            + self.clusters
            + self.convexity
            + self.organised
    }
}

/// Segments one cloud into support planes and objects (see the crate docs for the method).
///
/// Non-finite points are ignored and labelled 0. Never panics; an empty or all-invalid input
/// gives no planes and no objects.
pub fn segment(points: &[Vec3], config: &SegmentConfig) -> Segmentation {
    segment_timed(points, config, &[]).0
}

/// [`segment`] starting from known support planes, typically the previous frame's
/// (`Segmentation::planes`). Each hint, in order, is refined on these points; if it still holds
/// [`SegmentConfig::min_plane_fraction`] of them it is taken without a RANSAC search (a camera
/// that moved a little moves the plane by less than the inlier distance). Hints that no longer
/// fit are skipped, and planes not found from hints come from RANSAC as in [`segment`]. Only
/// `normal` and `offset_m` of the hints are used.
pub fn segment_with_hints(
    points: &[Vec3],
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> Segmentation {
    segment_timed(points, config, hints).0
}

/// [`segment_with_hints`], also returning how long each stage took.
pub fn segment_timed(
    points: &[Vec3],
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> (Segmentation, StageTimes) {
    let mut times = StageTimes::default();
    let clock = Instant::now();
    let finite: Vec<u32> = (0..points.len() as u32)
        .into_par_iter()
        .filter(|&i| points[i as usize].is_finite())
        .collect();
    // Planes are searched and fitted on an even stride through the finite points; every point
    // is assigned to them afterwards.
    let stride = finite
        .len()
        .div_ceil(config.plane_sample_points.max(1))
        .max(1);
    let plane_sample: Vec<u32> = if stride > 1 {
        finite.iter().step_by(stride).copied().collect()
    } else {
        finite.clone()
    };
    let min_plane_points =
        (config.min_plane_fraction.max(0.0) as f64 * plane_sample.len() as f64).ceil();
    let hints: Vec<(Vec3, f32)> = hints.iter().map(|h| (h.normal, h.offset_m)).collect();
    let band = plane_band(config);
    let found = planes::find_planes(
        points,
        &plane_sample,
        &band,
        config.max_planes,
        min_plane_points.min(usize::MAX as f64) as usize,
        config.seed,
        &hints,
    );
    let (mut planes, mut background, mut object_faces) = (Vec::new(), Vec::new(), Vec::new());
    let roles = scene::plane_roles(&found, &band, config);
    for (plane, role) in found.into_iter().zip(roles) {
        match role {
            scene::PlaneRole::Support => planes.push(plane),
            scene::PlaneRole::Background => background.push(plane),
            scene::PlaneRole::ObjectFace => object_faces.push(SupportPlane {
                inliers: Vec::new(),
                ..plane
            }),
        }
    }
    times.planes = clock.elapsed();

    let clock = Instant::now();
    let mut candidates = classify(points, &finite, &mut planes, &mut background, config);
    // A raised support with sides down to the one below is the top of an object (a flat box
    // on the table): its points are the object's, and the plane a hint for the next frame.
    let tops = scene::object_tops(points, &candidates, &planes, &band, config);
    if !tops.is_empty() {
        for k in tops.into_iter().rev() {
            let top = planes.remove(k);
            object_faces.push(SupportPlane {
                inliers: Vec::new(),
                ..top
            });
        }
        candidates = classify(points, &finite, &mut planes, &mut background, config);
    }
    times.classify = clock.elapsed();

    let background_of = |object: &[u32]| {
        scene::background_cluster(points, object, &planes, &background, &band, config)
    };
    let (objects, background_clusters) = if config.voxel_size_m > 0.0
        && config.voxel_size_m.is_finite()
    {
        // Creases and clusters on the cells' centroids; each point takes its cell's object.
        let clock = Instant::now();
        let coarsen = cluster_reach(config);
        let cells = voxels::voxel_cells(points, &candidates, config.voxel_size_m, &coarsen);
        let all_cells: Vec<u32> = (0..cells.counts.len() as u32).collect();
        times.voxels = clock.elapsed();
        let params = convexity_params(config);
        // The clustering's links, for clustering, creases joining their objects and the
        // convexity split.
        let clock = Instant::now();
        let links = links::Links::new(&cells.centroids, &all_cells, &coarsen);
        times.clusters = clock.elapsed();
        let (cell_objects, normals) = find_objects(
            &cells.centroids,
            &all_cells,
            &cells.counts,
            config,
            params.enabled(),
            Some(&links),
            &mut times,
        );
        let clock = Instant::now();
        let to_points =
            |cell_lists: &[Vec<u32>]| voxels::points_of_cell_lists(&cells, &candidates, cell_lists);
        let mut objects = Vec::with_capacity(cell_objects.len());
        let mut dropped = 0;
        for (cell_list, object) in cell_objects.iter().zip(to_points(&cell_objects)) {
            if background_of(&object).is_some() {
                dropped += 1;
                continue;
            }
            objects.push(cell_list);
        }
        times.clusters += clock.elapsed();
        // Touching objects: each cluster split where its surface folds concavely.
        let clock = Instant::now();
        let cell_m = |p: Vec3| config.voxel_size_m * (1u32 << coarsen.band(p)) as f32;
        // Each cell's position in its object, for the split to find its links there.
        let mut position = vec![u32::MAX; cells.counts.len()];
        for cell_list in &objects {
            for (k, &c) in cell_list.iter().enumerate() {
                position[c as usize] = k as u32;
            }
        }
        let pieces: Vec<Vec<u32>> = objects
            .par_iter()
            .flat_map_iter(|cell_list| {
                convexity::split_at_concave_creases(
                    &cells.centroids,
                    &cells.counts,
                    &normals,
                    cell_list,
                    (&links, &position),
                    &params,
                    cell_m,
                )
            })
            .filter(|piece| {
                piece
                    .iter()
                    .map(|&c| cells.counts[c as usize] as usize)
                    .sum::<usize>()
                    >= config.min_cluster_points.max(1)
            })
            .collect();
        let pieces = to_points(&pieces);
        times.convexity = clock.elapsed();
        (pieces, dropped)
    } else {
        let (objects, _) = find_objects(points, &candidates, &[], config, false, None, &mut times);
        let clock = Instant::now();
        let before = objects.len();
        let objects: Vec<Vec<u32>> = objects
            .into_iter()
            .filter(|object| background_of(object).is_none())
            .collect();
        times.clusters += clock.elapsed();
        let dropped = before - objects.len();
        (objects, dropped)
    };

    let clock = Instant::now();
    let mut objects = objects;
    largest_first(&mut objects);
    let labels = object_labels(&objects, points.len());
    times.clusters += clock.elapsed();
    let segmentation = Segmentation {
        planes,
        background,
        object_faces,
        background_clusters,
        objects,
        labels,
    };
    (segmentation, times)
}

/// One label per point of a cloud of `points` points: `k` for the points of `objects[k - 1]`
/// (indices into the cloud), 0 for the rest; as [`Segmentation::labels`] is.
pub fn object_labels(objects: &[Vec<u32>], points: usize) -> Vec<u32> {
    let mut labels = vec![0u32; points];
    for (k, object) in objects.iter().enumerate() {
        for &i in object {
            labels[i as usize] = k as u32 + 1;
        }
    }
    labels
}

/// Objects (non-empty, each ascending) in the order [`Segmentation::objects`] lists them:
/// largest first, then by their first index.
pub(crate) fn largest_first(objects: &mut [Vec<u32>]) {
    objects.sort_by(|a, b| b.len().cmp(&a.len()).then(a[0].cmp(&b[0])));
}

/// The inlier distance of a plane at a point's range: the configured distance, or ¾ of a depth
/// step far away, where a slanted surface is a staircase of steps.
fn plane_band(config: &SegmentConfig) -> range::RangeDistance {
    range::RangeDistance::new(
        config.plane_distance_m,
        config.range_step_per_m2,
        0.75,
        config.viewpoint_m,
    )
}

/// The linking distance of clustering at a point's range (see [`SegmentConfig::cluster_tolerance_m`]).
fn cluster_reach(config: &SegmentConfig) -> range::RangeDistance {
    range::RangeDistance::new(
        config.cluster_tolerance_m,
        config.range_step_per_m2,
        1.5,
        config.viewpoint_m,
    )
}

/// The convexity split's settings from the config, for points seen from its viewpoint.
fn convexity_params(config: &SegmentConfig) -> convexity::ConvexityParams {
    convexity::ConvexityParams {
        patch_m: config.patch_size_m,
        concave_tolerance_deg: config.concave_tolerance_deg,
        min_piece_weight: config.min_cluster_points,
        viewpoint: config.viewpoint_m,
        range_step_per_m2: config.range_step_per_m2,
    }
}

/// Stage 2: assigns each finite point to the first support it lies within its band of
/// (replacing the planes' inliers, which may have come from a sample), then the fringe up to
/// `plane_margin_m` above a support to that support; drops points on a background plane, and
/// points below the lowest support (the floor, or the table when no floor is seen: nothing is
/// seen through it); and returns the rest (ascending): the object candidates. Points below a
/// raised support stay candidates (a chair beside the table, a box under it).
fn classify(
    points: &[Vec3],
    finite: &[u32],
    planes: &mut [SupportPlane],
    background: &mut [SupportPlane],
    config: &SegmentConfig,
) -> Vec<u32> {
    let band = plane_band(config);
    let margin_m = config.plane_margin_m.max(0.0);
    if planes.is_empty() && background.is_empty() {
        return finite.to_vec();
    }
    // The lowest support is the one the sensor is highest above.
    let lowest = (0..planes.len()).max_by(|&a, &b| {
        let height = |k: usize| planes[k].signed_distance_m(config.viewpoint_m);
        height(a).total_cmp(&height(b))
    });
    let mut inliers: Vec<Vec<u32>> = planes.iter().map(|_| Vec::new()).collect();
    let mut fringes: Vec<Vec<u32>> = planes.iter().map(|_| Vec::new()).collect();
    let mut dropped: Vec<Vec<u32>> = background.iter().map(|_| Vec::new()).collect();
    let mut candidates = Vec::with_capacity(finite.len() / 4);
    'points: for &i in finite {
        let p = points[i as usize];
        let threshold_m = band.at(p);
        for (k, plane) in planes.iter().enumerate() {
            if plane.signed_distance_m(p).abs() <= threshold_m {
                inliers[k].push(i);
                continue 'points;
            }
        }
        for (k, plane) in background.iter().enumerate() {
            if plane.signed_distance_m(p).abs() <= threshold_m {
                dropped[k].push(i);
                continue 'points;
            }
        }
        for (k, plane) in planes.iter().enumerate() {
            let d = plane.signed_distance_m(p);
            if d < -threshold_m {
                if Some(k) == lowest {
                    continue 'points;
                }
                continue;
            }
            if d <= threshold_m + margin_m {
                fringes[k].push(i);
                continue 'points;
            }
        }
        candidates.push(i);
    }
    for ((plane, inliers), fringe) in planes.iter_mut().zip(inliers).zip(fringes) {
        plane.inliers = merge_ascending(&inliers, &fringe);
    }
    for (plane, dropped) in background.iter_mut().zip(dropped) {
        plane.inliers = dropped;
    }
    candidates
}

/// The union of two disjoint ascending lists, ascending.
fn merge_ascending(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len() + b.len());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i] < b[j] {
            out.push(a[i]);
            i += 1;
        } else {
            out.push(b[j]);
            j += 1;
        }
    }
    out.extend_from_slice(&a[i..]);
    out.extend_from_slice(&b[j..]);
    out
}

/// Stages 4 and 5 on `indices` into `points` (each standing for `weights[i]` input points, or
/// one if `weights` is empty): the crease test, Euclidean clustering of the points outside
/// creases, then crease points joining their nearest object. Returns the objects (in no
/// particular order) and, if the crease test ran or `need_normals` asks for them, each
/// point's local normal (in the order of `indices`; zero where undetermined).
///
/// `links`, if given, are the clustering's links of every point (`indices` must then be every
/// point, in order): voxel cells, whose links the convexity split walks again, find them
/// once; points, whose links are too many to keep, are searched on voxel grids as needed.
fn find_objects(
    points: &[Vec3],
    indices: &[u32],
    weights: &[u32],
    config: &SegmentConfig,
    need_normals: bool,
    links: Option<&links::Links>,
    times: &mut StageTimes,
) -> (Vec<Vec<u32>>, Vec<Vec3>) {
    // Concave creases: points deeper than `max_valley_depth_m` below their local plane do not
    // link clusters; afterwards each joins the object of its nearest linked neighbour.
    let clock = Instant::now();
    let use_creases = config.crease_radius_m > 0.0
        && config.crease_radius_m.is_finite()
        && config.max_valley_depth_m < f32::INFINITY;
    let planes = if use_creases || need_normals {
        creases::local_planes(points, indices, config.crease_radius_m, config.viewpoint_m)
    } else {
        Vec::new()
    };
    let mut core = Vec::with_capacity(indices.len());
    let mut valley: Vec<u32> = Vec::new();
    for (k, &i) in indices.iter().enumerate() {
        match planes.get(k) {
            Some(plane) if use_creases && plane.valley_depth_m > config.max_valley_depth_m => {
                valley.push(i)
            }
            _ => core.push(i),
        }
    }
    times.creases = clock.elapsed();

    let clock = Instant::now();
    let reach = cluster_reach(config);
    let (min_points, max_points) = (config.min_cluster_points.max(1), config.max_cluster_points);
    let mut objects = match links {
        _ if !clusters::links_at_all(&reach) => Vec::new(),
        Some(links) => {
            clusters::clusters_of_links(points.len(), &core, links, weights, min_points, max_points)
        }
        None => {
            clusters::euclidean_clusters(points, &core, weights, &reach, min_points, max_points)
        }
    };
    // Creases fill in from their edges: each pass attaches the points next to an object.
    let tolerance_m = config.cluster_tolerance_m;
    if !(objects.is_empty() || valley.is_empty() || tolerance_m <= 0.0 || !tolerance_m.is_finite())
    {
        match links {
            // Points within the tolerance of each other are linked (the reach is at least
            // the tolerance).
            Some(links) => {
                attach_to_nearest(points, &mut objects, valley, tolerance_m, |i, visit| {
                    links.of(i as usize).iter().for_each(|&j| visit(j))
                })
            }
            None => {
                let grid = grid::VoxelGrid::new(points, indices, tolerance_m);
                attach_to_nearest(points, &mut objects, valley, tolerance_m, |i, visit| {
                    grid.for_each_near(points[i as usize], visit)
                })
            }
        }
    }
    times.clusters += clock.elapsed();
    let normals = planes.into_iter().map(|plane| plane.normal).collect();
    (objects, normals)
}

/// Adds each of `loose` to the object of its nearest object point within `tolerance_m`, in
/// passes (creases fill in from their edges: each pass attaches the points next to an
/// object), until a pass attaches none; each object's indices stay ascending.
/// `near(i, visit)` visits a superset of the points within `tolerance_m` of point `i`.
fn attach_to_nearest(
    points: &[Vec3],
    objects: &mut [Vec<u32>],
    mut loose: Vec<u32>,
    tolerance_m: f32,
    near: impl Fn(u32, &mut dyn FnMut(u32)) + Sync,
) {
    let mut object_of = vec![u32::MAX; points.len()];
    for (k, object) in objects.iter().enumerate() {
        for &i in object {
            object_of[i as usize] = k as u32;
        }
    }
    let tolerance_sq = tolerance_m * tolerance_m;
    loop {
        // Each pass judges every loose point against the objects as they were before it.
        let owners: Vec<u32> = loose
            .par_iter()
            .map(|&i| {
                let p = points[i as usize];
                let mut best: Option<(f32, u32)> = None;
                near(i, &mut |j| {
                    if object_of[j as usize] == u32::MAX {
                        return;
                    }
                    let d = p.distance_squared(points[j as usize]);
                    if d <= tolerance_sq && best.is_none_or(|(bd, bj)| (d, j) < (bd, bj)) {
                        best = Some((d, j));
                    }
                });
                best.map_or(u32::MAX, |(_, j)| object_of[j as usize])
            })
            .collect();
        let before = loose.len();
        let mut still_loose = Vec::new();
        for (&i, owner) in loose.iter().zip(owners) {
            if owner == u32::MAX {
                still_loose.push(i);
            } else {
                objects[owner as usize].push(i);
                object_of[i as usize] = owner;
            }
        }
        loose = still_loose;
        if loose.is_empty() || loose.len() == before {
            break;
        }
    }
    for object in objects.iter_mut() {
        object.sort_unstable();
    }
}

/// [`segment`] on the points of a [`PointCloud`] (normals are not used).
pub fn segment_cloud(cloud: &PointCloud, config: &SegmentConfig) -> Segmentation {
    segment(&cloud.points, config)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The default settings for these scenes: world z up, the sensor at the origin looking
    /// down (tables at z = -1).
    fn z_up() -> SegmentConfig {
        SegmentConfig {
            up: Vec3::Z,
            forward: Vec3::NEG_Z,
            ..SegmentConfig::default()
        }
    }

    /// Deterministic jitter in ±`amplitude`.
    fn jitter(k: u32, amplitude: f32) -> f32 {
        let h = k
            .wrapping_mul(2_654_435_761)
            .rotate_left(13)
            .wrapping_mul(40_503);
        (h as f32 / u32::MAX as f32 - 0.5) * 2.0 * amplitude
    }

    /// A 1.2 m × 1 m table at z = 1 m below the sensor (sensor at the origin looking down −z),
    /// with three objects on it: a box, a sphere and a cylinder. Returns the points and the
    /// ground-truth object of each (0 for the table).
    fn tabletop() -> (Vec<Vec3>, Vec<u32>) {
        let mut points = Vec::new();
        let mut truth = Vec::new();
        let mut k = 0u32;
        let mut push = |p: Vec3, id: u32, points: &mut Vec<Vec3>, truth: &mut Vec<u32>| {
            k += 1;
            points.push(p + Vec3::new(0.0, 0.0, jitter(k, 0.002)));
            truth.push(id);
        };
        for i in 0..240 {
            for j in 0..200 {
                let p = Vec3::new(-0.6 + i as f32 * 0.005, -0.5 + j as f32 * 0.005, -1.0);
                push(p, 0, &mut points, &mut truth);
            }
        }
        // Box 10 × 10 × 15 cm at (-0.3, 0): top and four sides.
        let c = Vec3::new(-0.3, 0.0, -1.0);
        for i in 0..=20 {
            for j in 0..=20 {
                let (u, v) = (-0.05 + i as f32 * 0.005, -0.05 + j as f32 * 0.005);
                push(c + Vec3::new(u, v, 0.15), 1, &mut points, &mut truth);
            }
        }
        for i in 0..=20 {
            for h in 1..=30 {
                let (u, z) = (-0.05 + i as f32 * 0.005, h as f32 * 0.005);
                for side in [
                    Vec3::new(u, -0.05, z),
                    Vec3::new(u, 0.05, z),
                    Vec3::new(-0.05, u, z),
                    Vec3::new(0.05, u, z),
                ] {
                    push(c + side, 1, &mut points, &mut truth);
                }
            }
        }
        // Sphere of radius 6 cm resting on the table at (0.1, 0.25).
        let c = Vec3::new(0.1, 0.25, -1.0 + 0.06);
        for i in 0..40 {
            for j in 0..80 {
                // The part a camera above the table sees.
                let theta = 0.6 * std::f32::consts::PI * (i as f32 + 0.5) / 40.0;
                let phi = 2.0 * std::f32::consts::PI * j as f32 / 80.0;
                let dir = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    theta.cos(),
                );
                push(c + dir * 0.06, 2, &mut points, &mut truth);
            }
        }
        // Cylinder of radius 4 cm, 12 cm tall, at (0.3, -0.25).
        let c = Vec3::new(0.3, -0.25, -1.0);
        for h in 1..=24 {
            for j in 0..60 {
                let phi = 2.0 * std::f32::consts::PI * j as f32 / 60.0;
                push(
                    c + Vec3::new(0.04 * phi.cos(), 0.04 * phi.sin(), h as f32 * 0.005),
                    3,
                    &mut points,
                    &mut truth,
                );
            }
        }
        (points, truth)
    }

    #[test]
    fn segment_finds_table_and_three_objects() {
        let (points, truth) = tabletop();
        let seg = segment(&points, &z_up());
        assert_eq!(seg.planes.len(), 1);
        let plane = &seg.planes[0];
        assert!(
            plane.normal.dot(Vec3::Z) > 0.999,
            "normal {:?}",
            plane.normal
        );
        // The bottom rows of the objects pull the least-squares fit up by a few millimetres.
        assert!(
            (plane.offset_m + 1.0).abs() < 0.006,
            "offset {}",
            plane.offset_m
        );
        assert_eq!(seg.objects.len(), 3);
        // Each object is exactly one true object, minus its bottom fringe (within plane distance + margin of the table).
        for object in &seg.objects {
            let id = truth[object[0] as usize];
            assert!(id > 0);
            assert!(object.iter().all(|&i| truth[i as usize] == id));
            let missing = (0..points.len() as u32)
                .filter(|&i| truth[i as usize] == id && points[i as usize].z > -1.0 + 0.04)
                .filter(|i| object.binary_search(i).is_err())
                .count();
            assert_eq!(
                missing, 0,
                "object {id} misses points more than 4 cm above the table"
            );
        }
        // Largest first, each true object once.
        assert!(seg.objects.windows(2).all(|w| w[0].len() >= w[1].len()));
        let mut ids: Vec<u32> = seg.objects.iter().map(|o| truth[o[0] as usize]).collect();
        ids.sort_unstable();
        assert_eq!(ids, vec![1, 2, 3]);
        for (i, &label) in seg.labels.iter().enumerate() {
            if label > 0 {
                assert!(seg.objects[label as usize - 1]
                    .binary_search(&(i as u32))
                    .is_ok());
            }
        }
        // The outline is the table's rectangle.
        let outline = plane.outline();
        assert_eq!(outline.len(), 4, "{outline:?}");
        for c in outline {
            assert!(
                (c.x.abs() - 0.6).abs() < 0.01 || (c.x - 0.595).abs() < 0.01,
                "{c}"
            );
            assert!((c.z + 1.0).abs() < 0.003);
        }
    }

    /// Points on the top and sides of an axis-aligned box (corner `lo`, size `size`) every
    /// `step`: the x-min and y-min sides, which a sensor at the origin sees when the box lies
    /// at positive x and y below it, and the other two if `all_sides`. Top points for which
    /// `hidden` holds are left out.
    fn box_faces(
        lo: Vec3,
        size: Vec3,
        step: f32,
        all_sides: bool,
        hidden: impl Fn(Vec3) -> bool,
    ) -> Vec<Vec3> {
        let n = |len: f32| (len / step).round() as i32;
        let mut points = Vec::new();
        for i in 0..=n(size.x) {
            for j in 0..=n(size.y) {
                let p = lo + Vec3::new(i as f32 * step, j as f32 * step, size.z);
                if !hidden(p) {
                    points.push(p);
                }
            }
        }
        for h in 0..n(size.z) {
            let z = h as f32 * step;
            for i in 0..=n(size.x) {
                points.push(lo + Vec3::new(i as f32 * step, 0.0, z));
                if all_sides {
                    points.push(lo + Vec3::new(i as f32 * step, size.y, z));
                }
            }
            for j in 0..=n(size.y) {
                points.push(lo + Vec3::new(0.0, j as f32 * step, z));
                if all_sides {
                    points.push(lo + Vec3::new(size.x, j as f32 * step, z));
                }
            }
        }
        points
    }

    #[test]
    fn segment_separates_a_box_standing_on_a_box() {
        // Table at z = -1; a 24 × 24 × 10 cm box, and a 10 × 10 × 10 cm box on its middle
        // (with all four sides, so that its base meets the big top all round).
        let mut points = Vec::new();
        for i in 0..200 {
            for j in 0..200 {
                points.push(Vec3::new(
                    -0.2 + i as f32 * 0.005,
                    -0.2 + j as f32 * 0.005,
                    -1.0,
                ));
            }
        }
        let table = points.len();
        let under_small = |p: Vec3| (0.27..=0.37).contains(&p.x) && (0.27..=0.37).contains(&p.y);
        points.extend(box_faces(
            Vec3::new(0.2, 0.2, -1.0),
            Vec3::new(0.24, 0.24, 0.1),
            0.004,
            false,
            under_small,
        ));
        let bottom = points.len();
        points.extend(box_faces(
            Vec3::new(0.27, 0.27, -0.9),
            Vec3::new(0.1, 0.1, 0.1),
            0.004,
            true,
            |_| false,
        ));
        let seg = segment(&points, &z_up());
        assert_eq!(
            seg.objects.len(),
            2,
            "{:?}",
            seg.objects.iter().map(Vec::len).collect::<Vec<_>>()
        );
        // Each object is (almost all) one box. Crease points join the nearest object, so the
        // strip of the big top next to the small box (about 5 % of it) goes with the small one.
        let purity = |object: &[u32], range: std::ops::Range<usize>| {
            object
                .iter()
                .filter(|&&i| range.contains(&(i as usize)))
                .count() as f32
                / object.len() as f32
        };
        assert!(purity(&seg.objects[0], table..bottom) > 0.93);
        assert!(purity(&seg.objects[1], bottom..points.len()) > 0.93);
    }

    #[test]
    fn segment_without_plane_gives_one_object() {
        // A sphere of 10 cm radius alone: no plane holds 10 % of it within 12 mm... except its
        // caps, so ask for big planes only.
        let mut points = Vec::new();
        for i in 0..60 {
            for j in 0..120 {
                let theta = std::f32::consts::PI * (i as f32 + 0.5) / 60.0;
                let phi = 2.0 * std::f32::consts::PI * j as f32 / 120.0;
                points.push(
                    Vec3::new(
                        theta.sin() * phi.cos(),
                        theta.sin() * phi.sin(),
                        theta.cos(),
                    ) * 0.1
                        + Vec3::new(0.0, 0.0, -1.0),
                );
            }
        }
        let config = SegmentConfig {
            min_plane_fraction: 0.3,
            ..z_up()
        };
        let seg = segment(&points, &config);
        assert!(seg.planes.is_empty());
        assert_eq!(seg.objects.len(), 1);
        assert_eq!(seg.objects[0].len(), points.len());
        assert!(seg.labels.iter().all(|&l| l == 1));
    }

    #[test]
    fn segment_of_nothing_is_empty() {
        let seg = segment(&[], &z_up());
        assert!(seg.planes.is_empty() && seg.objects.is_empty() && seg.labels.is_empty());
    }

    #[test]
    fn segment_ignores_non_finite_points() {
        let points = vec![Vec3::NAN; 1000];
        let seg = segment(&points, &z_up());
        assert!(seg.planes.is_empty() && seg.objects.is_empty());
        assert_eq!(seg.labels, vec![0; 1000]);

        let (mut points, _) = tabletop();
        for (k, p) in points.iter_mut().enumerate() {
            if k % 7 == 0 {
                *p = if k % 2 == 0 {
                    Vec3::NAN
                } else {
                    Vec3::new(f32::INFINITY, 0.0, 0.0)
                };
            }
        }
        let seg = segment(&points, &z_up());
        assert_eq!(seg.objects.len(), 3);
        assert!((0..points.len()).step_by(7).all(|k| seg.labels[k] == 0));
    }

    #[test]
    fn segment_is_deterministic_for_a_seed() {
        let (points, _) = tabletop();
        let config = SegmentConfig { seed: 42, ..z_up() };
        let a = segment(&points, &config);
        let b = segment(&points, &config);
        assert_eq!(a, b);
    }

    #[test]
    fn segment_drops_points_below_the_plane() {
        let (mut points, _) = tabletop();
        let n = points.len();
        // A blob 30 cm below the table (the floor side, away from the sensor).
        for k in 0..500 {
            points.push(Vec3::new(
                jitter(k, 0.05),
                jitter(k + 7, 0.05),
                -1.3 + jitter(k + 13, 0.05),
            ));
        }
        let seg = segment(&points, &z_up());
        assert_eq!(seg.objects.len(), 3);
        assert!(seg.labels[n..].iter().all(|&l| l == 0));
        assert!(seg.planes[0].inliers.iter().all(|&i| (i as usize) < n));
    }
}
