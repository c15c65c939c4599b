//! Slamtec RPLIDAR A-series serial protocol, the legacy "standard scan" subset: pure encoders and
//! decoders, no I/O.
//!
//! Written from Slamtec's published protocol description (as mirrored by the `rplidar_sdk`
//! headers):
//!
//! - **Request**: `A5 cmd`, or with a payload `A5 cmd len payload… checksum` where the checksum
//!   XORs every byte before it. Commands used here carry no payload: STOP `25`, RESET `40`,
//!   SCAN `20`, FORCE_SCAN `21`, GET_INFO `50`, GET_HEALTH `52`.
//! - **Response descriptor** (7 bytes): `A5 5A`, a u32 LE whose low 30 bits are the length of one
//!   response and whose top 2 bits are the send mode (0 single, 1 multiple/streaming), then a data
//!   type byte. GET_INFO answers `len 20, single, 0x04`; GET_HEALTH `len 3, single, 0x06`;
//!   SCAN `len 5, multiple, 0x81`. STOP and RESET have no response.
//! - **GET_INFO** payload: model u8, firmware minor u8, firmware major u8, hardware u8, 16-byte
//!   serial number.
//! - **GET_HEALTH** payload: status u8 (0 good, 1 warning, 2 error), error code u16 LE.
//! - **Standard scan node** (5 bytes): `quality << 2 | !S << 1 | S` where S marks the first node
//!   of a new 360° scan; `angle_q6 << 1 | C` as u16 LE with check bit C = 1 (degrees × 64);
//!   `distance_q2` u16 LE (mm × 4, 0 = no reading).
//!
//! Standard nodes carry only weak framing (two check bits), so [`NodeDecoder`] accepts a node
//! when its checks pass and its angle is below 360°; on failure it drops one byte and retries,
//! counting the resynchronisation, and while out of sync it also requires the following 5 bytes
//! to be a plausible node before it trusts the framing again. A misaligned window can still pass
//! by chance (about 1 in 6 per window, 1 in 30 for two), so a corrupted stream may leak a rare
//! wrong point.
//!
//! Entry points: [`request`], [`ResponseDescriptor`], [`DeviceInfo`], [`Health`], [`ScanNode`],
//! [`NodeDecoder`], [`RplidarScanner`].

use crate::revolution::{Revolution, RevolutionAssembler, ScanSample};

pub const SYNC: u8 = 0xA5;
pub const DESCRIPTOR_SYNC: [u8; 2] = [0xA5, 0x5A];
pub const DESCRIPTOR_LEN: usize = 7;
pub const NODE_LEN: usize = 5;
pub const INFO_LEN: usize = 20;
pub const HEALTH_LEN: usize = 3;

pub const TYPE_INFO: u8 = 0x04;
pub const TYPE_HEALTH: u8 = 0x06;
pub const TYPE_SCAN: u8 = 0x81;

/// The requests this crate sends (or, in the emulator, answers).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    Stop,
    Reset,
    Scan,
    ForceScan,
    GetInfo,
    GetHealth,
}

impl Command {
    pub fn code(self) -> u8 {
        match self {
            Command::Stop => 0x25,
            Command::Reset => 0x40,
            Command::Scan => 0x20,
            Command::ForceScan => 0x21,
            Command::GetInfo => 0x50,
            Command::GetHealth => 0x52,
        }
    }

    pub fn from_code(code: u8) -> Option<Self> {
        [
            Command::Stop,
            Command::Reset,
            Command::Scan,
            Command::ForceScan,
            Command::GetInfo,
            Command::GetHealth,
        ]
        .into_iter()
        .find(|c| c.code() == code)
    }
}

/// The bytes of a payload-less request.
pub fn request(command: Command) -> [u8; 2] {
    [SYNC, command.code()]
}

/// The bytes of a request with a payload (`cmd | 0x80` by convention; the caller chooses the
/// code). The checksum XORs every preceding byte.
pub fn request_with_payload(code: u8, payload: &[u8]) -> Result<Vec<u8>, ProtocolError> {
    let len = u8::try_from(payload.len())
        .map_err(|_| ProtocolError::PayloadTooLong { len: payload.len() })?;
    let mut bytes = vec![SYNC, code, len];
    bytes.extend_from_slice(payload);
    let checksum = bytes.iter().fold(0u8, |acc, b| acc ^ b);
    bytes.push(checksum);
    Ok(bytes)
}

/// What went wrong decoding device bytes.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ProtocolError {
    #[error("response descriptor does not start with A5 5A")]
    BadDescriptorSync,
    #[error(
        "expected a response of type {expected:#04x} (length {expected_len}), got type \
         {got:#04x} (length {got_len}): is this an RPLIDAR A-series at the right baud rate?"
    )]
    UnexpectedResponse {
        expected: u8,
        expected_len: u32,
        got: u8,
        got_len: u32,
    },
    #[error("scan node fails its check bits")]
    BadNode,
    #[error("request payload of {len} bytes is longer than 255")]
    PayloadTooLong { len: usize },
}

/// How the device sends the responses that follow a descriptor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SendMode {
    Single,
    Multiple,
    /// Modes 2 and 3 are reserved.
    Reserved(u8),
}

/// The 7-byte header before every response.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ResponseDescriptor {
    /// Bytes in one response (30 bits).
    pub len: u32,
    pub mode: SendMode,
    pub data_type: u8,
}

impl ResponseDescriptor {
    pub const INFO: Self = Self {
        len: INFO_LEN as u32,
        mode: SendMode::Single,
        data_type: TYPE_INFO,
    };
    pub const HEALTH: Self = Self {
        len: HEALTH_LEN as u32,
        mode: SendMode::Single,
        data_type: TYPE_HEALTH,
    };
    pub const SCAN: Self = Self {
        len: NODE_LEN as u32,
        mode: SendMode::Multiple,
        data_type: TYPE_SCAN,
    };

    pub fn parse(bytes: &[u8; DESCRIPTOR_LEN]) -> Result<Self, ProtocolError> {
        if bytes[..2] != DESCRIPTOR_SYNC {
            return Err(ProtocolError::BadDescriptorSync);
        }
        let word = u32::from_le_bytes([bytes[2], bytes[3], bytes[4], bytes[5]]);
        let mode = match (word >> 30) as u8 {
            0 => SendMode::Single,
            1 => SendMode::Multiple,
            other => SendMode::Reserved(other),
        };
        Ok(Self {
            len: word & 0x3FFF_FFFF,
            mode,
            data_type: bytes[6],
        })
    }

    pub fn encode(&self) -> [u8; DESCRIPTOR_LEN] {
        let mode = match self.mode {
            SendMode::Single => 0,
            SendMode::Multiple => 1,
            SendMode::Reserved(m) => u32::from(m & 3),
        };
        let word = (self.len & 0x3FFF_FFFF) | (mode << 30);
        let w = word.to_le_bytes();
        [0xA5, 0x5A, w[0], w[1], w[2], w[3], self.data_type]
    }

    /// `Ok` when this is the descriptor `expected`, else the mismatch as an error.
    pub fn expect(&self, expected: &Self) -> Result<(), ProtocolError> {
        if self == expected {
            return Ok(());
        }
        Err(ProtocolError::UnexpectedResponse {
            expected: expected.data_type,
            expected_len: expected.len,
            got: self.data_type,
            got_len: self.len,
        })
    }
}

/// The answer to GET_INFO.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceInfo {
    pub model: u8,
    pub firmware_major: u8,
    pub firmware_minor: u8,
    pub hardware: u8,
    pub serial_number: [u8; 16],
}

impl DeviceInfo {
    pub fn parse(bytes: &[u8; INFO_LEN]) -> Self {
        Self {
            model: bytes[0],
            firmware_minor: bytes[1],
            firmware_major: bytes[2],
            hardware: bytes[3],
            serial_number: std::array::from_fn(|i| bytes[4 + i]),
        }
    }

    pub fn encode(&self) -> [u8; INFO_LEN] {
        let mut bytes = [0u8; INFO_LEN];
        bytes[..4].copy_from_slice(&[
            self.model,
            self.firmware_minor,
            self.firmware_major,
            self.hardware,
        ]);
        bytes[4..].copy_from_slice(&self.serial_number);
        bytes
    }

    /// The serial number as the usual 32 upper-case hex digits.
    pub fn serial_hex(&self) -> String {
        self.serial_number
            .iter()
            .map(|b| format!("{b:02X}"))
            .collect()
    }
}

/// Device self-check status.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HealthStatus {
    Good,
    Warning,
    Error,
    Unknown(u8),
}

/// The answer to GET_HEALTH.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Health {
    pub status: HealthStatus,
    pub error_code: u16,
}

impl Health {
    pub fn parse(bytes: &[u8; HEALTH_LEN]) -> Self {
        let status = match bytes[0] {
            0 => HealthStatus::Good,
            1 => HealthStatus::Warning,
            2 => HealthStatus::Error,
            other => HealthStatus::Unknown(other),
        };
        Self {
            status,
            error_code: u16::from_le_bytes([bytes[1], bytes[2]]),
        }
    }

    pub fn encode(&self) -> [u8; HEALTH_LEN] {
        let status = match self.status {
            HealthStatus::Good => 0,
            HealthStatus::Warning => 1,
            HealthStatus::Error => 2,
            HealthStatus::Unknown(s) => s,
        };
        let code = self.error_code.to_le_bytes();
        [status, code[0], code[1]]
    }
}

/// One standard-scan measurement, fields raw as on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ScanNode {
    /// S: the first node of a new 360° scan.
    pub start: bool,
    /// 6-bit signal quality.
    pub quality: u8,
    /// Degrees × 64, clockwise.
    pub angle_q6: u16,
    /// Millimetres × 4; 0 means no reading.
    pub distance_q2: u16,
}

impl ScanNode {
    /// Decodes a node, checking S ≠ !S and C = 1.
    pub fn parse(bytes: &[u8; NODE_LEN]) -> Result<Self, ProtocolError> {
        let s = bytes[0] & 1;
        let not_s = (bytes[0] >> 1) & 1;
        if s == not_s || bytes[1] & 1 != 1 {
            return Err(ProtocolError::BadNode);
        }
        Ok(Self {
            start: s == 1,
            quality: bytes[0] >> 2,
            angle_q6: u16::from_le_bytes([bytes[1], bytes[2]]) >> 1,
            distance_q2: u16::from_le_bytes([bytes[3], bytes[4]]),
        })
    }

    pub fn encode(&self) -> [u8; NODE_LEN] {
        let s = u8::from(self.start);
        let angle = ((self.angle_q6 & 0x7FFF) << 1 | 1).to_le_bytes();
        let distance = self.distance_q2.to_le_bytes();
        [
            (self.quality & 0x3F) << 2 | (1 - s) << 1 | s,
            angle[0],
            angle[1],
            distance[0],
            distance[1],
        ]
    }

    pub fn angle_deg(&self) -> f32 {
        self.angle_q6 as f32 / 64.0
    }

    pub fn distance_m(&self) -> f32 {
        self.distance_q2 as f32 / 4000.0
    }

    pub fn to_sample(&self) -> ScanSample {
        ScanSample {
            angle_deg: self.angle_deg().rem_euclid(360.0),
            distance_m: self.distance_m(),
            quality: self.quality,
            valid: self.distance_q2 != 0,
        }
    }
}

/// Node validity beyond the check bits: the angle must be below 360°.
fn plausible_node(bytes: &[u8]) -> Option<ScanNode> {
    let bytes: &[u8; NODE_LEN] = bytes.try_into().ok()?;
    ScanNode::parse(bytes)
        .ok()
        .filter(|node| node.angle_q6 < 360 * 64)
}

/// Running counts of the node stream.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct NodeStats {
    pub nodes: u64,
    /// Nodes with distance 0 (no reading).
    pub no_reading: u64,
    /// Bytes dropped to regain node framing.
    pub skipped_bytes: u64,
    /// Times framing was lost (a run of dropped bytes counts once).
    pub resyncs: u64,
}

/// Streaming decoder of standard scan nodes (the bytes after the SCAN descriptor).
#[derive(Debug)]
pub struct NodeDecoder {
    buffer: Vec<u8>,
    at: usize,
    stats: NodeStats,
    in_sync: bool,
}

impl NodeDecoder {
    /// A decoder that trusts the framing of the first bytes (they follow the SCAN descriptor).
    pub fn new() -> Self {
        Self {
            buffer: Vec::new(),
            at: 0,
            stats: NodeStats::default(),
            in_sync: true,
        }
    }

    pub fn feed(&mut self, bytes: &[u8]) {
        if self.at > 0 && self.at >= self.buffer.len() / 2 {
            self.buffer.drain(..self.at);
            self.at = 0;
        }
        self.buffer.extend_from_slice(bytes);
    }

    /// The next node; `None` when more bytes are needed. In sync, a node needs only its own
    /// checks; regaining sync, the 5 bytes after it must be plausible too (see the module doc).
    pub fn next_node(&mut self) -> Option<ScanNode> {
        loop {
            let rest = &self.buffer[self.at..];
            let needed = if self.in_sync { NODE_LEN } else { 2 * NODE_LEN };
            if rest.len() < needed {
                return None;
            }
            let own = plausible_node(&rest[..NODE_LEN]);
            let confirmed = self.in_sync || plausible_node(&rest[NODE_LEN..needed]).is_some();
            match own {
                Some(node) if confirmed => {
                    self.at += NODE_LEN;
                    self.in_sync = true;
                    self.stats.nodes += 1;
                    self.stats.no_reading += u64::from(node.distance_q2 == 0);
                    return Some(node);
                }
                _ => {
                    if self.in_sync {
                        self.stats.resyncs += 1;
                        tracing::trace!("rplidar: scan node framing lost, resynchronising");
                    }
                    self.in_sync = false;
                    self.at += 1;
                    self.stats.skipped_bytes += 1;
                }
            }
        }
    }

    pub fn stats(&self) -> NodeStats {
        self.stats
    }
}

impl Default for NodeDecoder {
    fn default() -> Self {
        Self::new()
    }
}

/// Node bytes → revolutions, cut at the S flag (or an angle wrap, if the S node was lost).
#[derive(Debug, Default)]
pub struct RplidarScanner {
    decoder: NodeDecoder,
    assembler: RevolutionAssembler,
}

impl RplidarScanner {
    pub fn new() -> Self {
        Self::default()
    }

    /// Decodes `bytes` and appends every revolution they close to `out`.
    pub fn feed(&mut self, bytes: &[u8], out: &mut Vec<Revolution>) {
        self.decoder.feed(bytes);
        while let Some(node) = self.decoder.next_node() {
            out.extend(self.assembler.push(node.to_sample(), node.start));
        }
    }

    pub fn stats(&self) -> NodeStats {
        self.decoder.stats()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_encode_sync_and_command() {
        assert_eq!(request(Command::GetHealth), [0xA5, 0x52]);
        assert_eq!(request(Command::GetInfo), [0xA5, 0x50]);
        assert_eq!(request(Command::Scan), [0xA5, 0x20]);
        assert_eq!(request(Command::Stop), [0xA5, 0x25]);
        assert_eq!(request(Command::Reset), [0xA5, 0x40]);
        assert_eq!(Command::from_code(0x52), Some(Command::GetHealth));
    }

    #[test]
    fn payload_request_checksum_xors_all_bytes() {
        // A5 ^ F0 ^ 02 ^ 94 ^ 02 = C1.
        let bytes = request_with_payload(0xF0, &[0x94, 0x02]).unwrap();
        assert_eq!(bytes, vec![0xA5, 0xF0, 0x02, 0x94, 0x02, 0xC1]);
    }

    #[test]
    fn scan_descriptor_golden_bytes() {
        let bytes = [0xA5, 0x5A, 0x05, 0x00, 0x00, 0x40, 0x81];
        assert_eq!(
            ResponseDescriptor::parse(&bytes),
            Ok(ResponseDescriptor::SCAN)
        );
        assert_eq!(ResponseDescriptor::SCAN.encode(), bytes);
        assert_eq!(
            ResponseDescriptor::INFO.encode(),
            [0xA5, 0x5A, 0x14, 0, 0, 0, 0x04]
        );
        assert_eq!(
            ResponseDescriptor::HEALTH.encode(),
            [0xA5, 0x5A, 0x03, 0, 0, 0, 0x06]
        );
    }

    #[test]
    fn descriptor_rejects_bad_sync_and_reports_unexpected_type() {
        let bytes = [0xA5, 0x5B, 0x05, 0x00, 0x00, 0x40, 0x81];
        assert_eq!(
            ResponseDescriptor::parse(&bytes),
            Err(ProtocolError::BadDescriptorSync)
        );
        let err = ResponseDescriptor::HEALTH
            .expect(&ResponseDescriptor::INFO)
            .unwrap_err();
        assert!(err.to_string().contains("0x04"), "{err}");
    }

    #[test]
    fn info_and_health_decode_golden_bytes() {
        let mut bytes = [0u8; 20];
        bytes[..4].copy_from_slice(&[0x18, 0x1D, 0x01, 0x07]);
        bytes[4] = 0xAB;
        let info = DeviceInfo::parse(&bytes);
        assert_eq!(
            (
                info.model,
                info.firmware_major,
                info.firmware_minor,
                info.hardware
            ),
            (0x18, 1, 29, 7)
        );
        assert!(info.serial_hex().starts_with("AB00"));
        assert_eq!(info.encode(), bytes);
        let health = Health::parse(&[0x02, 0x34, 0x12]);
        assert_eq!(health.status, HealthStatus::Error);
        assert_eq!(health.error_code, 0x1234);
        assert_eq!(health.encode(), [0x02, 0x34, 0x12]);
    }

    #[test]
    fn scan_node_golden_bytes() {
        // S = 1, quality 15, 90° (q6 5760), 1000 mm (q2 4000).
        let bytes = [15 << 2 | 0b01, 0x01, 0x2D, 0xA0, 0x0F];
        let node = ScanNode::parse(&bytes).unwrap();
        assert_eq!(
            node,
            ScanNode {
                start: true,
                quality: 15,
                angle_q6: 5760,
                distance_q2: 4000
            }
        );
        assert_eq!(node.angle_deg(), 90.0);
        assert_eq!(node.distance_m(), 1.0);
        assert_eq!(node.encode(), bytes);
    }

    #[test]
    fn scan_node_check_bits_are_enforced() {
        let good = ScanNode {
            start: false,
            quality: 10,
            angle_q6: 100,
            distance_q2: 8,
        }
        .encode();
        let mut both_s = good;
        both_s[0] |= 0b11;
        let mut neither_s = good;
        neither_s[0] &= !0b11;
        let mut no_c = good;
        no_c[1] &= !1;
        for bad in [both_s, neither_s, no_c] {
            assert_eq!(ScanNode::parse(&bad), Err(ProtocolError::BadNode));
        }
    }

    fn nodes(count: u16) -> Vec<u8> {
        (0..count)
            .flat_map(|i| {
                ScanNode {
                    start: i % 100 == 0,
                    quality: 20,
                    angle_q6: (u32::from(i % 100) * 64 * 36 / 10) as u16,
                    distance_q2: 4000 + i,
                }
                .encode()
            })
            .collect()
    }

    #[test]
    fn node_decoder_resyncs_after_inserted_garbage() {
        let mut bytes = nodes(50);
        bytes.splice(100..100, [0xFF, 0x13, 0x00]);
        let mut decoder = NodeDecoder::new();
        decoder.feed(&bytes);
        let mut decoded = Vec::new();
        while let Some(node) = decoder.next_node() {
            decoded.push(node);
        }
        assert_eq!(decoded.len(), 50);
        assert!(decoded
            .iter()
            .all(|n| (4000..4050).contains(&n.distance_q2)));
        assert_eq!(decoder.stats().resyncs, 1);
        assert_eq!(decoder.stats().skipped_bytes, 3);
    }

    #[test]
    fn scanner_cuts_revolutions_at_the_start_flag() {
        let mut scanner = RplidarScanner::new();
        let mut out = Vec::new();
        for chunk in nodes(350).chunks(7) {
            scanner.feed(chunk, &mut out);
        }
        assert_eq!(out.len(), 3);
        assert!(out.iter().all(|r| r.complete && r.samples.len() == 100));
    }
}
