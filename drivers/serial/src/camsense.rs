//! Camsense X1-style 360° scanner protocol: a pure, streaming decoder (no I/O).
//!
//! Layout of one 36-byte packet (all integers little-endian), as described for the recorded
//! capture in `testdata/SOURCES.md` and by the community's reverse engineering of the X1:
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 4 | header `55 AA 03 08` (`08`: eight samples per packet) |
//! | 4 | 2 | motor speed; ÷ 3840 gives revolutions per second |
//! | 6 | 2 | start angle `v`: `(v / 64 − 640) mod 360` degrees, the first sample's angle |
//! | 8 | 8 × 3 | samples: distance u16 in mm (bit 15 = invalid), quality u8 |
//! | 32 | 2 | end angle, same encoding, the eighth sample's angle |
//! | 34 | 2 | checksum: **not verified** (its algorithm is not documented) |
//!
//! The samples' angles interpolate linearly from start to end, through 360° when the packet
//! straddles 0°. Since the checksum is not checked, a packet is rejected (counted in
//! [`CamsenseStats::bad_packets`]) when an angle field is outside the encoding's range
//! (`v` in `[40960, 64000)`), when start and end are implausibly far apart, or when another header
//! starts inside its 36 bytes (a truncated packet followed by the next one); the decoder then
//! resynchronises on the next header. Bytes dropped while searching for a header are counted in
//! [`CamsenseStats::skipped_bytes`].
//!
//! Entry points: [`CamsenseDecoder`] (bytes → packets), [`CamsenseScanner`] (bytes →
//! [`Revolution`]s), [`parse_packet`].

use crate::revolution::{Revolution, RevolutionAssembler, ScanSample};

pub const HEADER: [u8; 4] = [0x55, 0xAA, 0x03, 0x08];
pub const PACKET_LEN: usize = 36;
pub const SAMPLES_PER_PACKET: usize = 8;
/// Bit 15 of a distance marks the sample invalid.
pub const INVALID_FLAG: u16 = 0x8000;
/// Raw speed units per revolution per second.
pub const SPEED_UNITS_PER_REV_PER_S: f32 = 3840.0;

/// Raw angle range: `(v / 64 − 640)` lies in `[0, 360)` for `v` in this range.
const ANGLE_RAW_MIN: u16 = 640 * 64;
const ANGLE_RAW_END: u16 = (640 + 360) * 64;
/// A packet spans about 6° at 5 rev/s (≈ 7° at 6 rev/s); more than this is not one packet.
const MAX_PACKET_SPAN_DEG: f32 = 45.0;

/// Why a 36-byte window that starts with the header is not a packet.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PacketError {
    #[error("packet does not start with 55 AA 03 08")]
    BadHeader,
    #[error("{field} angle raw value {raw} is outside [40960, 64000)")]
    AngleOutOfRange { field: &'static str, raw: u16 },
    #[error("packet spans {span_deg}° from start to end angle, more than one packet can")]
    ImplausibleSpan { span_deg: f32 },
    #[error("another header starts at byte {offset} inside the packet: truncated packet")]
    Truncated { offset: usize },
}

/// One decoded packet, fields raw as on the wire plus converted accessors.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CamsensePacket {
    pub speed_raw: u16,
    pub start_angle_raw: u16,
    pub end_angle_raw: u16,
    /// `(distance_raw, quality)`; `distance_raw` keeps the invalid flag (bit 15).
    pub samples: [(u16, u8); SAMPLES_PER_PACKET],
    /// The trailing two bytes, kept but not verified.
    pub checksum_raw: u16,
}

fn angle_deg(raw: u16) -> f32 {
    (raw as f32 / 64.0 - 640.0).rem_euclid(360.0)
}

impl CamsensePacket {
    pub fn speed_rev_per_s(&self) -> f32 {
        self.speed_raw as f32 / SPEED_UNITS_PER_REV_PER_S
    }

    pub fn start_angle_deg(&self) -> f32 {
        angle_deg(self.start_angle_raw)
    }

    pub fn end_angle_deg(&self) -> f32 {
        angle_deg(self.end_angle_raw)
    }

    /// Degrees swept from the first to the eighth sample, through 360° if the packet wraps.
    pub fn span_deg(&self) -> f32 {
        (self.end_angle_deg() - self.start_angle_deg()).rem_euclid(360.0)
    }

    /// The eight samples with interpolated angles in `[0, 360)`.
    pub fn scan_samples(&self) -> [ScanSample; SAMPLES_PER_PACKET] {
        let (start, span) = (self.start_angle_deg(), self.span_deg());
        let step = span / (SAMPLES_PER_PACKET - 1) as f32;
        std::array::from_fn(|k| {
            let (distance_raw, quality) = self.samples[k];
            let valid = distance_raw & INVALID_FLAG == 0 && distance_raw != 0;
            ScanSample {
                angle_deg: (start + step * k as f32).rem_euclid(360.0),
                distance_m: (distance_raw & !INVALID_FLAG) as f32 * 1e-3,
                quality,
                valid,
            }
        })
    }

    /// How many of the eight samples carry the invalid flag.
    pub fn flagged_invalid(&self) -> usize {
        self.samples
            .iter()
            .filter(|(d, _)| d & INVALID_FLAG != 0)
            .count()
    }
}

fn u16_at(bytes: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// Decodes one packet from exactly [`PACKET_LEN`] bytes, with the plausibility checks of the
/// module doc.
pub fn parse_packet(bytes: &[u8; PACKET_LEN]) -> Result<CamsensePacket, PacketError> {
    if bytes[..4] != HEADER {
        return Err(PacketError::BadHeader);
    }
    if let Some(offset) = (1..=PACKET_LEN - HEADER.len()).find(|&i| bytes[i..i + 4] == HEADER) {
        return Err(PacketError::Truncated { offset });
    }
    let packet = CamsensePacket {
        speed_raw: u16_at(bytes, 4),
        start_angle_raw: u16_at(bytes, 6),
        end_angle_raw: u16_at(bytes, 32),
        samples: std::array::from_fn(|k| (u16_at(bytes, 8 + 3 * k), bytes[10 + 3 * k])),
        checksum_raw: u16_at(bytes, 34),
    };
    for (field, raw) in [
        ("start", packet.start_angle_raw),
        ("end", packet.end_angle_raw),
    ] {
        if !(ANGLE_RAW_MIN..ANGLE_RAW_END).contains(&raw) {
            return Err(PacketError::AngleOutOfRange { field, raw });
        }
    }
    let span_deg = packet.span_deg();
    if span_deg > MAX_PACKET_SPAN_DEG {
        return Err(PacketError::ImplausibleSpan { span_deg });
    }
    Ok(packet)
}

/// Running counts of what the decoder saw.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct CamsenseStats {
    /// Packets decoded.
    pub packets: u64,
    /// Samples in decoded packets (8 per packet).
    pub samples: u64,
    /// Of those, samples carrying the 0x8000 invalid flag.
    pub flagged_invalid: u64,
    /// Bytes dropped while looking for a header (leading partial packet, garbage, bad packets).
    pub skipped_bytes: u64,
    /// Windows that started with a header but failed a check of [`parse_packet`].
    pub bad_packets: u64,
}

/// Streaming packet decoder: feed it byte chunks of any size, pull out packets.
#[derive(Debug, Default)]
pub struct CamsenseDecoder {
    buffer: Vec<u8>,
    /// Read position in `buffer`; consumed bytes are drained lazily.
    at: usize,
    stats: CamsenseStats,
}

impl CamsenseDecoder {
    pub fn new() -> Self {
        Self::default()
    }

    /// Appends received bytes.
    pub fn feed(&mut self, bytes: &[u8]) {
        if self.at > 0 && self.at >= self.buffer.len() / 2 {
            self.buffer.drain(..self.at);
            self.at = 0;
        }
        self.buffer.extend_from_slice(bytes);
    }

    /// The next complete packet in the buffered bytes, skipping garbage and bad packets;
    /// `None` when more bytes are needed.
    pub fn next_packet(&mut self) -> Option<CamsensePacket> {
        loop {
            let rest = &self.buffer[self.at..];
            // Find the header; keep a possible header prefix at the end for the next feed.
            let start = match rest.windows(HEADER.len()).position(|w| w == HEADER) {
                Some(start) => start,
                None => {
                    let keep = (1..HEADER.len())
                        .rev()
                        .find(|&n| rest.ends_with(&HEADER[..n]))
                        .unwrap_or(0);
                    let dropped = rest.len() - keep;
                    self.stats.skipped_bytes += dropped as u64;
                    self.at += dropped;
                    return None;
                }
            };
            self.stats.skipped_bytes += start as u64;
            self.at += start;
            let window: &[u8; PACKET_LEN] = self
                .buffer
                .get(self.at..self.at + PACKET_LEN)?
                .try_into()
                .ok()?;
            match parse_packet(window) {
                Ok(packet) => {
                    self.at += PACKET_LEN;
                    self.stats.packets += 1;
                    self.stats.samples += SAMPLES_PER_PACKET as u64;
                    self.stats.flagged_invalid += packet.flagged_invalid() as u64;
                    return Some(packet);
                }
                Err(error) => {
                    tracing::trace!(%error, "camsense: bad packet, resynchronising");
                    self.stats.bad_packets += 1;
                    // Drop up to the inner header of a truncated packet, else just this header's
                    // first byte, and look again.
                    let drop = match error {
                        PacketError::Truncated { offset } => offset,
                        _ => 1,
                    };
                    self.stats.skipped_bytes += drop as u64;
                    self.at += drop;
                }
            }
        }
    }

    pub fn stats(&self) -> CamsenseStats {
        self.stats
    }

    /// Bytes received but not yet consumed (a partial packet at most, after [`Self::next_packet`]
    /// returned `None`).
    pub fn pending_bytes(&self) -> usize {
        self.buffer.len() - self.at
    }
}

/// Bytes → revolutions: a [`CamsenseDecoder`] followed by a [`RevolutionAssembler`].
#[derive(Debug, Default)]
pub struct CamsenseScanner {
    decoder: CamsenseDecoder,
    assembler: RevolutionAssembler,
    last_speed_rev_per_s: Option<f32>,
}

impl CamsenseScanner {
    pub fn new() -> Self {
        Self::default()
    }

    /// Decodes `bytes` and appends every revolution they close to `out`.
    pub fn feed(&mut self, bytes: &[u8], out: &mut Vec<Revolution>) {
        self.decoder.feed(bytes);
        while let Some(packet) = self.decoder.next_packet() {
            self.last_speed_rev_per_s = Some(packet.speed_rev_per_s());
            for sample in packet.scan_samples() {
                out.extend(self.assembler.push(sample, false));
            }
        }
    }

    /// The unfinished revolution at the end of the stream, if any (marked incomplete).
    pub fn finish(&mut self) -> Option<Revolution> {
        self.assembler.flush()
    }

    pub fn stats(&self) -> CamsenseStats {
        self.decoder.stats()
    }

    /// The motor speed of the latest packet.
    pub fn speed_rev_per_s(&self) -> Option<f32> {
        self.last_speed_rev_per_s
    }
}

/// Encodes a packet: the inverse of [`parse_packet`], with the checksum bytes as given.
/// For tests and simulators.
pub fn encode_packet(packet: &CamsensePacket) -> [u8; PACKET_LEN] {
    let mut bytes = [0u8; PACKET_LEN];
    bytes[..4].copy_from_slice(&HEADER);
    bytes[4..6].copy_from_slice(&packet.speed_raw.to_le_bytes());
    bytes[6..8].copy_from_slice(&packet.start_angle_raw.to_le_bytes());
    for (k, (distance, quality)) in packet.samples.iter().enumerate() {
        bytes[8 + 3 * k..10 + 3 * k].copy_from_slice(&distance.to_le_bytes());
        bytes[10 + 3 * k] = *quality;
    }
    bytes[32..34].copy_from_slice(&packet.end_angle_raw.to_le_bytes());
    bytes[34..36].copy_from_slice(&packet.checksum_raw.to_le_bytes());
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A packet from `start_deg` to `end_deg` with distances 1000, 1001, … mm.
    fn packet(start_deg: f32, end_deg: f32) -> CamsensePacket {
        let raw = |deg: f32| ((deg.rem_euclid(360.0) + 640.0) * 64.0).round() as u16;
        CamsensePacket {
            speed_raw: 20_000,
            start_angle_raw: raw(start_deg),
            end_angle_raw: raw(end_deg),
            samples: std::array::from_fn(|k| (1000 + k as u16, 200)),
            checksum_raw: 0xBEEF,
        }
    }

    #[test]
    fn packet_round_trips_through_bytes() {
        let p = packet(10.0, 17.0);
        assert_eq!(parse_packet(&encode_packet(&p)), Ok(p));
    }

    #[test]
    fn golden_packet_from_the_capture_decodes() {
        // The first whole packet of camsense_x1_protocol_uart_capture.bin (bytes 20..56).
        let bytes: [u8; 36] = [
            0x55, 0xaa, 0x03, 0x08, 0x87, 0x4d, 0x18, 0xc7, 0xa3, 0x07, 0x10, 0xa0, 0x07, 0x3c,
            0x86, 0x06, 0x5c, 0x92, 0x06, 0x48, 0x18, 0x0a, 0x3b, 0x2a, 0x0a, 0x3d, 0x48, 0x0a,
            0x3b, 0x61, 0x0a, 0x3b, 0xa9, 0xc8, 0x99, 0x6e,
        ];
        let p = parse_packet(&bytes).unwrap();
        assert!((p.speed_rev_per_s() - 19847.0 / 3840.0).abs() < 1e-6);
        assert_eq!(p.start_angle_deg(), 156.375);
        assert_eq!(p.end_angle_deg(), 162.0 + 41.0 / 64.0);
        assert_eq!(p.samples[0], (0x07a3, 0x10));
        let s = p.scan_samples();
        assert_eq!(s[0].angle_deg, 156.375);
        assert_eq!(s[7].angle_deg, 162.0 + 41.0 / 64.0);
        assert!((s[0].distance_m - 1.955).abs() < 1e-6);
    }

    #[test]
    fn sample_angles_interpolate_through_360() {
        let s = packet(357.0, 4.0).scan_samples();
        assert_eq!(s[0].angle_deg, 357.0);
        assert!((s[3].angle_deg - 0.0).abs() < 1e-4 || (s[3].angle_deg - 360.0).abs() < 1e-3);
        assert!((s[4].angle_deg - 1.0).abs() < 1e-4, "{}", s[4].angle_deg);
        assert!((s[7].angle_deg - 4.0).abs() < 1e-4);
    }

    #[test]
    fn invalid_flag_marks_sample_invalid() {
        let mut p = packet(10.0, 17.0);
        p.samples[2] = (0x8000, 0);
        p.samples[3] = (0x8123, 0);
        let s = p.scan_samples();
        assert!(!s[2].valid && !s[3].valid && s[4].valid);
        assert_eq!(p.flagged_invalid(), 2);
    }

    #[test]
    fn decoder_accepts_byte_at_a_time() {
        let bytes: Vec<u8> = (0..5)
            .flat_map(|i| encode_packet(&packet(7.0 * i as f32, 7.0 * i as f32 + 6.0)))
            .collect();
        let mut decoder = CamsenseDecoder::new();
        let mut packets = 0;
        for b in bytes {
            decoder.feed(&[b]);
            while decoder.next_packet().is_some() {
                packets += 1;
            }
        }
        assert_eq!(packets, 5);
        assert_eq!(decoder.stats().skipped_bytes, 0);
    }

    #[test]
    fn decoder_resyncs_after_garbage_and_counts_it() {
        let mut bytes = vec![0x55, 0x00, 0x12, 0x55, 0xAA];
        bytes.extend(encode_packet(&packet(0.0, 6.0)));
        bytes.extend([1, 2, 3]);
        bytes.extend(encode_packet(&packet(7.0, 13.0)));
        let mut decoder = CamsenseDecoder::new();
        decoder.feed(&bytes);
        assert!(decoder.next_packet().is_some() && decoder.next_packet().is_some());
        assert!(decoder.next_packet().is_none());
        assert_eq!(decoder.stats().skipped_bytes, 8);
        assert_eq!(decoder.stats().bad_packets, 0);
    }

    #[test]
    fn truncated_packet_is_counted_and_the_next_one_kept() {
        let first = encode_packet(&packet(0.0, 6.0));
        let mut bytes = first[..20].to_vec();
        bytes.extend(encode_packet(&packet(7.0, 13.0)));
        let mut decoder = CamsenseDecoder::new();
        decoder.feed(&bytes);
        let p = decoder.next_packet().unwrap();
        assert_eq!(p.start_angle_deg(), 7.0);
        assert_eq!(decoder.stats().bad_packets, 1);
        assert_eq!(decoder.stats().skipped_bytes, 20);
    }

    #[test]
    fn out_of_range_angle_is_a_bad_packet() {
        let mut bytes = encode_packet(&packet(0.0, 6.0));
        bytes[7] = 0x01; // start angle raw 0x01xx < 40960
        assert!(matches!(
            parse_packet(&bytes),
            Err(PacketError::AngleOutOfRange { field: "start", .. })
        ));
        let mut decoder = CamsenseDecoder::new();
        decoder.feed(&bytes);
        assert!(decoder.next_packet().is_none());
        assert_eq!(decoder.stats().bad_packets, 1);
        assert_eq!(decoder.stats().skipped_bytes, 36);
    }

    #[test]
    fn scanner_closes_a_revolution_at_the_wrap() {
        let mut scanner = CamsenseScanner::new();
        let mut out = Vec::new();
        for i in 0..120 {
            let start = (7.0 * i as f32) % 360.0;
            scanner.feed(&encode_packet(&packet(start, start + 6.0)), &mut out);
        }
        // 120 packets × 7° = 840°: two wraps.
        assert_eq!(out.len(), 2);
        assert!(!out[0].complete && out[1].complete);
        assert!(scanner.finish().is_some());
    }
}
