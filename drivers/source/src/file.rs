//! Reading files named from outside (a recording, a cloud, a scene, a config) without letting
//! the name decide how much is read or whether the read ends: only regular files are read (a
//! FIFO would block the start for ever, `/dev/zero` would never end), and only up to a cap
//! that the caller states for its kind of file.

use std::io::{Error, ErrorKind, Read};
use std::path::Path;

/// Checks that `path` (symlinks followed) is a regular file of at most `max_bytes`; returns its
/// size. The errors say what was found and what the limit is.
pub fn check_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<u64> {
    let metadata = std::fs::metadata(path)?;
    let kind = metadata.file_type();
    if !kind.is_file() {
        use std::os::unix::fs::FileTypeExt;
        let what = if kind.is_dir() {
            "a directory"
        } else if kind.is_fifo() {
            "a FIFO (named pipe)"
        } else if kind.is_char_device() || kind.is_block_device() {
            "a device"
        } else if kind.is_socket() {
            "a socket"
        } else {
            "not a regular file"
        };
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("it is {what}: only regular files are read"),
        ));
    }
    if metadata.len() > max_bytes {
        return Err(too_large(metadata.len(), max_bytes));
    }
    Ok(metadata.len())
}

/// Reads a regular file of at most `max_bytes` whole (see [`check_regular_file`]); a file that
/// grows past the cap while it is read is refused too.
pub fn read_regular_file(path: &Path, max_bytes: u64) -> std::io::Result<Vec<u8>> {
    let size = check_regular_file(path, max_bytes)?;
    let file = std::fs::File::open(path)?;
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(max_bytes.saturating_add(1))
        .read_to_end(&mut bytes)?;
    if bytes.len() as u64 > max_bytes {
        return Err(too_large(bytes.len() as u64, max_bytes));
    }
    Ok(bytes)
}

/// [`read_regular_file`] as UTF-8 text.
pub fn read_regular_text(path: &Path, max_bytes: u64) -> std::io::Result<String> {
    String::from_utf8(read_regular_file(path, max_bytes)?)
        .map_err(|_| Error::new(ErrorKind::InvalidData, "it is not UTF-8 text"))
}

fn too_large(size: u64, max_bytes: u64) -> Error {
    Error::new(
        ErrorKind::InvalidData,
        format!(
            "it is {size} bytes, more than the {} MiB a file of this kind may have",
            max_bytes >> 20
        ),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn devices_fifos_and_directories_are_refused_and_large_files_capped() {
        let dir = tempfile::tempdir().unwrap();
        for (path, what) in [
            (Path::new("/dev/zero"), "a device"),
            (dir.path(), "a directory"),
        ] {
            let err = read_regular_file(path, 1 << 20).unwrap_err().to_string();
            assert!(err.contains(what), "{err}");
        }
        let link = dir.path().join("zero.png");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        let err = read_regular_file(&link, 1 << 20).unwrap_err().to_string();
        assert!(err.contains("a device"), "{err}");
        let fifo = dir.path().join("take.oni");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            // Refused before it is opened: opening a FIFO to read waits for a writer.
            let err = check_regular_file(&fifo, 1 << 20).unwrap_err().to_string();
            assert!(err.contains("FIFO"), "{err}");
        }
        let file = dir.path().join("big.ply");
        std::fs::write(&file, vec![b'x'; 3 << 20]).unwrap();
        let err = read_regular_file(&file, 2 << 20).unwrap_err().to_string();
        assert!(err.contains("more than the 2 MiB"), "{err}");
        assert_eq!(read_regular_file(&file, 3 << 20).unwrap().len(), 3 << 20);
    }
}
