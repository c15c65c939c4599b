//! What to replay, as the daemon's config or command line gives it.
//!
//! Entry points: [`ReplaySpec::parse`] for `PATH?key=value&...`, serde `Deserialize` for a
//! TOML table with the same keys, and [`ReplaySpec::open`] to get a [`ReplaySource`]. The keys
//! are listed in the crate docs.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use glam::Affine3A;
use serde::Deserialize;
use tacmesh_source::{DepthSource, Intrinsics, Observation, SourceError};

use crate::cache::DEFAULT_LOOP_CACHE_BYTES;
use crate::clouds::{CloudSequence, CloudSequenceConfig};
use crate::decode::{extension, is_depth_image_path, read_depth_image, Z16Layout};
use crate::images::{ImageSequence, ImageSequenceConfig};
use crate::listing::{
    is_cloud_path, list_clouds, list_depth_images, looks_like_association_file,
    read_association_file, read_pose_file, DepthFile,
};
use crate::pacing::Pacing;
use crate::ReplayError;

/// Whether a replay is of depth images or of point clouds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ReplayKind {
    Images,
    Clouds,
}

impl FromStr for ReplayKind {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "images" => Ok(Self::Images),
            "clouds" => Ok(Self::Clouds),
            _ => Err(format!("kind {s:?} is neither \"images\" nor \"clouds\"")),
        }
    }
}

/// The replay rate: `"recorded"`, `"max"` or frames per second.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(try_from = "RateRepr")]
pub enum Rate {
    Recorded,
    Max,
    Fps(f64),
}

#[derive(Deserialize)]
#[serde(untagged)]
enum RateRepr {
    Name(String),
    Fps(f64),
}

impl TryFrom<RateRepr> for Rate {
    type Error = String;

    fn try_from(repr: RateRepr) -> Result<Self, String> {
        match repr {
            RateRepr::Name(name) => name.parse(),
            RateRepr::Fps(fps) => Rate::fps(fps),
        }
    }
}

impl Rate {
    fn fps(fps: f64) -> Result<Self, String> {
        if fps.is_finite() && fps > 0.0 {
            Ok(Self::Fps(fps))
        } else {
            Err(format!(
                "rate {fps} must be a positive number of frames per second"
            ))
        }
    }
}

impl FromStr for Rate {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "recorded" => Ok(Self::Recorded),
            "max" => Ok(Self::Max),
            _ => s
                .parse()
                .map_err(|_| ())
                .and_then(|fps| Rate::fps(fps).map_err(|_| ()))
                .map_err(|()| {
                    format!(
                        "rate {s:?} is not \"recorded\", \"max\" or a positive frames per second"
                    )
                }),
        }
    }
}

/// A recorded sequence to replay; see the crate docs for each key's meaning and default.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReplaySpec {
    pub path: PathBuf,
    pub kind: Option<ReplayKind>,
    pub fx: Option<f32>,
    pub fy: Option<f32>,
    pub cx: Option<f32>,
    pub cy: Option<f32>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub row_stride_bytes: Option<usize>,
    pub depth_scale_m: Option<f32>,
    pub rate: Option<Rate>,
    #[serde(default, rename = "loop")]
    pub looping: bool,
    pub poses: Option<PathBuf>,
    /// `[tx, ty, tz, qx, qy, qz, qw]`, the order of a pose file's lines.
    pub world_from_sensor: Option<[f32; 7]>,
}

/// The depth scale when none is given: millimetres, as Kinect, PrimeSense and RealSense record.
pub const DEFAULT_DEPTH_SCALE_M: f32 = 0.001;

impl ReplaySpec {
    /// A spec of only a path, every key at its default.
    pub fn new(path: impl Into<PathBuf>) -> Self {
        Self {
            path: path.into(),
            kind: None,
            fx: None,
            fy: None,
            cx: None,
            cy: None,
            width: None,
            height: None,
            row_stride_bytes: None,
            depth_scale_m: None,
            rate: None,
            looping: false,
            poses: None,
            world_from_sensor: None,
        }
    }

    /// Parses `PATH[?key=value&key=value...]`. Unknown and repeated keys are errors; `loop`
    /// alone means `loop=true`; `world_from_sensor` is seven comma-separated numbers. Values
    /// are taken literally (no percent-decoding), and the path ends at the first `?`.
    pub fn parse(spec: &str) -> Result<Self, ReplayError> {
        let bad = |reason: String| ReplayError::Spec {
            spec: spec.to_owned(),
            reason,
        };
        let (path, query) = spec.split_once('?').unwrap_or((spec, ""));
        if path.is_empty() {
            return Err(bad("no path before the '?'".to_owned()));
        }
        let mut out = Self::new(path);
        let mut seen = Vec::new();
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair.split_once('=').unwrap_or((pair, "true"));
            if seen.contains(&key) {
                return Err(bad(format!("key {key:?} is given twice")));
            }
            seen.push(key);
            out.set(key, value).map_err(bad)?;
        }
        Ok(out)
    }

    fn set(&mut self, key: &str, value: &str) -> Result<(), String> {
        fn num<T: FromStr>(key: &str, value: &str) -> Result<Option<T>, String> {
            value
                .parse()
                .map(Some)
                .map_err(|_| format!("{key}={value:?} is not a number"))
        }
        match key {
            "kind" => self.kind = Some(value.parse()?),
            "fx" => self.fx = num(key, value)?,
            "fy" => self.fy = num(key, value)?,
            "cx" => self.cx = num(key, value)?,
            "cy" => self.cy = num(key, value)?,
            "width" => self.width = num(key, value)?,
            "height" => self.height = num(key, value)?,
            "row_stride_bytes" => self.row_stride_bytes = num(key, value)?,
            "depth_scale_m" => self.depth_scale_m = num(key, value)?,
            "rate" => self.rate = Some(value.parse()?),
            "loop" => {
                self.looping = value
                    .parse()
                    .map_err(|_| format!("loop={value:?} is neither true nor false"))?
            }
            "poses" => self.poses = Some(PathBuf::from(value)),
            "world_from_sensor" => {
                let fields: Vec<f32> = value
                    .split(',')
                    .map(|f| f.trim().parse())
                    .collect::<Result<_, _>>()
                    .map_err(|_| format!("world_from_sensor={value:?} is not numbers"))?;
                self.world_from_sensor = Some(fields.try_into().map_err(|_| {
                    "world_from_sensor needs 7 numbers: tx,ty,tz,qx,qy,qz,qw".to_owned()
                })?);
            }
            _ => {
                return Err(format!(
                    "unknown key {key:?}; the keys are kind, fx, fy, cx, cy, width, height, \
                     row_stride_bytes, depth_scale_m, rate, loop, poses, world_from_sensor"
                ))
            }
        }
        Ok(())
    }

    fn name(&self) -> String {
        self.path.display().to_string()
    }

    fn invalid(&self, reason: impl Into<String>) -> ReplayError {
        ReplayError::InvalidConfig {
            name: self.name(),
            reason: reason.into(),
        }
    }

    /// Decides, from the path, what the replay is and which files it plays. `.oni` and `.bag`
    /// are refused with [`ReplayError::NotASequence`] naming the crate that plays them.
    pub fn resolve(&self) -> Result<ReplayInput, ReplayError> {
        let path = &self.path;
        if let Some(handled_by) = handled_elsewhere(path) {
            return Err(ReplayError::NotASequence {
                name: self.name(),
                handled_by,
            });
        }
        let metadata = std::fs::metadata(path).map_err(|error| ReplayError::Io {
            name: self.name(),
            action: "open the replay path",
            error,
        })?;
        let want = |kind| self.kind.is_none_or(|k| k == kind);
        if metadata.is_dir() {
            let association = path.join("depth.txt");
            if want(ReplayKind::Images) && association.is_file() {
                return Ok(ReplayInput::Images(read_association_file(&association)?));
            }
            if want(ReplayKind::Images) {
                let images = list_depth_images(path)?;
                if !images.is_empty() || self.kind == Some(ReplayKind::Images) {
                    return Ok(ReplayInput::Images(images));
                }
            }
            let clouds = list_clouds(path)?;
            if !clouds.is_empty() || self.kind == Some(ReplayKind::Clouds) {
                return Ok(ReplayInput::Clouds(clouds));
            }
            return Err(ReplayError::NoFrames { name: self.name() });
        }
        let is_txt = extension(path) == "txt";
        let images = if is_txt {
            self.kind != Some(ReplayKind::Clouds) && looks_like_association_file(path)
        } else {
            is_depth_image_path(path)
        };
        let clouds = is_cloud_path(path) || (is_txt && !images);
        match (images, clouds) {
            (true, _) if want(ReplayKind::Images) && is_txt => {
                Ok(ReplayInput::Images(read_association_file(path)?))
            }
            (true, _) if want(ReplayKind::Images) => {
                Ok(ReplayInput::Images(vec![DepthFile::new(path)]))
            }
            (_, true) if want(ReplayKind::Clouds) => Ok(ReplayInput::Clouds(vec![path.clone()])),
            _ => Err(ReplayError::UnknownKind { name: self.name() }),
        }
    }

    fn world_from_sensor(&self) -> Result<Affine3A, ReplayError> {
        let Some(v) = self.world_from_sensor else {
            return Ok(Affine3A::IDENTITY);
        };
        let fields: Vec<String> = v.iter().map(f32::to_string).collect();
        let fields: Vec<&str> = fields.iter().map(String::as_str).collect();
        crate::listing::parse_pose(&fields)
            .map_err(|reason| self.invalid(format!("world_from_sensor: {reason}")))
    }

    /// Opens the replay: resolves the path, reads list and pose files, and checks the keys.
    /// For images without `width`/`height`, the first frame is decoded to learn its size.
    pub fn open(&self) -> Result<ReplaySource, ReplayError> {
        let world_from_sensor = self.world_from_sensor()?;
        let name = format!("replay:{}", self.path.display());
        match self.resolve()? {
            ReplayInput::Images(files) => {
                let first = files
                    .first()
                    .ok_or_else(|| ReplayError::NoFrames { name: self.name() })?;
                let (fx, fy, cx, cy) = match (self.fx, self.fy, self.cx, self.cy) {
                    (Some(fx), Some(fy), Some(cx), Some(cy)) => (fx, fy, cx, cy),
                    _ => return Err(ReplayError::MissingIntrinsics { name: self.name() }),
                };
                let z16_layout = match (self.width, self.height) {
                    (Some(width), Some(height)) => Some(Z16Layout {
                        width,
                        height,
                        row_stride_bytes: self.row_stride_bytes,
                    }),
                    (None, None) if self.row_stride_bytes.is_none() => None,
                    _ => {
                        return Err(self.invalid(
                            "give width and height together (row_stride_bytes needs both)",
                        ))
                    }
                };
                let (width, height) = match z16_layout {
                    Some(l) => (l.width, l.height),
                    None => {
                        let image = read_depth_image(&first.path, None)?;
                        (image.width, image.height)
                    }
                };
                let timestamps = files.iter().all(|f| f.timestamp_s.is_some());
                let pacing = match self.rate {
                    Some(Rate::Recorded) => Pacing::Recorded,
                    None if timestamps => Pacing::Recorded,
                    Some(Rate::Max) | None => Pacing::Max,
                    Some(Rate::Fps(fps)) => Pacing::Fixed { fps },
                };
                let poses = self.poses.as_deref().map(read_pose_file).transpose()?;
                let config = ImageSequenceConfig {
                    intrinsics: Intrinsics {
                        width,
                        height,
                        fx,
                        fy,
                        cx,
                        cy,
                    },
                    depth_scale_m: self.depth_scale_m.unwrap_or(DEFAULT_DEPTH_SCALE_M),
                    pacing,
                    looping: self.looping,
                    world_from_sensor,
                    poses,
                    z16_layout,
                    loop_cache_bytes: DEFAULT_LOOP_CACHE_BYTES,
                };
                Ok(ReplaySource::Images(ImageSequence::new(
                    name, files, config,
                )?))
            }
            ReplayInput::Clouds(files) => {
                let image_keys = [
                    ("fx", self.fx.is_some()),
                    ("fy", self.fy.is_some()),
                    ("cx", self.cx.is_some()),
                    ("cy", self.cy.is_some()),
                    ("width", self.width.is_some()),
                    ("height", self.height.is_some()),
                    ("row_stride_bytes", self.row_stride_bytes.is_some()),
                    ("depth_scale_m", self.depth_scale_m.is_some()),
                    ("poses", self.poses.is_some()),
                ];
                if let Some((key, _)) = image_keys.iter().find(|(_, set)| *set) {
                    return Err(self.invalid(format!(
                        "{key} applies to depth images, but this replays point clouds"
                    )));
                }
                let pacing = match self.rate {
                    Some(Rate::Recorded) => Pacing::Recorded,
                    Some(Rate::Max) | None => Pacing::Max,
                    Some(Rate::Fps(fps)) => Pacing::Fixed { fps },
                };
                let config = CloudSequenceConfig {
                    pacing,
                    looping: self.looping,
                    world_from_sensor,
                    loop_cache_bytes: DEFAULT_LOOP_CACHE_BYTES,
                };
                Ok(ReplaySource::Clouds(CloudSequence::new(
                    name, files, config,
                )?))
            }
        }
    }
}

/// What a spec's path resolved to.
#[derive(Debug, Clone, PartialEq)]
pub enum ReplayInput {
    Images(Vec<DepthFile>),
    Clouds(Vec<PathBuf>),
}

/// An opened replay of either kind.
#[derive(Debug)]
pub enum ReplaySource {
    Images(ImageSequence),
    Clouds(CloudSequence),
}

impl DepthSource for ReplaySource {
    fn name(&self) -> &str {
        match self {
            Self::Images(s) => s.name(),
            Self::Clouds(s) => s.name(),
        }
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        match self {
            Self::Images(s) => s.next_observation(),
            Self::Clouds(s) => s.next_observation(),
        }
    }
}

/// Whether a path names a recording another crate plays (`.oni`, `.bag`).
pub fn handled_elsewhere(path: &Path) -> Option<&'static str> {
    match extension(path).as_str() {
        "oni" => Some("tacmesh-oni"),
        "bag" => Some("tacmesh-rosbag"),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_parses_query_keys() {
        let spec = ReplaySpec::parse("/d/seq?fx=525&fy=525&cx=320&cy=240&rate=30&loop&kind=images")
            .expect("valid spec");
        assert_eq!(spec.path, PathBuf::from("/d/seq"));
        assert_eq!((spec.fx, spec.cy), (Some(525.0), Some(240.0)));
        assert_eq!(spec.rate, Some(Rate::Fps(30.0)));
        assert!(spec.looping);
        assert_eq!(spec.kind, Some(ReplayKind::Images));
    }

    #[test]
    fn spec_rejects_unknown_and_repeated_keys() {
        for bad in [
            "/d?fps=30",
            "/d?fx=1&fx=2",
            "/d?rate=fast",
            "/d?rate=0",
            "?fx=1",
        ] {
            let err = ReplaySpec::parse(bad).unwrap_err();
            assert!(matches!(err, ReplayError::Spec { .. }), "{bad}: {err}");
        }
    }

    #[test]
    fn spec_world_from_sensor_needs_seven_numbers() {
        let spec = ReplaySpec::parse("/d?world_from_sensor=1,2,3,0,0,0,1").expect("valid");
        assert_eq!(
            spec.world_from_sensor,
            Some([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])
        );
        assert!(ReplaySpec::parse("/d?world_from_sensor=1,2,3").is_err());
    }

    #[test]
    fn oni_and_bag_are_not_sequences() {
        for (path, crate_name) in [("x.oni", "tacmesh-oni"), ("y.bag", "tacmesh-rosbag")] {
            let err = ReplaySpec::new(path).open().unwrap_err();
            assert!(
                matches!(err, ReplayError::NotASequence { handled_by, .. } if handled_by == crate_name),
                "{err}"
            );
            assert_eq!(handled_elsewhere(Path::new(path)), Some(crate_name));
        }
    }
}
