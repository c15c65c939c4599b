//! An opened recording: its depth node, that node's properties and an index of its frames.
//!
//! Opening walks every record once (headers and fields only; frame payloads are skipped), so
//! a damaged file is rejected up front; frames are then read and decoded on demand.
//!
//! Entry points: [`OniRecording::open`], [`OniRecording::read_depth_mm`],
//! [`DepthStream::intrinsics`].

use std::collections::HashMap;
use std::fs::File;
use std::io::{BufReader, Read, Seek};
use std::path::Path;

use tacmesh_source::Intrinsics;

use crate::codec::decode_16zt;
use crate::container::{Content, FileHeader, Property, RecordReader};
use crate::OniError;

/// OpenNI's `XN_NODE_TYPE_DEPTH`.
const NODE_TYPE_DEPTH: u32 = 2;
/// Largest depth image accepted, pixels (bounds the decode allocation).
const MAX_PIXELS: u64 = 4096 * 4096;

/// One recorded depth frame: where its record and payload are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameIndex {
    /// Frame number as recorded (1-based in OpenNI recordings).
    pub frame_number: u32,
    /// Device timestamp, microseconds.
    pub timestamp_us: u64,
    /// Offset of the NewData record in the file.
    pub record_offset: u64,
    pub payload_offset: u64,
    pub payload_len: u32,
}

/// The depth node of a recording.
#[derive(Debug, Clone, PartialEq)]
pub struct DepthStream {
    pub node_id: u32,
    pub node_name: String,
    pub width: u32,
    pub height: u32,
    /// Horizontal and vertical field of view, radians (`xnFOV`), when recorded.
    pub fov_rad: Option<(f64, f64)>,
    /// Every property recorded for the node, by name. The last value in the file wins, so a
    /// recording whose resolution changes mid-stream is not supported (its earlier frames
    /// fail to decode with a pixel-count error).
    pub properties: HashMap<String, Property>,
    pub frames: Vec<FrameIndex>,
}

impl DepthStream {
    /// An integer property, e.g. `ZPD` (mm) or `xnDeviceMaxDepth` (mm).
    pub fn int_property(&self, name: &str) -> Option<u64> {
        match self.properties.get(name)? {
            Property::Int(v) => Some(*v),
            _ => None,
        }
    }

    /// A real property, e.g. `ZPPS` (mm).
    pub fn real_property(&self, name: &str) -> Option<f64> {
        match self.properties.get(name)? {
            Property::Real(v) => Some(*v),
            _ => None,
        }
    }

    /// Pinhole intrinsics of the depth image.
    ///
    /// Focal lengths from the field of view, `fx = (width / 2) / tan(hfov / 2)` (and `fy` from
    /// the vertical one); failing that, from PrimeSense's zero-plane parameters,
    /// `fx = fy = ZPD / ZPPS × width / 1280` (ZPPS is the pixel size at 1280-pixel SXGA).
    /// The principal point is the image centre in integer pixel coordinates,
    /// `cx = (width - 1) / 2`, `cy = (height - 1) / 2`: the recording does not store one, and
    /// [`tacmesh_source::DepthFrame::deproject`] puts pixel `(u, v)` at integer coordinates.
    pub fn intrinsics(&self) -> Option<Intrinsics> {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let (fx, fy) = match self.fov_rad {
            Some((hfov, vfov)) => (
                (w / 2.0) / (hfov / 2.0).tan(),
                (h / 2.0) / (vfov / 2.0).tan(),
            ),
            None => {
                let zpd_mm = self.int_property("ZPD")? as f64;
                let zpps_mm = self.real_property("ZPPS")?;
                let f = zpd_mm / zpps_mm * w / 1280.0;
                (f, f)
            }
        };
        let usable = |f: f64| f.is_finite() && f > 0.0;
        (usable(fx) && usable(fy)).then(|| Intrinsics {
            width: self.width,
            height: self.height,
            fx: fx as f32,
            fy: fy as f32,
            cx: (w as f32 - 1.0) / 2.0,
            cy: (h as f32 - 1.0) / 2.0,
        })
    }

    /// Pixels per frame.
    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }
}

/// An `.oni` recording opened for reading its depth frames.
pub struct OniRecording<R = BufReader<File>> {
    records: RecordReader<R>,
    header: FileHeader,
    depth: DepthStream,
}

impl OniRecording<BufReader<File>> {
    /// Opens and indexes the recording at `path`.
    pub fn open(path: impl AsRef<Path>) -> Result<Self, OniError> {
        let path = path.as_ref();
        let io = |error| OniError::Io {
            file: path.display().to_string(),
            error,
        };
        // A FIFO would block the open until a writer came; a device would never end.
        tacmesh_source::check_regular_file(path, u64::MAX).map_err(io)?;
        let file = File::open(path).map_err(io)?;
        Self::from_reader(BufReader::new(file), path.display().to_string())
    }
}

impl<R: Read + Seek> OniRecording<R> {
    /// Indexes a recording read from `reader`; `file` names it in errors.
    pub fn from_reader(reader: R, file: impl Into<String>) -> Result<Self, OniError> {
        let (mut records, header) = RecordReader::new(reader, file.into())?;
        let depth = index_depth_stream(&mut records)?;
        Ok(Self {
            records,
            header,
            depth,
        })
    }

    pub fn header(&self) -> &FileHeader {
        &self.header
    }

    pub fn depth(&self) -> &DepthStream {
        &self.depth
    }

    /// The file name as given when opening.
    pub fn file(&self) -> &str {
        self.records.file()
    }

    /// Reads and decodes depth frame `index` (0-based, in file order): `width × height`
    /// values, row-major, millimetres, 0 = no reading.
    pub fn read_depth_mm(&mut self, index: usize) -> Result<Vec<u16>, OniError> {
        let frame = *self
            .depth
            .frames
            .get(index)
            .ok_or_else(|| OniError::NoSuchFrame {
                file: self.file().to_owned(),
                index,
                count: self.depth.frames.len(),
            })?;
        let payload = self.records.read_exact_at(
            frame.payload_offset,
            frame.payload_len as usize,
            "a depth frame",
        )?;
        decode_16zt(&payload, self.depth.pixel_count()).map_err(|error| OniError::Frame {
            file: self.file().to_owned(),
            offset: frame.record_offset,
            frame_number: frame.frame_number,
            error,
        })
    }
}

/// Walks all records up to End: finds the first depth node, collects its properties and
/// indexes its NewData records.
fn index_depth_stream<R: Read + Seek>(
    records: &mut RecordReader<R>,
) -> Result<DepthStream, OniError> {
    let mut depth: Option<DepthStream> = None;
    loop {
        let record = records.next_record()?;
        let have_depth = depth.is_some();
        let ours = depth.as_mut().filter(|d| d.node_id == record.node_id);
        match record.content {
            Content::End => break,
            Content::NodeAdded {
                name,
                node_type,
                codec,
            } if node_type == NODE_TYPE_DEPTH && !have_depth => {
                if &codec != b"16zT" {
                    return Err(OniError::UnsupportedCodec {
                        file: records.file().to_owned(),
                        offset: record.offset,
                        node: name,
                        codec: String::from_utf8_lossy(&codec).into_owned(),
                    });
                }
                depth = Some(DepthStream {
                    node_id: record.node_id,
                    node_name: name,
                    width: 0,
                    height: 0,
                    fov_rad: None,
                    properties: HashMap::new(),
                    frames: Vec::new(),
                });
            }
            Content::Property { name, value } => {
                if let Some(d) = ours {
                    d.properties.insert(name, value);
                }
            }
            Content::NewData {
                timestamp_us,
                frame_number,
            } => {
                if let Some(d) = ours {
                    d.frames.push(FrameIndex {
                        frame_number,
                        timestamp_us,
                        record_offset: record.offset,
                        payload_offset: record.payload_offset,
                        payload_len: record.payload_len,
                    });
                }
            }
            _ => {}
        }
    }
    let mut depth = depth.ok_or_else(|| OniError::NoDepthNode {
        file: records.file().to_owned(),
    })?;
    apply_geometry(&mut depth, records.file())?;
    Ok(depth)
}

/// Resolution from `xnMapOutputMode` (`u32` x, `u32` y, `u32` fps) and field of view from
/// `xnFOV` / `xnFieldOfView` (two `f64`, horizontal then vertical).
fn apply_geometry(depth: &mut DepthStream, file: &str) -> Result<(), OniError> {
    let missing = |what| OniError::MissingProperty {
        file: file.to_owned(),
        node: depth.node_name.clone(),
        what,
    };
    let mode = match depth.properties.get("xnMapOutputMode") {
        Some(Property::General(raw)) if raw.len() >= 8 => raw,
        _ => {
            return Err(missing(
                "a 12-byte general property xnMapOutputMode (resolution)",
            ))
        }
    };
    let width = u32::from_le_bytes([mode[0], mode[1], mode[2], mode[3]]);
    let height = u32::from_le_bytes([mode[4], mode[5], mode[6], mode[7]]);
    let pixels = u64::from(width) * u64::from(height);
    if pixels == 0 || pixels > MAX_PIXELS {
        return Err(missing("a plausible resolution in xnMapOutputMode"));
    }
    let fov =
        ["xnFOV", "xnFieldOfView"]
            .iter()
            .find_map(|name| match depth.properties.get(*name) {
                Some(Property::General(raw)) if raw.len() == 16 => {
                    let h = f64::from_le_bytes(raw[..8].try_into().ok()?);
                    let v = f64::from_le_bytes(raw[8..].try_into().ok()?);
                    Some((h, v))
                }
                _ => None,
            });
    depth.width = width;
    depth.height = height;
    depth.fov_rad = fov;
    if depth.intrinsics().is_none() {
        return Err(missing(
            "a usable field of view (xnFOV) or zero-plane parameters (ZPD, ZPPS)",
        ));
    }
    Ok(())
}
