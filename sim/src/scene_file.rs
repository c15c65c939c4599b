//! Scene files: a simulated camera and a moving scene described in strict TOML.
//!
//! Entry points:
//! - [`SceneFile::load`] (a path) or [`SceneFile::parse`] (text) → [`SceneFile`]: the
//!   [`DynamicScene`] and the [`DepthCameraConfig`]; [`SceneFile::into_camera`] makes the
//!   [`SimulatedDepthCamera`].
//! - [`SceneFile::demo`]: `scenes/demo.toml`, embedded, the daemon's default scene.
//!
//! The format is documented key by key in `scenes/demo.toml`. In short:
//!
//! ```toml
//! loop_s = 36.0                     # optional: scene time wraps to t mod loop_s
//! [camera]                          # every key optional
//! width = 640                       # also height, fx, fy, cx, cy (pixels)
//! fps = 30.0                        # frame k shows scene time k / fps
//! paced = true                      # deliver at fps of wall-clock time, or as fast as read
//! eye = [0.0, -0.85, 0.85]          # with target (and up, default +Z): the pose by look_at
//! target = [0.0, 0.0, 0.0]
//! max_range_m = 4.0
//! seed = 0
//! [camera.noise]                    # k_z2 (sigma = k·z²) or constant_sigma_m, not both
//! k_z2 = 0.001
//! [table]                           # absent: no table
//! size_m = 2.0                      # side of the square top
//! height_m = 0.0                    # z of the top
//! [[object]]
//! id = 1                            # unique, >= 1 (the table is 0)
//! shape = "cube"                    # or mesh = "mug.ply", relative to this file
//! size_m = 0.2                      # largest bounding-box side
//! position = [-0.3, 0.0]            # [x, y] rests on the table; [x, y, z] puts the bottom at z
//! yaw_deg = 0.0
//! [object.path]                     # instead of position: waypoints
//! mode = "pingpong"                 # once | loop | pingpong
//! waypoints = [{ time_s = 0.0, position = [0.0, 0.3] }, { time_s = 4.0, position = [0.4, 0.3] }]
//! [[fault]]                         # optional, repeatable: an injected sensor fault
//! kind = "zeros"                    # error, disconnect, wrong_size, zeros, nan, absurd_intrinsics, stall
//! at_frame = 90                     # the first frame index affected (from 0)
//! frames = 10                       # how many frames, default 1
//! ```
//!
//! Placement rule: an object's frame has its origin at the centre of the bottom face of its
//! bounding box (the mesh is fitted to `size_m` if given, then moved so), and `position` (or a
//! waypoint's) is where that origin goes. A two-element position puts it at the table's
//! height (z = 0 without a table), so the object rests on the table; a three-element one gives
//! z explicitly. Yaw turns the object about its vertical axis through that origin.
//!
//! Errors name the file; syntax and type errors (unknown keys among them) carry toml's line
//! and column; validation errors name the object by id, name and line.
//!
//! Layout: the public types, then the raw TOML schema, then raw → camera, table, objects.

use std::collections::HashMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Vec3};
use serde::Deserialize;
use tacmesh_formats::FormatError;
use tacmesh_source::{Intrinsics, TriMesh};

use crate::depth_camera::check_config;
use crate::{
    check_faults, check_mesh, fit_to_extent, look_at, DepthCameraConfig, DepthCameraError,
    DepthNoise, DynamicObject, DynamicScene, Fault, FaultKind, Motion, PathMode, Shape,
    SimulatedDepthCamera, Waypoint, DEFAULT_INTRINSICS, TABLETOP_OBJECT_EXTENT_M,
    TABLETOP_TABLE_SIDE_M,
};

/// The text of `scenes/demo.toml`, the daemon's default scene.
pub const DEMO_SCENE_TOML: &str = include_str!("../../scenes/demo.toml");

/// A parsed and validated scene file.
#[derive(Debug, Clone, PartialEq)]
pub struct SceneFile {
    /// The file's stem (`demo` for `scenes/demo.toml`), for the camera's name.
    pub name: String,
    pub scene: DynamicScene,
    pub camera: DepthCameraConfig,
    /// Injected sensor faults (`[[fault]]`), none in a normal scene.
    pub faults: Vec<Fault>,
}

/// Why a scene file could not be used. Every message starts with the file.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum SceneFileError {
    #[error("cannot read scene file {}: {cause}", file.display())]
    Read {
        file: PathBuf,
        cause: std::io::Error,
    },

    /// Not TOML, a key the format does not have, or a value of the wrong type. toml's message
    /// gives the line and column.
    #[error("{file}: {message}")]
    Syntax { file: String, message: String },

    #[error("{file}: [camera]: {reason}")]
    Camera { file: String, reason: String },

    #[error("{file}: [table]: {reason}")]
    Table { file: String, reason: String },

    #[error("{file}: {reason}")]
    Scene { file: String, reason: String },

    #[error("{file}:{line}: [[fault]]: {reason}")]
    Fault {
        file: String,
        line: usize,
        reason: String,
    },

    #[error("{file}:{line}: object {id} ({name}): {reason}")]
    Object {
        file: String,
        line: usize,
        id: u32,
        name: String,
        reason: String,
    },

    #[error("{file}:{line}: object {id} ({name}): cannot load mesh = \"{mesh}\" (relative to the scene file's directory)")]
    Mesh {
        file: String,
        line: usize,
        id: u32,
        name: String,
        mesh: String,
        #[source]
        source: Box<FormatError>,
    },
}

/// The largest scene file read: 16 MiB of TOML (the demo's is 3 kB).
pub const MAX_SCENE_FILE_BYTES: u64 = 16 << 20;

impl SceneFile {
    /// Reads and parses the scene file at `path`; mesh paths are relative to its directory.
    pub fn load(path: impl AsRef<Path>) -> Result<SceneFile, SceneFileError> {
        let path = path.as_ref();
        let text =
            tacmesh_source::read_regular_text(path, MAX_SCENE_FILE_BYTES).map_err(|cause| {
                SceneFileError::Read {
                    file: path.to_owned(),
                    cause,
                }
            })?;
        let base_dir = path.parent().unwrap_or(Path::new("."));
        SceneFile::parse(&text, base_dir, &path.display().to_string())
    }

    /// Parses scene-file text. Mesh paths are resolved against `base_dir`;
    /// `name_for_errors` (normally the file's path) starts every error message, and its stem
    /// becomes [`SceneFile::name`].
    pub fn parse(
        text: &str,
        base_dir: &Path,
        name_for_errors: &str,
    ) -> Result<SceneFile, SceneFileError> {
        let file = name_for_errors.to_owned();
        let raw: RawFile = toml::from_str(text).map_err(|err| SceneFileError::Syntax {
            file: file.clone(),
            message: err.to_string().trim_end().to_owned(),
        })?;
        let context = Context {
            file: &file,
            text,
            base_dir,
        };
        let camera = context.camera(&raw.camera)?;
        let table = raw
            .table
            .as_ref()
            .map(|table| context.table(table))
            .transpose()?;
        let table_height_m = table.as_ref().map_or(0.0, |(_, height_m)| *height_m);
        let mut objects: Vec<DynamicObject> = table.into_iter().map(|(table, _)| table).collect();
        let mut lines_by_id: HashMap<u32, usize> = HashMap::new();
        for raw_object in &raw.objects {
            let object = context.object(raw_object, table_height_m)?;
            let line = context.line(raw_object.span());
            if let Some(first_line) = lines_by_id.insert(object.id, line) {
                return Err(context.object_error(
                    raw_object,
                    &object.name,
                    format!("id {} is already used by the object at line {first_line}: give every object its own id", object.id),
                ));
            }
            objects.push(object);
        }
        if let Some(loop_s) = raw.loop_s {
            if !(loop_s.is_finite() && loop_s > 0.0) {
                return Err(SceneFileError::Scene {
                    file,
                    reason: format!("loop_s must be a finite number of seconds > 0 (or absent not to loop), got {loop_s}"),
                });
            }
        }
        let faults = context.faults(&raw.faults)?;
        let name = Path::new(name_for_errors)
            .file_stem()
            .map_or_else(|| "scene".to_owned(), |s| s.to_string_lossy().into_owned());
        Ok(SceneFile {
            name,
            scene: DynamicScene {
                objects,
                loop_s: raw.loop_s,
            },
            camera,
            faults,
        })
    }

    /// `scenes/demo.toml` (embedded at build time, so it works from any working directory):
    /// a table, three static shapes, a cone sliding back and forth and a cylinder that comes
    /// and goes, seen at 640×480 and 30 fps in real time.
    pub fn demo() -> SceneFile {
        match SceneFile::parse(DEMO_SCENE_TOML, Path::new("."), "scenes/demo.toml") {
            Ok(file) => file,
            // The embedded file is valid; `demo_scene_parses_and_makes_a_camera` pins this.
            Err(err) => unreachable!("the embedded demo scene is invalid: {err}"),
        }
    }

    /// The camera this file describes, named `sim:<name>`. Fails only if the public fields
    /// were changed into something invalid after parsing.
    pub fn into_camera(self) -> Result<SimulatedDepthCamera, DepthCameraError> {
        let mut camera =
            SimulatedDepthCamera::new(format!("sim:{}", self.name), self.scene, self.camera)?;
        camera.set_faults(self.faults)?;
        Ok(camera)
    }
}

// -- the raw TOML schema --------------------------------------------------------------------------

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFile {
    loop_s: Option<f32>,
    #[serde(default)]
    camera: RawCamera,
    table: Option<RawTable>,
    #[serde(default, rename = "object")]
    objects: Vec<toml::Spanned<RawObject>>,
    #[serde(default, rename = "fault")]
    faults: Vec<toml::Spanned<RawFault>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFault {
    kind: String,
    at_frame: u64,
    frames: Option<u64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCamera {
    width: Option<u32>,
    height: Option<u32>,
    fx: Option<f32>,
    fy: Option<f32>,
    cx: Option<f32>,
    cy: Option<f32>,
    fps: Option<f32>,
    paced: Option<bool>,
    eye: Option<[f32; 3]>,
    target: Option<[f32; 3]>,
    up: Option<[f32; 3]>,
    max_range_m: Option<f32>,
    seed: Option<u64>,
    #[serde(default)]
    noise: RawNoise,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    k_z2: Option<f32>,
    constant_sigma_m: Option<f32>,
    dropout_probability: Option<f32>,
    flying_pixel_probability: Option<f32>,
    flying_pixel_edge_m: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTable {
    size_m: Option<f32>,
    height_m: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObject {
    id: u32,
    name: Option<String>,
    shape: Option<String>,
    mesh: Option<String>,
    size_m: Option<f32>,
    position: Option<Vec<f32>>,
    yaw_deg: Option<f32>,
    path: Option<RawPath>,
    appear_s: Option<f32>,
    leave_s: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPath {
    #[serde(default)]
    mode: RawPathMode,
    waypoints: Vec<RawWaypoint>,
}

#[derive(Debug, Default, Clone, Copy, Deserialize)]
#[serde(rename_all = "lowercase")]
enum RawPathMode {
    #[default]
    Once,
    Loop,
    PingPong,
}

impl From<RawPathMode> for PathMode {
    fn from(mode: RawPathMode) -> Self {
        match mode {
            RawPathMode::Once => PathMode::Once,
            RawPathMode::Loop => PathMode::Loop,
            RawPathMode::PingPong => PathMode::PingPong,
        }
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWaypoint {
    time_s: f32,
    position: Vec<f32>,
    yaw_deg: Option<f32>,
}

// -- raw → camera, table, objects ------------------------------------------------------------------

/// The file being parsed, for error messages and mesh paths.
struct Context<'a> {
    file: &'a str,
    text: &'a str,
    base_dir: &'a Path,
}

impl Context<'_> {
    /// The 1-based line of a byte offset range's start.
    fn line(&self, span: Range<usize>) -> usize {
        let start = span.start.min(self.text.len());
        1 + self.text.as_bytes()[..start]
            .iter()
            .filter(|&&b| b == b'\n')
            .count()
    }

    fn object_error(
        &self,
        raw: &toml::Spanned<RawObject>,
        name: &str,
        reason: impl Into<String>,
    ) -> SceneFileError {
        SceneFileError::Object {
            file: self.file.to_owned(),
            line: self.line(raw.span()),
            id: raw.get_ref().id,
            name: name.to_owned(),
            reason: reason.into(),
        }
    }

    fn camera(&self, raw: &RawCamera) -> Result<DepthCameraConfig, SceneFileError> {
        let fail = |reason: String| SceneFileError::Camera {
            file: self.file.to_owned(),
            reason,
        };
        let defaults = DepthCameraConfig::default();
        let width = raw.width.unwrap_or(DEFAULT_INTRINSICS.width);
        let height = raw.height.unwrap_or(DEFAULT_INTRINSICS.height);
        // The default focal length keeps the default field of view at any width.
        let default_f = DEFAULT_INTRINSICS.fx * width as f32 / DEFAULT_INTRINSICS.width as f32;
        let intrinsics = Intrinsics {
            width,
            height,
            fx: raw.fx.unwrap_or(default_f),
            fy: raw.fy.unwrap_or(default_f),
            cx: raw.cx.unwrap_or(0.5 * (width as f32 - 1.0)),
            cy: raw.cy.unwrap_or(0.5 * (height as f32 - 1.0)),
        };
        let world_from_sensor = match (raw.eye, raw.target) {
            (None, None) if raw.up.is_none() => DepthCameraConfig::tabletop_pose(),
            (Some(eye), Some(target)) => {
                let (eye, target) = (Vec3::from(eye), Vec3::from(target));
                let up = raw.up.map_or(Vec3::Z, Vec3::from);
                let pose = look_at(eye, target, up);
                if !pose.is_finite() {
                    return Err(fail(format!(
                        "eye {eye} must differ from target {target}, and up {up} must not point along the view direction"
                    )));
                }
                pose
            }
            _ => {
                return Err(fail(
                    "give both eye and target (and optionally up), or none of them for the default pose".into(),
                ))
            }
        };
        let noise = self.noise(&raw.noise).map_err(fail)?;
        let fps = raw.fps.unwrap_or(defaults.fps);
        let config = DepthCameraConfig {
            intrinsics,
            world_from_sensor,
            noise,
            max_range_m: raw.max_range_m.unwrap_or(defaults.max_range_m),
            seed: raw.seed.unwrap_or(defaults.seed),
            fps,
            rate_fps: raw.paced.unwrap_or(true).then_some(fps),
            render_threads: defaults.render_threads,
        };
        check_config(&config).map_err(|err| fail(err.to_string()))?;
        Ok(config)
    }

    fn noise(&self, raw: &RawNoise) -> Result<DepthNoise, String> {
        let defaults = DepthNoise::default();
        if raw.k_z2.is_some() && raw.constant_sigma_m.is_some() {
            return Err("[camera.noise] takes k_z2 (sigma = k·z²) or constant_sigma_m, not both: remove one".into());
        }
        Ok(DepthNoise {
            sigma_at_1m_m: raw.k_z2.unwrap_or(defaults.sigma_at_1m_m),
            constant_sigma_m: raw.constant_sigma_m,
            dropout_probability: raw
                .dropout_probability
                .unwrap_or(defaults.dropout_probability),
            flying_pixel_probability: raw
                .flying_pixel_probability
                .unwrap_or(defaults.flying_pixel_probability),
            flying_pixel_edge_m: raw
                .flying_pixel_edge_m
                .unwrap_or(defaults.flying_pixel_edge_m),
        })
    }

    /// The table (object 0, a square facing +Z) and the height of its top.
    fn table(&self, raw: &RawTable) -> Result<(DynamicObject, f32), SceneFileError> {
        let size_m = raw.size_m.unwrap_or(TABLETOP_TABLE_SIDE_M);
        let height_m = raw.height_m.unwrap_or(0.0);
        if !(size_m.is_finite() && size_m > 0.0 && height_m.is_finite()) {
            return Err(SceneFileError::Table {
                file: self.file.to_owned(),
                reason: format!("size_m must be a finite number of metres > 0 and height_m finite, got size_m {size_m} and height_m {height_m}"),
            });
        }
        let mesh = crate::shapes::square(size_m);
        let table = DynamicObject {
            id: 0,
            name: "table".into(),
            mesh,
            motion: Motion::Fixed(Affine3A::from_translation(Vec3::new(0.0, 0.0, height_m))),
            appear_s: None,
            leave_s: None,
        };
        Ok((table, height_m))
    }

    fn object(
        &self,
        spanned: &toml::Spanned<RawObject>,
        table_height_m: f32,
    ) -> Result<DynamicObject, SceneFileError> {
        let raw = spanned.get_ref();
        let name = match (&raw.name, &raw.shape, &raw.mesh) {
            (Some(name), _, _) => name.clone(),
            (None, Some(shape), _) => shape.clone(),
            (None, None, Some(mesh)) => mesh.clone(),
            (None, None, None) => "unnamed".into(),
        };
        let fail = |reason: String| self.object_error(spanned, &name, reason);
        if raw.id == 0 {
            return Err(fail("id 0 is the table's: number objects from 1".into()));
        }
        let mut mesh = match (&raw.shape, &raw.mesh) {
            (Some(shape), None) => {
                let shape = Shape::from_name(shape).ok_or_else(|| {
                    let known: Vec<&str> = Shape::ALL.iter().map(|s| s.name()).collect();
                    fail(format!(
                        "unknown shape \"{shape}\": use one of {}, or mesh = \"file.ply\"",
                        known.join(", ")
                    ))
                })?;
                shape.mesh()
            }
            (None, Some(mesh_path)) => {
                let path = self.base_dir.join(mesh_path);
                tacmesh_formats::read_mesh(&path).map_err(|source| SceneFileError::Mesh {
                    file: self.file.to_owned(),
                    line: self.line(spanned.span()),
                    id: raw.id,
                    name: name.clone(),
                    mesh: mesh_path.clone(),
                    source: Box::new(source),
                })?
            }
            _ => {
                return Err(fail(
                    "give exactly one of shape = \"<name>\" or mesh = \"<file>\"".into(),
                ))
            }
        };
        check_mesh(&mesh).map_err(|err| fail(format!("unusable mesh: {err}")))?;
        let size_m = match (raw.size_m, &raw.shape) {
            (Some(size_m), _) => Some(size_m),
            (None, Some(_)) => Some(TABLETOP_OBJECT_EXTENT_M),
            (None, None) => None,
        };
        if let Some(size_m) = size_m {
            if !(size_m.is_finite() && size_m > 0.0) {
                return Err(fail(format!(
                    "size_m must be a finite number of metres > 0, got {size_m}"
                )));
            }
        }
        rest_on_origin(&mut mesh, size_m);

        let yaw_deg = raw.yaw_deg.unwrap_or(0.0);
        let place = |position: &[f32]| -> Result<Vec3, String> {
            match *position {
                [x, y] => Ok(Vec3::new(x, y, table_height_m)),
                [x, y, z] => Ok(Vec3::new(x, y, z)),
                _ => Err(format!(
                    "a position is [x, y] (resting on the table) or [x, y, z] metres, got {} numbers",
                    position.len()
                )),
            }
        };
        let motion = match (&raw.path, &raw.position) {
            (Some(_), Some(_)) => {
                return Err(fail(
                    "give position or path, not both: the path's waypoints place the object".into(),
                ))
            }
            (Some(path), None) => {
                let waypoints = path
                    .waypoints
                    .iter()
                    .map(|w| {
                        Ok(Waypoint {
                            time_s: w.time_s,
                            position: place(&w.position)?,
                            yaw_deg: w.yaw_deg.unwrap_or(yaw_deg),
                        })
                    })
                    .collect::<Result<Vec<_>, String>>()
                    .map_err(&fail)?;
                Motion::Path {
                    waypoints,
                    mode: path.mode.into(),
                }
            }
            (None, position) => {
                let position = place(position.as_deref().unwrap_or(&[0.0, 0.0])).map_err(&fail)?;
                Motion::Fixed(
                    Waypoint {
                        time_s: 0.0,
                        position,
                        yaw_deg,
                    }
                    .world_from_object(),
                )
            }
        };
        motion.check().map_err(&fail)?;
        let finite = |t: Option<f32>| t.is_none_or(f32::is_finite);
        let ordered = match (raw.appear_s, raw.leave_s) {
            (Some(appear_s), Some(leave_s)) => appear_s < leave_s,
            _ => true,
        };
        if !(finite(raw.appear_s) && finite(raw.leave_s) && ordered) {
            return Err(fail(format!(
                "appear_s must come before leave_s, both finite seconds, got appear_s {:?} and leave_s {:?}",
                raw.appear_s, raw.leave_s
            )));
        }
        Ok(DynamicObject {
            id: raw.id,
            name,
            mesh,
            motion,
            appear_s: raw.appear_s,
            leave_s: raw.leave_s,
        })
    }
}

impl Context<'_> {
    /// The `[[fault]]` tables, in file order, checked for unknown kinds, empty windows and
    /// overlaps.
    fn faults(&self, raw: &[toml::Spanned<RawFault>]) -> Result<Vec<Fault>, SceneFileError> {
        let fail = |spanned: &toml::Spanned<RawFault>, reason: String| SceneFileError::Fault {
            file: self.file.to_owned(),
            line: self.line(spanned.span()),
            reason,
        };
        let mut faults = Vec::with_capacity(raw.len());
        for spanned in raw {
            let fault = spanned.get_ref();
            let kind = FaultKind::from_name(&fault.kind).ok_or_else(|| {
                let known: Vec<&str> = FaultKind::ALL.iter().map(|k| k.name()).collect();
                fail(
                    spanned,
                    format!(
                        "unknown kind \"{}\": use one of {}",
                        fault.kind,
                        known.join(", ")
                    ),
                )
            })?;
            faults.push(Fault {
                kind,
                at_frame: fault.at_frame,
                frames: fault.frames.unwrap_or(1),
            });
            // Checked as they come, so that the error names the table that broke the rule.
            check_faults(&faults).map_err(|reason| fail(spanned, reason))?;
        }
        Ok(faults)
    }
}

/// Fits `mesh` to `size_m` (largest bounding-box side) if given, keeping its scale otherwise,
/// and moves it so the centre of its bounding box's bottom face is the origin.
fn rest_on_origin(mesh: &mut TriMesh, size_m: Option<f32>) {
    if let Some(size_m) = size_m {
        fit_to_extent(mesh, size_m);
    }
    let Some((lo, hi)) = mesh.bounds() else {
        return;
    };
    let bottom_centre = Vec3::new(0.5 * (lo.x + hi.x), 0.5 * (lo.y + hi.y), lo.z);
    for v in &mut mesh.vertices {
        *v -= bottom_centre;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scenes_dir() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
    }

    fn parse(text: &str) -> Result<SceneFile, SceneFileError> {
        SceneFile::parse(text, &scenes_dir(), "test.toml")
    }

    fn error(text: &str) -> String {
        match parse(text) {
            Ok(file) => panic!("parsed: {file:?}"),
            Err(err) => {
                // The whole chain, as a log line would show it.
                let mut message = err.to_string();
                let mut source = std::error::Error::source(&err);
                while let Some(cause) = source {
                    message += &format!(": {cause}");
                    source = cause.source();
                }
                message
            }
        }
    }

    #[test]
    fn every_shipped_scene_parses() {
        let mut checked = 0;
        for entry in std::fs::read_dir(scenes_dir()).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let file = SceneFile::load(&path).unwrap_or_else(|err| panic!("{err}"));
                assert!(!file.scene.objects.is_empty(), "{}", path.display());
                file.into_camera().unwrap();
                checked += 1;
            }
        }
        assert!(checked >= 2, "only {checked} scene files");
    }

    #[test]
    fn demo_scene_parses_and_makes_a_camera() {
        let demo = SceneFile::demo();
        assert_eq!(
            demo,
            SceneFile::load(scenes_dir().join("demo.toml")).unwrap()
        );
        assert_eq!(demo.name, "demo");
        assert_eq!(demo.scene.loop_s, Some(36.0));
        assert_eq!(demo.camera.fps, 30.0);
        assert_eq!(demo.camera.rate_fps, Some(30.0));
        assert_eq!(demo.camera.intrinsics, DEFAULT_INTRINSICS);
        assert_eq!(demo.camera.noise, DepthNoise::default());
        let ids: Vec<u32> = demo.scene.objects.iter().map(|o| o.id).collect();
        assert_eq!(ids, [0, 1, 2, 3, 4, 5]);
        // The cone slides at 0.1 m/s; the cylinder is there from 5 s to 20 s only.
        let cone_x = |t_s| {
            demo.scene.objects[4]
                .motion
                .world_from_object_at(t_s)
                .translation
                .x
        };
        assert!((cone_x(2.0) - cone_x(1.0) - 0.1).abs() < 1e-5);
        assert!((cone_x(7.0) - cone_x(6.0) + 0.1).abs() < 1e-5);
        let present = |t_s| demo.scene.objects_at(t_s).iter().any(|o| o.id == 5);
        assert!(!present(4.9) && present(5.0) && present(19.9) && !present(20.0));
        let wrapped = demo.scene.wrap_time_s(41.0);
        assert!(
            present(wrapped),
            "loop_s brings it back (t 41 s -> {wrapped} s)"
        );
        // The wrap is a whole number of the cone's 12 s round trips: no jump.
        assert!((cone_x(demo.scene.wrap_time_s(36.0)) - cone_x(0.0)).abs() < 1e-6);
        let camera = demo.into_camera().unwrap();
        assert_eq!(tacmesh_source::DepthSource::name(&camera), "sim:demo");
    }

    #[test]
    fn objects_rest_on_the_table_unless_z_is_given() {
        let file = parse(
            "[table]\nheight_m = 0.5\n\
             [[object]]\nid = 1\nshape = \"sphere\"\nsize_m = 0.3\nposition = [0.1, 0.2]\nyaw_deg = 30\n\
             [[object]]\nid = 2\nshape = \"cube\"\nposition = [0.0, 0.0, 1.0]\n",
        )
        .unwrap();
        let objects = file.scene.objects_at(0.0);
        let world_bounds = |i: usize| {
            let o = &objects[i];
            let points: Vec<Vec3> = o
                .mesh
                .vertices
                .iter()
                .map(|&p| o.world_from_object.transform_point3(p))
                .collect();
            tacmesh_source::PointCloud::new(points).bounds().unwrap()
        };
        let (lo, hi) = world_bounds(1);
        assert!((lo.z - 0.5).abs() < 1e-6, "{lo}");
        assert!(((hi.z - lo.z) - 0.3).abs() < 1e-5);
        let centre = 0.5 * (lo + hi);
        assert!(centre.truncate().distance(glam::Vec2::new(0.1, 0.2)) < 1e-3);
        // The cube defaults to 0.2 m; its bottom at the explicit z.
        let (lo, hi) = world_bounds(2);
        assert!((lo.z - 1.0).abs() < 1e-6 && (hi.z - 1.2).abs() < 1e-6);
    }

    #[test]
    fn mesh_paths_are_relative_to_the_scene_file() {
        let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("assets");
        let text = "[[object]]\nid = 3\nmesh = \"suzanne.obj\"\nsize_m = 0.25\n";
        let file = SceneFile::parse(text, &assets, "assets/monkeys.toml").unwrap();
        let monkey = &file.scene.objects[0];
        assert_eq!(monkey.name, "suzanne.obj");
        let (lo, hi) = monkey.mesh.bounds().unwrap();
        assert!(((hi - lo).max_element() - 0.25).abs() < 1e-5);
        // No table: resting on z = 0, the origin at the bottom's centre.
        assert!(lo.z.abs() < 1e-6 && (lo.x + hi.x).abs() < 1e-5);
    }

    #[test]
    fn missing_mesh_file_names_the_path() {
        let message = error("[[object]]\nid = 3\nname = \"mug\"\nmesh = \"meshes/mug.ply\"\n");
        assert!(
            message.starts_with("test.toml:1: object 3 (mug)"),
            "{message}"
        );
        assert!(message.contains("mesh = \"meshes/mug.ply\""), "{message}");
        // The resolved path, from the reader's error.
        assert!(message.contains("scenes/meshes/mug.ply"), "{message}");
    }

    #[test]
    fn unknown_key_is_named_with_its_line() {
        let message = error("[camera]\nfps = 30.0\nwdth = 640\n");
        assert!(message.starts_with("test.toml: "), "{message}");
        assert!(message.contains("wdth"), "{message}");
        assert!(message.contains("line 3"), "{message}");
        let message = error("[[object]]\nid = 1\nshape = \"cube\"\nspeed = 2\n");
        assert!(
            message.contains("speed") && message.contains("line 4"),
            "{message}"
        );
    }

    #[test]
    fn duplicate_id_names_both_objects() {
        let message =
            error("[[object]]\nid = 1\nshape = \"cube\"\n\n[[object]]\nid = 1\nshape = \"cone\"\n");
        assert!(
            message.starts_with("test.toml:5: object 1 (cone)"),
            "{message}"
        );
        assert!(
            message.contains("already used by the object at line 1"),
            "{message}"
        );
    }

    #[test]
    fn unknown_shape_lists_the_known_ones() {
        let message = error("[[object]]\nid = 2\nshape = \"teapot\"\n");
        assert!(message.contains("object 2 (teapot)"), "{message}");
        assert!(message.contains("unknown shape \"teapot\""), "{message}");
        assert!(message.contains("cube"), "{message}");
    }

    #[test]
    fn invalid_objects_are_named() {
        let cases = [
            ("id = 0\nshape = \"cube\"", "id 0 is the table's"),
            ("id = 1", "exactly one of shape"),
            ("id = 1\nshape = \"cube\"\nmesh = \"a.ply\"", "exactly one of shape"),
            ("id = 1\nshape = \"cube\"\nsize_m = -1", "size_m"),
            ("id = 1\nshape = \"cube\"\nposition = [1.0]", "[x, y]"),
            ("id = 1\nshape = \"cube\"\nappear_s = 5\nleave_s = 2", "appear_s"),
            (
                "id = 1\nshape = \"cube\"\nposition = [0.0, 0.0]\npath = { waypoints = [{ time_s = 0, position = [0, 0] }] }",
                "position or path",
            ),
            (
                "id = 1\nshape = \"cube\"\npath = { waypoints = [{ time_s = 1, position = [0, 0] }, { time_s = 1, position = [1, 0] }] }",
                "strictly increase",
            ),
        ];
        for (object, expected) in cases {
            let message = error(&format!("[[object]]\n{object}\n"));
            assert!(message.contains("object "), "{message}");
            assert!(message.contains(expected), "{object}: {message}");
        }
        let message = error(
            "[[object]]\nid = 1\nshape = \"cube\"\npath = { mode = \"bounce\", waypoints = [] }\n",
        );
        assert!(message.contains("bounce"), "{message}");
    }

    #[test]
    fn camera_and_noise_settings_are_read() {
        let file = parse(
            "loop_s = 12.0\n[camera]\nwidth = 320\nheight = 240\nfps = 15\npaced = false\n\
             eye = [0.0, 0.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nup = [0.0, 1.0, 0.0]\nseed = 7\n\
             [camera.noise]\nconstant_sigma_m = 0.02\ndropout_probability = 0.0\n",
        )
        .unwrap();
        let camera = file.camera;
        assert_eq!(camera.intrinsics.width, 320);
        // Same field of view as the default at half the width.
        assert_eq!(camera.intrinsics.fx, 262.5);
        assert_eq!((camera.intrinsics.cx, camera.intrinsics.cy), (159.5, 119.5));
        assert_eq!((camera.fps, camera.rate_fps, camera.seed), (15.0, None, 7));
        assert_eq!(camera.noise.constant_sigma_m, Some(0.02));
        assert_eq!(camera.noise.dropout_probability, 0.0);
        assert_eq!(
            Vec3::from(camera.world_from_sensor.translation),
            Vec3::new(0.0, 0.0, 2.0)
        );
        assert_eq!(file.scene.loop_s, Some(12.0));
        assert!(file.scene.objects.is_empty(), "no [table], no objects");

        let both = error("[camera.noise]\nk_z2 = 0.001\nconstant_sigma_m = 0.02\n");
        assert!(both.contains("not both"), "{both}");
        let eye_only = error("[camera]\neye = [0.0, 0.0, 1.0]\n");
        assert!(
            eye_only.contains("[camera]") && eye_only.contains("target"),
            "{eye_only}"
        );
        let bad_fps = error("[camera]\nfps = 0\n");
        assert!(bad_fps.contains("fps"), "{bad_fps}");
        // A rate whose frame period overflows `Duration` (it once aborted the daemon), and a
        // camera whose image would take gigabytes, are refused with the range.
        for fps in ["1e-30", "1e30", "inf", "nan"] {
            let paced = error(&format!("[camera]\nfps = {fps}\n"));
            assert!(paced.contains("fps must be from"), "{fps}: {paced}");
        }
        let huge = error("[camera]\nwidth = 100000\nheight = 100000\n");
        assert!(huge.contains("100000x100000"), "{huge}");
        assert!(huge.contains("4096x4096"), "{huge}");
        let tall = error("[camera]\nwidth = 1\nheight = 20000\n");
        assert!(tall.contains("a side"), "{tall}");
        let bad_loop = error("loop_s = -1\n");
        assert!(bad_loop.contains("loop_s"), "{bad_loop}");
    }

    #[test]
    fn faults_are_read_and_checked() {
        let file = parse(
            "[[fault]]\nkind = \"zeros\"\nat_frame = 90\nframes = 10\n\
             [[fault]]\nkind = \"disconnect\"\nat_frame = 240\n",
        )
        .unwrap();
        assert_eq!(
            file.faults,
            [
                Fault {
                    kind: FaultKind::Zeros,
                    at_frame: 90,
                    frames: 10
                },
                Fault {
                    kind: FaultKind::Disconnect,
                    at_frame: 240,
                    frames: 1
                }
            ]
        );
        assert_eq!(file.clone().into_camera().unwrap().faults(), file.faults);
        assert!(SceneFile::demo().faults.is_empty());

        let unknown = error("[[fault]]\nkind = \"hang\"\nat_frame = 1\n");
        assert!(
            unknown.starts_with("test.toml:1: [[fault]]: unknown kind \"hang\""),
            "{unknown}"
        );
        assert!(unknown.contains("absurd_intrinsics"), "{unknown}");
        let overlap = error(
            "[[fault]]\nkind = \"nan\"\nat_frame = 5\nframes = 5\n\n\
             [[fault]]\nkind = \"zeros\"\nat_frame = 9\n",
        );
        assert!(
            overlap.starts_with("test.toml:6: [[fault]]") && overlap.contains("overlap"),
            "{overlap}"
        );
        let empty = error("[[fault]]\nkind = \"nan\"\nat_frame = 5\nframes = 0\n");
        assert!(empty.contains("at least 1"), "{empty}");
        let missing = error("[[fault]]\nkind = \"nan\"\n");
        assert!(missing.contains("at_frame"), "{missing}");
    }

    #[test]
    fn unreadable_file_names_it() {
        let err = SceneFile::load("/nonexistent/scene.toml").unwrap_err();
        assert!(err.to_string().contains("/nonexistent/scene.toml"), "{err}");
    }
}
