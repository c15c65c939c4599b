//! The real PrimeSense recording from `testdata/recordings` (see SOURCES.md, ONI entry),
//! replay, and malformed variants of it.

use std::io::Cursor;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use tacmesh_oni::{
    decode_16zt, AtEnd, CodecError, OniError, OniRecording, OniReplay, Pacing, ReplayOptions,
};
use tacmesh_source::glam::{Affine3A, Vec3};
use tacmesh_source::{DepthFrame, DepthSource, Observation, SourceError};

const FILE_NAME: &str = "openni1_primesense_12frames_640x480.oni";
/// Offset of the first depth NewData record, and where its payload starts and ends.
const FRAME1_RECORD: u64 = 100_338;
const FRAME1_PAYLOAD: std::ops::Range<usize> = 100_378..100_378 + 105_410;
/// Offset of the 12-byte `xnMapOutputMode` value of the depth node.
const MAP_OUTPUT_MODE_VALUE: usize = 28_305 + 28 + 4 + 16 + 4;

fn recording_path() -> PathBuf {
    tacmesh_testdata::path(&format!("recordings/{FILE_NAME}"))
}

fn recording_bytes() -> Vec<u8> {
    tacmesh_testdata::bytes(&format!("recordings/{FILE_NAME}"))
}

fn open_bytes(bytes: Vec<u8>) -> Result<OniRecording<Cursor<Vec<u8>>>, OniError> {
    OniRecording::from_reader(Cursor::new(bytes), "mangled.oni")
}

/// (valid pixel count, min valid mm, max mm)
fn stats(depth_mm: &[u16]) -> (usize, u16, u16) {
    let valid: Vec<u16> = depth_mm.iter().copied().filter(|&d| d > 0).collect();
    let min = valid.iter().copied().min().unwrap_or(0);
    let max = valid.iter().copied().max().unwrap_or(0);
    (valid.len(), min, max)
}

fn depth_frame(observation: Observation) -> DepthFrame {
    match observation {
        Observation::Depth(frame) => frame,
        other => panic!("expected a depth frame, got {other:?}"),
    }
}

/// A small fixed-seed generator (xorshift64*), enough to pick bytes to corrupt.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 33) as usize % n
    }
}

#[test]
fn recording_has_twelve_640x480_depth_frames() {
    let recording = OniRecording::open(recording_path()).unwrap();
    let depth = recording.depth();
    assert_eq!(depth.node_name, "Depth1");
    assert_eq!((depth.width, depth.height), (640, 480));
    assert_eq!(depth.frames.len(), 12);
    let numbers: Vec<u32> = depth.frames.iter().map(|f| f.frame_number).collect();
    assert_eq!(numbers, (1..=12).collect::<Vec<_>>());
    assert_eq!(depth.frames[0].record_offset, FRAME1_RECORD);
    assert_eq!(recording.header().max_timestamp_us, 378_742);
}

#[test]
fn frame_one_matches_sources_md() {
    let mut recording = OniRecording::open(recording_path()).unwrap();
    let depth_mm = recording.read_depth_mm(0).unwrap();
    assert_eq!(depth_mm.len(), 307_200);
    assert_eq!(stats(&depth_mm), (234_942, 628, 4521));
}

#[test]
fn every_frame_decodes_to_640x480_with_plausible_depths() {
    let mut recording = OniRecording::open(recording_path()).unwrap();
    for index in 0..12 {
        let depth_mm = recording.read_depth_mm(index).unwrap();
        assert_eq!(depth_mm.len(), 640 * 480, "frame {index}");
        let (valid, min, max) = stats(&depth_mm);
        // A room seen by a PrimeSense sensor: most pixels valid, 0.5–10 m.
        assert!(
            valid > 200_000 && valid < 307_200,
            "frame {index}: {valid} valid"
        );
        assert!(
            min >= 500 && max <= 10_000,
            "frame {index}: {min}..{max} mm"
        );
    }
    assert!(matches!(
        recording.read_depth_mm(12),
        Err(OniError::NoSuchFrame {
            index: 12,
            count: 12,
            ..
        })
    ));
}

#[test]
fn timestamps_increase_about_33_ms_apart() {
    let recording = OniRecording::open(recording_path()).unwrap();
    let frames = &recording.depth().frames;
    assert_eq!(frames[0].timestamp_us, 11_680);
    for pair in frames.windows(2) {
        let step_us = pair[1].timestamp_us - pair[0].timestamp_us;
        assert!((33_000..=34_000).contains(&step_us), "{step_us} µs");
    }
}

#[test]
fn intrinsics_come_from_xn_fov() {
    let recording = OniRecording::open(recording_path()).unwrap();
    let depth = recording.depth();
    let (hfov, vfov) = depth.fov_rad.unwrap();
    assert!((hfov - 1.01447).abs() < 1e-5 && (vfov - 0.78981).abs() < 1e-5);
    let k = depth.intrinsics().unwrap();
    assert!((k.fx - 575.8).abs() < 0.1, "fx {}", k.fx);
    assert!((k.fy - 575.8).abs() < 0.2, "fy {}", k.fy);
    assert_eq!((k.cx, k.cy), (319.5, 239.5));
    assert_eq!(depth.int_property("ZPD"), Some(120));
    assert!((depth.real_property("ZPPS").unwrap() - 0.1042).abs() < 1e-6);
    assert_eq!(depth.int_property("xnDeviceMaxDepth"), Some(10_000));

    // Without a field of view the zero-plane parameters give the same focal length.
    let mut no_fov = depth.clone();
    no_fov.fov_rad = None;
    let k = no_fov.intrinsics().unwrap();
    assert!((k.fx - 575.8).abs() < 0.1 && k.fx == k.fy, "fx {}", k.fx);
}

#[test]
fn replay_yields_metres_then_end_of_stream() {
    let pose = Affine3A::from_translation(Vec3::new(0.0, 0.0, 1.0));
    let options = ReplayOptions {
        pacing: Pacing::AsFastAsRead,
        at_end: AtEnd::Stop,
        world_from_sensor: pose,
    };
    let mut replay = OniReplay::open(recording_path(), options).unwrap();
    assert_eq!(
        replay.name(),
        format!("replay:{}", recording_path().display())
    );
    let mut last_capture = std::time::Duration::ZERO;
    for index in 0..12 {
        let frame = depth_frame(replay.next_observation().unwrap());
        assert!(frame.is_consistent());
        assert_eq!(frame.world_from_sensor, pose);
        assert!(frame.capture_time > last_capture);
        last_capture = frame.capture_time;
        if index == 0 {
            let valid: Vec<f32> = frame.depth_m.iter().copied().filter(|&z| z > 0.0).collect();
            assert_eq!(valid.len(), 234_942);
            let min = valid.iter().copied().fold(f32::INFINITY, f32::min);
            let max = valid.iter().copied().fold(0.0, f32::max);
            assert!((min - 0.628).abs() < 1e-6 && (max - 4.521).abs() < 1e-6);
        }
    }
    for _ in 0..2 {
        assert!(matches!(
            replay.next_observation(),
            Err(SourceError::EndOfStream { .. })
        ));
    }
}

#[test]
fn replay_loops_at_recorded_pace() {
    let options = ReplayOptions {
        pacing: Pacing::Recorded,
        at_end: AtEnd::Loop,
        ..ReplayOptions::default()
    };
    let mut replay = OniReplay::open(recording_path(), options).unwrap();
    let started = Instant::now();
    let first = depth_frame(replay.next_observation().unwrap());
    for _ in 1..12 {
        replay.next_observation().unwrap();
    }
    // 11 recorded gaps of ~33.4 ms.
    let elapsed = started.elapsed();
    assert!(elapsed >= Duration::from_millis(360), "{elapsed:?}");
    let again = depth_frame(replay.next_observation().unwrap());
    assert_eq!(again.depth_m, first.depth_m);
}

#[test]
fn wrong_magic_is_rejected() {
    let mut bytes = recording_bytes();
    bytes[..4].copy_from_slice(b"NI11");
    let err = open_bytes(bytes).err().unwrap();
    assert!(matches!(err, OniError::BadMagic { .. }), "{err}");
    assert!(err.to_string().contains("mangled.oni"), "{err}");
    assert!(matches!(open_bytes(vec![]), Err(OniError::BadMagic { .. })));
}

#[test]
fn truncated_file_is_an_error_at_every_cut() {
    let bytes = recording_bytes();
    let mut cuts: Vec<usize> = (0..bytes.len()).step_by(997).collect();
    // Around the record boundaries near the start, the first frame and the end.
    cuts.extend(20..40);
    cuts.extend(FRAME1_PAYLOAD.start - 50..FRAME1_PAYLOAD.start + 10);
    cuts.extend(bytes.len() - 40..bytes.len());
    for cut in cuts {
        let err = open_bytes(bytes[..cut].to_vec()).err();
        let err = err.unwrap_or_else(|| panic!("cut at {cut} opened"));
        assert!(err.to_string().contains("mangled.oni"), "{err}");
        assert!(
            matches!(err, OniError::Truncated { .. } | OniError::BadMagic { .. }),
            "cut at {cut}: {err}"
        );
    }
}

#[test]
fn corrupted_bytes_give_errors_not_panics() {
    let pristine = recording_bytes();
    let mut rng = Rng(0x5EED_0F0A_11CE_0001);
    let (mut open_errors, mut frame_errors) = (0, 0);
    for _ in 0..200 {
        let mut bytes = pristine.clone();
        for _ in 0..1 + rng.below(8) {
            // Bias half the hits towards the headers and properties, where damage matters most.
            let at = if rng.below(2) == 0 {
                rng.below(FRAME1_RECORD as usize + 64)
            } else {
                rng.below(bytes.len())
            };
            bytes[at] = rng.below(256) as u8;
        }
        let mut recording = match open_bytes(bytes) {
            Ok(recording) => recording,
            Err(_) => {
                open_errors += 1;
                continue;
            }
        };
        for index in 0..recording.depth().frames.len() {
            match recording.read_depth_mm(index) {
                Ok(depth_mm) => assert_eq!(depth_mm.len(), recording.depth().pixel_count()),
                Err(_) => frame_errors += 1,
            }
        }
    }
    // Most hits land in property values and image payloads, which need not be rejected; with
    // this seed some damage reaches record headers and depth payloads.
    assert!(open_errors > 0, "{open_errors} files rejected");
    assert!(frame_errors > 0, "{frame_errors} frames rejected");
    eprintln!("{open_errors} of 200 files and {frame_errors} frames rejected");
}

#[test]
fn frame_running_past_its_payload_is_a_frame_error() {
    let mut bytes = recording_bytes();
    bytes[FRAME1_PAYLOAD.end - 1] = 0xFF; // an escape with nothing after it
    let mut recording = open_bytes(bytes).unwrap();
    let err = recording.read_depth_mm(0).unwrap_err();
    assert!(
        matches!(
            err,
            OniError::Frame {
                offset: FRAME1_RECORD,
                frame_number: 1,
                error: CodecError::Truncated { .. },
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("offset 100338"), "{err}");
    assert!(recording.read_depth_mm(1).is_ok());
}

#[test]
fn frame_with_wrong_pixel_count_is_a_frame_error() {
    for (height, too_many) in [(479u32, true), (481, false)] {
        let mut bytes = recording_bytes();
        let at = MAP_OUTPUT_MODE_VALUE;
        assert_eq!(bytes[at..at + 8], [0x80, 2, 0, 0, 0xE0, 1, 0, 0]);
        bytes[at + 4..at + 8].copy_from_slice(&height.to_le_bytes());
        let mut recording = open_bytes(bytes).unwrap();
        match recording.read_depth_mm(0).unwrap_err() {
            OniError::Frame { error, .. } => match error {
                CodecError::TooManyPixels { expected, .. } => {
                    assert!(too_many);
                    assert_eq!(expected, 640 * 479);
                }
                CodecError::TooFewPixels { got, expected } => {
                    assert!(!too_many);
                    assert_eq!((got, expected), (640 * 480, 640 * 481));
                }
                other => panic!("{other}"),
            },
            other => panic!("{other}"),
        }
    }
}

#[test]
fn implausible_resolution_is_rejected_before_decoding() {
    let mut bytes = recording_bytes();
    bytes[MAP_OUTPUT_MODE_VALUE..MAP_OUTPUT_MODE_VALUE + 4]
        .copy_from_slice(&u32::MAX.to_le_bytes());
    let err = open_bytes(bytes).err().unwrap();
    assert!(matches!(err, OniError::MissingProperty { .. }), "{err}");
}

#[test]
fn codec_rejects_truncated_real_payload() {
    let bytes = recording_bytes();
    let payload = &bytes[FRAME1_PAYLOAD];
    assert_eq!(decode_16zt(payload, 307_200).unwrap().len(), 307_200);
    for cut in [0, 1, 2, 100, payload.len() / 2, payload.len() - 1] {
        assert!(
            decode_16zt(&payload[..cut], 307_200).is_err(),
            "cut at {cut}"
        );
    }
}
