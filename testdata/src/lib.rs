//! The real scans, recordings and meshes the tests use, carried beside this crate (see
//! `SOURCES.md` in this folder for where each came from and under which licence).
//!
//! - [`path`]: a data file's path, or a panic that names the file and where it should be.
//! - [`bytes`]: a data file's contents, with the same message when it is missing.
//! - [`DIR`]: the folder itself, for tools (the fuzz corpus builder, benchmarks) that list it.
//! - [`MOSD_SCENE_CHANGE`]: the labelled mOSD scans in the order the scene-change tests play
//!   them.
//!
//! Tests reach the data only through here, so a missing file reads as a missing file (which
//! one, where it was looked for, how to get it back), never as a bare `No such file` from deep
//! inside a reader under test.

use std::path::{Path, PathBuf};

/// The test-data folder of the repository (`testdata/`), as an absolute path.
pub const DIR: &str = env!("CARGO_MANIFEST_DIR");

/// The labelled mOSD scans (`pointclouds/mosd/NAME.pcd`) in the order the scene-change tests
/// play them as one recording: the eight scans, then the first again. The daemon's test
/// (`tests/real_scenes.rs`) plays them live; the segmenter's (`segment/tests/real_data.rs`)
/// segments each after the previous one's planes.
pub const MOSD_SCENE_CHANGE: [&str; 9] = [
    "osd_test0",
    "osd_test17",
    "osd_test20",
    "osd_test26",
    "osd_test35",
    "osd_test38",
    "osd_test45",
    "osd_test57",
    "osd_test0",
];

/// The path of `relative` (for example `"pointclouds/pcl/milk.pcd"`) in the test data.
///
/// # Panics
/// When the file or folder is not there: the message names it, the folder it was looked for
/// in, and what to do. A test that panics here has lost its input, not found a bug.
pub fn path(relative: &str) -> PathBuf {
    let path = Path::new(DIR).join(relative);
    if !path.exists() {
        panic!("{}", missing_message(relative, &path));
    }
    path
}

/// The contents of the data file `relative`.
///
/// # Panics
/// As [`path`] when the file is missing, and with the OS error when it cannot be read.
pub fn bytes(relative: &str) -> Vec<u8> {
    let path = path(relative);
    std::fs::read(&path).unwrap_or_else(|err| panic!("test data {}: {err}", path.display()))
}

fn missing_message(relative: &str, path: &Path) -> String {
    format!(
        "test data file {relative} is missing: it should be at {} (the repository carries it \
         in testdata/, listed in testdata/SOURCES.md; restore it with `git checkout -- \
         testdata/{relative}`)",
        path.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kept_file_is_found() {
        assert!(path("SOURCES.md").is_file());
        assert!(bytes("pointclouds/pcl/milk.pcd").starts_with(b"# .PCD"));
    }

    #[test]
    fn a_missing_file_names_itself_and_where_it_should_be() {
        let err = std::panic::catch_unwind(|| path("pointclouds/gone.pcd")).unwrap_err();
        let message = err
            .downcast_ref::<String>()
            .expect("a formatted panic message");
        assert!(
            message.contains("test data file pointclouds/gone.pcd is missing"),
            "{message}"
        );
        assert!(
            message.contains(&format!("{DIR}/pointclouds/gone.pcd")),
            "{message}"
        );
        assert!(message.contains("testdata/SOURCES.md"), "{message}");
    }

    /// Every file listed in SOURCES.md's tables is here, and every data file here is listed,
    /// so the provenance notes and the folder cannot drift apart.
    #[test]
    fn sources_lists_exactly_the_files_kept() {
        let sources = std::fs::read_to_string(path("SOURCES.md")).expect("SOURCES.md");
        let mut kept = Vec::new();
        collect_files(Path::new(DIR), &mut kept);
        for file in &kept {
            let name = file
                .file_name()
                .and_then(|n| n.to_str())
                .expect("UTF-8 names");
            assert!(
                sources.contains(name),
                "{} is kept but SOURCES.md does not say where it came from",
                file.display()
            );
        }
    }

    fn collect_files(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("the test-data folder lists") {
            let path = entry.expect("an entry").path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() {
                if name != "src" {
                    collect_files(&path, out);
                }
            } else if !matches!(name, "SOURCES.md" | "Cargo.toml") {
                out.push(path);
            }
        }
    }
}
