//! The real RealSense D435 bag: topics, frames, intrinsics, depth units.

use tacmesh_rosbag::{decode_float32, Bag, CameraInfo, Image};

use crate::util::{d435_bag, d435_frame0_z16, DEPTH_TOPIC};

#[test]
fn d435_bag_lists_its_topics() {
    let bag = Bag::open(d435_bag()).unwrap();
    let topics = bag.topics();
    println!(
        "{} connections, {} chunks, topics:",
        bag.connections().count(),
        bag.chunk_count()
    );
    for t in &topics {
        println!("  {t}");
    }
    assert_eq!(bag.connections().count(), 70);
    assert_eq!(bag.chunk_count(), 2);
    for t in [
        DEPTH_TOPIC,
        "/device_0/sensor_0/Depth_0/info/camera_info",
        "/device_0/sensor_0/option/Depth Units/value",
    ] {
        assert!(topics.contains(&t), "missing {t}");
    }
    let depth = bag.connections().find(|c| c.topic == DEPTH_TOPIC).unwrap();
    assert_eq!(depth.msg_type, "sensor_msgs/Image");
    assert_eq!(depth.md5sum.len(), 32);
    assert!(depth.message_definition.contains("uint32 step"));
}

#[test]
fn d435_bag_has_two_mono16_depth_frames_and_frame0_matches_z16() {
    let msgs = crate::util::read_all(&d435_bag()).unwrap();
    let depth: Vec<_> = msgs
        .iter()
        .filter(|m| m.connection.topic == DEPTH_TOPIC)
        .collect();
    assert_eq!(depth.len(), 2);
    assert!(depth[0].time <= depth[1].time);
    let img = Image::decode(&depth[0].data).unwrap();
    assert_eq!(
        (img.width, img.height, img.encoding.as_str()),
        (640, 480, "mono16")
    );
    assert_eq!((img.step, img.is_bigendian), (1280, false));
    assert_eq!(
        img.data,
        d435_frame0_z16(),
        "frame 0 payload differs from frame0_640x480.z16"
    );
    let mm = img.depth_u16().unwrap();
    let valid: Vec<u16> = mm.iter().copied().filter(|&d| d > 0).collect();
    assert_eq!(valid.len(), 286_520);
    assert_eq!(valid.iter().min(), Some(&341));
    assert_eq!(valid.iter().max(), Some(&3182));
    let second = Image::decode(&depth[1].data).unwrap();
    assert_eq!((second.width, second.height), (640, 480));
}

#[test]
fn d435_camera_info_and_depth_units() {
    let msgs = crate::util::read_all(&d435_bag()).unwrap();
    let info = msgs
        .iter()
        .find(|m| m.connection.topic == "/device_0/sensor_0/Depth_0/info/camera_info")
        .unwrap();
    assert_eq!(info.connection.msg_type, "sensor_msgs/CameraInfo");
    let info = CameraInfo::decode(&info.data).unwrap();
    let k = info.intrinsics();
    assert_eq!((k.width, k.height), (640, 480));
    for (got, want) in [
        (k.fx, 390.4315),
        (k.fy, 390.4315),
        (k.cx, 331.3879),
        (k.cy, 242.1873),
    ] {
        assert!((got - want).abs() < 1e-3, "{got} vs {want}");
    }
    assert!(info.d.iter().all(|&d| d == 0.0));
    let units = msgs
        .iter()
        .find(|m| m.connection.topic == "/device_0/sensor_0/option/Depth Units/value")
        .unwrap();
    assert_eq!(units.connection.msg_type, "std_msgs/Float32");
    assert!((decode_float32(&units.data).unwrap() - 0.001).abs() < 1e-9);
}
