//! The RPLIDAR response decoders on arbitrary device bytes, as `RplidarSource` meets them: the
//! 7-byte response descriptor, the GET_INFO and GET_HEALTH answers, then a standard-scan node
//! stream fed in chunks (the first byte picks the chunk size) to `NodeDecoder` and
//! `RplidarScanner`.
//!
//! Properties beyond "no panic":
//! - descriptors, device info, health and scan nodes that parse re-encode to the same bytes;
//! - every node the decoder accepts has an angle below 360°;
//! - every sample angle is in `[0, 360)` degrees and every cloud point is finite, on z = 0.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_serial::rplidar::{
    NodeDecoder, ResponseDescriptor, DESCRIPTOR_LEN, HEALTH_LEN, INFO_LEN,
};
use tacmesh_serial::{DeviceInfo, Health, Revolution, RplidarScanner, ScanNode};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk_seed, bytes)) = data.split_first() else {
        return;
    };
    let chunk_len = usize::from(chunk_seed).max(1);

    if let Some((descriptor, _)) = bytes.split_first_chunk::<DESCRIPTOR_LEN>() {
        if let Ok(parsed) = ResponseDescriptor::parse(descriptor) {
            // Reserved modes keep their two bits, so even those round-trip.
            assert_eq!(&parsed.encode(), descriptor);
            let _ = parsed.expect(&ResponseDescriptor::SCAN);
        }
    }
    if let Some((info, _)) = bytes.split_first_chunk::<INFO_LEN>() {
        let parsed = DeviceInfo::parse(info);
        assert_eq!(&parsed.encode(), info);
        assert_eq!(parsed.serial_hex().len(), 32);
    }
    if let Some((health, _)) = bytes.split_first_chunk::<HEALTH_LEN>() {
        assert_eq!(&Health::parse(health).encode(), health);
    }

    let mut decoder = NodeDecoder::new();
    let mut nodes = 0;
    for chunk in bytes.chunks(chunk_len) {
        decoder.feed(chunk);
        while let Some(node) = decoder.next_node() {
            assert!(node.angle_q6 < 360 * 64);
            assert_eq!(ScanNode::parse(&node.encode()), Ok(node));
            nodes += 1;
        }
    }
    assert_eq!(decoder.stats().nodes, nodes);

    let mut scanner = RplidarScanner::new();
    let mut revolutions = Vec::new();
    for chunk in bytes.chunks(chunk_len) {
        scanner.feed(chunk, &mut revolutions);
    }
    assert_eq!(scanner.stats(), decoder.stats());
    revolutions.iter().for_each(check_revolution);
});

fn check_revolution(revolution: &Revolution) {
    for sample in &revolution.samples {
        assert!(
            (0.0..360.0).contains(&sample.angle_deg),
            "angle {}",
            sample.angle_deg
        );
    }
    let (cloud, skipped) = revolution.to_cloud();
    assert_eq!(cloud.points.len() + skipped, revolution.samples.len());
    assert!(cloud.points.iter().all(|p| p.is_finite() && p.z == 0.0));
}
