//! Where the socket is by default, and who may have put it there.
//!
//! - [`default_socket_path`]: `$XDG_RUNTIME_DIR/tacmesh.sock`, else
//!   `$TMPDIR/tacmesh-UID/tacmesh.sock`: the same for the daemon and `tacmesh subscribe`.
//! - [`private_fallback_dir`]: that `tacmesh-UID` directory when it is the one in use.
//! - [`ensure_private_dir`] (the daemon) and [`check_private_dir`] (the clients): the fallback
//!   directory is the user's alone, created 0700 and checked before use, so that another local
//!   user cannot bind the default path first and serve forged meshes (a socket file directly in
//!   the shared temporary directory could be taken by anyone).

use std::io::ErrorKind;
use std::os::unix::fs::{DirBuilderExt, MetadataExt};
use std::path::{Path, PathBuf};

/// The file name of the socket in its directory.
const SOCKET_NAME: &str = "tacmesh.sock";

/// Why the private socket directory cannot be used. Each message says what to do.
#[derive(Debug, thiserror::Error)]
pub enum SocketDirError {
    #[error("cannot create the private socket directory {}: {cause}", dir.display())]
    Create { dir: PathBuf, cause: std::io::Error },
    #[error("cannot check the private socket directory {}: {cause}", dir.display())]
    Probe { dir: PathBuf, cause: std::io::Error },
    #[error(
        "{} is not a directory (a symlink or a file is there): another user may be \
         impersonating the daemon; remove it, or set XDG_RUNTIME_DIR, or choose --socket",
        dir.display()
    )]
    NotADirectory { dir: PathBuf },
    #[error(
        "the socket directory {} belongs to uid {owner}, not to you (uid {me}): another user \
         may be impersonating the daemon; remove it (as root), or set XDG_RUNTIME_DIR, or \
         choose --socket",
        dir.display()
    )]
    NotOurs { dir: PathBuf, owner: u32, me: u32 },
    #[error(
        "the socket directory {} has mode {mode:04o}: others could replace the socket in it; \
         `chmod 700` it, or remove it and let the daemon make it again",
        dir.display()
    )]
    OpenToOthers { dir: PathBuf, mode: u32 },
}

/// `$XDG_RUNTIME_DIR/tacmesh.sock` when the runtime directory is set and exists, else
/// `tacmesh.sock` in the private directory `tacmesh-UID` of the temporary directory
/// (`$TMPDIR`, else `/tmp`), UID being the process's numeric user id: per user, so two users
/// do not collide, and the same for the daemon and `tacmesh subscribe` whatever their
/// environment (`$USER` is often unset under systemd, cron or `env -i`, and can be set to
/// anything).
pub fn default_socket_path() -> PathBuf {
    let runtime_dir = std::env::var_os("XDG_RUNTIME_DIR").map(PathBuf::from);
    default_socket_path_for(runtime_dir, &std::env::temp_dir(), effective_uid())
}

/// The private directory the default socket is in, when there is no runtime directory.
pub fn private_fallback_dir() -> Option<PathBuf> {
    let runtime_dir = std::env::var_os("XDG_RUNTIME_DIR").map(PathBuf::from);
    fallback_dir_for(runtime_dir, &std::env::temp_dir(), effective_uid())
}

/// [`default_socket_path`] for a given runtime directory, temporary directory and user id.
pub(crate) fn default_socket_path_for(
    runtime_dir: Option<PathBuf>,
    temp_dir: &Path,
    uid: u32,
) -> PathBuf {
    match fallback_dir_for(runtime_dir.clone(), temp_dir, uid) {
        Some(dir) => dir.join(SOCKET_NAME),
        None => runtime_dir.unwrap_or_default().join(SOCKET_NAME),
    }
}

fn fallback_dir_for(runtime_dir: Option<PathBuf>, temp_dir: &Path, uid: u32) -> Option<PathBuf> {
    match runtime_dir {
        Some(dir) if dir.is_dir() => None,
        _ => Some(temp_dir.join(format!("tacmesh-{uid}"))),
    }
}

fn effective_uid() -> u32 {
    nix::unistd::geteuid().as_raw()
}

/// Makes `dir` (mode 0700) if it is not there, then checks it as [`check_private_dir`] does.
pub fn ensure_private_dir(dir: &Path) -> Result<(), SocketDirError> {
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(cause) if cause.kind() == ErrorKind::AlreadyExists => {}
        Err(cause) => {
            return Err(SocketDirError::Create {
                dir: dir.to_owned(),
                cause,
            })
        }
    }
    check_private_dir(dir)
}

/// Checks that `dir` is a directory itself (not a symlink), owned by this user, and that no
/// one else may write, read or enter it. A `dir` that does not exist is an error with the
/// kind `NotFound` in [`SocketDirError::Probe`].
pub fn check_private_dir(dir: &Path) -> Result<(), SocketDirError> {
    let metadata = std::fs::symlink_metadata(dir).map_err(|cause| SocketDirError::Probe {
        dir: dir.to_owned(),
        cause,
    })?;
    if !metadata.file_type().is_dir() {
        return Err(SocketDirError::NotADirectory {
            dir: dir.to_owned(),
        });
    }
    let me = effective_uid();
    if metadata.uid() != me {
        return Err(SocketDirError::NotOurs {
            dir: dir.to_owned(),
            owner: metadata.uid(),
            me,
        });
    }
    let mode = metadata.mode() & 0o7777;
    if mode & 0o077 != 0 {
        return Err(SocketDirError::OpenToOthers {
            dir: dir.to_owned(),
            mode,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn default_socket_is_in_the_runtime_dir_else_in_a_private_dir_named_by_uid() {
        let runtime = tempfile::tempdir().unwrap();
        let tmp = Path::new("/tmp");
        assert_eq!(
            default_socket_path_for(Some(runtime.path().to_owned()), tmp, 1000),
            runtime.path().join("tacmesh.sock")
        );
        let gone = runtime.path().join("gone");
        for runtime_dir in [None, Some(gone)] {
            assert_eq!(
                default_socket_path_for(runtime_dir.clone(), tmp, 1000),
                Path::new("/tmp/tacmesh-1000/tacmesh.sock")
            );
            assert_eq!(
                fallback_dir_for(runtime_dir, tmp, 1000).as_deref(),
                Some(Path::new("/tmp/tacmesh-1000"))
            );
        }
    }

    #[test]
    fn the_private_dir_is_made_0700_and_refused_when_open_or_not_a_dir() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("tacmesh-1");
        ensure_private_dir(&dir).unwrap();
        let mode = std::fs::metadata(&dir).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode, 0o700);
        // Again: it is there and fine.
        ensure_private_dir(&dir).unwrap();

        std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o770)).unwrap();
        let err = ensure_private_dir(&dir).unwrap_err();
        assert!(
            matches!(err, SocketDirError::OpenToOthers { mode: 0o770, .. }),
            "{err}"
        );
        assert!(err.to_string().contains("chmod 700"), "{err}");

        // A symlink to a directory someone else prepared is not taken for ours.
        let elsewhere = tmp.path().join("elsewhere");
        std::fs::DirBuilder::new()
            .mode(0o700)
            .create(&elsewhere)
            .unwrap();
        let link = tmp.path().join("tacmesh-2");
        std::os::unix::fs::symlink(&elsewhere, &link).unwrap();
        let err = ensure_private_dir(&link).unwrap_err();
        assert!(matches!(err, SocketDirError::NotADirectory { .. }), "{err}");

        let missing = check_private_dir(&tmp.path().join("none")).unwrap_err();
        assert!(
            matches!(&missing, SocketDirError::Probe { cause, .. } if cause.kind() == ErrorKind::NotFound),
            "{missing}"
        );
    }

    /// A directory another user made first (here: given away to `nobody` as root) is refused
    /// by name of its owner; skipped when not root, which cannot give a directory away.
    #[test]
    fn a_private_dir_another_user_made_first_is_refused() {
        if effective_uid() != 0 {
            eprintln!("skipped: only root can give a directory to another user");
            return;
        }
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("tacmesh-0");
        std::fs::DirBuilder::new().mode(0o700).create(&dir).unwrap();
        std::os::unix::fs::chown(&dir, Some(65534), Some(65534)).unwrap();
        let err = ensure_private_dir(&dir).unwrap_err();
        assert!(
            matches!(
                err,
                SocketDirError::NotOurs {
                    owner: 65534,
                    me: 0,
                    ..
                }
            ),
            "{err}"
        );
    }
}
