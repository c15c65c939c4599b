//! [`BagReplay`]: a RealSense `.bag` recording played back as a [`DepthSource`].
//!
//! RealSense bags (librealsense's recorder) put each stream under
//! `/device_<d>/sensor_<s>/<Stream>_<i>/…`: depth images at `…/Depth_0/image/data`
//! (`sensor_msgs/Image`, `mono16`), the intrinsics at `…/Depth_0/info/camera_info`
//! (`sensor_msgs/CameraInfo`), and the depth scale in metres per unit at
//! `/device_<d>/sensor_<s>/option/Depth Units/value` (`std_msgs/Float32`).

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use glam::Affine3A;
use tacmesh_source::{
    monotonic_now, DepthFrame, DepthSource, Intrinsics, Observation, SourceError,
};

use crate::bag::{Bag, BagError, Message, Messages};
use crate::messages::{decode_float32, CameraInfo, Image, MessageError};

/// The depth scale RealSense cameras use when a bag does not record `Depth Units`.
pub const DEFAULT_DEPTH_UNITS_M: f32 = 0.001;

/// How fast frames come out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Pacing {
    /// As recorded: frames are spaced by the differences of their message times.
    #[default]
    Recorded,
    /// As fast as the caller asks.
    MaxRate,
}

/// How a [`BagReplay`] plays its bag.
#[derive(Debug, Clone, Default)]
pub struct ReplayOptions {
    pub pacing: Pacing,
    /// Start over at the end instead of returning [`SourceError::EndOfStream`].
    pub looping: bool,
    /// The depth image topic; `None` picks the first `…/Depth_<i>/image/data` topic.
    pub depth_topic: Option<String>,
}

/// Why a bag cannot be replayed.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Bag(#[from] BagError),
    #[error("{path} has no depth image topic (`…/Depth_<i>/image/data`); topics are: {topics}")]
    NoDepthTopic { path: PathBuf, topics: String },
    #[error("{path} has no camera_info on {topic}, so the depth intrinsics are unknown")]
    NoCameraInfo { path: PathBuf, topic: String },
    #[error("{path}: cannot decode the {topic} message: {error}")]
    Message {
        path: PathBuf,
        topic: String,
        error: MessageError,
    },
}

/// Plays the depth frames of a RealSense `.bag` as [`Observation::Depth`]s.
pub struct BagReplay {
    name: String,
    bag: Bag,
    depth_topic: String,
    intrinsics: Intrinsics,
    depth_units_m: f32,
    world_from_sensor: Affine3A,
    options: ReplayOptions,
    messages: Messages,
    frames_this_pass: usize,
    /// Wall-clock instant and bag time of the frame pacing is measured from.
    pacing_origin: Option<(Instant, Duration)>,
}

impl BagReplay {
    /// Opens `path`, finds the depth topic, its camera_info and depth units (reading messages
    /// until all three are known), and prepares to play from the first frame. Frames are posed
    /// at `world_from_sensor`.
    pub fn open(
        path: impl AsRef<Path>,
        world_from_sensor: Affine3A,
        options: ReplayOptions,
    ) -> Result<BagReplay, ReplayError> {
        let bag = Bag::open(path)?;
        let mut depth_topic = options.depth_topic.clone().or_else(|| {
            bag.topics()
                .into_iter()
                .find(|t| is_depth_topic(t))
                .map(str::to_owned)
        });
        let mut info: Option<CameraInfo> = None;
        let mut units: Option<f32> = None;
        let mut topics_seen: Vec<String> = bag.topics().into_iter().map(str::to_owned).collect();
        for msg in bag.messages()? {
            let msg = msg?;
            let topic = msg.connection.topic.as_str();
            if depth_topic.is_none() && is_depth_topic(topic) {
                depth_topic = Some(topic.to_owned());
            }
            if !topics_seen.iter().any(|t| t == topic) {
                topics_seen.push(topic.to_owned());
            }
            let Some(depth) = depth_topic.as_deref() else {
                continue;
            };
            if info.is_none() && topic == info_topic(depth) {
                info =
                    Some(
                        CameraInfo::decode(&msg.data).map_err(|error| ReplayError::Message {
                            path: bag.path().to_path_buf(),
                            topic: topic.to_owned(),
                            error,
                        })?,
                    );
            }
            if units.is_none() && topic == units_topic(depth) {
                units = Some(
                    decode_float32(&msg.data).map_err(|error| ReplayError::Message {
                        path: bag.path().to_path_buf(),
                        topic: topic.to_owned(),
                        error,
                    })?,
                );
            }
            if info.is_some() && units.is_some() {
                break;
            }
        }
        let Some(depth_topic) = depth_topic else {
            return Err(ReplayError::NoDepthTopic {
                path: bag.path().to_path_buf(),
                topics: topics_seen.join(", "),
            });
        };
        let Some(info) = info else {
            return Err(ReplayError::NoCameraInfo {
                path: bag.path().to_path_buf(),
                topic: info_topic(&depth_topic),
            });
        };
        let depth_units_m = match units {
            Some(u) if u.is_finite() && u > 0.0 => u,
            Some(u) => {
                tracing::warn!(
                    units = u,
                    "bag records unusable Depth Units; using {DEFAULT_DEPTH_UNITS_M} m"
                );
                DEFAULT_DEPTH_UNITS_M
            }
            None => DEFAULT_DEPTH_UNITS_M,
        };
        tracing::info!(path = %bag.path().display(), %depth_topic, depth_units_m, "replaying bag");
        Ok(BagReplay {
            name: format!("replay:{}", bag.path().display()),
            messages: bag.messages()?,
            bag,
            depth_topic,
            intrinsics: info.intrinsics(),
            depth_units_m,
            world_from_sensor,
            options,
            frames_this_pass: 0,
            pacing_origin: None,
        })
    }

    /// The depth camera's intrinsics, from the bag's camera_info.
    pub fn intrinsics(&self) -> Intrinsics {
        self.intrinsics
    }

    /// Metres per depth unit (the bag's `Depth Units` option, else 0.001).
    pub fn depth_units_m(&self) -> f32 {
        self.depth_units_m
    }

    /// The topic the depth frames come from.
    pub fn depth_topic(&self) -> &str {
        &self.depth_topic
    }

    /// The next depth image message, starting over at the end when looping.
    fn next_depth_message(&mut self) -> Result<Message, SourceError> {
        loop {
            match self.messages.next() {
                Some(Ok(msg)) if msg.connection.topic == self.depth_topic => {
                    self.frames_this_pass += 1;
                    return Ok(msg);
                }
                Some(Ok(_)) => {}
                Some(Err(e)) => {
                    return Err(match e {
                        BagError::Io { .. } => SourceError::Disconnected {
                            device: self.name.clone(),
                            reason: e.to_string(),
                        },
                        _ => SourceError::Malformed {
                            device: self.name.clone(),
                            reason: e.to_string(),
                        },
                    })
                }
                None if self.options.looping && self.frames_this_pass > 0 => {
                    tracing::debug!(name = %self.name, "end of bag; looping");
                    self.messages = self.bag.messages().map_err(|e| SourceError::Disconnected {
                        device: self.name.clone(),
                        reason: e.to_string(),
                    })?;
                    self.frames_this_pass = 0;
                    self.pacing_origin = None;
                }
                None => {
                    return Err(SourceError::EndOfStream {
                        device: self.name.clone(),
                    })
                }
            }
        }
    }

    /// Sleeps until the frame recorded at `time` is due.
    fn pace(&mut self, time: Duration) {
        if self.options.pacing == Pacing::MaxRate {
            return;
        }
        match self.pacing_origin {
            Some((wall0, time0)) if time >= time0 => {
                let due = wall0 + (time - time0);
                let now = Instant::now();
                if due > now {
                    std::thread::sleep(due - now);
                }
            }
            // First frame, or time went backwards: measure from here.
            _ => self.pacing_origin = Some((Instant::now(), time)),
        }
    }

    fn decode_frame(&self, msg: &Message) -> Result<Vec<f32>, String> {
        let image = Image::decode(&msg.data).map_err(|e| e.to_string())?;
        if (image.width, image.height) != (self.intrinsics.width, self.intrinsics.height) {
            return Err(format!(
                "image is {}x{} but camera_info says {}x{}",
                image.width, image.height, self.intrinsics.width, self.intrinsics.height
            ));
        }
        let raw = image.depth_u16().map_err(|e| e.to_string())?;
        Ok(raw
            .into_iter()
            .map(|d| f32::from(d) * self.depth_units_m)
            .collect())
    }
}

impl DepthSource for BagReplay {
    fn name(&self) -> &str {
        &self.name
    }

    fn next_observation(&mut self) -> Result<Observation, SourceError> {
        let msg = self.next_depth_message()?;
        let depth_m = self
            .decode_frame(&msg)
            .map_err(|reason| SourceError::Malformed {
                device: self.name.clone(),
                reason: format!("{} message at {}: {reason}", self.depth_topic, msg.time),
            })?;
        self.pace(msg.time.as_duration());
        tracing::trace!(name = %self.name, time = %msg.time, "depth frame");
        Ok(Observation::Depth(DepthFrame {
            intrinsics: self.intrinsics,
            depth_m,
            world_from_sensor: self.world_from_sensor,
            capture_time: monotonic_now(),
        }))
    }
}

/// Whether `topic` is a RealSense depth image topic (`…/Depth_<i>/image/data`).
fn is_depth_topic(topic: &str) -> bool {
    topic.ends_with("/image/data") && topic.contains("/Depth_")
}

/// `…/Depth_0/image/data` → `…/Depth_0/info/camera_info`.
fn info_topic(depth_topic: &str) -> String {
    let stream = depth_topic
        .strip_suffix("/image/data")
        .unwrap_or(depth_topic);
    format!("{stream}/info/camera_info")
}

/// `/device_0/sensor_0/Depth_0/image/data` → `/device_0/sensor_0/option/Depth Units/value`.
fn units_topic(depth_topic: &str) -> String {
    let sensor = depth_topic
        .rfind("/Depth_")
        .map_or(depth_topic, |i| &depth_topic[..i]);
    format!("{sensor}/option/Depth Units/value")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn realsense_topic_names_derive_from_depth_topic() {
        let depth = "/device_0/sensor_0/Depth_0/image/data";
        assert!(is_depth_topic(depth));
        assert!(!is_depth_topic("/device_0/sensor_1/Color_0/image/data"));
        assert_eq!(
            info_topic(depth),
            "/device_0/sensor_0/Depth_0/info/camera_info"
        );
        assert_eq!(
            units_topic(depth),
            "/device_0/sensor_0/option/Depth Units/value"
        );
    }
}
