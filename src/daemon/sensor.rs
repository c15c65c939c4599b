//! `--sensor SPEC`: which backend to open, by the prefix of its spec.

use std::path::PathBuf;

use tacmesh_sim::SceneFile;
use tacmesh_source::DepthSource;

/// A sensor spec, parsed.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorSpec {
    /// The built-in demo scene.
    SimDemo,
    /// A simulated camera over a scene file.
    SimScene(PathBuf),
}

/// Why a sensor could not be opened.
#[derive(Debug, thiserror::Error)]
pub enum SensorError {
    #[error(
        "unknown sensor spec {spec:?}: expected `sim`, `sim:demo` or `sim:SCENE.toml` \
         (hardware backends come with later versions)"
    )]
    Unknown { spec: String },
    #[error(transparent)]
    SceneFile(#[from] tacmesh_sim::SceneFileError),
    #[error("the simulated camera of {name} cannot be built: {source}")]
    Camera {
        name: String,
        source: tacmesh_sim::DepthCameraError,
    },
}

impl SensorSpec {
    pub fn parse(spec: &str) -> Result<SensorSpec, SensorError> {
        let unknown = || SensorError::Unknown { spec: spec.into() };
        let (backend, rest) = match spec.split_once(':') {
            Some((backend, rest)) => (backend, Some(rest)),
            None => (spec, None),
        };
        match (backend, rest) {
            ("sim", None | Some("") | Some("demo")) => Ok(SensorSpec::SimDemo),
            ("sim", Some(path)) => Ok(SensorSpec::SimScene(PathBuf::from(path))),
            _ => Err(unknown()),
        }
    }

    /// Opens the source. `paced` overrides the scene's pacing when given.
    pub fn open(&self, paced: Option<bool>) -> Result<Box<dyn DepthSource>, SensorError> {
        let scene = match self {
            SensorSpec::SimDemo => SceneFile::demo(),
            SensorSpec::SimScene(path) => SceneFile::load(path)?,
        };
        let name = scene.name.clone();
        let mut camera = scene
            .into_camera()
            .map_err(|source| SensorError::Camera { name, source })?;
        if let Some(paced) = paced {
            camera.set_paced(paced);
        }
        Ok(Box::new(camera))
    }
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
        let err = SensorSpec::parse("kinect:0").unwrap_err();
        assert!(err.to_string().contains("kinect:0"), "{err}");
    }
}
