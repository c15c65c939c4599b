//! The daemon's configuration: a strict TOML file (unknown keys are errors naming the key and
//! line), every key optional with the default documented beside it. `tacmesh.example.toml` at
//! the repository root lists them all.

use super::access::{allowed_peers, group_id, AccessError, Principal};
use crate::socket_dir::default_socket_path;
use std::path::{Path, PathBuf};
use std::time::Duration;
use tacmesh_publish::AllowedPeers;

use serde::Deserialize;

/// Everything `tacmesh run` can be told. Command-line options override the file.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DaemonConfig {
    /// The sensors, each a `[[sensor]]` table; all feed one object map. Default: one `sim`.
    pub sensor: Vec<SensorSection>,
    pub socket: SocketSection,
    pub pipeline: PipelineSection,
    pub workspace: WorkspaceSection,
    pub track: TrackSection,
    pub mesh: MeshSection,
    pub stats: StatsSection,
    pub log: LogSection,
    /// Publish over Zenoh too (for subscribers on other machines). Default: off; the Unix
    /// socket is then the only way in. Needs a build with the `zenoh` feature.
    pub zenoh: Option<ZenohSection>,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            sensor: vec![SensorSection::default()],
            socket: SocketSection::default(),
            pipeline: PipelineSection::default(),
            workspace: WorkspaceSection::default(),
            track: TrackSection::default(),
            mesh: MeshSection::default(),
            stats: StatsSection::default(),
            log: LogSection::default(),
            zenoh: None,
        }
    }
}

/// The `[zenoh]` section: how the daemon (or `tacmesh subscribe --zenoh`) joins a Zenoh network
/// and under which robot name its objects are published (docs/operating.md, "Across the
/// network").
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohSection {
    /// The robot's name in every key expression: `tacmesh/<robot>/objects/<id>/shape`, …
    /// Letters, digits, `-` and `_`. Default `"robot"`.
    pub robot: String,
    /// `"peer"` (default), `"client"` (only through a Zenoh router) or `"router"`.
    pub mode: String,
    /// Endpoints to listen on, such as `"tcp/127.0.0.1:7447"`. Default: none.
    pub listen: Vec<String>,
    /// Endpoints to connect to (a router or a peer), such as `"tcp/192.0.2.10:7447"`.
    /// Default: none.
    pub connect: Vec<String>,
    /// Find peers by UDP multicast on the local network. Default false: name the endpoints.
    pub multicast_scouting: bool,
    /// A Zenoh configuration file (JSON5) the settings above are applied on top of: TLS,
    /// access control, timeouts. Default: none.
    pub config_file: Option<PathBuf>,
    /// How shapes are encoded on Zenoh: `"compact"` (default: a wide-area link counts every
    /// byte) or `"full"`.
    pub encoding: String,
}

impl Default for ZenohSection {
    fn default() -> Self {
        Self {
            robot: "robot".into(),
            mode: "peer".into(),
            listen: Vec::new(),
            connect: Vec::new(),
            multicast_scouting: false,
            config_file: None,
            encoding: "compact".into(),
        }
    }
}

impl ZenohSection {
    /// The shape encoding `encoding` names.
    pub fn shape_encoding(&self) -> Result<tacmesh_protocol::Encoding, ConfigError> {
        match self.encoding.as_str() {
            "compact" => Ok(tacmesh_protocol::Encoding::Compact),
            "full" => Ok(tacmesh_protocol::Encoding::Full),
            other => Err(ConfigError::OutOfRange {
                key: "zenoh.encoding",
                value: format!("{other:?}"),
                expected: "\"compact\" or \"full\"",
            }),
        }
    }

    /// The settings the Zenoh crate takes.
    #[cfg(feature = "zenoh")]
    pub fn settings(&self) -> Result<tacmesh_zenoh::ZenohSettings, ConfigError> {
        Ok(tacmesh_zenoh::ZenohSettings {
            robot: self.robot.clone(),
            mode: self.mode.clone(),
            listen: self.listen.clone(),
            connect: self.connect.clone(),
            multicast_scouting: self.multicast_scouting,
            config_file: self.config_file.clone(),
            encoding: self.shape_encoding()?,
        })
    }
}

/// One depth source to read.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorSection {
    /// Which backend and device, by prefix (see `tacmesh run --help`): `sim`, `sim:SCENE.toml`,
    /// `replay:PATH` (.oni, .bag, depth images or clouds), `serial:camsense:PORT`,
    /// `serial:rplidar:PORT`, `v4l2:/dev/videoN?…`, `openni2:[URI]`, `depthai:[…]`.
    /// Default `sim`.
    pub spec: String,
    /// Pacing: `true` delivers frames at the sensor's (or recording's) rate of wall-clock time,
    /// `false` as fast as the pipeline takes them. Default: the source's own choice (real time).
    pub paced: Option<bool>,
    /// Recordings only: start again at the end instead of stopping. Default false.
    #[serde(rename = "loop")]
    pub looping: bool,
    /// Where the sensor (rig) is in the world, applied on top of the pose the source reports
    /// (identity for hardware and recordings; the scene's camera pose for `sim`). Default: none.
    pub pose: Option<PoseSection>,
}

impl Default for SensorSection {
    fn default() -> Self {
        Self {
            spec: "sim".into(),
            paced: None,
            looping: false,
            pose: None,
        }
    }
}

/// A rigid pose: rotate by `rotation_deg` (roll about x, then pitch about y, then yaw about z,
/// in the world frame), then translate by `translation_m`.
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PoseSection {
    pub translation_m: [f32; 3],
    pub rotation_deg: [f32; 3],
}

impl PoseSection {
    pub fn world_from_sensor(&self) -> glam::Affine3A {
        let [roll, pitch, yaw] = self.rotation_deg.map(f32::to_radians);
        glam::Affine3A::from_rotation_translation(
            glam::Quat::from_euler(glam::EulerRot::ZYX, yaw, pitch, roll),
            glam::Vec3::from(self.translation_m),
        )
    }
}

/// The Unix socket meshes are served on.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SocketSection {
    /// Socket path. Default `$XDG_RUNTIME_DIR/tacmesh.sock`, or without a runtime directory
    /// `tacmesh.sock` in the private directory `tacmesh-UID` (UID: the numeric user id) of the
    /// temporary directory, made 0700 and checked to be the user's own.
    pub path: Option<PathBuf>,
    /// Permission bits of the socket file, as an octal string. Default `"0660"`.
    pub mode: Option<String>,
    /// Group (a name or a number) to give the socket file, so that its members may connect
    /// with mode 0660. Default: the daemon's own group.
    pub group: Option<Principal>,
    /// If set (or `allow_groups` is), only processes running as one of these users (names or
    /// numbers) may subscribe, checked with the kernel's `SO_PEERCRED`; others are cut off
    /// before Hello and counted. Default: whoever the file mode lets connect.
    pub allow_users: Option<Vec<Principal>>,
    /// As `allow_users`, by the connecting process's primary group.
    pub allow_groups: Option<Vec<Principal>>,
    /// The most subscribers served at once (each costs a socket and its buffers); one more
    /// gets a Goodbye saying so. 1 to 4096, default 64.
    pub max_subscribers: usize,
    /// The most subscribers one user may have at once. 1 to 4096, default 16.
    pub max_subscribers_per_user: usize,
}

impl Default for SocketSection {
    fn default() -> Self {
        Self {
            path: None,
            mode: None,
            group: None,
            allow_users: None,
            allow_groups: None,
            max_subscribers: tacmesh_publish::DEFAULT_MAX_SUBSCRIBERS,
            max_subscribers_per_user: tacmesh_publish::DEFAULT_MAX_SUBSCRIBERS_PER_USER,
        }
    }
}

/// The per-frame stages.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PipelineSection {
    /// Frames held between the sensor and the pipeline; when full, the oldest is dropped.
    /// Default 1: the pipeline always takes the newest frame, so a frame never waits behind
    /// an older one (measured with `cargo bench --bench daemon`: 2 added a frame's processing
    /// time to the p50 frame-to-publish latency whenever the pipeline ran near capacity).
    pub ring_capacity: usize,
    /// Depths beyond this many metres are invalid. Default 4.0.
    pub max_range_m: f32,
    /// Segment every n-th pixel in each direction (1 = every pixel). Points of the skipped
    /// pixels still join the object of their nearest segmented neighbour and are fused.
    /// Default 2.
    pub segment_stride: u32,
}

impl Default for PipelineSection {
    fn default() -> Self {
        Self {
            ring_capacity: 1,
            max_range_m: 4.0,
            segment_stride: 2,
        }
    }
}

/// Where objects can be, in the world frame.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct WorkspaceSection {
    /// Corners of the box, world frame, metres: points outside it are not segmented (they
    /// still show the sensor's free space, so what leaves the box is carved away). Either
    /// corner may be left out, leaving that side open. Default: no box.
    pub min_m: Option<[f32; 3]>,
    pub max_m: Option<[f32; 3]>,
    /// The largest object, metres: larger clusters, and larger planes that do not face up,
    /// are background (walls, furniture). Default 1.2.
    pub max_object_size_m: f32,
}

impl Default for WorkspaceSection {
    fn default() -> Self {
        Self {
            min_m: None,
            max_m: None,
            max_object_size_m: 1.2,
        }
    }
}

impl WorkspaceSection {
    /// Whether `p` (world frame) is inside the box.
    pub fn contains(&self, p: glam::Vec3) -> bool {
        self.min_m
            .is_none_or(|lo| p.cmpge(glam::Vec3::from(lo)).all())
            && self
                .max_m
                .is_none_or(|hi| p.cmple(glam::Vec3::from(hi)).all())
    }

    /// Whether the box bounds anything.
    pub fn is_bounded(&self) -> bool {
        self.min_m.is_some() || self.max_m.is_some()
    }
}

/// Object identity and fusion.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackSection {
    /// Fused voxel edge, metres. Default 0.005.
    pub voxel_size_m: f32,
    /// An object unseen for this many seconds is removed. Default 1.0.
    pub leave_after_s: f32,
    /// Least time between two meshings of one object, seconds. Default 0.25.
    pub remesh_interval_s: f32,
    /// Farther than this from the sensor, metres, what is seen may add to an object seen from
    /// nearer but never starts one. Default 3.5 (where a Kinect-class sensor's depth steps
    /// are 4 cm: a staircase of depth levels, not a shape).
    pub max_birth_range_m: f32,
    /// Estimate the camera's own motion or pose error from the objects standing still, and
    /// correct each frame by it (`tacmesh_track::camera_error`). Default true; a camera bolted
    /// in place, with a good extrinsic calibration, can turn it off.
    pub correct_camera: bool,
}

impl Default for TrackSection {
    fn default() -> Self {
        Self {
            voxel_size_m: 0.005,
            leave_after_s: 1.0,
            remesh_interval_s: 0.25,
            max_birth_range_m: 3.5,
            correct_camera: true,
        }
    }
}

/// Simplification.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MeshSection {
    /// The simplifier's stop rule: no marching-cubes vertex ends farther than this many metres
    /// from the published surface. Default 0.004.
    pub max_residual_m: f32,
    /// Fit the simplified vertices to the fused data (restores corners). Default true.
    pub fit_to_data: bool,
    /// Marching-cubes cell edge in voxels of `track.voxel_size_m`: 2 samples the signed
    /// distance on every second voxel corner, for a quarter of the faces to simplify. Default 1.
    pub mesh_step_voxels: i32,
    /// Threads meshing objects side by side. Default 2: when several objects change at
    /// once, the second keeps their new meshes from queueing behind each other. Each has a
    /// thread pool of its own for a run's parallel stages (as many threads as cores, or
    /// `RAYON_NUM_THREADS`), idle between runs.
    pub workers: usize,
}

impl Default for MeshSection {
    fn default() -> Self {
        Self {
            max_residual_m: 0.004,
            fit_to_data: true,
            mesh_step_voxels: 1,
            workers: 2,
        }
    }
}

/// Counters on the socket and in the log.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct StatsSection {
    /// Seconds between Stats messages to subscribers. Default 1.0.
    pub publish_interval_s: f32,
    /// Seconds between counter lines in the log. Default 10.0.
    pub log_interval_s: f32,
}

impl Default for StatsSection {
    fn default() -> Self {
        Self {
            publish_interval_s: 1.0,
            log_interval_s: 10.0,
        }
    }
}

/// Logging to standard error.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LogSection {
    /// What to log: a level (`error`, `warn`, `info`, `debug`, `trace`, `off`) or a
    /// tracing-subscriber filter such as `"info,tacmesh::daemon=debug"`. `RUST_LOG`, when
    /// set, and `-v` take precedence. Default `"info"`.
    pub level: String,
}

impl Default for LogSection {
    fn default() -> Self {
        Self {
            level: "info".into(),
        }
    }
}

/// The documented range of a number in the config, both ends included; `expected` says it
/// with its unit for the error.
pub struct Bounds {
    pub min: f32,
    pub max: f32,
    pub expected: &'static str,
}

impl Bounds {
    /// `seconds` as a duration, held within the bounds first (a validated config is within
    /// them already; this cannot panic whatever it is given, NaN going to the minimum).
    fn duration(&self, seconds: f32) -> Duration {
        let held = if seconds.is_nan() {
            self.min
        } else {
            seconds.clamp(self.min, self.max)
        };
        Duration::try_from_secs_f32(held).unwrap_or(Duration::ZERO)
    }

    fn check(&self, key: &'static str, value: f32) -> Result<(), ConfigError> {
        if (self.min..=self.max).contains(&value) {
            Ok(())
        } else {
            Err(ConfigError::OutOfRange {
                key,
                value: value.to_string(),
                expected: self.expected,
            })
        }
    }
}

/// `pipeline.max_range_m`: from 10 cm to 100 m.
pub const MAX_RANGE_M: Bounds = Bounds {
    min: 0.1,
    max: 100.0,
    expected: "from 0.1 to 100 metres",
};
/// `workspace.max_object_size_m`: from 1 cm to 100 m.
pub const MAX_OBJECT_SIZE_M: Bounds = Bounds {
    min: 0.01,
    max: 100.0,
    expected: "from 0.01 to 100 metres",
};
/// `track.voxel_size_m`: from 0.5 mm (finer than any depth camera resolves) to 50 cm.
pub const VOXEL_SIZE_M: Bounds = Bounds {
    min: 0.0005,
    max: 0.5,
    expected: "from 0.0005 to 0.5 metres",
};
/// `track.leave_after_s`: from 10 ms to a day.
pub const LEAVE_AFTER_S: Bounds = Bounds {
    min: 0.01,
    max: 86_400.0,
    expected: "from 0.01 to 86400 seconds",
};
/// `track.remesh_interval_s`: from 1 ms to an hour.
pub const REMESH_INTERVAL_S: Bounds = Bounds {
    min: 0.001,
    max: 3_600.0,
    expected: "from 0.001 to 3600 seconds",
};
/// `track.max_birth_range_m`: from 10 cm to 100 m.
pub const MAX_BIRTH_RANGE_M: Bounds = Bounds {
    min: 0.1,
    max: 100.0,
    expected: "from 0.1 to 100 metres",
};
/// `mesh.max_residual_m`: from 10 µm to 1 m.
pub const MAX_RESIDUAL_M: Bounds = Bounds {
    min: 0.00001,
    max: 1.0,
    expected: "from 0.00001 to 1 metre",
};
/// `stats.publish_interval_s`: from 10 ms to an hour.
pub const PUBLISH_INTERVAL_S: Bounds = Bounds {
    min: 0.01,
    max: 3_600.0,
    expected: "from 0.01 to 3600 seconds",
};
/// `stats.log_interval_s`: from 100 ms to a day.
pub const LOG_INTERVAL_S: Bounds = Bounds {
    min: 0.1,
    max: 86_400.0,
    expected: "from 0.1 to 86400 seconds",
};

/// `err`, about `key`, as a parse error of the file at the key's line (where it is in the
/// text: a default out of range has none).
fn at_line_of(text: &str, path: &Path, key: &str, err: ConfigError) -> ConfigError {
    match line_of_key(text, key) {
        Some(line) => ConfigError::Parse {
            path: path.to_owned(),
            message: format!("line {line}: {err}"),
        },
        None => err,
    }
}

/// The line (from 1) on which dotted `key` (`track.leave_after_s`; in an array of tables,
/// its first) is given in `text`.
fn line_of_key(text: &str, key: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    fn span_of(table: &DeTable<'_>, path: &[&str]) -> Option<std::ops::Range<usize>> {
        let (name, rest) = path.split_first()?;
        let (key, value) = table.iter().find(|(key, _)| &**key.get_ref() == *name)?;
        if rest.is_empty() {
            return Some(key.span());
        }
        match value.get_ref() {
            DeValue::Table(inner) => span_of(inner, rest),
            DeValue::Array(items) => items.iter().find_map(|item| match item.get_ref() {
                DeValue::Table(inner) => span_of(inner, rest),
                _ => None,
            }),
            _ => None,
        }
    }
    let document = DeTable::parse(text).ok()?;
    let path: Vec<&str> = key.split('.').collect();
    let span = span_of(document.get_ref(), &path)?;
    Some(text[..span.start.min(text.len())].matches('\n').count() + 1)
}

/// A configuration that cannot be used; the daemon stops before it starts anything.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read the config file {}: {cause}", path.display())]
    Read {
        path: PathBuf,
        cause: std::io::Error,
    },
    #[error("config file {}: {message}", path.display())]
    Parse { path: PathBuf, message: String },
    #[error("config: {key} = {value} is out of range: {expected}")]
    OutOfRange {
        key: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error(
        "config: a [{section}] section, but this tacmesh was built without the `{feature}` \
         feature: build it with `cargo build --release --features {feature}`, or remove the \
         section"
    )]
    FeatureMissing {
        section: &'static str,
        feature: &'static str,
    },
    #[error(
        "config: socket.mode = {value} is world-writable, which would let every local user \
         connect, read every mesh and flood the daemon; use \"0660\" with socket.group (or \
         socket.allow_users / socket.allow_groups) to choose who may subscribe"
    )]
    WorldWritable { value: String },
    #[error(transparent)]
    Access(#[from] AccessError),
}

/// The largest config file read: 1 MiB (the example is 5 kB).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

impl DaemonConfig {
    /// Reads and checks a config file.
    pub fn load(path: &Path) -> Result<DaemonConfig, ConfigError> {
        let text = tacmesh_source::read_regular_text(path, MAX_CONFIG_BYTES).map_err(|cause| {
            ConfigError::Read {
                path: path.to_owned(),
                cause,
            }
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks config text; `path` names it in errors, and a value out of range is
    /// named with its line.
    pub fn parse(text: &str, path: &Path) -> Result<DaemonConfig, ConfigError> {
        let config: DaemonConfig = toml::from_str(text).map_err(|err| ConfigError::Parse {
            path: path.to_owned(),
            message: describe_toml_error(text, &err),
        })?;
        config.validate().map_err(|err| match err {
            ConfigError::OutOfRange { key, .. } => at_line_of(text, path, key, err),
            ConfigError::WorldWritable { .. } => at_line_of(text, path, "socket.mode", err),
            other => other,
        })?;
        Ok(config)
    }

    /// Checks every value's range, so that a bad config fails at start and not mid-run. Each
    /// duration, rate and size has a documented minimum and maximum (tacmesh.example.toml):
    /// a number that is finite and positive can still overflow the clock it becomes
    /// (`leave_after_s = 1e30`) or the memory it sizes (`voxel_size_m = 1e-30`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (key, value, range) in [
            (
                "pipeline.max_range_m",
                self.pipeline.max_range_m,
                &MAX_RANGE_M,
            ),
            (
                "workspace.max_object_size_m",
                self.workspace.max_object_size_m,
                &MAX_OBJECT_SIZE_M,
            ),
            ("track.voxel_size_m", self.track.voxel_size_m, &VOXEL_SIZE_M),
            (
                "track.leave_after_s",
                self.track.leave_after_s,
                &LEAVE_AFTER_S,
            ),
            (
                "track.remesh_interval_s",
                self.track.remesh_interval_s,
                &REMESH_INTERVAL_S,
            ),
            (
                "track.max_birth_range_m",
                self.track.max_birth_range_m,
                &MAX_BIRTH_RANGE_M,
            ),
            (
                "mesh.max_residual_m",
                self.mesh.max_residual_m,
                &MAX_RESIDUAL_M,
            ),
            (
                "stats.publish_interval_s",
                self.stats.publish_interval_s,
                &PUBLISH_INTERVAL_S,
            ),
            (
                "stats.log_interval_s",
                self.stats.log_interval_s,
                &LOG_INTERVAL_S,
            ),
        ] {
            range.check(key, value)?;
        }
        if self.sensor.is_empty() {
            return Err(ConfigError::OutOfRange {
                key: "sensor",
                value: "[]".into(),
                expected: "at least one [[sensor]]",
            });
        }
        for sensor in &self.sensor {
            let finite = sensor.pose.as_ref().is_none_or(|pose| {
                pose.translation_m
                    .iter()
                    .chain(&pose.rotation_deg)
                    .all(|v| v.is_finite())
            });
            if !finite {
                return Err(ConfigError::OutOfRange {
                    key: "sensor.pose",
                    value: format!("{:?}", sensor.pose),
                    expected: "finite numbers",
                });
            }
        }
        for (key, corner) in [
            ("workspace.min_m", self.workspace.min_m),
            ("workspace.max_m", self.workspace.max_m),
        ] {
            if corner.is_some_and(|c| !c.iter().all(|v| v.is_finite())) {
                return Err(ConfigError::OutOfRange {
                    key,
                    value: format!("{corner:?}"),
                    expected: "three finite numbers",
                });
            }
        }
        if let (Some(lo), Some(hi)) = (self.workspace.min_m, self.workspace.max_m) {
            if lo.iter().zip(&hi).any(|(lo, hi)| lo >= hi) {
                return Err(ConfigError::OutOfRange {
                    key: "workspace.max_m",
                    value: format!("{hi:?}"),
                    expected: "above workspace.min_m on every axis",
                });
            }
        }
        if !(1..=64).contains(&self.pipeline.ring_capacity) {
            return Err(ConfigError::OutOfRange {
                key: "pipeline.ring_capacity",
                value: self.pipeline.ring_capacity.to_string(),
                expected: "1 to 64 frames",
            });
        }
        if !(1..=4).contains(&self.mesh.mesh_step_voxels) {
            return Err(ConfigError::OutOfRange {
                key: "mesh.mesh_step_voxels",
                value: self.mesh.mesh_step_voxels.to_string(),
                expected: "1 to 4 voxels",
            });
        }
        if !(1..=16).contains(&self.mesh.workers) {
            return Err(ConfigError::OutOfRange {
                key: "mesh.workers",
                value: self.mesh.workers.to_string(),
                expected: "1 to 16 threads",
            });
        }
        for (key, value) in [
            ("socket.max_subscribers", self.socket.max_subscribers),
            (
                "socket.max_subscribers_per_user",
                self.socket.max_subscribers_per_user,
            ),
        ] {
            if !(1..=4096).contains(&value) {
                return Err(ConfigError::OutOfRange {
                    key,
                    value: value.to_string(),
                    expected: "1 to 4096 subscribers",
                });
            }
        }
        if !(1..=16).contains(&self.pipeline.segment_stride) {
            return Err(ConfigError::OutOfRange {
                key: "pipeline.segment_stride",
                value: self.pipeline.segment_stride.to_string(),
                expected: "1 to 16 pixels",
            });
        }
        self.socket_mode()?;
        self.socket_access()?;
        if !is_log_filter(&self.log.level) {
            return Err(ConfigError::OutOfRange {
                key: "log.level",
                value: format!("{:?}", self.log.level),
                expected: "a level (error, warn, info, debug, trace, off) or a filter such as \"info,tacmesh=debug\"",
            });
        }
        if let Some(zenoh) = &self.zenoh {
            zenoh.shape_encoding()?;
            if !cfg!(feature = "zenoh") {
                return Err(ConfigError::FeatureMissing {
                    section: "zenoh",
                    feature: "zenoh",
                });
            }
        }
        Ok(())
    }

    /// The socket file mode: `socket.mode` parsed as octal, or 0660. A world-writable mode is
    /// refused: connecting to a Unix socket needs write permission on it, so o+w would let any
    /// local user subscribe, past the access lists' intent.
    pub fn socket_mode(&self) -> Result<u32, ConfigError> {
        let Some(text) = &self.socket.mode else {
            return Ok(tacmesh_publish::DEFAULT_SOCKET_MODE);
        };
        let digits = text.trim_start_matches("0o");
        match u32::from_str_radix(digits, 8) {
            Ok(mode) if mode & 0o002 != 0 && mode <= 0o777 => Err(ConfigError::WorldWritable {
                value: format!("{text:?}"),
            }),
            Ok(mode) if mode <= 0o777 => Ok(mode),
            _ => Err(ConfigError::OutOfRange {
                key: "socket.mode",
                value: format!("{text:?}"),
                expected: "an octal permission string such as \"0660\"",
            }),
        }
    }

    /// The socket file's group and the peers allowed to subscribe, names resolved to ids.
    pub fn socket_access(&self) -> Result<(Option<u32>, Option<AllowedPeers>), ConfigError> {
        let group = self
            .socket
            .group
            .as_ref()
            .map(|g| group_id(g, "socket.group"))
            .transpose()?;
        let peers = allowed_peers(
            self.socket.allow_users.as_deref(),
            self.socket.allow_groups.as_deref(),
        )?;
        Ok((group, peers))
    }

    /// The socket path: `socket.path`, else the default (see [`default_socket_path`]).
    pub fn socket_path(&self) -> PathBuf {
        self.socket.path.clone().unwrap_or_else(default_socket_path)
    }

    pub(crate) fn leave_after(&self) -> Duration {
        LEAVE_AFTER_S.duration(self.track.leave_after_s)
    }

    pub(crate) fn remesh_interval(&self) -> Duration {
        REMESH_INTERVAL_S.duration(self.track.remesh_interval_s)
    }

    pub(crate) fn stats_publish_interval(&self) -> Duration {
        PUBLISH_INTERVAL_S.duration(self.stats.publish_interval_s)
    }

    pub(crate) fn stats_log_interval(&self) -> Duration {
        LOG_INTERVAL_S.duration(self.stats.log_interval_s)
    }
}

/// A tracing-subscriber filter whose every directive names a level: `info`, or
/// `target=level` (a bare target, which tracing would take as "everything from it", is more
/// likely a typo of a level in a config file).
fn is_log_filter(text: &str) -> bool {
    use tracing_subscriber::filter::LevelFilter;
    let directives_name_levels = text.split(',').all(|directive| {
        // tracing reads an empty level as "error"; in a config it is a mistake.
        let level = directive.rsplit('=').next().unwrap_or_default().trim();
        !level.is_empty() && level.parse::<LevelFilter>().is_ok()
    });
    directives_name_levels && tracing_subscriber::EnvFilter::try_new(text).is_ok()
}

/// What each key wants, in words, for errors about a value of the wrong type or size (serde's
/// own words are Rust types: `expected f32`). Keyed by the dotted path without array indices.
const KEY_WANTS: &[(&str, &str)] = &[
    (
        "sensor",
        "one [[sensor]] table per sensor, each with a `spec`",
    ),
    (
        "sensor.spec",
        "a sensor spec string, for example \"sim\" or \"replay:scan.oni\" (see `tacmesh run --help`)",
    ),
    ("sensor.paced", "true or false"),
    ("sensor.loop", "true or false"),
    (
        "sensor.pose",
        "a table such as { translation_m = [0.0, 0.0, 1.2], rotation_deg = [-120.0, 0.0, 0.0] }",
    ),
    (
        "sensor.pose.translation_m",
        "three lengths in metres, [x, y, z], for example [0.0, 0.0, 1.2]",
    ),
    (
        "sensor.pose.rotation_deg",
        "three angles in degrees, [roll, pitch, yaw], for example [-120.0, 0.0, 0.0]",
    ),
    (
        "socket.path",
        "a file path string, for example \"/run/tacmesh/tacmesh.sock\"",
    ),
    (
        "socket.mode",
        "an octal permission string, for example \"0660\"",
    ),
    (
        "socket.max_subscribers",
        "a whole number of subscribers from 1 to 4096, for example 64",
    ),
    (
        "socket.max_subscribers_per_user",
        "a whole number of subscribers from 1 to 4096, for example 16",
    ),
    (
        "socket.group",
        "a group name or number, for example \"robot\" or 1001",
    ),
    (
        "socket.allow_users",
        "a list of user names or numbers, for example [\"operator\", 1001]",
    ),
    (
        "socket.allow_groups",
        "a list of group names or numbers, for example [\"teleop\", 1001]",
    ),
    (
        "pipeline.ring_capacity",
        "a whole number of frames from 1 to 64, for example 1",
    ),
    (
        "pipeline.max_range_m",
        "a distance in metres, for example 4.0",
    ),
    (
        "pipeline.segment_stride",
        "a whole number of pixels from 1 to 16, for example 2",
    ),
    (
        "workspace.min_m",
        "three coordinates in metres, [x, y, z], for example [-0.6, -0.4, 0.0]",
    ),
    (
        "workspace.max_m",
        "three coordinates in metres, [x, y, z], for example [0.6, 0.4, 0.8]",
    ),
    (
        "workspace.max_object_size_m",
        "a length in metres, for example 1.2",
    ),
    (
        "track.voxel_size_m",
        "a length in metres, for example 0.005",
    ),
    (
        "track.leave_after_s",
        "a time in seconds, for example 1.0",
    ),
    (
        "track.remesh_interval_s",
        "a time in seconds, for example 0.25",
    ),
    (
        "track.max_birth_range_m",
        "a length in metres, for example 3.5",
    ),
    ("track.correct_camera", "true or false"),
    (
        "mesh.max_residual_m",
        "a length in metres, for example 0.004",
    ),
    ("mesh.fit_to_data", "true or false"),
    (
        "mesh.mesh_step_voxels",
        "a whole number of voxels from 1 to 4, for example 2",
    ),
    (
        "mesh.workers",
        "a whole number of threads from 1 to 16, for example 2",
    ),
    (
        "stats.publish_interval_s",
        "a time in seconds, for example 1.0",
    ),
    (
        "stats.log_interval_s",
        "a time in seconds, for example 10.0",
    ),
    (
        "log.level",
        "a level or filter string, for example \"info\" or \"info,tacmesh::daemon=debug\"",
    ),
    ("socket", "a [socket] table (see tacmesh.example.toml)"),
    ("pipeline", "a [pipeline] table (see tacmesh.example.toml)"),
    ("workspace", "a [workspace] table (see tacmesh.example.toml)"),
    ("track", "a [track] table (see tacmesh.example.toml)"),
    ("mesh", "a [mesh] table (see tacmesh.example.toml)"),
    ("stats", "a [stats] table (see tacmesh.example.toml)"),
    ("log", "a [log] table (see tacmesh.example.toml)"),
    (
        "zenoh.robot",
        "a name of letters, digits, - and _, for example \"arm-1\"",
    ),
    (
        "zenoh.listen",
        "a list of Zenoh endpoints, for example [\"tcp/0.0.0.0:7447\"]",
    ),
    (
        "zenoh.connect",
        "a list of Zenoh endpoints, for example [\"tcp/192.0.2.10:7447\"]",
    ),
    ("zenoh.multicast_scouting", "true or false"),
    ("zenoh.mode", "\"peer\", \"client\" or \"router\""),
    ("zenoh.encoding", "\"compact\" or \"full\""),
    (
        "zenoh.config_file",
        "a file path string, for example \"/etc/tacmesh/zenoh.json5\"",
    ),
    ("zenoh", "a [zenoh] table (see tacmesh.example.toml)"),
];

/// What `key` (a dotted path) wants, in words.
fn key_wants(key: &str) -> Option<&'static str> {
    KEY_WANTS
        .iter()
        .find(|(name, _)| *name == key)
        .map(|(_, wants)| *wants)
}

/// The toml crate's message with the line number it points at, in one line. A value of the
/// wrong type or size is named by its key, with what the key wants in words.
fn describe_toml_error(text: &str, err: &toml::de::Error) -> String {
    let message = err.message().trim_end().replace('\n', "; ");
    let Some(span) = err.span() else {
        return message;
    };
    let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
    let key = key_at(text, span.start);
    match (key, wrong_value(&message)) {
        (Some(key), Some(found)) => match (key_wants(&key), found) {
            (Some(wants), Some(found)) => format!("line {line}: {key}: {wants}, not {found}"),
            (Some(wants), None) => format!("line {line}: {key}: {wants}"),
            (None, _) => format!("line {line}: {key}: {message}"),
        },
        _ => format!("line {line}: {message}"),
    }
}

/// What serde found, from its message about a value of the wrong type, size or range
/// (`invalid type: string "a", expected f32` → `Some(Some("string \"a\""))`, `Some(None)`
/// when the message does not say); `None` for other errors (an unknown key, a missing one),
/// whose messages say what is wrong already.
fn wrong_value(message: &str) -> Option<Option<String>> {
    let found = |rest: &str| {
        rest.split_once(", expected")
            .map_or(rest, |(found, _)| found)
            .trim()
            .to_owned()
    };
    if let Some(rest) = message.strip_prefix("invalid type: ") {
        Some(Some(found(rest)))
    } else if let Some(rest) = message.strip_prefix("invalid value: ") {
        Some(Some(found(rest)))
    } else if let Some(rest) = message.strip_prefix("invalid length ") {
        Some(Some(format!("{} values", found(rest))))
    } else if message.starts_with("data did not match any variant") {
        Some(None)
    } else {
        None
    }
}

/// The dotted path (array indices left out) of the innermost key whose value holds byte
/// `at` of `text`, if `text` is a TOML document.
fn key_at(text: &str, at: usize) -> Option<String> {
    fn walk<'a>(
        value: &'a toml::Spanned<toml::de::DeValue<'a>>,
        at: usize,
        path: &mut Vec<&'a str>,
        best: &mut Option<Vec<&'a str>>,
    ) {
        if value.span().contains(&at) && best.as_ref().is_none_or(|b| b.len() < path.len()) {
            *best = Some(path.clone());
        }
        match value.get_ref() {
            toml::de::DeValue::Table(table) => {
                for (key, value) in table {
                    path.push(&**key.get_ref());
                    walk(value, at, path, best);
                    path.pop();
                }
            }
            toml::de::DeValue::Array(items) => {
                for item in items.iter() {
                    walk(item, at, path, best);
                }
            }
            _ => {}
        }
    }
    let document = toml::de::DeTable::parse(text).ok()?;
    let mut best = None;
    for (key, value) in document.get_ref() {
        let mut path = vec![&**key.get_ref()];
        walk(value, at, &mut path, &mut best);
    }
    best.filter(|path| !path.is_empty())
        .map(|path| path.join("."))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<DaemonConfig, ConfigError> {
        DaemonConfig::parse(text, Path::new("test.toml"))
    }

    #[test]
    fn an_empty_file_is_the_defaults() {
        assert_eq!(parse("").unwrap(), DaemonConfig::default());
    }

    /// A [zenoh] section needs the feature, says so when it is missing, and takes only the
    /// encodings there are.
    #[test]
    fn a_zenoh_section_is_checked_and_needs_the_feature() {
        let text = "[zenoh]\nrobot = \"arm-1\"\nlisten = [\"tcp/127.0.0.1:7447\"]\n";
        match parse(text) {
            #[cfg(feature = "zenoh")]
            Ok(config) => {
                let settings = config.zenoh.expect("a section").settings().unwrap();
                assert_eq!(settings.robot, "arm-1");
                assert_eq!(settings.encoding, tacmesh_protocol::Encoding::Compact);
            }
            #[cfg(not(feature = "zenoh"))]
            Err(err @ ConfigError::FeatureMissing { .. }) => {
                assert!(err.to_string().contains("--features zenoh"), "{err}");
            }
            other => panic!("{other:?}"),
        }
        let err = parse("[zenoh]\nencoding = \"gzip\"\n").unwrap_err();
        assert!(err.to_string().contains("zenoh.encoding"), "{err}");
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line() {
        let err = parse("[track]\nvoxel_size_m = 0.01\nleave_aftr_s = 2\n").unwrap_err();
        let text = err.to_string();
        assert!(text.contains("leave_aftr_s"), "{text}");
        assert!(text.contains("line 3"), "{text}");
        assert!(text.contains("test.toml"), "{text}");
    }

    #[test]
    fn out_of_range_values_fail_at_load() {
        let err = parse("[track]\nvoxel_size_m = -1\n").unwrap_err();
        assert!(err.to_string().contains("track.voxel_size_m"), "{err}");
        let err = parse("[socket]\nmode = \"0999\"\n").unwrap_err();
        assert!(err.to_string().contains("socket.mode"), "{err}");
        let err = parse("[pipeline]\nring_capacity = 0\n").unwrap_err();
        assert!(err.to_string().contains("ring_capacity"), "{err}");
        for bad in ["loud", "", "info,tacmesh=loud"] {
            let err = parse(&format!("[log]\nlevel = {bad:?}\n")).unwrap_err();
            assert!(err.to_string().contains("log.level"), "{bad}: {err}");
        }
        assert_eq!(
            parse("[log]\nlevel = \"warn,tacmesh::daemon=debug\"\n")
                .unwrap()
                .log
                .level,
            "warn,tacmesh::daemon=debug"
        );
    }

    /// Every duration and size key refuses what once aborted the daemon (1e30 s overflowed
    /// `Duration`, 9.2e18 s overflowed `Instant`) and what is absurd (a 1e-30 m voxel),
    /// naming the key and its line; every value it takes becomes a duration without panic.
    #[test]
    fn durations_and_sizes_out_of_their_documented_range_fail_with_key_and_line() {
        let keys = [
            ("pipeline", "max_range_m"),
            ("workspace", "max_object_size_m"),
            ("track", "voxel_size_m"),
            ("track", "leave_after_s"),
            ("track", "remesh_interval_s"),
            ("track", "max_birth_range_m"),
            ("mesh", "max_residual_m"),
            ("stats", "publish_interval_s"),
            ("stats", "log_interval_s"),
        ];
        let bad = [
            "1e30", "9.2e18", "1e-30", "0.0", "-1.0", "inf", "-inf", "nan",
        ];
        for (section, key) in keys {
            for value in bad {
                // The key on line 3, after a comment, so that the line is the key's own.
                let text = format!("# a config\n[{section}]\n{key} = {value}\n");
                let err = parse(&text).expect_err(&text).to_string();
                assert!(err.contains(&format!("{section}.{key}")), "{text}: {err}");
                assert!(err.contains("line 3"), "{text}: {err}");
                assert!(err.contains(" to "), "the range is given: {err}");
            }
        }
        // Many values spread over the float range, as a property: each is refused, or the
        // durations it becomes are what it says.
        let mut x = 0x2545_f491_4f6c_dd1d_u64;
        for _ in 0..2_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let value = f32::from_bits(x as u32);
            for (section, key) in keys {
                let text = format!("[{section}]\n{key} = {value:e}\n");
                let Ok(config) = parse(&text) else { continue };
                let _ = (config.leave_after(), config.remesh_interval());
                let _ = (config.stats_publish_interval(), config.stats_log_interval());
                assert!(config.validate().is_ok());
            }
        }
        let config = parse("[track]\nleave_after_s = 86400\n").unwrap();
        assert_eq!(config.leave_after(), Duration::from_secs(86_400));
    }

    #[test]
    fn several_sensors_with_poses() {
        let config = parse(
            "[[sensor]]\nspec = \"sim\"\n[[sensor]]\nspec = \"replay:a.oni\"\nloop = true\n\
             pose = { translation_m = [1, 0, 0.5], rotation_deg = [0, 0, 90] }\n",
        )
        .unwrap();
        assert_eq!(config.sensor.len(), 2);
        assert!(config.sensor[1].looping);
        let pose = config.sensor[1].pose.as_ref().unwrap().world_from_sensor();
        // Yaw 90°: x goes to y, then the translation.
        let p = pose.transform_point3(glam::Vec3::X);
        assert!(p.abs_diff_eq(glam::Vec3::new(1.0, 1.0, 0.5), 1e-6), "{p}");
        let err = parse("[[sensor]]\nspec = \"sim\"\nposition = [1, 2, 3]\n").unwrap_err();
        assert!(err.to_string().contains("position"), "{err}");
    }

    #[test]
    fn socket_access_names_resolve_at_load() {
        let config = parse(
            "[socket]\ngroup = \"root\"\nallow_users = [\"root\", 1001]\nallow_groups = [0]\n",
        )
        .unwrap();
        let (group, peers) = config.socket_access().unwrap();
        assert_eq!(group, Some(0));
        let peers = peers.expect("allow lists given");
        assert_eq!((peers.uids, peers.gids), (vec![0, 1001], vec![0]));
        assert_eq!(
            DaemonConfig::default().socket_access().unwrap(),
            (None, None)
        );
        let err = parse("[socket]\nallow_users = [\"no-such-user-for-tacmesh\"]\n").unwrap_err();
        assert!(
            err.to_string().contains("socket.allow_users")
                && err.to_string().contains("no-such-user-for-tacmesh"),
            "{err}"
        );
    }

    #[test]
    fn socket_mode_is_octal() {
        let config = parse("[socket]\nmode = \"0600\"\n").unwrap();
        assert_eq!(config.socket_mode().unwrap(), 0o600);
        assert_eq!(DaemonConfig::default().socket_mode().unwrap(), 0o660);
    }

    #[test]
    fn a_world_writable_socket_mode_is_refused_with_the_reason() {
        for mode in ["777", "0666", "0o662"] {
            let err = parse(&format!("[socket]\nmode = {mode:?}\n")).unwrap_err();
            let text = err.to_string();
            assert!(
                text.contains("socket.mode") && text.contains("world-writable"),
                "{mode}: {text}"
            );
            assert!(text.contains("every local user"), "{mode}: {text}");
        }
        let config = parse("[socket]\nmode = \"0664\"\n").unwrap();
        assert_eq!(config.socket_mode().unwrap(), 0o664);
    }

    /// Values of the wrong type or size are named by their key, with what the key wants in
    /// words, not in Rust types.
    #[test]
    fn a_wrong_value_says_what_its_key_wants() {
        let err = parse("[track]\nvoxel_size_m = \"fine\"\n").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("track.voxel_size_m: a length in metres, for example 0.005"),
            "{text}"
        );
        assert!(text.contains("line 2") && !text.contains("f32"), "{text}");
        let err = parse("[pipeline]\nring_capacity = -1\n").unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("pipeline.ring_capacity: a whole number") && !text.contains("usize"),
            "{text}"
        );
        let err = parse(
            "[[sensor]]\nspec = \"sim\"\n[[sensor]]\nspec = \"sim\"\n\
             pose = { translation_m = [1, 0], rotation_deg = [0, 0, 90] }\n",
        )
        .unwrap_err();
        let text = err.to_string();
        assert!(
            text.contains("sensor.pose.translation_m: three lengths in metres"),
            "{text}"
        );
        assert!(
            text.contains("line 5") && text.contains("2 values"),
            "{text}"
        );
        let err = parse("[mesh]\nfit_to_data = \"yes\"\n").unwrap_err();
        assert!(
            err.to_string().contains("mesh.fit_to_data: true or false"),
            "{err}"
        );
        let err = parse("[socket]\ngroup = [1]\n").unwrap_err();
        assert!(
            err.to_string()
                .ends_with("socket.group: a group name or number, for example \"robot\" or 1001"),
            "{err}"
        );
        let err = parse("track = 3\n").unwrap_err();
        assert!(
            err.to_string().contains("track: a [track] table")
                && !err.to_string().contains("struct"),
            "{err}"
        );
    }

    /// Every key the example file lists, commented out or not, has its wants in words.
    #[test]
    fn every_example_key_says_what_it_wants() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tacmesh.example.toml");
        let text = std::fs::read_to_string(path).unwrap();
        // Uncomment the optional keys (`# key = value  # note`), leave the prose.
        let uncommented: String = text
            .lines()
            .map(|line| match line.strip_prefix("# ") {
                Some(rest) if rest.split_once(" = ").is_some_and(|(k, _)| is_bare_key(k)) => {
                    rest.to_owned()
                }
                // An optional section's header (`# [zenoh]`).
                Some(rest)
                    if rest
                        .strip_prefix('[')
                        .and_then(|r| r.strip_suffix(']'))
                        .is_some_and(is_bare_key) =>
                {
                    rest.to_owned()
                }
                _ => line.to_owned(),
            })
            .map(|line| line + "\n")
            .collect();
        let document = toml::de::DeTable::parse(&uncommented).unwrap();
        let mut keys = Vec::new();
        fn leaves(prefix: &str, value: &toml::de::DeValue<'_>, keys: &mut Vec<String>) {
            match value {
                toml::de::DeValue::Table(table) => {
                    for (key, value) in table {
                        let path = format!("{prefix}.{}", key.get_ref());
                        if matches!(value.get_ref(), toml::de::DeValue::Table(_)) {
                            keys.push(path.clone());
                        }
                        leaves(&path, value.get_ref(), keys);
                    }
                }
                toml::de::DeValue::Array(items) => {
                    for item in items.iter() {
                        leaves(prefix, item.get_ref(), keys);
                    }
                }
                _ => keys.push(prefix.to_owned()),
            }
        }
        for (key, value) in document.get_ref() {
            if !matches!(value.get_ref(), toml::de::DeValue::Table(_)) {
                keys.push(key.get_ref().to_string());
            }
            leaves(key.get_ref(), value.get_ref(), &mut keys);
        }
        keys.sort();
        keys.dedup();
        assert!(keys.len() > 20, "{keys:?}");
        for key in &keys {
            assert!(key_wants(key).is_some(), "{key} has no words in KEY_WANTS");
        }
    }

    fn is_bare_key(key: &str) -> bool {
        !key.is_empty() && key.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    }

    #[test]
    fn a_workspace_box_bounds_what_is_segmented() {
        let config = parse("[workspace]\nmin_m = [-1, -1, 0]\nmax_m = [1, 1, 0.8]\n").unwrap();
        let box_ = &config.workspace;
        assert!(box_.is_bounded());
        assert!(box_.contains(glam::Vec3::new(0.5, -0.5, 0.4)));
        assert!(!box_.contains(glam::Vec3::new(0.5, -0.5, 0.9)));
        assert!(!DaemonConfig::default().workspace.is_bounded());
        assert!(DaemonConfig::default()
            .workspace
            .contains(glam::Vec3::splat(1e6)));
        let err = parse("[workspace]\nmin_m = [0, 0, 1]\nmax_m = [1, 1, 1]\n").unwrap_err();
        assert!(err.to_string().contains("workspace.max_m"), "{err}");
        let err = parse("[workspace]\nmax_object_size_m = 0\n").unwrap_err();
        assert!(
            err.to_string().contains("workspace.max_object_size_m"),
            "{err}"
        );
    }

    #[test]
    fn the_example_file_parses_to_the_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("tacmesh.example.toml");
        let config = DaemonConfig::load(&path).unwrap();
        let mut expected = DaemonConfig::default();
        expected.socket.path = config.socket.path.clone();
        expected.socket.mode = Some("0660".into());
        assert_eq!(config, expected);
    }
}
