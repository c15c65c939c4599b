//! The ONI reader over bytes held in memory: `OniRecording::from_reader` on a cursor (the
//! container walk, the depth node, its properties and frame index), then `read_depth_mm` on the
//! first frames (the `16zT` codec on payloads the container points at), and the intrinsics.
//!
//! Properties beyond "no panic": a decoded frame has exactly `width × height` values.

#![no_main]

use std::io::Cursor;

use libfuzzer_sys::fuzz_target;
use tacmesh_oni::OniRecording;

/// Frames decoded per input: enough to reach a second frame's payload, few enough to stay fast.
const MAX_FRAMES: usize = 3;

fuzz_target!(|data: &[u8]| {
    let Ok(mut recording) = OniRecording::from_reader(Cursor::new(data), "fuzz.oni") else {
        return;
    };
    let depth = recording.depth();
    let pixels = depth.pixel_count();
    let frames = depth.frames.len();
    let _ = depth.intrinsics();
    for index in 0..frames.min(MAX_FRAMES) {
        if let Ok(depth_mm) = recording.read_depth_mm(index) {
            assert_eq!(depth_mm.len(), pixels);
        }
    }
});
