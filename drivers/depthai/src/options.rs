//! What to open: a live OAK camera with its stereo settings, or a DepthAI `.mcap` recording;
//! parsed from the daemon's `depthai:` sensor spec.

use std::path::PathBuf;

use glam::Affine3A;
use tacmesh_source::Intrinsics;

use crate::DepthAiError;

/// Which rectified view the depth map is aligned to (and whose calibration gives the
/// intrinsics).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DepthAlign {
    /// The rectified left mono camera (`CAM_B`).
    Left,
    /// The rectified right mono camera (`CAM_C`), DepthAI's default.
    Right,
    /// The colour camera (`CAM_A`).
    Rgb,
}

impl DepthAlign {
    /// The `dai.CameraBoardSocket` member name.
    pub fn socket(self) -> &'static str {
        match self {
            DepthAlign::Left => "CAM_B",
            DepthAlign::Right => "CAM_C",
            DepthAlign::Rgb => "CAM_A",
        }
    }
}

/// A live camera's stereo pipeline.
#[derive(Debug, Clone, PartialEq)]
pub struct LiveOptions {
    /// A device id (MXID), IP address or USB path; `None` is the first device found.
    pub device: Option<String>,
    /// Depth output size, pixels.
    pub width: u32,
    pub height: u32,
    pub fps: f32,
    pub align: DepthAlign,
    /// A `dai.node.StereoDepth.PresetMode` member name, e.g. `ROBOTICS`.
    pub preset: String,
    /// Also record the depth stream to this `.mcap` file with DepthAI's own recorder.
    pub record: Option<PathBuf>,
}

impl Default for LiveOptions {
    /// 640×400 at 30 Hz (the OAK mono sensors' 1280×800 halved), aligned to the rectified right
    /// camera, DepthAI's `ROBOTICS` preset (filters tuned for obstacle and object geometry).
    fn default() -> Self {
        Self {
            device: None,
            width: 640,
            height: 400,
            fps: 30.0,
            align: DepthAlign::Right,
            preset: "ROBOTICS".into(),
            record: None,
        }
    }
}

/// A DepthAI recording to play back.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayOptions {
    pub path: PathBuf,
    pub looping: bool,
    /// Play as fast as the pipeline reads instead of at the recorded rate.
    pub max_rate: bool,
    /// For recordings whose frames carry no intrinsics (DepthAI before v3 recorded none).
    pub intrinsics: Option<Intrinsics>,
}

#[derive(Debug, Clone, PartialEq)]
pub enum Mode {
    Live(LiveOptions),
    Replay(ReplayOptions),
}

/// Everything [`crate::DepthAiSource`] needs.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthAiOptions {
    pub mode: Mode,
    /// The virtual environment whose `site-packages` holds `depthai`. The embedded interpreter
    /// does not activate virtual environments by itself; `None` falls back to `$VIRTUAL_ENV`,
    /// then to the interpreter's own packages.
    pub venv: Option<PathBuf>,
    /// How long DepthAI searches for a device before giving up (`DEPTHAI_SEARCH_TIMEOUT`).
    pub search_timeout_ms: u32,
    /// How long a read waits for a frame before the stream counts as stalled.
    pub frame_timeout_ms: u32,
    pub world_from_sensor: Affine3A,
}

impl Default for DepthAiOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Live(LiveOptions::default()),
            venv: None,
            search_timeout_ms: 3000,
            frame_timeout_ms: 2000,
            world_from_sensor: Affine3A::IDENTITY,
        }
    }
}

impl DepthAiOptions {
    /// Parses what follows `depthai:` in a sensor spec: `[TARGET][?key=value&…]`.
    ///
    /// TARGET is empty (the first device), a device id / IP / USB path, or a path ending in
    /// `.mcap` (a recording). Keys: `venv`, `search_timeout_ms`, `frame_timeout_ms`; for a
    /// camera `width`, `height`, `fps`, `align` (`left`, `right`, `rgb`), `preset` (a
    /// StereoDepth preset, e.g. `robotics`, `high_detail`) and `record` (an `.mcap` path); for
    /// a recording `rate=max` and `fx`, `fy`, `cx`, `cy` when its frames carry no intrinsics.
    pub fn parse_spec(rest: &str) -> Result<DepthAiOptions, DepthAiError> {
        let spec = format!("depthai:{rest}");
        let bad = |reason: String| DepthAiError::BadOption {
            spec: spec.clone(),
            reason,
        };
        let (target, query) = rest.split_once('?').unwrap_or((rest, ""));
        let is_recording = target.to_ascii_lowercase().ends_with(".mcap");
        let mut options = DepthAiOptions::default();
        let mut live = LiveOptions {
            device: (!target.is_empty()).then(|| target.to_owned()),
            ..LiveOptions::default()
        };
        let mut max_rate = false;
        let mut pinhole = [None; 4];
        for pair in query.split('&').filter(|p| !p.is_empty()) {
            let (key, value) = pair
                .split_once('=')
                .ok_or_else(|| bad(format!("{pair:?} is not key=value")))?;
            let number = || -> Result<f32, DepthAiError> {
                value
                    .parse::<f32>()
                    .ok()
                    .filter(|x| x.is_finite() && *x > 0.0)
                    .ok_or_else(|| bad(format!("{key} = {value:?} is not a positive number")))
            };
            let whole =
                || -> Result<u32, DepthAiError> {
                    value.parse::<u32>().ok().filter(|&x| x > 0).ok_or_else(|| {
                        bad(format!("{key} = {value:?} is not a positive whole number"))
                    })
                };
            let camera_only = |what: &str| -> Result<(), DepthAiError> {
                if is_recording {
                    Err(bad(format!("{what} is for a camera, not a recording")))
                } else {
                    Ok(())
                }
            };
            match key {
                "venv" => options.venv = Some(PathBuf::from(value)),
                "search_timeout_ms" => options.search_timeout_ms = whole()?,
                "frame_timeout_ms" => options.frame_timeout_ms = whole()?,
                "width" => {
                    camera_only(key)?;
                    live.width = whole()?
                }
                "height" => {
                    camera_only(key)?;
                    live.height = whole()?
                }
                "fps" => {
                    camera_only(key)?;
                    live.fps = number()?
                }
                "align" => {
                    camera_only(key)?;
                    live.align = match value {
                        "left" => DepthAlign::Left,
                        "right" => DepthAlign::Right,
                        "rgb" => DepthAlign::Rgb,
                        _ => return Err(bad(format!("align = {value:?}: left, right or rgb"))),
                    }
                }
                "preset" => {
                    camera_only(key)?;
                    const PRESETS: [&str; 8] = [
                        "FAST_ACCURACY",
                        "FAST_DENSITY",
                        "DEFAULT",
                        "FACE",
                        "HIGH_DETAIL",
                        "ROBOTICS",
                        "DENSITY",
                        "ACCURACY",
                    ];
                    let preset = value.to_ascii_uppercase();
                    if !PRESETS.contains(&preset.as_str()) {
                        return Err(bad(format!(
                            "preset = {value:?}: one of {}",
                            PRESETS.join(", ").to_ascii_lowercase()
                        )));
                    }
                    live.preset = preset;
                }
                "record" => {
                    camera_only(key)?;
                    live.record = Some(PathBuf::from(value))
                }
                "rate" if is_recording => match value {
                    "max" => max_rate = true,
                    "recorded" => max_rate = false,
                    _ => return Err(bad(format!("rate = {value:?}: max or recorded"))),
                },
                "fx" | "fy" | "cx" | "cy" if is_recording => {
                    let slot = ["fx", "fy", "cx", "cy"].iter().position(|k| *k == key);
                    pinhole[slot.unwrap_or(0)] = Some(number()?);
                }
                _ => {
                    return Err(bad(format!(
                        "unknown key {key:?} (venv, search_timeout_ms, frame_timeout_ms; a \
                         camera: width, height, fps, align, preset, record; a recording: rate, \
                         fx, fy, cx, cy)"
                    )))
                }
            }
        }
        options.mode = if is_recording {
            let intrinsics = match pinhole {
                [None, None, None, None] => None,
                [Some(fx), Some(fy), Some(cx), Some(cy)] => Some(Intrinsics {
                    // The size comes from each frame.
                    width: 0,
                    height: 0,
                    fx,
                    fy,
                    cx,
                    cy,
                }),
                _ => return Err(bad("give all of fx, fy, cx and cy, or none".into())),
            };
            Mode::Replay(ReplayOptions {
                path: PathBuf::from(target),
                looping: false,
                max_rate,
                intrinsics,
            })
        } else {
            Mode::Live(live)
        };
        Ok(options)
    }

    /// A short name for logs: `depthai: (the first device found)`, `depthai:<id>` or
    /// `depthai:<file>`. The spec as typed comes first, so that it never reads as a device
    /// named "first device".
    pub fn name(&self) -> String {
        match &self.mode {
            Mode::Live(live) => match &live.device {
                Some(device) => format!("depthai:{device}"),
                None => "depthai: (the first device found)".to_owned(),
            },
            Mode::Replay(replay) => format!("depthai:{}", replay.path.display()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_spec_is_the_first_camera_with_defaults() {
        let options = DepthAiOptions::parse_spec("").unwrap();
        assert_eq!(options, DepthAiOptions::default());
        assert_eq!(options.name(), "depthai: (the first device found)");
    }

    #[test]
    fn camera_keys_are_read() {
        let options = DepthAiOptions::parse_spec(
            "14442C108144F1D000?width=1280&height=800&fps=15&align=rgb&preset=high_detail\
             &record=/tmp/r.mcap&venv=/opt/tacmesh/venv&search_timeout_ms=1500",
        )
        .unwrap();
        let Mode::Live(live) = &options.mode else {
            panic!("{options:?}")
        };
        assert_eq!(live.device.as_deref(), Some("14442C108144F1D000"));
        assert_eq!((live.width, live.height, live.fps), (1280, 800, 15.0));
        assert_eq!(live.align, DepthAlign::Rgb);
        assert_eq!(live.preset, "HIGH_DETAIL");
        assert_eq!(live.record, Some(PathBuf::from("/tmp/r.mcap")));
        assert_eq!(options.venv, Some(PathBuf::from("/opt/tacmesh/venv")));
        assert_eq!(options.search_timeout_ms, 1500);
    }

    #[test]
    fn an_mcap_target_is_a_recording() {
        let options = DepthAiOptions::parse_spec("rec/run1.MCAP?rate=max").unwrap();
        assert_eq!(
            options.mode,
            Mode::Replay(ReplayOptions {
                path: "rec/run1.MCAP".into(),
                looping: false,
                max_rate: true,
                intrinsics: None,
            })
        );
        let with_pinhole =
            DepthAiOptions::parse_spec("a.mcap?fx=400&fy=401&cx=320&cy=200").unwrap();
        let Mode::Replay(replay) = with_pinhole.mode else {
            panic!()
        };
        assert_eq!(
            replay.intrinsics.map(|i| (i.fx, i.cy)),
            Some((400.0, 200.0))
        );
    }

    #[test]
    fn bad_options_name_the_key() {
        for (spec, needle) in [
            ("?width=0", "width"),
            ("?fps=fast", "fps"),
            ("?align=up", "left, right or rgb"),
            ("?preset=best", "high_detail"),
            ("?gain=3", "gain"),
            ("?width", "not key=value"),
            ("a.mcap?width=640", "not a recording"),
            ("a.mcap?fx=400", "all of fx"),
            ("a.mcap?rate=slow", "max or recorded"),
            ("cam?rate=max", "unknown key \"rate\""),
        ] {
            let err = DepthAiOptions::parse_spec(spec).unwrap_err().to_string();
            assert!(err.contains(needle), "{spec}: {err}");
            assert!(err.contains(&format!("depthai:{spec}")), "{err}");
        }
    }
}
