//! Helpers that make the tests read like scripts.

use std::path::{Path, PathBuf};

use glam::Vec3;
use tacmesh_source::TriMesh;

/// A file in the repository's test data (`testdata/`, see its SOURCES.md).
pub use tacmesh_testdata::path as data;

/// A scratch directory removed when dropped, and a path in it.
pub fn scratch(file_name: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().expect("create a scratch directory");
    let path = dir.path().join(file_name);
    (dir, path)
}

/// Writes `bytes` to a scratch file named `file_name`.
pub fn scratch_file(file_name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let (dir, path) = scratch(file_name);
    std::fs::write(&path, bytes).expect("write a scratch file");
    (dir, path)
}

pub fn read(path: &Path) -> Vec<u8> {
    std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Bytes up to and including a PLY's `end_header` line.
pub fn ply_header_len(bytes: &[u8]) -> usize {
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end);
    at.expect("a PLY header") + end.len()
}

/// A closed square pyramid: a unit base in z = 0 (two triangles) and four sides.
pub fn small_mesh() -> TriMesh {
    TriMesh::new(
        vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
            Vec3::new(0.5, 0.5, 0.75),
        ],
        vec![
            [0, 2, 1],
            [0, 3, 2],
            [0, 1, 4],
            [1, 2, 4],
            [2, 3, 4],
            [3, 0, 4],
        ],
    )
}

/// A deterministic pseudo-random sequence (Knuth's MMIX LCG), so tests need no extra crates.
pub struct Lcg(u64);

impl Lcg {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        self.0 >> 16
    }

    /// Uniform in `0..n` (n > 0), near enough for choosing offsets.
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
}
