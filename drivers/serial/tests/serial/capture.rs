//! The real Camsense capture through the pure decoder: the counts recorded in SOURCES.md, and
//! corruption of those bytes.

use tacmesh_serial::camsense::{CamsenseDecoder, CamsenseScanner, PACKET_LEN};
use tacmesh_serial::Revolution;

use crate::util::{capture, Lcg};

const LEADING_PARTIAL: usize = 20;
const PACKETS: u64 = 18_195;
const SAMPLES: u64 = 145_560;
const FLAGGED_INVALID: u64 = 10_327;
/// Wraps through 0° in the capture: each closes a revolution.
const WRAPS: usize = 362;

fn scan(bytes: &[u8], chunk: impl Fn(usize) -> usize) -> (CamsenseScanner, Vec<Revolution>) {
    let mut scanner = CamsenseScanner::new();
    let mut revolutions = Vec::new();
    let (mut at, mut i) = (0, 0);
    while at < bytes.len() {
        let end = (at + chunk(i)).min(bytes.len());
        scanner.feed(&bytes[at..end], &mut revolutions);
        (at, i) = (end, i + 1);
    }
    (scanner, revolutions)
}

#[test]
fn capture_counts_match_sources_md() {
    let bytes = capture();
    assert_eq!(bytes.len(), 655_075);
    let (mut scanner, revolutions) = scan(&bytes, |_| bytes.len());
    let stats = scanner.stats();
    assert_eq!(stats.packets, PACKETS);
    assert_eq!(stats.samples, SAMPLES);
    assert_eq!(stats.flagged_invalid, FLAGGED_INVALID);
    assert_eq!(stats.skipped_bytes, LEADING_PARTIAL as u64);
    assert_eq!(stats.bad_packets, 0);

    // 362 wraps close 362 revolutions: the first is the partial turn the capture starts in
    // (from 156.4°), the other 361 are whole; the samples after the last wrap stay pending.
    assert_eq!(revolutions.len(), WRAPS);
    assert!(!revolutions[0].complete);
    assert_eq!(revolutions[0].samples[0].angle_deg, 156.375);
    assert!(revolutions[1..].iter().all(|r| r.complete));
    let tail = scanner.finish().expect("a partial last revolution");
    assert!(!tail.complete);
    let all: Vec<&Revolution> = revolutions.iter().chain(std::iter::once(&tail)).collect();
    let samples: usize = all.iter().map(|r| r.samples.len()).sum();
    assert_eq!(samples as u64, SAMPLES);
    let invalid: usize = all.iter().map(|r| r.invalid_samples()).sum();
    assert_eq!(
        invalid as u64, FLAGGED_INVALID,
        "no zero distances besides the flag"
    );
    // Whole revolutions hold 383..422 samples: about 400 per turn.
    let sizes = revolutions[1..].iter().map(|r| r.samples.len());
    assert!(sizes.clone().min().unwrap() > 350 && sizes.max().unwrap() < 450);
}

#[test]
fn capture_speed_is_about_5_2_rev_per_s() {
    let bytes = capture();
    let mut decoder = CamsenseDecoder::new();
    decoder.feed(&bytes);
    let (mut sum, mut n, mut lo, mut hi) = (0.0f64, 0, f32::MAX, f32::MIN);
    while let Some(p) = decoder.next_packet() {
        let s = p.speed_rev_per_s();
        (sum, n, lo, hi) = (sum + f64::from(s), n + 1, lo.min(s), hi.max(s));
    }
    let mean = sum / n as f64;
    assert!((mean - 5.185).abs() < 0.01, "mean speed {mean}");
    assert!(lo > 4.9 && hi < 5.5, "{lo}..{hi}");
    // The last 35 bytes are a partial packet, kept for the next feed.
    assert_eq!(decoder.pending_bytes(), 35);
}

#[test]
fn capture_revolutions_are_planar_clouds_of_a_room() {
    let bytes = capture();
    let (_, revolutions) = scan(&bytes, |_| bytes.len());
    for revolution in &revolutions[1..] {
        let (cloud, skipped) = revolution.to_cloud();
        assert_eq!(cloud.len() + skipped, revolution.samples.len());
        assert!(cloud.len() > 300);
        for p in &cloud.points {
            assert!(p.is_finite() && p.z == 0.0);
            let range = p.length();
            assert!(range > 0.0 && range < 12.0, "{range}");
        }
    }
}

#[test]
fn chunking_does_not_change_the_revolutions() {
    let bytes = capture();
    let bytes = &bytes[..100_000];
    let (_, whole) = scan(bytes, |_| usize::MAX);
    let (_, one_by_one) = scan(bytes, |_| 1);
    let (_, ragged) = scan(bytes, |i| 1 + (i * 37) % 113);
    assert_eq!(whole, one_by_one);
    assert_eq!(whole, ragged);
}

/// Byte offset of packet `k` of the capture.
fn packet_at(k: usize) -> usize {
    LEADING_PARTIAL + k * PACKET_LEN
}

#[test]
fn flipped_header_byte_loses_one_packet() {
    let mut bytes = capture();
    bytes[packet_at(100) + 1] ^= 0xFF;
    let (scanner, _) = scan(&bytes, |_| 4096);
    let stats = scanner.stats();
    assert_eq!(stats.packets, PACKETS - 1);
    assert_eq!(stats.skipped_bytes, (LEADING_PARTIAL + PACKET_LEN) as u64);
    assert_eq!(stats.bad_packets, 0);
}

#[test]
fn flipped_angle_byte_is_a_counted_bad_packet() {
    let mut bytes = capture();
    bytes[packet_at(200) + 7] = 0x00; // start angle high byte: raw < 40960
    bytes[packet_at(300) + 33] = 0xFF; // end angle high byte: raw ≥ 64000
    let (scanner, _) = scan(&bytes, |_| 4096);
    let stats = scanner.stats();
    assert_eq!(stats.packets, PACKETS - 2);
    assert_eq!(stats.bad_packets, 2);
    assert_eq!(
        stats.skipped_bytes,
        (LEADING_PARTIAL + 2 * PACKET_LEN) as u64
    );
}

#[test]
fn inserted_garbage_is_skipped_and_counted() {
    let mut bytes = capture();
    // Garbage with a false header prefix, between packets 50 and 51.
    bytes.splice(
        packet_at(51)..packet_at(51),
        [0x55, 0xAA, 0x03, 0x01, 0x02, 0x55, 0x55],
    );
    let (scanner, revolutions) = scan(&bytes, |_| 1000);
    let stats = scanner.stats();
    assert_eq!(stats.packets, PACKETS);
    assert_eq!(stats.skipped_bytes, LEADING_PARTIAL as u64 + 7);
    assert_eq!(revolutions.len(), WRAPS);
}

#[test]
fn truncated_packet_is_a_bad_packet_and_the_next_survives() {
    let mut bytes = capture();
    // Packet 400 loses its last 12 bytes: the next header lands inside its 36-byte window.
    bytes.drain(packet_at(401) - 12..packet_at(401));
    let (scanner, _) = scan(&bytes, |_| 777);
    let stats = scanner.stats();
    assert_eq!(stats.packets, PACKETS - 1);
    assert_eq!(stats.bad_packets, 1);
    assert_eq!(
        stats.skipped_bytes,
        (LEADING_PARTIAL + PACKET_LEN - 12) as u64
    );
}

#[test]
fn random_corruption_never_panics_and_stays_accounted() {
    let original = capture();
    let mut rng = Lcg(7);
    for round in 0..20 {
        let mut bytes = original[..50_000].to_vec();
        for _ in 0..200 {
            let at = rng.below(bytes.len());
            match rng.below(3) {
                0 => bytes[at] ^= 1 << rng.below(8),
                1 => bytes.insert(at, rng.next() as u8),
                _ => {
                    let end = (at + rng.below(40)).min(bytes.len());
                    bytes.drain(at..end);
                }
            }
        }
        let (mut scanner, revolutions) = scan(&bytes, |i| 1 + (i * 13 + round) % 300);
        let stats = scanner.stats();
        // Every byte is either in a packet, skipped, or pending (< one packet).
        let accounted = stats.packets * PACKET_LEN as u64 + stats.skipped_bytes;
        assert!(accounted <= bytes.len() as u64);
        assert!(bytes.len() as u64 - accounted < PACKET_LEN as u64);
        assert!(stats.packets > 1000, "{stats:?}");
        let tail = scanner.finish();
        let samples: usize = revolutions
            .iter()
            .chain(tail.iter())
            .map(|r| r.samples.len())
            .sum();
        assert_eq!(samples as u64, stats.samples);
    }
}
