//! The `16zT` depth codec (OpenNI `XN_CODEC_16Z_EMB_TABLES`, "16Z with an embedded value table").
//!
//! Follows the stream layout of OpenNI's `XnStreamUncompressDepth16ZWithEmbTable`
//! (OpenNI 1.x `XnStreamCompression`, carried over into OpenNI2's `OniFile` driver); this is a
//! re-implementation from that description with bounds checks added.
//!
//! A frame is a table of the distinct depth values it contains, then a delta-coded stream of
//! *indices* into that table:
//!
//! | bytes            | meaning                                                            |
//! |------------------|--------------------------------------------------------------------|
//! | `u16` LE `n`     | number of table entries                                            |
//! | `n` × `u16` LE   | the table: depth values (mm), ascending                            |
//! | `u16` LE         | index of the first pixel                                           |
//! | stream …         | one code per byte, below                                           |
//!
//! Stream codes, each updating the running index `i` and emitting `table[i]`:
//!
//! | byte `b`          | meaning                                                           |
//! |-------------------|-------------------------------------------------------------------|
//! | `0x00..=0xDF`     | two nibbles, high first; each nibble `d` emits with `i -= d - 6`,  |
//! |                   | except low nibble `0xD` (padding: nothing) and `0xF` (an escape   |
//! |                   | follows, as for `0xFF`)                                            |
//! | `0xE0..=0xFE`     | run: emit the current value `2 × (b - 0xE0)` times                 |
//! | `0xFF`            | escape: next byte `c`; if `c ≥ 0x80`, `i -= c - 192`; else         |
//! |                   | `i = (c << 8) | next byte` (absolute index, big-endian)            |
//!
//! Entry point: [`decode_16zt`].

/// Why a `16zT` payload could not be decoded. Offsets are within the payload.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CodecError {
    #[error("payload ends at byte {at} inside {what}")]
    Truncated { at: usize, what: &'static str },
    #[error("byte {at}: value index {index} is outside the {table_len}-entry value table")]
    IndexOutOfTable {
        at: usize,
        index: u16,
        table_len: usize,
    },
    #[error("byte {at}: decoding produces more than the expected {expected} pixels")]
    TooManyPixels { at: usize, expected: usize },
    #[error("payload decodes to {got} pixels, expected {expected}")]
    TooFewPixels { got: usize, expected: usize },
}

/// Decodes one `16zT` payload into exactly `pixels` depth values (table entries; millimetres in
/// PrimeSense recordings, 0 meaning no reading).
///
/// Allocates `pixels` values once; the caller bounds `pixels` by the frame size. Any payload
/// that would read past its end, index outside its table, or produce a different pixel count
/// is an error.
pub fn decode_16zt(payload: &[u8], pixels: usize) -> Result<Vec<u16>, CodecError> {
    let mut input = Input {
        bytes: payload,
        at: 0,
    };
    let table_len = usize::from(input.u16_le("the value-table length")?);
    let table = input.take(table_len * 2, "the value table")?;
    let table: Vec<u16> = table
        .chunks_exact(2)
        .map(|pair| u16::from_le_bytes([pair[0], pair[1]]))
        .collect();

    let mut out = Output {
        table: &table,
        depth: Vec::with_capacity(pixels),
        expected: pixels,
    };
    let first_at = input.at;
    let mut index = input.u16_le("the first pixel's index")?;
    out.emit(index, 1, first_at)?;

    while let Some(byte) = input.next_byte() {
        let at = input.at - 1;
        match byte {
            0x00..=0xDF => {
                index = step(index, byte >> 4);
                out.emit(index, 1, at)?;
                match byte & 0x0F {
                    0x0D => {}
                    0x0F => {
                        index = escape(&mut input, index)?;
                        out.emit(index, 1, at)?;
                    }
                    low => {
                        index = step(index, low);
                        out.emit(index, 1, at)?;
                    }
                }
            }
            0xFF => {
                index = escape(&mut input, index)?;
                out.emit(index, 1, at)?;
            }
            run => out.emit(index, 2 * usize::from(run - 0xE0), at)?,
        }
    }

    if out.depth.len() != pixels {
        return Err(CodecError::TooFewPixels {
            got: out.depth.len(),
            expected: pixels,
        });
    }
    Ok(out.depth)
}

/// A small delta: nibble `d` stands for `index -= d - 6` (so 0..=12 covers -6..=+6).
/// Indices wrap as 16-bit values, as the reference decoder's do; the table check catches
/// any wrap that lands outside the table.
fn step(index: u16, nibble: u8) -> u16 {
    index.wrapping_sub(u16::from(nibble)).wrapping_add(6)
}

/// After an escape: a one-byte delta (`c ≥ 0x80`: `index -= c - 192`) or a big-endian
/// absolute index.
fn escape(input: &mut Input<'_>, index: u16) -> Result<u16, CodecError> {
    let c = input.byte("an escaped delta")?;
    if c & 0x80 != 0 {
        Ok(index.wrapping_add(192).wrapping_sub(u16::from(c)))
    } else {
        let low = input.byte("an absolute index")?;
        Ok(u16::from_be_bytes([c, low]))
    }
}

struct Input<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Input<'a> {
    fn take(&mut self, len: usize, what: &'static str) -> Result<&'a [u8], CodecError> {
        let end = self
            .at
            .checked_add(len)
            .filter(|&end| end <= self.bytes.len())
            .ok_or(CodecError::Truncated {
                at: self.bytes.len(),
                what,
            })?;
        let taken = &self.bytes[self.at..end];
        self.at = end;
        Ok(taken)
    }

    fn u16_le(&mut self, what: &'static str) -> Result<u16, CodecError> {
        let b = self.take(2, what)?;
        Ok(u16::from_le_bytes([b[0], b[1]]))
    }

    fn byte(&mut self, what: &'static str) -> Result<u8, CodecError> {
        Ok(self.take(1, what)?[0])
    }

    fn next_byte(&mut self) -> Option<u8> {
        let b = *self.bytes.get(self.at)?;
        self.at += 1;
        Some(b)
    }
}

struct Output<'a> {
    table: &'a [u16],
    depth: Vec<u16>,
    expected: usize,
}

impl Output<'_> {
    /// Appends `table[index]` `count` times, refusing to grow past the expected pixel count.
    fn emit(&mut self, index: u16, count: usize, at: usize) -> Result<(), CodecError> {
        let value = *self
            .table
            .get(usize::from(index))
            .ok_or(CodecError::IndexOutOfTable {
                at,
                index,
                table_len: self.table.len(),
            })?;
        if self.depth.len() + count > self.expected {
            return Err(CodecError::TooManyPixels {
                at,
                expected: self.expected,
            });
        }
        self.depth.extend(std::iter::repeat_n(value, count));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Table [0, 500, 1000], first index 1.
    fn header() -> Vec<u8> {
        let mut bytes = vec![3, 0];
        for v in [0u16, 500, 1000] {
            bytes.extend(v.to_le_bytes());
        }
        bytes.extend(1u16.to_le_bytes());
        bytes
    }

    #[test]
    fn nibbles_runs_and_escapes_decode() {
        let mut bytes = header();
        // 0x57: i -= 5-6 → 2, i -= 7-6 → 1.  0xE1: two more of table[1].
        // 0xFF 0xC1: i -= 0xC1-192 → 0.  0xFF 0x00 0x02: absolute index 2.
        // 0x6D: i unchanged, then padding.
        bytes.extend([0x57, 0xE1, 0xFF, 0xC1, 0xFF, 0x00, 0x02, 0x6D]);
        let depth = decode_16zt(&bytes, 8).unwrap();
        assert_eq!(depth, vec![500, 1000, 500, 500, 500, 0, 1000, 1000]);
    }

    #[test]
    fn low_nibble_escape_reads_following_byte() {
        let mut bytes = header();
        bytes.extend([0x6F, 0xBF]); // i stays 1, then escape: i -= 0xBF-192 = -1 → 2
        assert_eq!(decode_16zt(&bytes, 3).unwrap(), vec![500, 500, 1000]);
    }

    #[test]
    fn decode_rejects_escape_past_payload_end() {
        let mut bytes = header();
        bytes.extend([0xFF]);
        assert!(matches!(
            decode_16zt(&bytes, 2),
            Err(CodecError::Truncated { .. })
        ));
    }

    #[test]
    fn decode_rejects_table_longer_than_payload() {
        let bytes = [0xFF, 0xFF, 1, 2, 3];
        assert!(matches!(
            decode_16zt(&bytes, 1),
            Err(CodecError::Truncated { .. })
        ));
    }

    #[test]
    fn decode_rejects_index_outside_table() {
        let mut bytes = header();
        bytes.extend([0xFF, 0x00, 0x09]);
        assert_eq!(
            decode_16zt(&bytes, 2),
            Err(CodecError::IndexOutOfTable {
                at: 10,
                index: 9,
                table_len: 3
            })
        );
    }

    #[test]
    fn decode_rejects_too_many_and_too_few_pixels() {
        let mut bytes = header();
        bytes.push(0xEF); // 30 more pixels
        assert!(matches!(
            decode_16zt(&bytes, 10),
            Err(CodecError::TooManyPixels { expected: 10, .. })
        ));
        assert_eq!(
            decode_16zt(&bytes, 40),
            Err(CodecError::TooFewPixels {
                got: 31,
                expected: 40
            })
        );
    }
}
