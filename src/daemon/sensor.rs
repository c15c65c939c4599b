//! `--sensor SPEC` / `[[sensor]] spec`: which backend to open, by the prefix of its spec.
//!
//! | spec | backend |
//! |---|---|
//! | `sim`, `sim:demo` | the simulated demo scene |
//! | `sim:SCENE.toml` | a simulated camera over a scene file |
//! | `replay:FILE.oni` | an OpenNI recording, read by our own reader (`tacmesh-oni`) |
//! | `replay:FILE.bag` | a RealSense ROS bag (v2, LZ4 chunks), by `tacmesh-rosbag` |
//! | `replay:PATH?fx=…&fy=…&cx=…&cy=…[&depth_scale_m=…&rate=…]` | depth images (16-bit PNG, TIFF, PGM, Z16) or clouds (PCD, PLY, XYZ): a folder, a TUM `depth.txt`, one file (`tacmesh-replay`; keys in its docs) |
//! | `serial:camsense:PORT` | a Camsense X1-style 360° scanner (115200 baud) |
//! | `serial:rplidar:PORT[@BAUD]` | an RPLIDAR A-series (115200 baud; A3: `@256000`) |
//! | `v4l2:/dev/videoN?fx=…&fy=…&cx=…&cy=…[&width=640&height=480&fps=30&depth_scale_m=0.001]` | a V4L2 depth camera (Z16 or Y16), with the cargo feature `v4l2` |
//! | `openni2:` (first device), `openni2:URI` (a device URI or an .oni file) | OpenNI2 through our own FFI, with the cargo feature `openni2` |
//! | `depthai:[DEVICE][?width=…&height=…&fps=…&align=left\|right\|rgb&preset=…&record=FILE.mcap&venv=…]` | a Luxonis OAK camera's stereo depth through DepthAI's Python package, with the cargo feature `depthai` |
//! | `depthai:FILE.mcap[?rate=max&venv=…]` | a DepthAI recording (same feature) |

use std::path::{Path, PathBuf};

use tacmesh_sim::SceneFile;
use tacmesh_source::DepthSource;

use super::config::SensorSection;

/// The kinds of spec the parser accepts, by prefix: [`SensorSpec::parse`] finds a spec's kind
/// in [`SpecKind::ALL`] and nowhere else, so this table is the list of what `--sensor` takes
/// (`tacmesh run --help` and the README's sensor table must name every prefix in it; a test
/// checks the help).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SpecKind {
    /// `sim`, `sim:demo`, `sim:SCENE.toml`
    Sim,
    /// `replay:PATH[?…]`
    Replay,
    /// `serial:camsense:PORT`
    Camsense,
    /// `serial:rplidar:PORT[@BAUD]`
    Rplidar,
    /// `v4l2:/dev/videoN?fx=…`
    V4l2,
    /// `openni2:[URI]`
    OpenNi2,
    /// `depthai:[DEVICE|FILE.mcap][?…]`
    DepthAi,
}

impl SpecKind {
    /// Every kind, in the order the help lists them.
    pub const ALL: [SpecKind; 7] = [
        SpecKind::Sim,
        SpecKind::Replay,
        SpecKind::Camsense,
        SpecKind::Rplidar,
        SpecKind::V4l2,
        SpecKind::OpenNi2,
        SpecKind::DepthAi,
    ];

    /// The prefix a spec of this kind starts with. `sim`, `openni2` and `depthai` may also
    /// stand alone (no colon, no options).
    pub fn prefix(self) -> &'static str {
        match self {
            SpecKind::Sim => "sim:",
            SpecKind::Replay => "replay:",
            SpecKind::Camsense => "serial:camsense:",
            SpecKind::Rplidar => "serial:rplidar:",
            SpecKind::V4l2 => "v4l2:",
            SpecKind::OpenNi2 => "openni2:",
            SpecKind::DepthAi => "depthai:",
        }
    }

    /// The backend's name and the cargo feature that builds it, for the backends behind one.
    pub fn feature(self) -> Option<(&'static str, &'static str)> {
        match self {
            SpecKind::V4l2 => Some(("V4L2", "v4l2")),
            SpecKind::OpenNi2 => Some(("OpenNI2", "openni2")),
            SpecKind::DepthAi => Some(("DepthAI", "depthai")),
            SpecKind::Sim | SpecKind::Replay | SpecKind::Camsense | SpecKind::Rplidar => None,
        }
    }

    /// Whether this build has the backend.
    pub fn is_built(self) -> bool {
        match self {
            SpecKind::V4l2 => cfg!(feature = "v4l2"),
            SpecKind::OpenNi2 => cfg!(feature = "openni2"),
            SpecKind::DepthAi => cfg!(feature = "depthai"),
            SpecKind::Sim | SpecKind::Replay | SpecKind::Camsense | SpecKind::Rplidar => true,
        }
    }

    /// The kind of `spec` and what follows its prefix.
    fn split(spec: &str) -> Option<(SpecKind, &str)> {
        SpecKind::ALL.into_iter().find_map(|kind| {
            let prefix = kind.prefix();
            let alone = matches!(kind, SpecKind::Sim | SpecKind::OpenNi2 | SpecKind::DepthAi)
                && spec == prefix.trim_end_matches(':');
            if alone {
                Some((kind, ""))
            } else {
                spec.strip_prefix(prefix).map(|rest| (kind, rest))
            }
        })
    }
}

/// A sensor spec, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorSpec {
    /// The built-in demo scene.
    SimDemo,
    /// A simulated camera over a scene file.
    SimScene(PathBuf),
    /// An OpenNI `.oni` recording.
    Oni(PathBuf),
    /// A ROS bag (RealSense `.bag`).
    Bag(PathBuf),
    /// Depth images or clouds (a folder, a list, one file), with their options.
    Sequence(Box<tacmesh_replay::ReplaySpec>),
    /// A V4L2 depth camera: its node and intrinsics (the resolution asked of it) and options.
    V4l2(Box<V4l2Spec>),
    /// An OpenNI2 device: `None` is the first one found, else a URI or an `.oni` path.
    OpenNi2(Option<String>),
    /// A Camsense X1-style scanner on a serial port.
    Camsense(String),
    /// An RPLIDAR A-series on a serial port, at a baud rate.
    Rplidar { port: String, baud: u32 },
    /// A Luxonis OAK camera, or a DepthAI `.mcap` recording.
    DepthAi(Box<tacmesh_depthai::DepthAiOptions>),
}

/// `v4l2:DEVICE?key=value&…`: the device node, the intrinsics (fx, fy, cx, cy required; width
/// and height default to 640×480 and are what the camera is asked for), the frame rate and the
/// depth scale (metres per unit).
#[derive(Debug, Clone, PartialEq)]
pub struct V4l2Spec {
    pub device: String,
    pub intrinsics: tacmesh_source::Intrinsics,
    pub fps: u32,
    pub depth_scale_m: f32,
}

impl V4l2Spec {
    fn parse(spec: &str, rest: &str) -> Result<V4l2Spec, SensorError> {
        let bad = |reason: String| SensorError::BadOption {
            spec: spec.into(),
            reason,
        };
        let (device, query) = rest.split_once('?').unwrap_or((rest, ""));
        if device.is_empty() {
            return Err(bad("no device node, e.g. v4l2:/dev/video2?fx=…".into()));
        }
        let (mut width, mut height, mut fps) = (640u32, 480u32, 30u32);
        let mut depth_scale_m = 0.001f32;
        let (mut fx, mut fy, mut cx, mut cy) = (None, None, None, None);
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(format!("{pair:?} is not key=value")))?;
            let number = |v: &str| -> Result<f32, SensorError> {
                v.parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite())
                    .ok_or_else(|| bad(format!("{key} = {v:?} is not a number")))
            };
            let whole = |v: &str| -> Result<u32, SensorError> {
                v.parse::<u32>()
                    .map_err(|_| bad(format!("{key} = {v:?} is not a whole number")))
            };
            match key {
                "fx" => fx = Some(number(value)?),
                "fy" => fy = Some(number(value)?),
                "cx" => cx = Some(number(value)?),
                "cy" => cy = Some(number(value)?),
                "width" => width = whole(value)?,
                "height" => height = whole(value)?,
                "fps" => fps = whole(value)?,
                "depth_scale_m" => depth_scale_m = number(value)?,
                _ => {
                    return Err(bad(format!(
                        "unknown key {key:?} (fx, fy, cx, cy, width, height, fps, depth_scale_m)"
                    )))
                }
            }
        }
        let (Some(fx), Some(fy), Some(cx), Some(cy)) = (fx, fy, cx, cy) else {
            return Err(bad(
                "the intrinsics fx, fy, cx and cy are required (from the camera's calibration)"
                    .into(),
            ));
        };
        if !(1..=8192).contains(&width) || !(1..=8192).contains(&height) {
            return Err(bad(format!(
                "{width}x{height}: width and height are 1 to 8192 pixels"
            )));
        }
        if !(1..=1000).contains(&fps) {
            return Err(bad(format!(
                "fps = {fps}: a camera's rate is 1 to 1000 frames a second"
            )));
        }
        if !(depth_scale_m > 0.0 && depth_scale_m <= 1.0) {
            return Err(bad(format!(
                "depth_scale_m = {depth_scale_m}: metres per unit, above 0 and at most 1 (0.001 \
                 for millimetres)"
            )));
        }
        let intrinsics = tacmesh_source::Intrinsics {
            width,
            height,
            fx,
            fy,
            cx,
            cy,
        };
        intrinsics.check_plausible().map_err(bad)?;
        Ok(V4l2Spec {
            device: device.into(),
            intrinsics,
            fps,
            depth_scale_m,
        })
    }
}

/// Why a sensor could not be opened.
/// Each message states its cause itself; the cause is a field named `cause`, not `source`, so
/// that a printer of error chains (anyhow's `{:#}`) does not print it a second time.
#[derive(Debug, thiserror::Error)]
pub enum SensorError {
    #[error(
        "unknown sensor spec {spec:?}: expected `sim`, `sim:SCENE.toml`, `replay:PATH`, \
         `serial:camsense:PORT`, `serial:rplidar:PORT[@BAUD]`, `v4l2:/dev/videoN?…`, \
         `openni2:[URI]` or `depthai:[DEVICE|FILE.mcap]` (see `tacmesh run --help`)"
    )]
    Unknown { spec: String },
    #[error(
        "sensor {spec:?}: this tacmesh was built without the {backend} backend; rebuild with \
         `cargo build --release --features {feature}`"
    )]
    FeatureOff {
        spec: String,
        backend: &'static str,
        feature: &'static str,
    },
    #[error("sensor {spec:?}: {reason}")]
    BadOption { spec: String, reason: String },
    #[error(transparent)]
    SceneFile(#[from] tacmesh_sim::SceneFileError),
    #[error("the simulated camera of {name} cannot be built: {cause}")]
    Camera {
        name: String,
        cause: tacmesh_sim::DepthCameraError,
    },
    #[error(transparent)]
    Oni(#[from] tacmesh_oni::OniError),
    #[error(transparent)]
    Bag(#[from] tacmesh_rosbag::ReplayError),
    #[error(transparent)]
    Device(#[from] tacmesh_source::SourceError),
    #[error(transparent)]
    Sequence(#[from] tacmesh_replay::ReplayError),
    #[error(transparent)]
    DepthAi(#[from] tacmesh_depthai::DepthAiError),
}

impl SensorError {
    /// Whether the sensor is simply not there (unplugged, not yet enumerated, no camera on the
    /// bus), as opposed to a wrong spec, a missing file or a backend not built: the daemon
    /// starts without an absent device and keeps trying to open it.
    pub fn is_device_absent(&self) -> bool {
        matches!(
            self,
            SensorError::Device(tacmesh_source::SourceError::DeviceMissing { .. })
                | SensorError::DepthAi(tacmesh_depthai::DepthAiError::NoDevice { .. })
        )
    }
}

impl SensorSpec {
    /// Whether the source is a recording: read without losing frames (the reader waits for
    /// the pipeline) rather than dropping the oldest like a live sensor.
    pub fn is_recording(&self) -> bool {
        match self {
            SensorSpec::Oni(_) | SensorSpec::Bag(_) | SensorSpec::Sequence(_) => true,
            SensorSpec::DepthAi(options) => {
                matches!(options.mode, tacmesh_depthai::Mode::Replay(_))
            }
            _ => false,
        }
    }

    /// Parses a spec by its prefix (one of [`SpecKind::ALL`]). A spec of a backend this build
    /// lacks fails with [`SensorError::FeatureOff`] before its options are looked at: no point
    /// getting the intrinsics right for a backend that is not there.
    pub fn parse(spec: &str) -> Result<SensorSpec, SensorError> {
        let unknown = || SensorError::Unknown { spec: spec.into() };
        let (kind, rest) = SpecKind::split(spec).ok_or_else(unknown)?;
        if let Some((backend, feature)) = kind.feature().filter(|_| !kind.is_built()) {
            return Err(SensorError::FeatureOff {
                spec: spec.into(),
                backend,
                feature,
            });
        }
        match kind {
            SpecKind::Sim => match rest {
                "" | "demo" => Ok(SensorSpec::SimDemo),
                path => Ok(SensorSpec::SimScene(PathBuf::from(path))),
            },
            SpecKind::Replay => {
                if rest.is_empty() {
                    return Err(unknown());
                }
                let path = PathBuf::from(rest);
                match extension(&path).as_str() {
                    "oni" => Ok(SensorSpec::Oni(path)),
                    "bag" => Ok(SensorSpec::Bag(path)),
                    _ => Ok(SensorSpec::Sequence(Box::new(
                        tacmesh_replay::ReplaySpec::parse(rest)?,
                    ))),
                }
            }
            SpecKind::Camsense if !rest.is_empty() => Ok(SensorSpec::Camsense(rest.into())),
            SpecKind::Rplidar if !rest.is_empty() => {
                let (port, baud) = match rest.rsplit_once('@') {
                    Some((port, baud)) => (port, baud.parse().map_err(|_| unknown())?),
                    None => (rest, tacmesh_serial::SerialConfig::RPLIDAR_A1_A2.baud_rate),
                };
                Ok(SensorSpec::Rplidar {
                    port: port.into(),
                    baud,
                })
            }
            SpecKind::Camsense | SpecKind::Rplidar => Err(unknown()),
            SpecKind::V4l2 => Ok(SensorSpec::V4l2(Box::new(V4l2Spec::parse(spec, rest)?))),
            SpecKind::OpenNi2 => Ok(SensorSpec::OpenNi2(
                Some(rest).filter(|uri| !uri.is_empty()).map(str::to_owned),
            )),
            SpecKind::DepthAi => Ok(SensorSpec::DepthAi(Box::new(
                tacmesh_depthai::DepthAiOptions::parse_spec(rest)?,
            ))),
        }
    }

    /// Opens the source with the section's options (pacing, looping).
    pub fn open(&self, section: &SensorSection) -> Result<Box<dyn DepthSource>, SensorError> {
        match self {
            SensorSpec::SimDemo | SensorSpec::SimScene(_) => {
                let scene = match self {
                    SensorSpec::SimScene(path) => SceneFile::load(path)?,
                    _ => SceneFile::demo(),
                };
                let name = scene.name.clone();
                let mut camera = scene
                    .into_camera()
                    .map_err(|cause| SensorError::Camera { name, cause })?;
                if let Some(paced) = section.paced {
                    camera.set_paced(paced);
                }
                Ok(Box::new(camera))
            }
            SensorSpec::Bag(path) => {
                use tacmesh_rosbag::{BagReplay, Pacing, ReplayOptions};
                let options = ReplayOptions {
                    pacing: if section.paced == Some(false) {
                        Pacing::MaxRate
                    } else {
                        Pacing::Recorded
                    },
                    looping: section.looping,
                    depth_topic: None,
                };
                Ok(Box::new(BagReplay::open(
                    path,
                    glam::Affine3A::IDENTITY,
                    options,
                )?))
            }
            SensorSpec::Sequence(spec) => {
                let mut spec = spec.as_ref().clone();
                if section.looping {
                    spec.looping = true;
                }
                if section.paced == Some(false) {
                    spec.rate = Some(tacmesh_replay::Rate::Max);
                }
                Ok(Box::new(spec.open()?))
            }
            SensorSpec::V4l2(v4l2) => open_v4l2(v4l2),
            SensorSpec::OpenNi2(uri) => open_openni2(uri.as_deref()),
            SensorSpec::DepthAi(options) => {
                let mut options = options.as_ref().clone();
                if let tacmesh_depthai::Mode::Replay(replay) = &mut options.mode {
                    replay.looping |= section.looping;
                    if section.paced == Some(false) {
                        replay.max_rate = true;
                    }
                }
                open_depthai(options)
            }
            SensorSpec::Camsense(port) => Ok(Box::new(tacmesh_serial::CamsenseSource::open(
                port,
                glam::Affine3A::IDENTITY,
            )?)),
            SensorSpec::Rplidar { port, baud } => {
                let config = tacmesh_serial::SerialConfig {
                    baud_rate: *baud,
                    ..tacmesh_serial::SerialConfig::RPLIDAR_A1_A2
                };
                Ok(Box::new(tacmesh_serial::RplidarSource::open(
                    port,
                    config,
                    glam::Affine3A::IDENTITY,
                )?))
            }
            SensorSpec::Oni(path) => {
                use tacmesh_oni::{AtEnd, OniReplay, Pacing, ReplayOptions};
                let options = ReplayOptions {
                    pacing: if section.paced == Some(false) {
                        Pacing::AsFastAsRead
                    } else {
                        Pacing::Recorded
                    },
                    at_end: if section.looping {
                        AtEnd::Loop
                    } else {
                        AtEnd::Stop
                    },
                    ..ReplayOptions::default()
                };
                Ok(Box::new(OniReplay::open(path, options)?))
            }
        }
    }
}

#[cfg(feature = "v4l2")]
fn open_v4l2(spec: &V4l2Spec) -> Result<Box<dyn DepthSource>, SensorError> {
    let mut config = tacmesh_v4l2::V4l2Config::new(spec.device.clone(), spec.intrinsics);
    config.fps = spec.fps;
    config.depth_scale_m = spec.depth_scale_m;
    match tacmesh_v4l2::V4l2Source::open(&config) {
        Ok(source) => Ok(Box::new(source)),
        Err(tacmesh_v4l2::V4l2Error::Source(err)) => Err(SensorError::Device(err)),
        Err(err) => Err(SensorError::BadOption {
            spec: format!("v4l2:{}", spec.device),
            reason: err.to_string(),
        }),
    }
}

#[cfg(not(feature = "v4l2"))]
fn open_v4l2(spec: &V4l2Spec) -> Result<Box<dyn DepthSource>, SensorError> {
    Err(SensorError::FeatureOff {
        spec: format!("v4l2:{}", spec.device),
        backend: "V4L2",
        feature: "v4l2",
    })
}

#[cfg(feature = "openni2")]
fn open_openni2(uri: Option<&str>) -> Result<Box<dyn DepthSource>, SensorError> {
    let source = tacmesh_openni2::OpenNi2Source::open(uri, Default::default())?;
    Ok(Box::new(source))
}

#[cfg(not(feature = "openni2"))]
fn open_openni2(uri: Option<&str>) -> Result<Box<dyn DepthSource>, SensorError> {
    Err(SensorError::FeatureOff {
        spec: format!("openni2:{}", uri.unwrap_or("")),
        backend: "OpenNI2",
        feature: "openni2",
    })
}

#[cfg(feature = "depthai")]
fn open_depthai(
    options: tacmesh_depthai::DepthAiOptions,
) -> Result<Box<dyn DepthSource>, SensorError> {
    Ok(Box::new(tacmesh_depthai::DepthAiSource::open(options)?))
}

#[cfg(not(feature = "depthai"))]
fn open_depthai(
    options: tacmesh_depthai::DepthAiOptions,
) -> Result<Box<dyn DepthSource>, SensorError> {
    Err(SensorError::FeatureOff {
        spec: options.name(),
        backend: "DepthAI",
        feature: "depthai",
    })
}

fn extension(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_by_prefix() {
        assert_eq!(SensorSpec::parse("sim").unwrap(), SensorSpec::SimDemo);
        assert_eq!(SensorSpec::parse("sim:demo").unwrap(), SensorSpec::SimDemo);
        assert_eq!(
            SensorSpec::parse("sim:scenes/static.toml").unwrap(),
            SensorSpec::SimScene("scenes/static.toml".into())
        );
        assert_eq!(
            SensorSpec::parse("replay:a/b.ONI").unwrap(),
            SensorSpec::Oni("a/b.ONI".into())
        );
        let err = SensorSpec::parse("kinect:0").unwrap_err();
        assert!(err.to_string().contains("kinect:0"), "{err}");
        assert_eq!(
            SensorSpec::parse("serial:rplidar:/dev/ttyUSB0@256000").unwrap(),
            SensorSpec::Rplidar {
                port: "/dev/ttyUSB0".into(),
                baud: 256_000
            }
        );
        assert_eq!(
            SensorSpec::parse("serial:camsense:/dev/ttyUSB1").unwrap(),
            SensorSpec::Camsense("/dev/ttyUSB1".into())
        );
        assert!(SensorSpec::parse("serial:lds:/dev/ttyUSB1").is_err());
        assert!(SensorSpec::parse("simulated").is_err());
        assert!(SensorSpec::parse("replay:").is_err());
        if cfg!(feature = "openni2") {
            assert_eq!(
                SensorSpec::parse("openni2:").unwrap(),
                SensorSpec::OpenNi2(None)
            );
            assert_eq!(
                SensorSpec::parse("openni2").unwrap(),
                SensorSpec::OpenNi2(None)
            );
            assert_eq!(
                SensorSpec::parse("openni2:Dummy").unwrap(),
                SensorSpec::OpenNi2(Some("Dummy".into()))
            );
        }
        if cfg!(feature = "depthai") {
            let recording = SensorSpec::parse("depthai:runs/a.mcap?rate=max").unwrap();
            assert!(recording.is_recording());
            let err = SensorSpec::parse("depthai:?fps=0").unwrap_err();
            assert!(err.to_string().contains("fps"), "{err}");
        }
    }

    #[test]
    fn v4l2_options_need_intrinsics_and_known_keys() {
        let err = V4l2Spec::parse("v4l2:/dev/video2", "/dev/video2").unwrap_err();
        assert!(err.to_string().contains("fx, fy, cx and cy"), "{err}");
        let spec = "v4l2:/dev/video2?fx=390&fy=390&cx=331&cy=242&gain=3";
        let err = V4l2Spec::parse(spec, spec.trim_start_matches("v4l2:")).unwrap_err();
        assert!(err.to_string().contains("gain"), "{err}");
        // Values no camera has are refused where they are parsed, naming the key.
        for (options, key) in [
            ("fx=-5&fy=390&cx=331&cy=242", "fx="),
            ("fx=390&fy=0&cx=331&cy=242", "fy="),
            ("fx=0.5&fy=390&cx=331&cy=242", "fx="),
            ("fx=390&fy=390&cx=5000&cy=242", "cx="),
            ("fx=390&fy=390&cx=331&cy=242&width=0", "width"),
            ("fx=390&fy=390&cx=331&cy=242&fps=0", "fps"),
            (
                "fx=390&fy=390&cx=331&cy=242&depth_scale_m=-1",
                "depth_scale_m",
            ),
        ] {
            let spec = format!("v4l2:/dev/video2?{options}");
            let err = V4l2Spec::parse(&spec, spec.trim_start_matches("v4l2:")).unwrap_err();
            assert!(err.to_string().contains(key), "{options}: {err}");
        }
    }

    /// Without the feature, a spec of the backend says how to build it, whatever its options
    /// (it does not first ask for intrinsics it could not use), naming the spec as given.
    #[test]
    fn a_backend_not_built_says_so_before_checking_options() {
        for (spec, feature) in [
            ("v4l2:/dev/video99", "v4l2"),
            ("openni2:", "openni2"),
            ("depthai:", "depthai"),
            ("depthai:?fps=0", "depthai"),
        ] {
            let kind = SpecKind::split(spec).expect("a known prefix").0;
            if kind.is_built() {
                continue;
            }
            let text = SensorSpec::parse(spec).unwrap_err().to_string();
            assert!(
                text.contains(&format!("--features {feature}")),
                "{spec}: {text}"
            );
            assert!(text.contains(&format!("{spec:?}")), "{spec}: {text}");
            assert!(!text.contains("fx, fy"), "{spec}: {text}");
            assert!(!text.contains("first device"), "{spec}: {text}");
        }
    }

    #[test]
    fn v4l2_specs_carry_intrinsics() {
        let spec =
            "v4l2:/dev/video2?fx=390.43&fy=390.43&cx=331.39&cy=242.19&width=848&height=480&fps=15";
        let v4l2 = V4l2Spec::parse(spec, spec.trim_start_matches("v4l2:")).unwrap();
        assert_eq!(v4l2.device, "/dev/video2");
        assert_eq!((v4l2.intrinsics.width, v4l2.fps), (848, 15));
        assert_eq!(v4l2.depth_scale_m, 0.001);
        // With the feature, the missing node is named at open.
        if cfg!(feature = "v4l2") {
            let err = SensorSpec::parse(spec)
                .unwrap()
                .open(&SensorSection::default())
                .err()
                .expect("no camera here");
            assert!(err.to_string().contains("/dev/video2"), "{err}");
        }
    }

    #[test]
    fn a_depthai_recording_names_its_file_or_the_feature() {
        let err = match SensorSpec::parse("depthai:/nonexistent/run.mcap") {
            Ok(spec) => spec
                .open(&SensorSection::default())
                .err()
                .expect("no such recording"),
            Err(err) => err,
        };
        let text = err.to_string();
        if cfg!(feature = "depthai") {
            assert!(text.contains("/nonexistent/run.mcap"), "{text}");
        } else {
            assert!(text.contains("--features depthai"), "{text}");
        }
    }

    #[test]
    fn a_missing_recording_fails_at_open_naming_it() {
        let spec = SensorSpec::parse("replay:/nonexistent/x.oni").unwrap();
        let err = spec
            .open(&SensorSection::default())
            .err()
            .expect("no such file");
        assert!(err.to_string().contains("/nonexistent/x.oni"), "{err}");
    }
}
