//! The daemon's configuration: a strict TOML file (unknown keys are errors naming the key and
//! line), every key optional with the default documented beside it. `tacmesh.example.toml` at
//! the repository root lists them all.

use super::access::{allowed_peers, group_id, AccessError, Principal};
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
    pub track: TrackSection,
    pub mesh: MeshSection,
    pub stats: StatsSection,
    pub log: LogSection,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            sensor: vec![SensorSection::default()],
            socket: SocketSection::default(),
            pipeline: PipelineSection::default(),
            track: TrackSection::default(),
            mesh: MeshSection::default(),
            stats: StatsSection::default(),
            log: LogSection::default(),
        }
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
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SocketSection {
    /// Socket path. Default `$XDG_RUNTIME_DIR/tacmesh.sock`, or `tacmesh-UID.sock` (UID: the
    /// numeric user id) in the temporary directory when there is no runtime directory.
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
}

impl Default for TrackSection {
    fn default() -> Self {
        Self {
            voxel_size_m: 0.005,
            leave_after_s: 1.0,
            remesh_interval_s: 0.25,
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
    /// Threads meshing objects side by side. Default 2: when several objects change at
    /// once, the second keeps their new meshes from queueing behind each other.
    pub workers: usize,
}

impl Default for MeshSection {
    fn default() -> Self {
        Self {
            max_residual_m: 0.004,
            fit_to_data: true,
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

/// A configuration that cannot be used; the daemon stops before it starts anything.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read the config file {}: {source}", path.display())]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("config file {}: {message}", path.display())]
    Parse { path: PathBuf, message: String },
    #[error("config: {key} = {value} is out of range: {expected}")]
    OutOfRange {
        key: &'static str,
        value: String,
        expected: &'static str,
    },
    #[error(transparent)]
    Access(#[from] AccessError),
}

impl DaemonConfig {
    /// Reads and checks a config file.
    pub fn load(path: &Path) -> Result<DaemonConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        Self::parse(&text, path)
    }

    /// Parses and checks config text; `path` names it in errors.
    pub fn parse(text: &str, path: &Path) -> Result<DaemonConfig, ConfigError> {
        let config: DaemonConfig = toml::from_str(text).map_err(|err| ConfigError::Parse {
            path: path.to_owned(),
            message: describe_toml_error(text, &err),
        })?;
        config.validate()?;
        Ok(config)
    }

    /// Checks every value's range, so that a bad config fails at start and not mid-run.
    pub fn validate(&self) -> Result<(), ConfigError> {
        fn positive(key: &'static str, value: f32) -> Result<(), ConfigError> {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(ConfigError::OutOfRange {
                    key,
                    value: value.to_string(),
                    expected: "a finite number above 0",
                })
            }
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
        positive("pipeline.max_range_m", self.pipeline.max_range_m)?;
        positive("track.voxel_size_m", self.track.voxel_size_m)?;
        positive("track.leave_after_s", self.track.leave_after_s)?;
        positive("track.remesh_interval_s", self.track.remesh_interval_s)?;
        positive("mesh.max_residual_m", self.mesh.max_residual_m)?;
        positive("stats.publish_interval_s", self.stats.publish_interval_s)?;
        positive("stats.log_interval_s", self.stats.log_interval_s)?;
        if !(1..=64).contains(&self.pipeline.ring_capacity) {
            return Err(ConfigError::OutOfRange {
                key: "pipeline.ring_capacity",
                value: self.pipeline.ring_capacity.to_string(),
                expected: "1 to 64 frames",
            });
        }
        if !(1..=16).contains(&self.mesh.workers) {
            return Err(ConfigError::OutOfRange {
                key: "mesh.workers",
                value: self.mesh.workers.to_string(),
                expected: "1 to 16 threads",
            });
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
        Ok(())
    }

    /// The socket file mode: `socket.mode` parsed as octal, or 0660.
    pub fn socket_mode(&self) -> Result<u32, ConfigError> {
        let Some(text) = &self.socket.mode else {
            return Ok(tacmesh_publish::DEFAULT_SOCKET_MODE);
        };
        let digits = text.trim_start_matches("0o");
        match u32::from_str_radix(digits, 8) {
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
        Duration::from_secs_f32(self.track.leave_after_s)
    }

    pub(crate) fn remesh_interval(&self) -> Duration {
        Duration::from_secs_f32(self.track.remesh_interval_s)
    }
}

/// `$XDG_RUNTIME_DIR/tacmesh.sock` when the runtime directory is set and exists, else
/// `tacmesh-UID.sock` in the temporary directory (`$TMPDIR`, else `/tmp`), UID being the
/// process's numeric user id: per user, so two users do not collide, and the same for the
/// daemon and `tacmesh subscribe` whatever their environment (`$USER` is often unset under
/// systemd, cron or `env -i`, and can be set to anything).
pub fn default_socket_path() -> PathBuf {
    default_socket_path_for(
        std::env::var_os("XDG_RUNTIME_DIR").map(PathBuf::from),
        &std::env::temp_dir(),
        nix::unistd::geteuid().as_raw(),
    )
}

/// [`default_socket_path`] for a given runtime directory, temporary directory and user id.
fn default_socket_path_for(runtime_dir: Option<PathBuf>, temp_dir: &Path, uid: u32) -> PathBuf {
    match runtime_dir {
        Some(dir) if dir.is_dir() => dir.join("tacmesh.sock"),
        _ => temp_dir.join(format!("tacmesh-{uid}.sock")),
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

/// The toml crate's message with the line number it points at, in one line.
fn describe_toml_error(text: &str, err: &toml::de::Error) -> String {
    let message = err.message().trim_end().to_owned();
    match err.span() {
        Some(span) => {
            let line = text[..span.start.min(text.len())].matches('\n').count() + 1;
            format!("line {line}: {message}")
        }
        None => message,
    }
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
    fn default_socket_is_in_the_runtime_dir_else_named_by_uid() {
        let runtime = tempfile::tempdir().unwrap();
        let tmp = Path::new("/tmp");
        assert_eq!(
            default_socket_path_for(Some(runtime.path().to_owned()), tmp, 1000),
            runtime.path().join("tacmesh.sock")
        );
        let gone = runtime.path().join("gone");
        for runtime_dir in [None, Some(gone)] {
            assert_eq!(
                default_socket_path_for(runtime_dir, tmp, 1000),
                Path::new("/tmp/tacmesh-1000.sock")
            );
        }
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
