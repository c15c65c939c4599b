//! Truncated and bit-flipped copies of the real bag: typed errors naming file and offset,
//! never a panic, never a huge allocation.

use tacmesh_rosbag::{Bag, BagError};

use crate::util::{d435_bag, read_and_decode, Rng};

fn write_temp(name: &str, bytes: &[u8]) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("tacmesh-rosbag-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

#[test]
fn every_truncation_is_a_typed_error_naming_the_file() {
    let full = std::fs::read(d435_bag()).unwrap();
    let mut cuts: Vec<usize> = (0..300).collect();
    cuts.extend((300..full.len()).step_by(4093));
    // Around the index section and the very end.
    cuts.extend(full.len() - 2000..full.len());
    let path = write_temp("truncated.bag", &[]);
    for cut in cuts {
        std::fs::write(&path, &full[..cut]).unwrap();
        let err = read_and_decode(&path).expect_err(&format!("truncation at {cut} went unnoticed"));
        assert!(err.contains("truncated.bag"), "cut {cut}: {err}");
    }
}

#[test]
fn truncation_error_reports_byte_offset() {
    let full = std::fs::read(d435_bag()).unwrap();
    let path = write_temp("cut_in_chunk.bag", &full[..500_000]);
    match Bag::open(&path) {
        // index_pos lies past the new end of the file.
        Err(BagError::Corrupt { offset, reason, .. }) => {
            assert_eq!(offset, 13);
            assert!(reason.contains("outside the file"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn seeded_byte_flips_never_panic() {
    let full = std::fs::read(d435_bag()).unwrap();
    let path = write_temp("flipped.bag", &[]);
    let mut rng = Rng(0x5eed_1234_abcd_0001);
    let (mut failed, mut runs) = (0, 0);
    for _ in 0..150 {
        let mut bytes = full.clone();
        for _ in 0..1 + rng.below(4) {
            // Bias half the flips into the first 8 KiB, where headers are dense.
            let at = if rng.below(2) == 0 {
                rng.below(8192)
            } else {
                rng.below(full.len() as u64)
            };
            bytes[at as usize] ^= 1 << rng.below(8);
        }
        std::fs::write(&path, &bytes).unwrap();
        runs += 1;
        if read_and_decode(&path).is_err() {
            failed += 1;
        }
    }
    println!("{failed} of {runs} flipped bags were rejected, the rest read (flips in pixels)");
}

#[test]
fn hostile_lengths_are_refused() {
    let full = std::fs::read(d435_bag()).unwrap();
    // The bag header's header_len (bytes 13..17) set to 4 GiB - 1.
    let mut bytes = full.clone();
    bytes[13..17].copy_from_slice(&u32::MAX.to_le_bytes());
    let path = write_temp("hostile.bag", &bytes);
    match Bag::open(&path) {
        Err(BagError::Corrupt { offset, reason, .. }) => {
            assert_eq!(offset, 17);
            assert!(reason.contains("needs 4294967295 bytes"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn not_a_bag_is_named() {
    let path = write_temp("empty.bag", b"#ROSBAG V1.2\n");
    assert!(matches!(Bag::open(&path), Err(BagError::NotABag { .. })));
    let err = Bag::open("/nonexistent/x.bag").unwrap_err().to_string();
    assert!(err.contains("/nonexistent/x.bag"), "{err}");
}
