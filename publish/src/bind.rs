//! Claiming the socket path: refuse a live daemon or a non-socket, clear a stale socket, bind,
//! set the mode.

use std::io::ErrorKind;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::Path;

use crate::PublishError;

pub(crate) struct Bound {
    pub(crate) listener: UnixListener,
    /// (device, inode) of the socket file, if it could be read back after binding.
    pub(crate) file_id: Option<(u64, u64)>,
}

pub(crate) fn claim(path: &Path, mode: u32, group: Option<u32>) -> Result<Bound, PublishError> {
    if mode & !0o7777 != 0 {
        return Err(PublishError::InvalidMode { mode });
    }
    if let Some(dir) = path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
        if !dir.is_dir() {
            return Err(PublishError::NoSocketDir {
                dir: dir.to_path_buf(),
            });
        }
    }
    clear_stale(path)?;

    let listener = UnixListener::bind(path).map_err(|source| match source.kind() {
        // Another daemon won the race between our check and our bind.
        ErrorKind::AddrInUse => PublishError::AlreadyRunning {
            path: path.to_path_buf(),
        },
        _ => PublishError::Bind {
            path: path.to_path_buf(),
            cause: source,
        },
    })?;
    let file_id = file_id(path);
    if let Err(source) = std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)) {
        remove_if_ours(path, file_id);
        return Err(PublishError::SetMode {
            path: path.to_path_buf(),
            mode,
            cause: source,
        });
    }
    if let Some(gid) = group {
        if let Err(source) = std::os::unix::fs::chown(path, None, Some(gid)) {
            remove_if_ours(path, file_id);
            return Err(PublishError::SetGroup {
                path: path.to_path_buf(),
                gid,
                cause: source,
            });
        }
    }
    Ok(Bound { listener, file_id })
}

/// Leaves `path` free to bind, or says why it cannot be.
fn clear_stale(path: &Path) -> Result<(), PublishError> {
    let metadata = match std::fs::symlink_metadata(path) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == ErrorKind::NotFound => return Ok(()),
        Err(source) => {
            return Err(PublishError::Probe {
                path: path.to_path_buf(),
                cause: source,
            })
        }
    };
    if !metadata.file_type().is_socket() {
        return Err(PublishError::NotASocket {
            path: path.to_path_buf(),
        });
    }
    match UnixStream::connect(path) {
        Ok(_) => Err(PublishError::AlreadyRunning {
            path: path.to_path_buf(),
        }),
        Err(error) if error.kind() == ErrorKind::ConnectionRefused => {
            std::fs::remove_file(path).map_err(|source| PublishError::RemoveStale {
                path: path.to_path_buf(),
                cause: source,
            })?;
            tracing::info!(
                "removed the stale socket {} left by a daemon that is no longer running",
                path.display()
            );
            Ok(())
        }
        Err(source) => Err(PublishError::Probe {
            path: path.to_path_buf(),
            cause: source,
        }),
    }
}

fn file_id(path: &Path) -> Option<(u64, u64)> {
    std::fs::symlink_metadata(path)
        .ok()
        .map(|metadata| (metadata.dev(), metadata.ino()))
}

/// Removes the socket file if it is still the one we bound (not one a later daemon made).
pub(crate) fn remove_if_ours(path: &Path, ours: Option<(u64, u64)>) {
    if ours.is_none() || file_id(path) != ours {
        return;
    }
    if let Err(error) = std::fs::remove_file(path) {
        tracing::warn!(
            "cannot remove the socket {}: {error}; remove it before the next start",
            path.display()
        );
    }
}
