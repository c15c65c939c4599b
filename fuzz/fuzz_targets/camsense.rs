//! The Camsense X1-style packet decoder on an arbitrary UART byte stream, fed in chunks the way
//! a serial port returns them (the first byte picks the chunk size): `CamsenseDecoder` (bytes →
//! packets) and `CamsenseScanner` (bytes → revolutions → planar clouds), as `CamsenseSource`
//! drives them.
//!
//! Properties beyond "no panic":
//! - every packet decoded re-encodes to bytes that parse back to the same packet;
//! - once the decoder asks for more bytes, it holds less than one packet;
//! - every sample angle is in `[0, 360)` degrees and every cloud point is finite, on z = 0.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_serial::camsense::{encode_packet, parse_packet, PACKET_LEN};
use tacmesh_serial::{CamsenseDecoder, CamsenseScanner, Revolution};

fuzz_target!(|data: &[u8]| {
    let Some((&chunk_seed, stream)) = data.split_first() else {
        return;
    };
    let chunk_len = usize::from(chunk_seed).max(1);

    let mut decoder = CamsenseDecoder::new();
    for chunk in stream.chunks(chunk_len) {
        decoder.feed(chunk);
        while let Some(packet) = decoder.next_packet() {
            assert_eq!(parse_packet(&encode_packet(&packet)), Ok(packet));
        }
        assert!(decoder.pending_bytes() < PACKET_LEN);
    }

    let mut scanner = CamsenseScanner::new();
    let mut revolutions = Vec::new();
    for chunk in stream.chunks(chunk_len) {
        scanner.feed(chunk, &mut revolutions);
    }
    revolutions.extend(scanner.finish());
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
