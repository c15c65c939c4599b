//! A simulated depth camera: one ray per pixel through a [`DynamicScene`] (objects may move,
//! appear and leave), with a real sensor's noise, as a [`DepthSource`] like any hardware
//! backend.
//!
//! Entry points:
//! - [`SimulatedDepthCamera::new`] (or [`SimulatedDepthCamera::tabletop`], or a scene file's
//!   [`SceneFile::into_camera`](crate::SceneFile::into_camera)) with a [`DepthCameraConfig`];
//!   as a [`DepthSource`] it yields [`Observation::Depth`] frames stamped with the host's
//!   monotonic clock, paced at `rate_fps` of wall-clock time or as fast as they are consumed.
//! - [`SimulatedDepthCamera::render`]: the frame for a given frame index, without pacing.
//! - Ground truth per frame index: [`scene_time_s`](SimulatedDepthCamera::scene_time_s),
//!   [`scene_at`](SimulatedDepthCamera::scene_at) (true poses),
//!   [`render_ids`](SimulatedDepthCamera::render_ids) (which object each pixel sees),
//!   [`visible_surface`](SimulatedDepthCamera::visible_surface) (noise-free surface points).
//! - [`DepthNoise`]: axial Gaussian noise `sigma = k·z²` (Intel RealSense D400 datasheet's
//!   depth-RMS model; or the paper's constant sigma), dropouts, and flying pixels at depth edges.
//! - [`look_at`]: a sensor pose from an eye point and a target.
//!
//! Scene time: frame `k` shows the scene at `k / fps` seconds (wrapped by the scene's
//! `loop_s`), whatever the pacing and however slowly frames are consumed, so a frame depends
//! only on (scene, configuration, seed, frame index).
//!
//! Pipeline per frame, in this order: pose the moving objects at the frame's time → clean depth
//! and object id per pixel → flying pixels (decided on the clean image) → Gaussian noise along
//! the ray → dropouts. The static objects ([`DynamicObject::is_static`](crate::DynamicObject::is_static))
//! look the same in every frame, so the camera casts every pixel against them once, when it is
//! built; a frame casts only the pixels inside the screen rectangles of the other objects
//! present, against those objects only, and keeps the nearer of that hit and the cached one.
//! Each pixel draws its noise from its own counter-based stream keyed by (seed, frame index,
//! pixel), so a frame is bit-identical whatever the thread count.
//!
//! Threads: a frame renders on the calling thread unless
//! [`render_threads`](DepthCameraConfig::render_threads) asks for more, which then come from
//! the camera's own pool, never rayon's global one (the pipeline's parallel work must not queue
//! behind the camera's).
//!
//! Depth is z in the sensor frame (x right, y down, z forward), not ray length; noise is added
//! to z, which moves the deprojected point along its pixel's ray. Casting the ray
//! `world_from_sensor.translation + t · world_from_sensor.matrix3 · (x, y, 1)` makes the time
//! of impact `t` that z exactly, for any affine pose.

use std::collections::BTreeMap;
use std::thread;
use std::time::{Duration, Instant};

use glam::{Affine3A, Mat3A, Vec3, Vec3A};
use rayon::prelude::*;
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::dynamic_scene::{DynamicScene, DynamicSceneBvh};
use crate::faults::{check_faults, fault_at, Fault, FaultKind};
use crate::scene::{RayHit, Scene, SceneBvh, SceneError, SceneObject};

/// The sensor's noise model. All probabilities are per pixel and per frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthNoise {
    /// `k` of the axial noise `sigma = k·z²`: the standard deviation at 1 m, metres.
    pub sigma_at_1m_m: f32,
    /// If set, a depth-independent sigma in metres used instead of `k·z²` (the paper's noise
    /// is a constant 0.02 m).
    pub constant_sigma_m: Option<f32>,
    /// Probability that a pixel reads 0 (no return).
    pub dropout_probability: f32,
    /// Probability that a pixel at a depth edge reads a depth between the two surfaces.
    pub flying_pixel_probability: f32,
    /// A pixel is at a depth edge when a 4-neighbour's clean depth differs by more than this,
    /// metres. Neighbours without a hit do not count (there is nothing to interpolate to).
    pub flying_pixel_edge_m: f32,
}

impl DepthNoise {
    /// No noise at all: the clean ray-cast depth.
    pub const NONE: DepthNoise = DepthNoise {
        sigma_at_1m_m: 0.0,
        constant_sigma_m: None,
        dropout_probability: 0.0,
        flying_pixel_probability: 0.0,
        flying_pixel_edge_m: 0.05,
    };

    /// The standard deviation of the depth noise at depth `z_m`, metres.
    pub fn sigma_m(&self, z_m: f32) -> f32 {
        self.constant_sigma_m
            .unwrap_or(self.sigma_at_1m_m * z_m * z_m)
    }

    fn check(&self) -> Result<(), DepthCameraError> {
        let fields = [
            ("sigma_at_1m_m", self.sigma_at_1m_m, f32::INFINITY),
            (
                "constant_sigma_m",
                self.constant_sigma_m.unwrap_or(0.0),
                f32::INFINITY,
            ),
            ("dropout_probability", self.dropout_probability, 1.0),
            (
                "flying_pixel_probability",
                self.flying_pixel_probability,
                1.0,
            ),
            (
                "flying_pixel_edge_m",
                self.flying_pixel_edge_m,
                f32::INFINITY,
            ),
        ];
        for (field, value, max) in fields {
            if !(value.is_finite() && (0.0..=max).contains(&value)) {
                return Err(DepthCameraError::InvalidNoise { field, value });
            }
        }
        Ok(())
    }
}

impl Default for DepthNoise {
    /// RealSense-like: 1 mm at 1 m (4 mm at 2 m), 1 % dropouts, 30 % flying pixels at edges
    /// deeper than 5 cm.
    fn default() -> Self {
        DepthNoise {
            sigma_at_1m_m: 0.001,
            constant_sigma_m: None,
            dropout_probability: 0.01,
            flying_pixel_probability: 0.3,
            flying_pixel_edge_m: 0.05,
        }
    }
}

/// Everything about the simulated camera except the scene.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthCameraConfig {
    pub intrinsics: Intrinsics,
    /// The sensor pose (x right, y down, z forward); see [`look_at`].
    pub world_from_sensor: Affine3A,
    pub noise: DepthNoise,
    /// Surfaces at z beyond this read 0, metres.
    pub max_range_m: f32,
    /// With the frame index, the seed of every random draw.
    pub seed: u64,
    /// The scene's frame rate: frame `k` shows scene time `k / fps` seconds, paced or not.
    pub fps: f32,
    /// Frames per second of wall-clock time to pace at; `None` renders as fast as consumed.
    /// Normally `Some(fps)` (real time); another rate plays the scene faster or slower.
    pub rate_fps: Option<f32>,
    /// Threads rendering each frame: 1 (the default; 0 counts as 1) renders on the calling
    /// thread, more use a pool of that many threads owned by the camera, never rayon's global
    /// pool. The frames are the same bit for bit either way.
    pub render_threads: usize,
}

/// 640×480 with the focal length of a Kinect-class sensor (about 63° horizontal field of view).
pub const DEFAULT_INTRINSICS: Intrinsics = Intrinsics {
    width: 640,
    height: 480,
    fx: 525.0,
    fy: 525.0,
    cx: 319.5,
    cy: 239.5,
};

/// How far the default camera is from the table centre, metres.
pub const DEFAULT_VIEW_DISTANCE_M: f32 = 1.2;

impl DepthCameraConfig {
    /// The default camera pose for [`Scene::tabletop`]: 1.2 m from the table centre, on the
    /// −Y side, looking down at 45° at the centre.
    pub fn tabletop_pose() -> Affine3A {
        let (sin, cos) = std::f32::consts::FRAC_PI_4.sin_cos();
        let eye = DEFAULT_VIEW_DISTANCE_M * Vec3::new(0.0, -cos, sin);
        look_at(eye, Vec3::ZERO, Vec3::Z)
    }
}

impl Default for DepthCameraConfig {
    /// [`DEFAULT_INTRINSICS`], [`tabletop_pose`](Self::tabletop_pose), default noise, 4 m
    /// range, seed 0, 30 fps paced in real time, rendered on the calling thread.
    fn default() -> Self {
        DepthCameraConfig {
            intrinsics: DEFAULT_INTRINSICS,
            world_from_sensor: Self::tabletop_pose(),
            noise: DepthNoise::default(),
            max_range_m: 4.0,
            seed: 0,
            fps: 30.0,
            rate_fps: Some(30.0),
            render_threads: 1,
        }
    }
}

/// Why a simulated camera could not be built.
#[derive(Debug, thiserror::Error)]
pub enum DepthCameraError {
    #[error("cannot index the scene")]
    Scene(#[from] SceneError),

    #[error("noise parameter {field} must be finite and within its range (sigmas >= 0, probabilities in [0, 1]), got {value}")]
    InvalidNoise { field: &'static str, value: f32 },

    #[error("intrinsics must have a non-zero size and finite, non-zero focal lengths and a finite principal point, got {intrinsics:?}")]
    InvalidIntrinsics { intrinsics: Intrinsics },

    #[error("max_range_m must be a finite number of metres > 0, got {max_range_m}")]
    InvalidRange { max_range_m: f32 },

    #[error("the image is {width}x{height}: the simulated camera renders at most {MAX_SIDE_PIXELS} pixels a side and {MAX_IMAGE_PIXELS} pixels in all (4096x4096)")]
    ImageTooLarge { width: u32, height: u32 },

    #[error("fps must be from {MIN_FPS} to {MAX_FPS} frames per second of scene time, got {fps}")]
    InvalidFps { fps: f32 },

    #[error("rate_fps must be from {MIN_FPS} to {MAX_FPS} frames per second (or none to run as fast as consumed), got {rate_fps}")]
    InvalidRate { rate_fps: f32 },

    #[error("world_from_sensor must be finite and invertible, got {world_from_sensor:?}")]
    InvalidPose { world_from_sensor: Affine3A },

    #[error("injected faults: {reason}")]
    InvalidFaults { reason: String },

    #[error("cannot start {threads} render threads: lower render_threads (1 renders on the calling thread)")]
    RenderThreads {
        threads: usize,
        #[source]
        source: rayon::ThreadPoolBuildError,
    },
}

/// A pixel's nearest hit, naming the object by its index in the scene (unique, and the order
/// that breaks ties).
#[derive(Debug, Clone, Copy, PartialEq)]
struct SceneHit {
    time_of_impact: f32,
    scene_index: u32,
}

impl SceneHit {
    /// No hit: nearer than nothing, and later than every object.
    const NONE: SceneHit = SceneHit {
        time_of_impact: f32::INFINITY,
        scene_index: u32::MAX,
    };

    /// The depth image's value: the time of impact, 0 for no hit.
    fn depth_m(self) -> f32 {
        if self.time_of_impact.is_finite() {
            self.time_of_impact
        } else {
            0.0
        }
    }
}

impl Default for SceneHit {
    fn default() -> Self {
        SceneHit::NONE
    }
}

/// The pixels whose rays can meet an object: columns `u.0..=u.1` of rows `v.0..=v.1` (empty
/// if a start exceeds its end).
#[derive(Debug, Clone, Copy)]
struct PixelRect {
    u: (i64, i64),
    v: (i64, i64),
}

/// The sensor pose at `eye` looking at `target`, with the image's up direction as close to `up`
/// as possible: sensor z towards the target, x to the right, y down in the image.
///
/// `up` must not be parallel to the viewing direction (the result is not finite then).
pub fn look_at(eye: Vec3, target: Vec3, up: Vec3) -> Affine3A {
    let forward = (target - eye).normalize();
    let right = forward.cross(up).normalize();
    let down = forward.cross(right);
    Affine3A::from_mat3_translation(glam::Mat3::from_cols(right, down, forward), eye)
}

/// A pinhole depth camera rendering a (possibly moving) scene by ray casting.
pub struct SimulatedDepthCamera {
    name: String,
    config: DepthCameraConfig,
    /// The ground truth, for [`scene_at`](Self::scene_at).
    scene: DynamicScene,
    bvh: DynamicSceneBvh,
    /// Sensor-frame ray `(x, y, 1)` of every pixel, row-major; computed once.
    rays_in_sensor: Vec<Vec3A>,
    /// The nearest hit of every pixel's ray among the static objects alone, row-major;
    /// computed once (see the module docs).
    static_hits: Vec<SceneHit>,
    /// The id of every object, by index in the scene.
    object_ids: Vec<u32>,
    /// The render threads if `render_threads > 1`; `None`: the calling thread.
    pool: Option<rayon::ThreadPool>,
    frame_index: u64,
    next_due: Option<Instant>,
    /// Injected faults by frame index (see [`set_faults`](Self::set_faults)); none by default.
    faults: Vec<Fault>,
}

impl SimulatedDepthCamera {
    /// A camera named `name` (e.g. `sim:tabletop`) looking at `scene` (a [`DynamicScene`], or
    /// a static [`Scene`] or `&Scene`). Fails on an unusable object mesh, motion or presence
    /// window, or an out-of-range configuration value.
    pub fn new(
        name: impl Into<String>,
        scene: impl Into<DynamicScene>,
        config: DepthCameraConfig,
    ) -> Result<Self, DepthCameraError> {
        check_config(&config)?;
        let scene: DynamicScene = scene.into();
        let bvh = scene.build_bvh()?;
        let object_ids = scene.objects.iter().map(|object| object.id).collect();
        let k = config.intrinsics;
        let rays_in_sensor = (0..k.height)
            .flat_map(|v| (0..k.width).map(move |u| Vec3A::from(k.ray(u as f32, v as f32))))
            .collect();
        let threads = config.render_threads;
        let pool = (threads > 1)
            .then(|| {
                rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .thread_name(|i| format!("sim-render-{i}"))
                    .build()
                    .map_err(|source| DepthCameraError::RenderThreads { threads, source })
            })
            .transpose()?;
        let mut camera = SimulatedDepthCamera {
            name: name.into(),
            config,
            scene,
            bvh,
            rays_in_sensor,
            static_hits: Vec::new(),
            object_ids,
            pool,
            frame_index: 0,
            next_due: None,
            faults: Vec::new(),
        };
        let nothing = vec![SceneHit::NONE; camera.rays_in_sensor.len()];
        camera.static_hits = camera.cast_rays(&camera.bvh.static_part(), &nothing, |hit, _| hit);
        Ok(camera)
    }

    /// [`Scene::tabletop`] seen by the default camera with the given seed.
    pub fn tabletop(seed: u64) -> Self {
        let config = DepthCameraConfig {
            seed,
            ..DepthCameraConfig::default()
        };
        match Self::new("sim:tabletop", Scene::tabletop(), config) {
            Ok(camera) => camera,
            // The built-in scene and defaults are valid; the tests pin this down.
            Err(err) => unreachable!("the built-in tabletop camera is invalid: {err}"),
        }
    }

    pub fn config(&self) -> &DepthCameraConfig {
        &self.config
    }

    /// Paces frames at the scene's `fps` of wall-clock time (`true`) or delivers them as fast
    /// as they are read (`false`). Scene time per frame stays `1 / fps` either way.
    pub fn set_paced(&mut self, paced: bool) {
        self.config.rate_fps = paced.then_some(self.config.fps);
        self.next_due = None;
    }

    /// The scene the camera looks at, at all times.
    pub fn scene(&self) -> &DynamicScene {
        &self.scene
    }

    /// Makes frames of the given indices fail or come out malformed (see [`Fault`]); replaces
    /// any faults set before. Fails, naming them, on faults that cover no frame or overlap.
    pub fn set_faults(&mut self, faults: Vec<Fault>) -> Result<(), DepthCameraError> {
        check_faults(&faults).map_err(|reason| DepthCameraError::InvalidFaults { reason })?;
        self.faults = faults;
        Ok(())
    }

    /// The injected faults.
    pub fn faults(&self) -> &[Fault] {
        &self.faults
    }

    /// The scene time frame `frame_index` shows: `frame_index / fps` seconds, wrapped by the
    /// scene's `loop_s`.
    pub fn scene_time_s(&self, frame_index: u64) -> f32 {
        self.scene
            .wrap_time_s(frame_index as f64 / f64::from(self.config.fps))
    }

    /// The objects present in frame `frame_index` at their true poses (ground truth): each
    /// mesh in its object frame with its `world_from_object` at that frame's scene time.
    pub fn scene_at(&self, frame_index: u64) -> Vec<SceneObject> {
        self.scene.objects_at(self.scene_time_s(frame_index))
    }

    /// The ray-casting index of frame `frame_index`'s scene (for ground-truth queries such as
    /// [`SceneBvh::distance_to_surface`]).
    pub fn scene_bvh(&self, frame_index: u64) -> SceneBvh {
        self.bvh.at(self.scene_time_s(frame_index))
    }

    /// The index of the frame the next [`next_observation`](DepthSource::next_observation)
    /// renders (0 for the first).
    pub fn frame_index(&self) -> u64 {
        self.frame_index
    }

    /// The depth image of frame `frame_index`, row-major, metres along the optical axis, 0
    /// for no reading. Pure: the same camera configuration and frame index give the same
    /// buffer bit for bit, whatever the thread count.
    pub fn render_depth(&self, frame_index: u64) -> Vec<f32> {
        let clean_m = self.cast_frame(frame_index, |hit, _| hit.depth_m());
        self.add_noise(&clean_m, frame_index)
    }

    /// Frame `frame_index` as a [`DepthFrame`] stamped with `capture_time`.
    pub fn render(&self, frame_index: u64, capture_time: Duration) -> DepthFrame {
        DepthFrame {
            intrinsics: self.config.intrinsics,
            depth_m: self.render_depth(frame_index),
            world_from_sensor: self.config.world_from_sensor,
            capture_time,
        }
    }

    /// Which object each pixel of frame `frame_index` sees (`None`: nothing within range),
    /// row-major, without noise.
    pub fn render_ids(&self, frame_index: u64) -> Vec<Option<u32>> {
        self.cast_frame(frame_index, |hit, _| {
            self.ray_hit(hit).map(|hit| hit.object_id)
        })
    }

    /// The surface points frame `frame_index` sees, without noise: per object id (ascending),
    /// the world point where each pixel's ray meets that object, pixels in row-major order.
    /// They lie on the true surface at the true pose ([`scene_at`](Self::scene_at)); objects
    /// no pixel sees are left out.
    pub fn visible_surface(&self, frame_index: u64) -> Vec<(u32, Vec<Vec3>)> {
        let origin = Vec3::from(self.config.world_from_sensor.translation);
        let hits = self.cast_frame(frame_index, |hit, pixel| {
            self.ray_hit(hit).map(|hit| {
                (
                    hit.object_id,
                    origin + hit.time_of_impact * self.world_dir(pixel),
                )
            })
        });
        let mut by_id: BTreeMap<u32, Vec<Vec3>> = BTreeMap::new();
        for (id, p_in_world) in hits.into_iter().flatten() {
            by_id.entry(id).or_default().push(p_in_world);
        }
        by_id.into_iter().collect()
    }

    // -- stage 1: clean depth and object id per pixel --------------------------------------------

    /// Frame `frame_index`'s nearest hit per pixel, row-major, through `pixel(hit, pixel
    /// index)`: the cached static hit, unless one of the moving objects present is nearer.
    fn cast_frame<T: Send + Copy + Default>(
        &self,
        frame_index: u64,
        pixel: impl Fn(SceneHit, usize) -> T + Sync,
    ) -> Vec<T> {
        let moving = self.bvh.moving_at(self.scene_time_s(frame_index));
        self.cast_rays(&moving, &self.static_hits, pixel)
    }

    /// One ray per pixel through the posed objects `bvh` (with their indices in the scene),
    /// rows on the render threads: the nearest hit among the objects whose pixel rectangle
    /// holds the pixel, or `behind[pixel]` (a hit already known, from other objects) if that
    /// is nearer. Pixels outside every rectangle cast nothing. `pixel(hit, pixel index)`
    /// makes each output.
    ///
    /// On a tie in `t` the object earlier in the scene wins, as in one cast through all of
    /// them (whose nearer-only test keeps the first of equal hits): so with `behind` the
    /// static objects' hits and `bvh` the others present, the result is that of a cast
    /// through the whole scene (the tests pin this down), up to the rounding of the box
    /// tests that prune the trees.
    fn cast_rays<T: Send + Copy + Default>(
        &self,
        (bvh, scene_indices): &(SceneBvh, Vec<u32>),
        behind: &[SceneHit],
        pixel: impl Fn(SceneHit, usize) -> T + Sync,
    ) -> Vec<T> {
        let origin = Vec3::from(self.config.world_from_sensor.translation);
        let max_range_m = self.config.max_range_m;
        let width = self.config.intrinsics.width as usize;
        let rects = self.pixel_rects(bvh);
        let mut out = vec![T::default(); self.rays_in_sensor.len()];
        self.for_each_row(&mut out, |v, out_row| {
            let first = v * width;
            let behind = &behind[first..first + width];
            let row: Vec<(usize, PixelRect)> = rects
                .iter()
                .copied()
                .enumerate()
                .filter(|(_, rect)| {
                    rect.u.0 <= rect.u.1 && (rect.v.0..=rect.v.1).contains(&(v as i64))
                })
                .collect();
            // Columns `lo..hi` hold every rectangle of the row; the others keep `behind`.
            let (lo, hi) = row.iter().fold((width, 0), |(lo, hi), (_, rect)| {
                let clamp = |u: i64| u.clamp(0, width as i64) as usize;
                (lo.min(clamp(rect.u.0)), hi.max(clamp(rect.u.1 + 1)))
            });
            let lo = lo.min(hi);
            for u in (0..lo).chain(hi..width) {
                out_row[u] = pixel(behind[u], first + u);
            }
            for u in lo..hi {
                let known = behind[u];
                let mut candidates = row
                    .iter()
                    .filter(|(_, rect)| (rect.u.0..=rect.u.1).contains(&(u as i64)))
                    .map(|&(i, _)| i)
                    .peekable();
                if candidates.peek().is_none() {
                    out_row[u] = pixel(known, first + u);
                    continue;
                }
                // Up to and including the known hit's `t`, for the tie rule.
                let max_t = known.time_of_impact.next_up().min(max_range_m);
                let dir = self.world_dir(first + u);
                let hit = match bvh.cast_nearest_among(origin, dir, max_t, candidates) {
                    Some((i, t))
                        if t < known.time_of_impact || scene_indices[i] < known.scene_index =>
                    {
                        SceneHit {
                            time_of_impact: t,
                            scene_index: scene_indices[i],
                        }
                    }
                    _ => known,
                };
                out_row[u] = pixel(hit, first + u);
            }
        });
        out
    }

    /// `hit` as the public [`RayHit`], naming the object by its id.
    fn ray_hit(&self, hit: SceneHit) -> Option<RayHit> {
        self.object_ids
            .get(hit.scene_index as usize)
            .map(|&object_id| RayHit {
                object_id,
                time_of_impact: hit.time_of_impact,
            })
    }

    /// The world direction of pixel `pixel`'s ray (row-major index), scaled so that its time
    /// of impact is the depth.
    fn world_dir(&self, pixel: usize) -> Vec3 {
        let rotation: Mat3A = self.config.world_from_sensor.matrix3;
        Vec3::from(rotation * self.rays_in_sensor[pixel])
    }

    /// Runs `row(v, out[row v])` for every image row of `out`: in order on the calling thread,
    /// or in parallel on the camera's pool if it has one.
    fn for_each_row<T: Send>(&self, out: &mut [T], row: impl Fn(usize, &mut [T]) + Sync) {
        let width = self.config.intrinsics.width as usize;
        match &self.pool {
            None => out
                .chunks_mut(width)
                .enumerate()
                .for_each(|(v, out_row)| row(v, out_row)),
            Some(pool) => pool.install(|| {
                out.par_chunks_mut(width)
                    .enumerate()
                    .for_each(|(v, out_row)| row(v, out_row))
            }),
        }
    }

    /// Per object of `bvh`, the pixels whose rays can meet its world box: the bounding
    /// rectangle of the box's projected corners, widened by a pixel, or the whole image if a
    /// corner is not in front of the sensor (the projection is not bounded then).
    fn pixel_rects(&self, bvh: &SceneBvh) -> Vec<PixelRect> {
        let k = self.config.intrinsics;
        let sensor_from_world = self.config.world_from_sensor.inverse();
        let whole = PixelRect {
            u: (0, i64::from(k.width) - 1),
            v: (0, i64::from(k.height) - 1),
        };
        bvh.world_boxes()
            .map(|(lo, hi)| {
                let mut u_range = (f32::INFINITY, f32::NEG_INFINITY);
                let mut v_range = u_range;
                for corner in 0..8 {
                    let pick = |bit: u32, l: f32, h: f32| if corner & bit == 0 { l } else { h };
                    let p_in_world = Vec3::new(
                        pick(1, lo.x, hi.x),
                        pick(2, lo.y, hi.y),
                        pick(4, lo.z, hi.z),
                    );
                    let p = sensor_from_world.transform_point3(p_in_world);
                    if p.z.is_nan() || p.z <= 1e-6 {
                        return whole;
                    }
                    let (u, v) = (k.fx * p.x / p.z + k.cx, k.fy * p.y / p.z + k.cy);
                    u_range = (u_range.0.min(u), u_range.1.max(u));
                    v_range = (v_range.0.min(v), v_range.1.max(v));
                }
                // Pixel (u, v)'s ray goes through the projection (u, v), so rounding outwards
                // keeps every pixel whose ray can meet the box; one more pixel is margin for
                // rounding. Clamping to the image may leave an empty range (off the image).
                let clamp = |(lo, hi): (f32, f32), size: u32| {
                    let lo = (lo.floor() - 1.0).max(-1.0).min(size as f32);
                    let hi = (hi.ceil() + 1.0).max(-1.0).min(size as f32);
                    (lo as i64, hi as i64)
                };
                PixelRect {
                    u: clamp(u_range, k.width),
                    v: clamp(v_range, k.height),
                }
            })
            .collect()
    }

    // -- stages 2–4: flying pixels, Gaussian noise, dropouts ---------------------------------------

    fn add_noise(&self, clean_m: &[f32], frame_index: u64) -> Vec<f32> {
        let noise = self.config.noise;
        let width = self.config.intrinsics.width as usize;
        let height = self.config.intrinsics.height as usize;
        let key = frame_key(self.config.seed, frame_index);
        let flying = Chance::new(noise.flying_pixel_probability);
        let dropout = Chance::new(noise.dropout_probability);
        let mut noisy_m = vec![0.0f32; clean_m.len()];
        self.for_each_row(&mut noisy_m, |v, out_row| {
            for (u, out) in out_row.iter_mut().enumerate() {
                let pixel = v * width + u;
                let mut z = clean_m[pixel];
                if z <= 0.0 {
                    continue;
                }
                let draws = PixelDraws::new(key, pixel);
                let small = draws.word(0);
                if flying.possible() {
                    let partner =
                        edge_partner(clean_m, width, height, u, v, noise.flying_pixel_edge_m);
                    if let Some(far_z) = partner {
                        if flying.happens(bits(small, 48, 16)) {
                            z += unit_uniform(bits(draws.word(2), 0, 24)) * (far_z - z);
                        }
                    }
                }
                let sigma_m = noise.sigma_m(z);
                if sigma_m > 0.0 {
                    z += sigma_m * standard_normal(draws.word(1), bits(small, 0, 24));
                }
                if dropout.happens(bits(small, 24, 24)) {
                    z = 0.0;
                }
                // Noise cannot put a surface behind the sensor.
                *out = z.max(0.0);
            }
        });
        noisy_m
    }

    /// Sleeps until frame `frame_index` is due at `rate_fps`; a camera that has fallen behind
    /// does not burst to catch up, it restarts its schedule from now.
    fn pace(&mut self) {
        let Some(rate_fps) = self.config.rate_fps else {
            return;
        };
        // `check_config` holds the rate to MIN_FPS..=MAX_FPS, so the period fits.
        let period = Duration::try_from_secs_f64(1.0 / f64::from(rate_fps)).unwrap_or_default();
        let now = Instant::now();
        let due = self.next_due.unwrap_or(now);
        if due > now {
            thread::sleep(due - now);
        }
        let next = due + period;
        self.next_due = Some(if next < Instant::now() {
            Instant::now() + period
        } else {
            next
        });
    }
}

impl DepthSource for SimulatedDepthCamera {
    fn name(&self) -> &str {
        &self.name
    }

    /// Paces to `rate_fps` if set, then renders the next frame, stamped with the host's
    /// monotonic clock ([`monotonic_now`]) when rendering began (its capture time). A frame
    /// with an injected fault ([`set_faults`](Self::set_faults)) is paced like any other and
    /// then fails or comes out malformed as its [`FaultKind`] says.
    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        self.pace();
        let capture_time = monotonic_now();
        let mut frame_index = self.frame_index;
        self.frame_index += 1;
        let Some(&fault) = fault_at(&self.faults, frame_index) else {
            return Ok(Observation::Depth(self.render(frame_index, capture_time)));
        };
        let kind = fault.kind;
        let reason = format!("injected fault {} at frame {frame_index}", kind.name());
        let pixels = self.rays_in_sensor.len();
        let blank = |depth_m: Vec<f32>| DepthFrame {
            intrinsics: self.config.intrinsics,
            depth_m,
            world_from_sensor: self.config.world_from_sensor,
            capture_time,
        };
        let frame = match kind {
            FaultKind::Error => {
                return Err(SourceError::Malformed {
                    device: self.name.clone(),
                    reason,
                })
            }
            FaultKind::Disconnect => {
                return Err(SourceError::Disconnected {
                    device: self.name.clone(),
                    reason,
                })
            }
            FaultKind::WrongSize => {
                let mut frame = self.render(frame_index, capture_time);
                frame.depth_m.truncate(pixels / 2);
                frame
            }
            FaultKind::Zeros => blank(vec![0.0; pixels]),
            FaultKind::Nan => blank(vec![f32::NAN; pixels]),
            FaultKind::AbsurdIntrinsics => {
                let mut frame = self.render(frame_index, capture_time);
                frame.intrinsics.fx = 0.0;
                frame.intrinsics.fy = f32::NAN;
                frame
            }
            FaultKind::Stall => {
                let left = fault.frames().end - frame_index;
                thread::sleep(
                    Duration::try_from_secs_f64(left as f64 / f64::from(self.config.fps))
                        .unwrap_or_default(),
                );
                // The frames of the window are lost; the schedule starts again from now.
                frame_index = fault.frames().end;
                self.frame_index = frame_index + 1;
                self.next_due = None;
                self.render(frame_index, monotonic_now())
            }
        };
        Ok(Observation::Depth(frame))
    }
}

/// The slowest simulated frame rate: a frame every 100 s.
pub const MIN_FPS: f32 = 0.01;
/// The fastest simulated frame rate.
pub const MAX_FPS: f32 = 1_000.0;
/// The widest or tallest simulated image, pixels.
pub const MAX_SIDE_PIXELS: u32 = 16_384;
/// The most pixels in a simulated image: 4096×4096 (a 100000×100000 camera once took 3 GB
/// before rendering anything).
pub const MAX_IMAGE_PIXELS: u64 = 4096 * 4096;

pub(crate) fn check_config(config: &DepthCameraConfig) -> Result<(), DepthCameraError> {
    let k = config.intrinsics;
    if !k.is_usable() {
        return Err(DepthCameraError::InvalidIntrinsics { intrinsics: k });
    }
    let pose = config.world_from_sensor;
    if !(pose.is_finite() && pose.matrix3.determinant() != 0.0) {
        return Err(DepthCameraError::InvalidPose {
            world_from_sensor: pose,
        });
    }
    if !(config.max_range_m.is_finite() && config.max_range_m > 0.0) {
        return Err(DepthCameraError::InvalidRange {
            max_range_m: config.max_range_m,
        });
    }
    let pixels = u64::from(k.width) * u64::from(k.height);
    if k.width > MAX_SIDE_PIXELS || k.height > MAX_SIDE_PIXELS || pixels > MAX_IMAGE_PIXELS {
        return Err(DepthCameraError::ImageTooLarge {
            width: k.width,
            height: k.height,
        });
    }
    // A frame period is 1/fps: a tiny rate overflows `Duration` (fps = 1e-30 once aborted).
    if !(MIN_FPS..=MAX_FPS).contains(&config.fps) {
        return Err(DepthCameraError::InvalidFps { fps: config.fps });
    }
    if let Some(rate_fps) = config.rate_fps {
        if !(MIN_FPS..=MAX_FPS).contains(&rate_fps) {
            return Err(DepthCameraError::InvalidRate { rate_fps });
        }
    }
    config.noise.check()
}

// -- per-pixel random numbers ---------------------------------------------------------------------
//
// Why not a crate RNG (a ChaCha8 stream per row, as before, with rand_distr's normal): a pixel
// needs at most three 64-bit draws, and must get the same ones whichever thread renders it. ChaCha's
// block refills and `Rng::sample` cost more than all the rest of the noise stage. Counter-based
// SplitMix64 (Steele, Lea, Flood: "Fast splittable pseudorandom number generators", OOPSLA 2014;
// its output passes BigCrush) gives any draw of any pixel directly, as one 64-bit mix of a
// counter, and the three draws of a pixel are independent instructions.

/// SplitMix64's increment: 2^64 over the golden ratio, odd.
const GOLDEN_GAMMA: u64 = 0x9e37_79b9_7f4a_7c15;

/// SplitMix64's output function (Stafford's "Mix13" variant of MurmurHash3's finaliser): a
/// bijection of `u64` that spreads every input bit over every output bit.
fn mix64(z: u64) -> u64 {
    let z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The seed of a frame's noise: a hash of the camera's seed and the frame index (distinct
/// frames of one seed never share it, `mix64` being a bijection).
fn frame_key(seed: u64, frame_index: u64) -> u64 {
    mix64(mix64(seed) ^ frame_index)
}

/// The random words of one pixel of one frame: word `k` of pixel `pixel` (row-major index)
/// is output `3·pixel + k + 1` of the SplitMix64 generator seeded with the frame's key, so
/// each is one hash, computed only if needed. Word 0 holds the small draws: bits 0–23 the
/// normal's dither, 24–47 the dropout coin, 48–63 the flying-pixel coin; word 1 the normal's
/// 64 bits; word 2 where a flying pixel lands between the two surfaces.
#[derive(Clone, Copy)]
struct PixelDraws(u64);

impl PixelDraws {
    fn new(key: u64, pixel: usize) -> Self {
        PixelDraws(key.wrapping_add((3 * pixel as u64).wrapping_mul(GOLDEN_GAMMA)))
    }

    #[inline]
    fn word(self, k: u64) -> u64 {
        mix64(self.0.wrapping_add((k + 1).wrapping_mul(GOLDEN_GAMMA)))
    }
}

/// Bits `lowest .. lowest + count` of `word` as the top bits of a `u32` (the rest zero), so a
/// draw of `count` bits reads as a 32-bit one of that resolution.
fn bits(word: u64, lowest: u32, count: u32) -> u32 {
    ((word >> lowest) << (64 - count) >> 32) as u32
}

/// A uniform number in `[0, 1)` from 32 random bits (their top 24, all an `f32` can hold).
fn unit_uniform(bits: u32) -> f32 {
    (bits >> 8) as f32 * (1.0 / 16_777_216.0)
}

/// A standard normal number from 64 + 24 random bits, by the central limit theorem: the
/// number of ones among the 64 `bits` (binomial: mean 32, variance 16) plus a uniform in
/// `[-0.5, 0.5)` from `dither_bits` that fills the gaps between its integers (variance 1/12),
/// scaled to unit variance. Its distribution function is within 0.0013 of the Gaussian's
/// everywhere; the tails beyond 2 and 3 sigma hold 1.006 and 0.95 times the Gaussian's mass,
/// beyond 4 sigma 0.77 times, and nothing lies beyond 8 sigma. Enough for a sensor's depth
/// noise, at a popcount instead of a logarithm and a cosine (Box-Muller) or a table walk
/// (ziggurat).
fn standard_normal(bits: u64, dither_bits: u32) -> f32 {
    /// `1 / sqrt(16 + 1/12)`.
    const UNIT_SIGMA: f32 = 0.249_351_49;
    (bits.count_ones() as f32 - 32.5 + unit_uniform(dither_bits)) * UNIT_SIGMA
}

/// A probability as a threshold on 32 random bits, so that a coin flip needs no float.
#[derive(Clone, Copy)]
struct Chance(u64);

impl Chance {
    /// `probability` in `[0, 1]` (checked with the configuration).
    fn new(probability: f32) -> Self {
        Chance((f64::from(probability) * 4_294_967_296.0).round() as u64)
    }

    fn possible(self) -> bool {
        self.0 > 0
    }

    /// Whether the event happens, given 32 random `bits`: with the probability rounded to a
    /// multiple of 2^-32.
    fn happens(self, bits: u32) -> bool {
        u64::from(bits) < self.0
    }
}

/// If pixel `(u, v)` lies on a depth edge, the clean depth of the 4-neighbour that differs most
/// (by more than `edge_m`); neighbours without a hit are ignored.
#[inline]
fn edge_partner(
    clean_m: &[f32],
    width: usize,
    height: usize,
    u: usize,
    v: usize,
    edge_m: f32,
) -> Option<f32> {
    let i = v * width + u;
    let z = clean_m[i];
    // 0 (no hit) for a neighbour off the image, which the test below ignores like any other.
    let at = |inside: bool, j: usize| if inside { clean_m[j] } else { 0.0 };
    let neighbours = [
        at(u > 0, i.wrapping_sub(1)),
        at(u + 1 < width, i + 1),
        at(v > 0, i.wrapping_sub(width)),
        at(v + 1 < height, i + width),
    ];
    // Most pixels are not at an edge: one branch-free test first.
    let at_edge = neighbours.iter().fold(false, |any, &n| {
        any | ((n > 0.0) & ((n - z).abs() > edge_m))
    });
    if !at_edge {
        return None;
    }
    let mut partner = None;
    let mut most_m = edge_m;
    for n in neighbours {
        let differs_m = (n - z).abs();
        if n > 0.0 && differs_m > most_m {
            most_m = differs_m;
            partner = Some(n);
        }
    }
    partner
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{SceneFile, Shape};
    use tacmesh_source::TriMesh;

    /// A 10 m × 10 m plane at z = 0 facing +Z.
    fn floor() -> SceneObject {
        SceneObject {
            id: 7,
            mesh: TriMesh::new(
                vec![
                    Vec3::new(-5.0, -5.0, 0.0),
                    Vec3::new(5.0, -5.0, 0.0),
                    Vec3::new(5.0, 5.0, 0.0),
                    Vec3::new(-5.0, 5.0, 0.0),
                ],
                vec![[0, 1, 2], [0, 2, 3]],
            ),
            world_from_object: Affine3A::IDENTITY,
        }
    }

    fn looking_down_from(height_m: f32, noise: DepthNoise) -> DepthCameraConfig {
        DepthCameraConfig {
            world_from_sensor: look_at(Vec3::new(0.0, 0.0, height_m), Vec3::ZERO, Vec3::Y),
            noise,
            rate_fps: None,
            ..DepthCameraConfig::default()
        }
    }

    fn floor_camera(height_m: f32, noise: DepthNoise) -> SimulatedDepthCamera {
        let scene = Scene {
            objects: vec![floor()],
        };
        SimulatedDepthCamera::new("test", &scene, looking_down_from(height_m, noise)).unwrap()
    }

    fn depth_of(observation: Observation) -> DepthFrame {
        match observation {
            Observation::Depth(frame) => frame,
            other => panic!("expected a depth frame, got {other:?}"),
        }
    }

    /// Each injected fault makes exactly its frames fail or come out malformed, as its kind
    /// says, and the frames around them are the camera's normal frames.
    #[test]
    fn injected_faults_break_exactly_their_frames() {
        let mut camera = floor_camera(2.0, DepthNoise::NONE);
        let kinds = FaultKind::ALL;
        let faults = kinds
            .iter()
            .enumerate()
            .map(|(k, &kind)| Fault {
                kind,
                at_frame: 1 + 2 * k as u64,
                frames: 1,
            })
            .collect();
        camera.set_faults(faults).unwrap();
        let pixels = (DEFAULT_INTRINSICS.width * DEFAULT_INTRINSICS.height) as usize;
        for (k, &kind) in kinds.iter().enumerate() {
            let good = depth_of(camera.next_observation().unwrap());
            assert!(good.is_consistent() && good.depth_m.iter().all(|&z| (z - 2.0).abs() < 1e-4));
            let stall_started = Instant::now();
            let faulty = camera.next_observation();
            // A stall skips its window: the camera delivers the frame after it.
            let skipped = u64::from(kind == FaultKind::Stall);
            assert_eq!(camera.frame_index(), 2 + 2 * k as u64 + skipped);
            match (kind, faulty) {
                (FaultKind::Error, Err(SourceError::Malformed { reason, .. }))
                | (FaultKind::Disconnect, Err(SourceError::Disconnected { reason, .. })) => {
                    assert!(reason.contains(kind.name()), "{reason}");
                }
                (FaultKind::WrongSize, Ok(Observation::Depth(frame))) => {
                    assert_eq!(frame.depth_m.len(), pixels / 2);
                    assert!(!frame.is_consistent());
                }
                (FaultKind::Zeros, Ok(Observation::Depth(frame))) => {
                    assert!(frame.is_consistent() && frame.depth_m.iter().all(|&z| z == 0.0));
                }
                (FaultKind::Nan, Ok(Observation::Depth(frame))) => {
                    assert!(frame.is_consistent() && frame.depth_m.iter().all(|z| z.is_nan()));
                }
                (FaultKind::Stall, Ok(Observation::Depth(frame))) => {
                    // One frame at 30 fps; then the frame after the window, which this scene
                    // shows the same.
                    assert!(stall_started.elapsed() >= Duration::from_millis(33));
                    assert_eq!(frame.depth_m, good.depth_m);
                }
                (FaultKind::AbsurdIntrinsics, Ok(Observation::Depth(frame))) => {
                    assert!(frame.is_consistent());
                    assert!(frame.intrinsics.fx == 0.0 && frame.intrinsics.fy.is_nan());
                    assert_eq!(frame.depth_m, good.depth_m);
                }
                (kind, other) => panic!("{kind:?}: {other:?}"),
            }
        }
        assert!(depth_of(camera.next_observation().unwrap()).is_consistent());
        let overlapping = vec![
            Fault {
                kind: FaultKind::Nan,
                at_frame: 0,
                frames: 2,
            };
            2
        ];
        assert!(matches!(
            camera.set_faults(overlapping),
            Err(DepthCameraError::InvalidFaults { .. })
        ));
    }

    /// Möller–Trumbore against every triangle: the exact nearest hit, independent of parry.
    fn brute_force_hit(mesh: &TriMesh, pose: Affine3A, origin: Vec3, dir: Vec3) -> Option<f32> {
        (0..mesh.triangles.len())
            .filter_map(|t| {
                let [a, b, c] = mesh.corners(t).map(|p| pose.transform_point3(p));
                let (e1, e2) = (b - a, c - a);
                let p = dir.cross(e2);
                let det = e1.dot(p);
                if det.abs() < 1e-12 {
                    return None;
                }
                let s = origin - a;
                let bu = s.dot(p) / det;
                let q = s.cross(e1);
                let bv = dir.dot(q) / det;
                let t = e2.dot(q) / det;
                (bu >= 0.0 && bv >= 0.0 && bu + bv <= 1.0 && t > 0.0).then_some(t)
            })
            .min_by(f32::total_cmp)
    }

    #[test]
    fn look_at_points_sensor_axes_right_down_forward() {
        let pose = DepthCameraConfig::tabletop_pose();
        let eye = Vec3::from(pose.translation);
        assert!((eye.length() - DEFAULT_VIEW_DISTANCE_M).abs() < 1e-6);
        assert!(eye.z > 0.0 && eye.y < 0.0, "eye {eye}");
        // The optical axis goes through the table centre, 45° downwards.
        let forward = pose.transform_vector3(Vec3::Z);
        assert!(forward.dot(-eye.normalize()) > 1.0 - 1e-6);
        assert!((forward.z + std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-6);
        // World +X is image right, world up is image up (smaller v).
        let sensor_from_world = pose.inverse();
        let project = |p: Vec3| {
            let q = sensor_from_world.transform_point3(p);
            let k = DEFAULT_INTRINSICS;
            (k.fx * q.x / q.z + k.cx, k.fy * q.y / q.z + k.cy)
        };
        let (u0, v0) = project(Vec3::ZERO);
        assert!((u0 - 319.5).abs() < 1e-3 && (v0 - 239.5).abs() < 1e-3);
        let (u_right, _) = project(Vec3::new(0.1, 0.0, 0.0));
        assert!(u_right > u0 + 10.0);
        let (_, v_up) = project(Vec3::new(0.0, 0.0, 0.1));
        assert!(v_up < v0 - 10.0);
        // Rigid: the rotation is orthonormal and right-handed.
        assert!((pose.matrix3.determinant() - 1.0).abs() < 1e-5);
    }

    #[test]
    fn depth_is_exact_on_a_plane_one_metre_below() {
        let mut camera = floor_camera(1.0, DepthNoise::NONE);
        let frame = depth_of(camera.next_observation().unwrap());
        assert!(frame.is_consistent());
        assert_eq!(frame.intrinsics, DEFAULT_INTRINSICS);
        let worst = frame
            .depth_m
            .iter()
            .map(|z| (z - 1.0).abs())
            .fold(0.0f32, f32::max);
        assert!(worst <= 1e-5, "worst depth error {worst} m");
        assert!(camera.render_ids(0).iter().all(|&id| id == Some(7)));
    }

    #[test]
    fn sphere_depth_at_centre_and_background_around_it() {
        // Off the pole so the centre ray hits the inside of a triangle, not a vertex.
        let sphere_centre = Vec3::new(0.013, 0.021, 0.0);
        let sphere = SceneObject {
            id: 3,
            mesh: Shape::Sphere.mesh(),
            world_from_object: Affine3A::from_translation(sphere_centre),
        };
        let scene = Scene {
            objects: vec![sphere.clone()],
        };
        let config = looking_down_from(2.0, DepthNoise::NONE);
        let camera = SimulatedDepthCamera::new("test", &scene, config).unwrap();
        let depth_m = camera.render_depth(0);
        let k = config.intrinsics;
        let width = k.width as usize;
        let (uc, vc) = (320usize, 240usize);
        let eye = Vec3::new(0.0, 0.0, 2.0);
        let dir = config
            .world_from_sensor
            .transform_vector3(k.ray(uc as f32, vc as f32));
        let expected = brute_force_hit(&sphere.mesh, sphere.world_from_object, eye, dir).unwrap();
        let centre = depth_m[vc * width + uc];
        assert!((centre - expected).abs() < 1e-5, "{centre} vs {expected}");
        // The faceted sphere of radius 0.5 m is within 1 cm of the round one.
        assert!((centre - 1.5).abs() < 0.01, "{centre}");
        // Pixels clearly outside the sphere's silhouette read 0, clearly inside read a depth.
        let to_centre = (sphere_centre - eye).normalize();
        let half_angle = (0.5 / (sphere_centre - eye).length()).asin();
        for (i, &z) in depth_m.iter().enumerate() {
            let (u, v) = ((i % width) as f32, (i / width) as f32);
            let ray = config.world_from_sensor.transform_vector3(k.ray(u, v));
            let angle = ray.normalize().dot(to_centre).clamp(-1.0, 1.0).acos();
            if angle > half_angle + 0.01 {
                assert_eq!(z, 0.0, "pixel ({u}, {v}) sees something");
            } else if angle < half_angle - 0.02 {
                assert!(z > 1.4 && z < 2.0, "pixel ({u}, {v}) reads {z}");
            }
        }
    }

    #[test]
    fn axial_noise_grows_with_the_square_of_depth() {
        let noise = DepthNoise {
            sigma_at_1m_m: 0.01,
            dropout_probability: 0.0,
            flying_pixel_probability: 0.0,
            ..DepthNoise::default()
        };
        let camera = floor_camera(2.0, noise);
        let depth_m = camera.render_depth(0);
        let n = depth_m.len() as f64;
        let mean = depth_m.iter().map(|&z| f64::from(z)).sum::<f64>() / n;
        let var = depth_m
            .iter()
            .map(|&z| (f64::from(z) - mean).powi(2))
            .sum::<f64>()
            / (n - 1.0);
        let std = var.sqrt();
        assert!((mean - 2.0).abs() < 1e-3, "mean {mean}");
        assert!(
            (std - 0.04).abs() < 0.004,
            "std {std}, expected k·z² = 0.04"
        );
    }

    #[test]
    fn constant_sigma_replaces_the_quadratic_model() {
        let noise = DepthNoise {
            constant_sigma_m: Some(0.02),
            ..DepthNoise::NONE
        };
        assert_eq!(noise.sigma_m(3.0), 0.02);
        let depth_m = floor_camera(2.0, noise).render_depth(0);
        let n = depth_m.len() as f64;
        let rms = (depth_m
            .iter()
            .map(|&z| (f64::from(z) - 2.0).powi(2))
            .sum::<f64>()
            / n)
            .sqrt();
        assert!((rms - 0.02).abs() < 0.002, "rms {rms}");
    }

    #[test]
    fn dropout_rate_matches_its_probability() {
        let noise = DepthNoise {
            dropout_probability: 0.1,
            ..DepthNoise::NONE
        };
        let depth_m = floor_camera(1.0, noise).render_depth(3);
        let rate = depth_m.iter().filter(|&&z| z == 0.0).count() as f64 / depth_m.len() as f64;
        // 307 200 pixels: the binomial standard error is 0.0005.
        assert!((rate - 0.1).abs() < 0.003, "dropout rate {rate}");
    }

    #[test]
    fn flying_pixels_appear_between_surfaces_only_at_edges() {
        // A cube 0.5 m in front of a floor: its silhouette is a 0.5 m depth edge.
        let scene = Scene {
            objects: vec![
                floor(),
                SceneObject {
                    id: 1,
                    mesh: Shape::Cube.mesh(),
                    world_from_object: Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.5)),
                },
            ],
        };
        let render = |probability| {
            let noise = DepthNoise {
                flying_pixel_probability: probability,
                ..DepthNoise::NONE
            };
            let config = looking_down_from(3.0, noise);
            let camera = SimulatedDepthCamera::new("test", &scene, config).unwrap();
            camera.render_depth(0)
        };
        // Clean depths are 2.0 (cube top) and 3.0 (floor); flying pixels lie between.
        let between = |depth_m: &[f32]| {
            depth_m
                .iter()
                .filter(|&&z| z > 2.0 + 1e-4 && z < 3.0 - 1e-4)
                .count()
        };
        assert_eq!(between(&render(0.0)), 0);
        // The top face, 1 m at 2 m, is 262 pixels wide: its outline is about 4 × 262 pixels on
        // each side of the edge, and every one of them flies.
        let flying = between(&render(1.0));
        assert!((1800..2400).contains(&flying), "{flying} flying pixels");
    }

    #[test]
    fn same_seed_and_frame_give_identical_frames() {
        let a = SimulatedDepthCamera::tabletop(42);
        let b = SimulatedDepthCamera::tabletop(42);
        assert_eq!(a.render_depth(5), b.render_depth(5));
        assert_ne!(a.render_depth(5), a.render_depth(6));
        assert_ne!(
            a.render_depth(5),
            SimulatedDepthCamera::tabletop(43).render_depth(5)
        );
        // The same through the DepthSource interface, apart from the capture time.
        let unpaced = |seed| {
            let mut camera = SimulatedDepthCamera::tabletop(seed);
            camera.config.rate_fps = None;
            camera
        };
        let (mut a, mut b) = (unpaced(42), unpaced(42));
        let a0 = depth_of(a.next_observation().unwrap());
        let b0 = depth_of(b.next_observation().unwrap());
        assert_eq!(a0.depth_m, b0.depth_m);
        let a1 = depth_of(a.next_observation().unwrap());
        assert_ne!(a0.depth_m, a1.depth_m);
        assert_eq!(a.frame_index(), 2);
        assert!(a1.capture_time > a0.capture_time);
    }

    /// The demo camera with `render_threads` threads.
    fn demo_camera_on(render_threads: usize) -> SimulatedDepthCamera {
        let mut file = SceneFile::demo();
        file.camera.render_threads = render_threads;
        file.into_camera().unwrap()
    }

    #[test]
    fn frames_do_not_depend_on_the_thread_count() {
        let single = demo_camera_on(1);
        let three = demo_camera_on(3);
        assert!(single.pool.is_none() && three.pool.is_some());
        // 0 counts as 1: the calling thread.
        assert!(demo_camera_on(0).pool.is_none());
        // Frame 200: the cone moving, the cylinder present.
        assert_eq!(single.render_depth(200), three.render_depth(200));
        assert_eq!(single.render_ids(200), three.render_ids(200));
        assert_eq!(single.visible_surface(200), three.visible_surface(200));
        // Nor on the pool they are called from.
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        assert_eq!(
            pool.install(|| single.render_depth(4)),
            three.render_depth(4)
        );
    }

    /// Frame `frame_index`'s (clean depth, object id) per pixel, cast from scratch through
    /// every object present, without the static cache.
    fn full_cast(camera: &SimulatedDepthCamera, frame_index: u64) -> Vec<(f32, Option<u32>)> {
        let all = camera.bvh.indexed_at(camera.scene_time_s(frame_index));
        let nothing = vec![SceneHit::NONE; camera.rays_in_sensor.len()];
        camera.cast_rays(&all, &nothing, |hit, _| {
            camera
                .ray_hit(hit)
                .map_or((0.0, None), |hit| (hit.time_of_impact, Some(hit.object_id)))
        })
    }

    /// Asserts that `camera`'s cached render of each frame equals a full cast: the same
    /// object at every pixel, at the same depth up to f32 rounding.
    fn assert_cache_matches_full_cast(camera: &SimulatedDepthCamera, frames: &[u64]) {
        for &frame in frames {
            let cached = camera.cast_frame(frame, |hit, _| {
                camera
                    .ray_hit(hit)
                    .map_or((0.0, None), |hit| (hit.time_of_impact, Some(hit.object_id)))
            });
            let full = full_cast(camera, frame);
            let mut exact = 0;
            for (i, (&(z, id), &(z_full, id_full))) in cached.iter().zip(&full).enumerate() {
                assert_eq!(id, id_full, "frame {frame}, pixel {i}");
                assert!(
                    (z - z_full).abs() <= 4.0 * f32::EPSILON * z_full,
                    "frame {frame}, pixel {i}: {z} vs {z_full}"
                );
                exact += usize::from(z == z_full);
            }
            assert!(
                exact > cached.len() * 99 / 100,
                "frame {frame}: {exact} exact"
            );
            // The public renders take the same path.
            let ids: Vec<Option<u32>> = full.iter().map(|&(_, id)| id).collect();
            assert_eq!(camera.render_ids(frame), ids, "frame {frame}");
        }
    }

    #[test]
    fn cached_static_render_equals_a_full_cast() {
        let camera = SceneFile::demo().into_camera().unwrap();
        // The static part is cast once: the table and the three still shapes.
        let mut cached_ids: Vec<u32> = camera
            .static_hits
            .iter()
            .filter_map(|&hit| camera.ray_hit(hit).map(|hit| hit.object_id))
            .collect();
        cached_ids.sort_unstable();
        cached_ids.dedup();
        assert_eq!(cached_ids, [0, 1, 2, 3]);
        // The cone sliding (it turns at 6 s = frame 180), the cylinder absent (before 5 s),
        // appearing (frame 150), present, leaving (20 s = frame 600) and gone; then the
        // second lap.
        let frames = [
            0,
            75,
            149,
            150,
            165,
            180,
            225,
            450,
            599,
            600,
            750,
            1080 + 160,
        ];
        for frame in frames {
            let ids = camera.render_ids(frame);
            assert!(ids.contains(&Some(4)), "frame {frame}: no cone");
            let cylinder = (150..600).contains(&(frame % 1080));
            assert_eq!(ids.contains(&Some(5)), cylinder, "frame {frame}: cylinder");
        }
        assert_cache_matches_full_cast(&camera, &frames);
    }

    #[test]
    fn cached_render_equals_a_full_cast_with_moving_objects_listed_first() {
        // The sliding cube before the floor and a fixed cube that it passes in front of (the
        // cube is 1 m tall, the fixed one 0.5 m below its top), and a fixed object that
        // appears late: not static, so cast every frame.
        use crate::{DynamicObject, Motion};
        let mut sliding = sliding_cube_camera().scene().clone();
        sliding.objects.reverse();
        sliding.objects.push(DynamicObject {
            id: 2,
            name: "low cube".into(),
            mesh: Shape::Cube.mesh(),
            motion: Motion::Fixed(Affine3A::from_translation(Vec3::new(0.3, 0.3, 0.0))),
            appear_s: None,
            leave_s: None,
        });
        sliding.objects.push(DynamicObject {
            id: 3,
            name: "late cube".into(),
            mesh: Shape::Cube.mesh(),
            motion: Motion::Fixed(Affine3A::from_translation(Vec3::new(-0.6, -0.8, 0.2))),
            appear_s: Some(1.0),
            leave_s: None,
        });
        let config = *sliding_cube_camera().config();
        let camera = SimulatedDepthCamera::new("test", sliding, config).unwrap();
        assert_cache_matches_full_cast(&camera, &[0, 5, 9, 10, 15, 20]);
    }

    #[test]
    fn gaussian_noise_has_zero_mean_and_the_configured_sigma() {
        let sigma_m = 0.01;
        let noise = DepthNoise {
            constant_sigma_m: Some(sigma_m),
            ..DepthNoise::NONE
        };
        let camera = floor_camera(1.0, noise);
        let (mut n, mut sum, mut sum_sq) = (0.0f64, 0.0f64, 0.0f64);
        for frame in 0..4 {
            for z in camera.render_depth(frame) {
                let e = f64::from(z) - 1.0;
                n += 1.0;
                sum += e;
                sum_sq += e * e;
            }
        }
        let mean = sum / n;
        let std = (sum_sq / n - mean * mean).sqrt();
        // 1.2 million pixels: the mean's standard error is 9 µm.
        assert!(mean.abs() < 5e-5, "mean {mean}");
        let ratio = std / f64::from(sigma_m);
        assert!(
            (ratio - 1.0).abs() < 0.03,
            "sigma {std}, {ratio} times the configured"
        );
    }

    #[test]
    fn standard_normal_follows_the_gaussian_to_three_sigma() {
        let key = frame_key(3, 7);
        let n = 1_000_000;
        let (mut sum, mut sum_sq) = (0.0f64, 0.0f64);
        let mut beyond = [0usize; 3];
        for pixel in 0..n {
            let draws = PixelDraws::new(key, pixel);
            let x = f64::from(standard_normal(draws.word(1), bits(draws.word(0), 0, 24)));
            sum += x;
            sum_sq += x * x;
            for (k, count) in beyond.iter_mut().enumerate() {
                *count += usize::from(x.abs() > (k + 1) as f64);
            }
        }
        let mean = sum / n as f64;
        let var = sum_sq / n as f64 - mean * mean;
        assert!(mean.abs() < 0.005, "mean {mean}");
        assert!((var - 1.0).abs() < 0.01, "variance {var}");
        // The Gaussian's two-sided tails beyond 1, 2 and 3 sigma.
        for (count, tail) in beyond.into_iter().zip([0.3173, 0.0455, 0.0027]) {
            let fraction = count as f64 / n as f64;
            assert!((fraction / tail - 1.0).abs() < 0.1, "{fraction} vs {tail}");
        }
    }

    #[test]
    fn draws_are_uniform_and_coin_flips_keep_their_probability() {
        let key = frame_key(0, 1);
        let n = 200_000;
        let coin = Chance::new(0.3);
        let (mut heads, mut sum) = (0usize, 0.0f64);
        for pixel in 0..n {
            let draws = PixelDraws::new(key, pixel);
            heads += usize::from(coin.happens(bits(draws.word(0), 48, 16)));
            sum += f64::from(unit_uniform(bits(draws.word(2), 0, 24)));
        }
        let rate = heads as f64 / n as f64;
        assert!((rate - 0.3).abs() < 0.005, "{rate}");
        assert!((sum / n as f64 - 0.5).abs() < 0.003);
        assert!(Chance::new(1.0).happens(u32::MAX) && !Chance::new(0.0).happens(0));
        assert_eq!(bits(0xabcd_0000_0000_0000, 48, 16), 0xabcd_0000);
    }

    #[test]
    fn tabletop_camera_sees_the_table_and_all_three_objects() {
        let camera = SimulatedDepthCamera::tabletop(0);
        assert_eq!(camera.name(), "sim:tabletop");
        let ids = camera.render_ids(0);
        let mut counts = [0usize; 4];
        for id in ids.iter().flatten() {
            counts[*id as usize] += 1;
        }
        // Each 0.2 m object at about 1.2 m covers thousands of pixels (the flat torus fewer).
        assert!(counts[0] > 100_000, "table pixels {counts:?}");
        for (id, &count) in counts.iter().enumerate().skip(1) {
            assert!(count > 1000, "object {id} barely visible: {counts:?}");
        }
    }

    #[test]
    fn deprojected_noiseless_frame_lies_on_the_scene() {
        let config = DepthCameraConfig {
            noise: DepthNoise::NONE,
            rate_fps: None,
            ..DepthCameraConfig::default()
        };
        let camera = SimulatedDepthCamera::new("test", Scene::tabletop(), config).unwrap();
        let frame = camera.render(0, Duration::ZERO);
        let bvh = camera.scene_bvh(0);
        let k = frame.intrinsics;
        let width = k.width as usize;
        let mut checked = 0;
        for (i, &z) in frame.depth_m.iter().enumerate() {
            if z == 0.0 {
                continue;
            }
            let p_in_sensor = z * k.ray((i % width) as f32, (i / width) as f32);
            let p_in_world = frame.world_from_sensor.transform_point3(p_in_sensor);
            let d = bvh.distance_to_surface(p_in_world);
            assert!(d < 1e-4, "pixel {i} at {p_in_world} is {d} m off the scene");
            checked += 1;
        }
        assert!(checked > 200_000, "only {checked} valid pixels");
    }

    #[test]
    fn surfaces_beyond_max_range_read_zero() {
        let config = DepthCameraConfig {
            max_range_m: 0.9,
            ..looking_down_from(1.0, DepthNoise::NONE)
        };
        let scene = Scene {
            objects: vec![floor()],
        };
        let camera = SimulatedDepthCamera::new("test", &scene, config).unwrap();
        assert!(camera.render_depth(0).iter().all(|&z| z == 0.0));
        assert!(camera.render_ids(0).iter().all(Option::is_none));
    }

    #[test]
    fn new_rejects_out_of_range_configuration() {
        let scene = Scene::default();
        let with = |change: fn(&mut DepthCameraConfig)| {
            let mut config = DepthCameraConfig::default();
            change(&mut config);
            SimulatedDepthCamera::new("test", &scene, config).err()
        };
        assert!(with(|_| {}).is_none());
        assert!(matches!(
            with(|c| c.noise.dropout_probability = 1.5),
            Some(DepthCameraError::InvalidNoise {
                field: "dropout_probability",
                ..
            })
        ));
        assert!(matches!(
            with(|c| c.intrinsics.width = 0),
            Some(DepthCameraError::InvalidIntrinsics { .. })
        ));
        assert!(matches!(
            with(|c| c.rate_fps = Some(0.0)),
            Some(DepthCameraError::InvalidRate { .. })
        ));
        assert!(matches!(
            with(|c| c.max_range_m = f32::NAN),
            Some(DepthCameraError::InvalidRange { .. })
        ));
        assert!(matches!(
            with(|c| c.world_from_sensor = Affine3A::ZERO),
            Some(DepthCameraError::InvalidPose { .. })
        ));
    }

    #[test]
    fn paced_camera_keeps_its_rate() {
        let mut camera = floor_camera(1.0, DepthNoise::NONE);
        camera.config.rate_fps = Some(50.0);
        let started = Instant::now();
        for _ in 0..4 {
            camera.next_observation().unwrap();
        }
        // Frames at 0, 20, 40, 60 ms: at least 60 ms (no upper bound: CI machines stall).
        assert!(started.elapsed() >= Duration::from_millis(60));
    }

    /// The floor and a 1 m cube that slides from x = -1 to x = 1 between 0 s and 2 s, seen
    /// from 3 m straight above at 10 fps without noise.
    fn sliding_cube_camera() -> SimulatedDepthCamera {
        use crate::{DynamicObject, Motion, PathMode, Waypoint};
        let at = |time_s, x| Waypoint {
            time_s,
            position: Vec3::new(x, 0.0, 0.5),
            yaw_deg: 0.0,
        };
        let mut scene = DynamicScene::from(Scene {
            objects: vec![floor()],
        });
        scene.objects.push(DynamicObject {
            id: 1,
            name: "cube".into(),
            mesh: Shape::Cube.mesh(),
            motion: Motion::Path {
                waypoints: vec![at(0.0, -1.0), at(2.0, 1.0)],
                mode: PathMode::Once,
            },
            appear_s: None,
            leave_s: None,
        });
        let config = DepthCameraConfig {
            fps: 10.0,
            ..looking_down_from(3.0, DepthNoise::NONE)
        };
        SimulatedDepthCamera::new("test", scene, config).unwrap()
    }

    /// The pixel that sees world point `p_in_world`.
    fn pixel_of(camera: &SimulatedDepthCamera, p_in_world: Vec3) -> usize {
        let config = camera.config();
        let p = config
            .world_from_sensor
            .inverse()
            .transform_point3(p_in_world);
        let k = config.intrinsics;
        let u = (k.fx * p.x / p.z + k.cx).round() as usize;
        let v = (k.fy * p.y / p.z + k.cy).round() as usize;
        v * k.width as usize + u
    }

    #[test]
    fn scene_time_is_frame_index_over_fps_wrapped_by_loop() {
        let camera = SceneFile::demo().into_camera().unwrap();
        assert_eq!(camera.scene_time_s(0), 0.0);
        assert_eq!(camera.scene_time_s(45), 1.5);
        // 30 fps and loop_s = 36: frame 1080 starts the second lap.
        assert_eq!(camera.scene_time_s(1080), 0.0);
        assert_eq!(camera.scene_time_s(1095), 0.5);
        assert_eq!(camera.scene_at(1095), camera.scene_at(15));
        let ids = |frame| {
            camera
                .scene_at(frame)
                .iter()
                .map(|o| o.id)
                .collect::<Vec<_>>()
        };
        assert_eq!(ids(0), [0, 1, 2, 3, 4]);
        assert_eq!(ids(300), [0, 1, 2, 3, 4, 5]);
        assert_eq!(ids(600), [0, 1, 2, 3, 4]);
        assert_eq!(ids(1080 + 300), [0, 1, 2, 3, 4, 5]);
    }

    #[test]
    fn moving_object_changes_depth_where_it_goes() {
        let camera = sliding_cube_camera();
        let left = pixel_of(&camera, Vec3::new(-1.0, 0.0, 1.0));
        let right = pixel_of(&camera, Vec3::new(1.0, 0.0, 1.0));
        let start = camera.render_depth(0);
        // The cube's top is at z = 1, 2 m below the camera; the floor 3 m.
        assert!((start[left] - 2.0).abs() < 1e-5, "{}", start[left]);
        assert!((start[right] - 3.0).abs() < 1e-5, "{}", start[right]);
        // At 1 s (frame 10) it is in the middle, at 2 s on the right.
        let middle = camera.render_depth(10);
        assert!((middle[left] - 3.0).abs() < 1e-5);
        assert!((middle[pixel_of(&camera, Vec3::new(0.0, 0.0, 1.0))] - 2.0).abs() < 1e-5);
        let end = camera.render_depth(20);
        assert!((end[left] - 3.0).abs() < 1e-5 && (end[right] - 2.0).abs() < 1e-5);
        // Only pixels the cube covers at one time or the other change.
        let ids_start = camera.render_ids(0);
        let ids_end = camera.render_ids(20);
        for (i, (a, b)) in start.iter().zip(&end).enumerate() {
            if a != b {
                assert!(
                    ids_start[i] == Some(1) || ids_end[i] == Some(1),
                    "pixel {i} changed without the cube"
                );
            }
        }
        assert_eq!(camera.render_ids(25), ids_end, "once: holds the last pose");
    }

    #[test]
    fn visible_surface_lies_on_the_true_posed_meshes() {
        let config = DepthCameraConfig {
            noise: DepthNoise::NONE,
            ..SceneFile::demo().camera
        };
        let camera = SimulatedDepthCamera::new("test", SceneFile::demo().scene, config).unwrap();
        // 7.5 s: the cone is on its way back, the cylinder present.
        for frame in [0, 225] {
            let truth = camera.scene_at(frame);
            let surface = camera.visible_surface(frame);
            let seen: Vec<u32> = surface.iter().map(|(id, _)| *id).collect();
            let expected: Vec<u32> = truth.iter().map(|o| o.id).collect();
            assert_eq!(seen, expected, "frame {frame}");
            for (id, points) in &surface {
                let object = truth.iter().find(|o| o.id == *id).unwrap();
                let object_from_world = object.world_from_object.inverse();
                let in_object: Vec<Vec3> = points
                    .iter()
                    .map(|&p| object_from_world.transform_point3(p))
                    .collect();
                let worst = crate::point_to_mesh_distances(&object.mesh, &in_object)
                    .unwrap()
                    .into_iter()
                    .fold(0.0f32, f32::max);
                assert!(worst < 1e-4, "frame {frame}, object {id}: {worst} m off");
            }
            // The same pixels the depth image has, at the same depths.
            let depth_m = camera.render_depth(frame);
            let valid = depth_m.iter().filter(|&&z| z > 0.0).count();
            let points: usize = surface.iter().map(|(_, p)| p.len()).sum();
            assert_eq!(valid, points);
        }
        // The cone moved between the two frames.
        let cone_at = |frame| {
            let objects = camera.scene_at(frame);
            let cone = objects.iter().find(|o| o.id == 4).unwrap();
            Vec3::from(cone.world_from_object.translation)
        };
        assert!((cone_at(225) - cone_at(0)).length() > 0.3);
    }

    #[test]
    fn culling_by_pixel_rectangles_keeps_every_hit() {
        let camera = SceneFile::demo().into_camera().unwrap();
        let frame = 225;
        let bvh = camera.scene_bvh(frame);
        let config = camera.config();
        let origin = Vec3::from(config.world_from_sensor.translation);
        let k = config.intrinsics;
        let ids = camera.render_ids(frame);
        for (i, id) in ids.iter().enumerate() {
            let ray = k.ray((i % k.width as usize) as f32, (i / k.width as usize) as f32);
            let dir = config.world_from_sensor.transform_vector3(ray);
            let unculled = bvh.cast_ray(origin, dir, config.max_range_m);
            assert_eq!(*id, unculled.map(|hit| hit.object_id), "pixel {i}");
        }
    }

    #[test]
    fn dynamic_frames_are_deterministic() {
        let a = SceneFile::demo().into_camera().unwrap();
        let b = SceneFile::demo().into_camera().unwrap();
        assert_eq!(a.render_depth(200), b.render_depth(200));
        assert_eq!(a.render_depth(200 + 900), a.render_depth(200 + 900));
        // Same scene (one loop later) but another frame index: other noise.
        assert_ne!(a.render_depth(200), a.render_depth(200 + 900));
    }

    #[test]
    fn set_paced_switches_between_real_time_and_as_fast_as_read() {
        let mut camera = SimulatedDepthCamera::tabletop(0);
        camera.set_paced(false);
        assert_eq!(camera.config().rate_fps, None);
        camera.set_paced(true);
        assert_eq!(camera.config().rate_fps, Some(camera.config().fps));
    }

    #[test]
    fn frames_are_stamped_on_the_host_monotonic_clock() {
        let mut camera = floor_camera(1.0, DepthNoise::NONE);
        let before = monotonic_now();
        let frame = depth_of(camera.next_observation().unwrap());
        let after = monotonic_now();
        assert!(before <= frame.capture_time && frame.capture_time <= after);
    }

    /// Not a test: prints the render time per frame of the demo scene (`scenes/demo.toml`,
    /// frames 150–179: scene time 5–6 s, the cone moving and the cylinder present) and of the
    /// static tabletop scene as its peer, on 1 and 2 render threads: the best of five runs of
    /// wall time, and on one thread also of the thread's CPU time (Linux
    /// `/proc/thread-self/schedstat`), which other processes queueing for the cores do not
    /// inflate. "Before" is the same frame cast from scratch through every object (no static
    /// cache), the same noise added. Run with
    /// `cargo test -p tacmesh-sim --release depth_camera_render_time -- --ignored --nocapture`.
    #[test]
    #[ignore = "benchmark, prints timings"]
    fn depth_camera_render_time() {
        /// CPU time of the calling thread, if the kernel reports it.
        fn thread_cpu_time() -> Option<Duration> {
            let stat = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
            let ns = stat.split_whitespace().next()?.parse().ok()?;
            Some(Duration::from_nanos(ns))
        }
        /// Best of five runs of 30 frames: (wall, CPU of the calling thread) per frame.
        fn best_per_frame<T>(render: impl Fn(u64) -> T) -> (Duration, Option<Duration>) {
            let frames = 30u64;
            render(150);
            let mut best = (Duration::MAX, None::<Duration>);
            for _ in 0..5 {
                let (started, cpu_started) = (Instant::now(), thread_cpu_time());
                for i in 150..150 + frames {
                    std::hint::black_box(render(i));
                }
                let wall = started.elapsed() / frames as u32;
                let cpu = cpu_started
                    .zip(thread_cpu_time())
                    .map(|(a, b)| (b - a) / frames as u32);
                best.0 = best.0.min(wall);
                best.1 = match (best.1, cpu) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
            }
            best
        }
        let fps = |d: Duration| 1.0 / d.as_secs_f64();
        let cpu_text = |cpu: Option<Duration>| {
            cpu.map_or(String::new(), |cpu| {
                format!(", CPU {cpu:?} ({:.0} fps)", fps(cpu))
            })
        };
        for threads in [1, 2] {
            let demo = demo_camera_on(threads);
            let tabletop = SimulatedDepthCamera::new(
                "sim:tabletop",
                Scene::tabletop(),
                DepthCameraConfig {
                    seed: 1,
                    render_threads: threads,
                    ..DepthCameraConfig::default()
                },
            )
            .unwrap();
            let mut demo_wall = Duration::ZERO;
            for (name, camera) in [("demo", &demo), ("tabletop", &tabletop)] {
                let (wall, cpu) = best_per_frame(|i| camera.render_depth(i));
                // Only the calling thread's CPU time is measured.
                let cpu = if threads == 1 {
                    cpu_text(cpu)
                } else {
                    String::new()
                };
                let (cast_only, _) = best_per_frame(|i| camera.render_ids(i));
                let ratio = if name == "demo" {
                    demo_wall = wall;
                    String::new()
                } else {
                    format!(
                        ", demo / tabletop = {:.2}",
                        demo_wall.as_secs_f64() / wall.as_secs_f64()
                    )
                };
                println!(
                    "{name:>8}, {threads} thread(s): wall {wall:?} ({:.0} fps) per 640x480 frame with noise{cpu}; {cast_only:?} ray casting only{ratio}",
                    fps(wall)
                );
            }
            if threads == 1 {
                let (before, before_cpu) = best_per_frame(|i| {
                    let clean_m: Vec<f32> =
                        full_cast(&demo, i).into_iter().map(|(z, _)| z).collect();
                    demo.add_noise(&clean_m, i)
                });
                let (before_cast, _) = best_per_frame(|i| full_cast(&demo, i));
                println!(
                    "  before, 1 thread(s): wall {before:?} ({:.0} fps) per demo frame cast from scratch{}; {before_cast:?} ray casting only; after / before = {:.2}",
                    fps(before),
                    cpu_text(before_cpu),
                    demo_wall.as_secs_f64() / before.as_secs_f64()
                );
            }
        }
    }
}
