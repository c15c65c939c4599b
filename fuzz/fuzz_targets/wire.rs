//! The wire decoder, both directions: what a client reads from the daemon
//! (`FrameDecoder::new(Sender::Server)`) and what the daemon's per-subscriber reader thread reads
//! from a client (`FrameDecoder::new(Sender::Client)`, as in `tacmesh-publish`'s `client.rs`).
//!
//! The input is split into chunks the way a socket might return it (the first byte picks the
//! chunk size), so frame reassembly across pushes is exercised too. Properties checked beyond
//! "no panic":
//! - every message decoded re-encodes to exactly the bytes of its frame (the decoder accepts
//!   nothing the encoder would not write, and loses nothing);
//! - the decoder never buffers more than one frame beyond what was taken out.

#![no_main]

use libfuzzer_sys::fuzz_target;
use tacmesh_protocol::{encode, FrameDecoder, Sender, MAX_FRAME_BYTES};

/// Bytes of the length prefix.
const PREFIX_BYTES: usize = 4;

fuzz_target!(|data: &[u8]| {
    let Some((&chunk_seed, stream)) = data.split_first() else {
        return;
    };
    let chunk_len = usize::from(chunk_seed).max(1);
    for from in [Sender::Server, Sender::Client] {
        decode_stream(stream, from, chunk_len);
    }
});

fn decode_stream(stream: &[u8], from: Sender, chunk_len: usize) {
    let mut decoder = FrameDecoder::new(from);
    // Where the next frame starts in `stream`, to compare re-encoded messages against.
    let mut frame_start = 0;
    for chunk in stream.chunks(chunk_len) {
        decoder.push(chunk);
        loop {
            match decoder.next_message() {
                Ok(Some(message)) => {
                    let frame_len = frame_length(&stream[frame_start..]);
                    let frame = &stream[frame_start..frame_start + PREFIX_BYTES + frame_len];
                    let mut encoded = Vec::new();
                    encode(&message, &mut encoded).expect("a decoded message encodes");
                    assert_eq!(encoded, frame, "{message:?} does not round-trip");
                    frame_start += frame.len();
                }
                Ok(None) => break,
                // The daemon drops the connection here; nothing more to read.
                Err(_) => return,
            }
        }
        assert!(
            decoder.buffered_len() <= PREFIX_BYTES + MAX_FRAME_BYTES + chunk_len,
            "the decoder holds {} bytes",
            decoder.buffered_len()
        );
    }
}

fn frame_length(at: &[u8]) -> usize {
    let prefix: [u8; PREFIX_BYTES] = at[..PREFIX_BYTES].try_into().expect("a whole prefix");
    u32::from_le_bytes(prefix) as usize
}
