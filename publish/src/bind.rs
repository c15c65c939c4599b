//! Claiming the socket path: refuse a live daemon or a non-socket, clear a stale socket, bind,
//! set the mode.

use std::io::ErrorKind;
use std::os::unix::fs::{FileTypeExt, MetadataExt};
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
    let dir = match path.parent().filter(|dir| !dir.as_os_str().is_empty()) {
        Some(dir) => dir,
        None => Path::new("."),
    };
    if !dir.is_dir() {
        return Err(PublishError::NoSocketDir {
            dir: dir.to_path_buf(),
        });
    }
    check_socket_dir(dir)?;
    clear_stale(path)?;

    // The socket file appears only once it is listening and has its mode: a client that waits
    // for the file and then connects is never refused. `UnixListener::bind` binds and then
    // listens, so the socket is bound in a fresh private directory beside `path`, given its
    // mode and group there, and hard-linked to `path` (which fails if `path` exists: another
    // daemon won the race between our check and our link).
    let listener = match bind_privately(path, dir, mode, group)? {
        Some(listener) => listener,
        // No private name could be bound or linked (too long for a socket address, or a file
        // system without hard links): bind in place, where a client may be refused for the
        // moment before `listen`. The directory passed `check_socket_dir`, so no other user
        // can swap the name for a symlink between the bind and the chmod.
        None => {
            let listener = UnixListener::bind(path).map_err(|source| bind_error(path, source))?;
            if let Err(error) = prepare_in_place(path, dir, mode, group) {
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

/// Refuses a directory in which another user could replace the socket or what the daemon
/// chmods: one that others (group or world) can write and that is not sticky, or that belongs
/// to a user other than the daemon's and root.
fn check_socket_dir(dir: &Path) -> Result<(), PublishError> {
    let unsafe_dir = |reason: String| PublishError::UnsafeSocketDir {
        dir: dir.to_path_buf(),
        reason,
    };
    let metadata = std::fs::metadata(dir).map_err(|source| PublishError::Probe {
        path: dir.to_path_buf(),
        cause: source,
    })?;
    let (mode, owner) = (metadata.mode(), metadata.uid());
    let me = rustix::process::geteuid().as_raw();
    if owner != me && owner != 0 {
        return Err(unsafe_dir(format!(
            "it belongs to uid {owner}, who could replace the socket (the daemon runs as uid {me})"
        )));
    }
    if mode & 0o022 != 0 && mode & 0o1000 == 0 {
        return Err(unsafe_dir(format!(
            "others can write to it (mode {:04o}) and it is not sticky, so any of them could \
             replace the socket",
            mode & 0o7777
        )));
    }
    Ok(())
}

/// Binds in a fresh private directory beside `path` (mode 0700, checked through its file
/// descriptor), sets the socket's mode and group there by name relative to that descriptor, and
/// links it to `path`; `None` if the private socket cannot be bound or linked. Another user
/// who can rename entries of `dir` cannot make the chmod or chown land on a file of their
/// choosing: the socket's name is looked up only in a directory nobody else can write.
fn bind_privately(
    path: &Path,
    dir: &Path,
    mode: u32,
    group: Option<u32>,
) -> Result<Option<UnixListener>, PublishError> {
    use rustix::fs::{AtFlags, Mode, OFlags};
    let Some(name) = path.file_name() else {
        return Ok(None);
    };
    let private_name = format!(".{}.{}.binding", name.to_string_lossy(), std::process::id());
    let directory = OFlags::DIRECTORY | OFlags::NOFOLLOW | OFlags::CLOEXEC | OFlags::RDONLY;
    let Ok(dir_fd) = rustix::fs::open(dir, directory, Mode::empty()) else {
        return Ok(None);
    };
    // Left empty by an earlier process with our pid (anything else there, a symlink above
    // all, stays, and the socket is then bound in place).
    let _ = rustix::fs::unlinkat(&dir_fd, private_name.as_str(), AtFlags::REMOVEDIR);
    if rustix::fs::mkdirat(&dir_fd, private_name.as_str(), Mode::RWXU).is_err() {
        return Ok(None);
    }
    let remove_private = || {
        let _ = rustix::fs::unlinkat(&dir_fd, private_name.as_str(), AtFlags::REMOVEDIR);
    };
    let Ok(private_fd) =
        rustix::fs::openat(&dir_fd, private_name.as_str(), directory, Mode::empty())
    else {
        remove_private();
        return Ok(None);
    };
    // What was opened is the directory just made, not one another user put in its place.
    let me = rustix::process::geteuid().as_raw();
    match rustix::fs::fstat(&private_fd) {
        Ok(stat) if stat.st_uid == me && stat.st_mode & 0o077 == 0 => {}
        _ => {
            return Err(PublishError::UnsafeSocketDir {
                dir: dir.to_path_buf(),
                reason: format!(
                    "its private directory {private_name} was replaced while the socket was \
                     being bound: another user is racing the daemon"
                ),
            })
        }
    }
    let Ok(listener) = UnixListener::bind(dir.join(&private_name).join("s")) else {
        remove_private();
        return Ok(None);
    };
    #[cfg(test)]
    tests::after_bind(dir, &private_name);
    let linked = prepare_at(&private_fd, "s".as_ref(), path, mode, group).and_then(|()| {
        match rustix::fs::linkat(&private_fd, "s", &dir_fd, name, AtFlags::empty()) {
            Ok(()) => Ok(true),
            // Another daemon won the race between our check and our link.
            Err(rustix::io::Errno::EXIST) => Err(bind_error(
                path,
                std::io::Error::from(ErrorKind::AlreadyExists),
            )),
            Err(_) => Ok(false),
        }
    });
    let _ = rustix::fs::unlinkat(&private_fd, "s", AtFlags::empty());
    remove_private();
    Ok(linked?.then_some(listener))
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

/// Gives the socket file at `path`, bound in place in `dir` (which `check_socket_dir` passed),
/// its mode and group, by its name relative to `dir`.
fn prepare_in_place(
    path: &Path,
    dir: &Path,
    mode: u32,
    group: Option<u32>,
) -> Result<(), PublishError> {
    use rustix::fs::{Mode, OFlags};
    let directory = OFlags::DIRECTORY | OFlags::CLOEXEC | OFlags::RDONLY;
    let dir_fd =
        rustix::fs::open(dir, directory, Mode::empty()).map_err(|errno| PublishError::SetMode {
            path: path.to_path_buf(),
            mode,
            cause: errno.into(),
        })?;
    // A bound path has a file name.
    let name = path.file_name().unwrap_or(path.as_os_str());
    prepare_at(&dir_fd, name, path, mode, group)
}

/// Gives the socket `name` in the directory `dir_fd` (to be published as `path`) its mode and
/// group, by name relative to that directory (the private one, or the socket's own).
fn prepare_at(
    dir_fd: &impl std::os::fd::AsFd,
    name: &std::ffi::OsStr,
    path: &Path,
    mode: u32,
    group: Option<u32>,
) -> Result<(), PublishError> {
    use rustix::fs::{AtFlags, Mode};
    rustix::fs::chmodat(dir_fd, name, Mode::from_raw_mode(mode), AtFlags::empty()).map_err(
        |errno| PublishError::SetMode {
            path: path.to_path_buf(),
            mode,
            cause: errno.into(),
        },
    )?;
    if let Some(gid) = group {
        let set_group = |cause: std::io::Error| PublishError::SetGroup {
            path: path.to_path_buf(),
            gid,
            cause,
        };
        // -1 means "leave unchanged" to chown, and is no group.
        if gid == u32::MAX {
            return Err(set_group(ErrorKind::InvalidInput.into()));
        }
        let gid = rustix::fs::Gid::from_raw(gid);
        rustix::fs::chownat(dir_fd, name, None, Some(gid), AtFlags::SYMLINK_NOFOLLOW)
            .map_err(|errno| set_group(errno.into()))?;
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

#[cfg(test)]
pub(crate) mod tests {
    use std::path::{Path, PathBuf};
    use std::sync::Mutex;

    type Hook = Box<dyn Fn(&Path, &str) + Send>;

    /// What a test does between the private bind and the chmod, for sockets in its directory:
    /// the moment another user once won by swapping a name for a symlink.
    static AFTER_BIND: Mutex<Vec<(PathBuf, Hook)>> = Mutex::new(Vec::new());

    pub(crate) fn on_bind_in(dir: &Path, hook: impl Fn(&Path, &str) + Send + 'static) {
        let mut hooks = AFTER_BIND.lock().unwrap_or_else(|e| e.into_inner());
        hooks.push((dir.to_path_buf(), Box::new(hook)));
    }

    pub(super) fn after_bind(dir: &Path, private_name: &str) {
        let hooks = AFTER_BIND.lock().unwrap_or_else(|e| e.into_inner());
        for (hook_dir, hook) in hooks.iter() {
            if hook_dir == dir {
                hook(dir, private_name);
            }
        }
    }
}
