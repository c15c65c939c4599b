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
//! | `v4l2:…`, `openni2:…`, `depthai:…` | hardware backends not in this build (a clear error) |

use std::path::{Path, PathBuf};

use tacmesh_sim::SceneFile;
use tacmesh_source::DepthSource;

use super::config::SensorSection;

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
    /// A Camsense X1-style scanner on a serial port.
    Camsense(String),
    /// An RPLIDAR A-series on a serial port, at a baud rate.
    Rplidar { port: String, baud: u32 },
}

/// Why a sensor could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SensorError {
    #[error(
        "unknown sensor spec {spec:?}: expected `sim`, `sim:SCENE.toml`, `replay:FILE.oni|.bag`, \
         `serial:camsense:PORT` or `serial:rplidar:PORT[@BAUD]`"
    )]
    Unknown { spec: String },
    #[error(
        "sensor {spec:?}: the {backend} backend is not part of this build of tacmesh yet; \
         use `sim`, `sim:SCENE.toml`, `replay:PATH` or `serial:…`"
    )]
    NotBuilt { spec: String, backend: &'static str },
    #[error(transparent)]
    SceneFile(#[from] tacmesh_sim::SceneFileError),
    #[error("the simulated camera of {name} cannot be built: {source}")]
    Camera {
        name: String,
        source: tacmesh_sim::DepthCameraError,
    },
    #[error(transparent)]
    Oni(#[from] tacmesh_oni::OniError),
    #[error(transparent)]
    Bag(#[from] tacmesh_rosbag::ReplayError),
    #[error(transparent)]
    Device(#[from] tacmesh_source::SourceError),
    #[error(transparent)]
    Sequence(#[from] tacmesh_replay::ReplayError),
}

impl SensorSpec {
    /// Whether the source is a recording: read without losing frames (the reader waits for
    /// the pipeline) rather than dropping the oldest like a live sensor.
    pub fn is_recording(&self) -> bool {
        matches!(
            self,
            SensorSpec::Oni(_) | SensorSpec::Bag(_) | SensorSpec::Sequence(_)
        )
    }

    pub fn parse(spec: &str) -> Result<SensorSpec, SensorError> {
        let unknown = || SensorError::Unknown { spec: spec.into() };
        let (backend, rest) = match spec.split_once(':') {
            Some((backend, rest)) => (backend, Some(rest)),
            None => (spec, None),
        };
        match (backend, rest) {
            ("sim", None | Some("") | Some("demo")) => Ok(SensorSpec::SimDemo),
            ("sim", Some(path)) => Ok(SensorSpec::SimScene(PathBuf::from(path))),
            ("replay", Some(path)) if !path.is_empty() => {
                let path = PathBuf::from(path);
                match extension(&path).as_str() {
                    "oni" => Ok(SensorSpec::Oni(path)),
                    "bag" => Ok(SensorSpec::Bag(path)),
                    _ => Ok(SensorSpec::Sequence(Box::new(
                        tacmesh_replay::ReplaySpec::parse(&path.to_string_lossy())?,
                    ))),
                }
            }
            ("serial", Some(rest)) => match rest.split_once(':') {
                Some(("camsense", port)) if !port.is_empty() => {
                    Ok(SensorSpec::Camsense(port.into()))
                }
                Some(("rplidar", port)) if !port.is_empty() => {
                    let (port, baud) = match port.rsplit_once('@') {
                        Some((port, baud)) => (port, baud.parse().map_err(|_| unknown())?),
                        None => (port, tacmesh_serial::SerialConfig::RPLIDAR_A1_A2.baud_rate),
                    };
                    Ok(SensorSpec::Rplidar {
                        port: port.into(),
                        baud,
                    })
                }
                _ => Err(unknown()),
            },
            ("v4l2" | "openni2" | "depthai", _) => Err(SensorError::NotBuilt {
                spec: spec.into(),
                backend: match backend {
                    "v4l2" => "V4L2",
                    "openni2" => "OpenNI2",
                    _ => "DepthAI",
                },
            }),
            _ => Err(unknown()),
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
                    .map_err(|source| SensorError::Camera { name, source })?;
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
        let err = SensorSpec::parse("v4l2:/dev/video2").unwrap_err();
        assert!(err.to_string().contains("V4L2"), "{err}");
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
