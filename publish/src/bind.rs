//! Claiming the socket path: refuse a live daemon or a non-socket, clear a stale socket, bind,
//! set the mode.

use std::io::ErrorKind;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};

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

    // The socket file appears only once it is listening and has its mode: a client that waits
    // for the file and then connects is never refused. `UnixListener::bind` binds and then
    // listens, so the socket is bound under a private name beside `path`, given its mode and
    // group there, and hard-linked to `path` (which fails if `path` exists: another daemon won
    // the race between our check and our link).
    let listener = match bind_privately(path, mode, group)? {
        Some(listener) => listener,
        // No private name could be bound or linked (too long for a socket address, or a file
        // system without hard links): bind in place, where a client may be refused for the
        // moment before `listen`.
        None => {
            let listener = UnixListener::bind(path).map_err(|source| bind_error(path, source))?;
            if let Err(error) = prepare(path, path, mode, group) {
                remove_if_ours(path, file_id(path));
                return Err(error);
            }
            listener
        }
    };
    Ok(Bound {
        listener,
        file_id: file_id(path),
    })
}

/// Binds under a private name beside `path`, sets its mode and group, and links it to `path`;
/// `None` if the private name cannot be bound or linked.
fn bind_privately(
    path: &Path,
    mode: u32,
    group: Option<u32>,
) -> Result<Option<UnixListener>, PublishError> {
    let Some(private) = private_name(path) else {
        return Ok(None);
    };
    let _ = std::fs::remove_file(&private); // left by an earlier process with our pid
    let Ok(listener) = UnixListener::bind(&private) else {
        return Ok(None);
    };
    let linked = prepare(&private, path, mode, group).and_then(|()| {
        match std::fs::hard_link(&private, path) {
            Ok(()) => Ok(true),
            // Another daemon won the race between our check and our link.
            Err(source) if source.kind() == ErrorKind::AlreadyExists => {
                Err(bind_error(path, source))
            }
            Err(_) => Ok(false),
        }
    });
    let _ = std::fs::remove_file(&private);
    Ok(linked?.then_some(listener))
}

/// `.NAME.PID.binding` beside `path`, if `path` has a file name.
fn private_name(path: &Path) -> Option<PathBuf> {
    let name = path.file_name()?.to_str()?;
    Some(path.with_file_name(format!(".{name}.{}.binding", std::process::id())))
}

fn bind_error(path: &Path, source: std::io::Error) -> PublishError {
    match source.kind() {
        // Another daemon won the race between our check and our bind.
        ErrorKind::AddrInUse | ErrorKind::AlreadyExists => PublishError::AlreadyRunning {
            path: path.to_path_buf(),
        },
        _ => PublishError::Bind {
            path: path.to_path_buf(),
            cause: source,
        },
    }
}

/// Gives the socket file at `at` (to be published as `path`) its mode and group.
fn prepare(at: &Path, path: &Path, mode: u32, group: Option<u32>) -> Result<(), PublishError> {
    std::fs::set_permissions(at, std::fs::Permissions::from_mode(mode)).map_err(|source| {
        PublishError::SetMode {
            path: path.to_path_buf(),
            mode,
            cause: source,
        }
    })?;
    if let Some(gid) = group {
        std::os::unix::fs::chown(at, None, Some(gid)).map_err(|source| PublishError::SetGroup {
            path: path.to_path_buf(),
            gid,
            cause: source,
        })?;
    }
    Ok(())
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
