//! The ROS bag reader on arbitrary file contents: `Bag::open` (magic, bag header, index
//! section), `Bag::messages` (chunks, `none` and `lz4` decompression, records inside chunks),
//! then the message decoders a replay uses (`Image` and `depth_u16`, `CameraInfo`,
//! `decode_float32`) on every message, whatever its type says.
//!
//! `Bag` reads only from a path (it reopens the file for each walk over the messages), so each
//! input is written to a file in the temporary directory first, named by the process id so that
//! parallel jobs (`-jobs=N`) do not share one.
//!
//! Properties beyond "no panic": a decoded depth image has `width × height` pixels.

#![no_main]

use std::path::PathBuf;
use std::sync::LazyLock;

use libfuzzer_sys::fuzz_target;
use tacmesh_rosbag::{decode_float32, Bag, CameraInfo, Image};

/// Messages decoded per input; a bag that yields more is not more interesting.
const MAX_MESSAGES: usize = 64;

static BAG_PATH: LazyLock<PathBuf> = LazyLock::new(|| {
    std::env::temp_dir().join(format!("tacmesh-fuzz-rosbag-{}.bag", std::process::id()))
});

fuzz_target!(|data: &[u8]| {
    std::fs::write(&*BAG_PATH, data).expect("the temporary directory is writable");
    let Ok(bag) = Bag::open(&*BAG_PATH) else {
        return;
    };
    let _ = bag.topics();
    let Ok(messages) = bag.messages() else {
        return;
    };
    for message in messages.take(MAX_MESSAGES) {
        let Ok(message) = message else {
            break;
        };
        if let Ok(image) = Image::decode(&message.data) {
            if let Ok(depth) = image.depth_u16() {
                assert_eq!(
                    depth.len() as u64,
                    u64::from(image.width) * u64::from(image.height)
                );
            }
        }
        if let Ok(info) = CameraInfo::decode(&message.data) {
            let _ = info.intrinsics();
        }
        let _ = decode_float32(&message.data);
    }
});
