//! The ONI depth codec alone: `tacmesh_oni::decode_16zt` on an arbitrary payload, for a pixel
//! count taken from the input's first four bytes (what a recording's resolution would say),
//! capped at four VGA frames (the container allows 4096 × 4096; a smaller cap keeps runs fast).
//!
//! The `oni` target reaches the codec only through a valid container; this one mutates the
//! payload directly. Property beyond "no panic": a decoded frame has exactly `pixels` values,
//! each one of the table's.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_oni::decode_16zt;

const MAX_PIXELS: usize = 4 * 640 * 480;

fuzz_target!(|data: &[u8]| {
    let Some((pixels, payload)) = data.split_first_chunk::<4>() else {
        return;
    };
    let pixels = (u32::from_le_bytes(*pixels) as usize).min(MAX_PIXELS);
    if let Ok(depth_mm) = decode_16zt(payload, pixels) {
        assert_eq!(depth_mm.len(), pixels);
        let table_len = usize::from(u16::from_le_bytes([payload[0], payload[1]]));
        let mut table: Vec<u16> = payload[2..2 + 2 * table_len]
            .chunks_exact(2)
            .map(|pair| u16::from_le_bytes([pair[0], pair[1]]))
            .collect();
        table.sort_unstable();
        assert!(depth_mm.iter().all(|d| table.binary_search(d).is_ok()));
    }
});
