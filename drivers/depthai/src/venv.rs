//! Finding a virtual environment's packages for the embedded interpreter.
//!
//! An embedded CPython starts from the prefix of the libpython it was linked with and never
//! reads `pyvenv.cfg` (that happens only when the `python` executable of a venv starts), so a
//! `pip install depthai` inside a venv stays invisible unless its `site-packages` is added to
//! `sys.path` by hand. The venv must have been made by the same Python minor version as the
//! linked libpython: compiled packages such as `depthai` are built per version.

use std::path::{Path, PathBuf};

use crate::DepthAiError;

/// A virtual environment as read from its `pyvenv.cfg`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct VirtualEnv {
    pub root: PathBuf,
    /// The Python version that made it, major and minor.
    pub version: (u32, u32),
    /// `lib/pythonX.Y/site-packages`, which exists.
    pub site_packages: PathBuf,
}

impl VirtualEnv {
    /// Reads `root/pyvenv.cfg` (its `version` or `version_info` key) and checks that
    /// `lib/pythonX.Y/site-packages` exists.
    pub fn read(root: &Path) -> Result<VirtualEnv, DepthAiError> {
        let fail = |reason: String| DepthAiError::Venv {
            venv: root.to_path_buf(),
            reason,
        };
        let cfg_path = root.join("pyvenv.cfg");
        let cfg = std::fs::read_to_string(&cfg_path).map_err(|e| {
            fail(format!(
                "cannot read {} ({e}): is this a virtual environment (python3 -m venv)?",
                cfg_path.display()
            ))
        })?;
        let version_text = cfg
            .lines()
            .filter_map(|line| line.split_once('='))
            .map(|(key, value)| (key.trim(), value.trim()))
            .find(|(key, _)| *key == "version" || *key == "version_info")
            .map(|(_, value)| value)
            .ok_or_else(|| fail(format!("{} has no version key", cfg_path.display())))?;
        let mut parts = version_text.split('.').map(str::parse::<u32>);
        let version = match (parts.next(), parts.next()) {
            (Some(Ok(major)), Some(Ok(minor))) => (major, minor),
            _ => {
                return Err(fail(format!(
                    "{} says version = {version_text:?}, not X.Y[.Z]",
                    cfg_path.display()
                )))
            }
        };
        let site_packages = root
            .join("lib")
            .join(format!("python{}.{}", version.0, version.1))
            .join("site-packages");
        if !site_packages.is_dir() {
            return Err(fail(format!("no {}", site_packages.display())));
        }
        Ok(VirtualEnv {
            root: root.to_path_buf(),
            version,
            site_packages,
        })
    }

    /// Refuses a venv made by another Python minor version than the embedded one's.
    pub fn check_python(&self, running: (u32, u32)) -> Result<(), DepthAiError> {
        if self.version == running {
            return Ok(());
        }
        Err(DepthAiError::Venv {
            venv: self.root.clone(),
            reason: format!(
                "it was made by Python {}.{} but tacmesh embeds Python {}.{}; make it with \
                 python{}.{} -m venv (or rebuild tacmesh with PYO3_PYTHON naming that Python)",
                self.version.0, self.version.1, running.0, running.1, running.0, running.1
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn make_venv(cfg: &str, lib: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("pyvenv.cfg"), cfg).unwrap();
        std::fs::create_dir_all(dir.path().join("lib").join(lib).join("site-packages")).unwrap();
        dir
    }

    #[test]
    fn reads_pip_and_uv_style_configs() {
        let pip = make_venv(
            "home = /usr/bin\ninclude-system-site-packages = false\nversion = 3.11.7\n",
            "python3.11",
        );
        let venv = VirtualEnv::read(pip.path()).unwrap();
        assert_eq!(venv.version, (3, 11));
        assert!(venv.site_packages.ends_with("lib/python3.11/site-packages"));
        venv.check_python((3, 11)).unwrap();
        let uv = make_venv(
            "home = /usr/bin\nversion_info = 3.12.4.final.0\n",
            "python3.12",
        );
        assert_eq!(VirtualEnv::read(uv.path()).unwrap().version, (3, 12));
    }

    #[test]
    fn problems_are_named() {
        let missing = tempfile::tempdir().unwrap();
        let err = VirtualEnv::read(missing.path()).unwrap_err().to_string();
        assert!(
            err.contains("pyvenv.cfg") && err.contains("python3 -m venv"),
            "{err}"
        );
        let no_site = make_venv("version = 3.11.2\n", "python3.10");
        let err = VirtualEnv::read(no_site.path()).unwrap_err().to_string();
        assert!(err.contains("python3.11/site-packages"), "{err}");
        let garbled = make_venv("version = three\n", "python3.11");
        let err = VirtualEnv::read(garbled.path()).unwrap_err().to_string();
        assert!(err.contains("three"), "{err}");
        let other = make_venv("version = 3.12.1\n", "python3.12");
        let err = VirtualEnv::read(other.path())
            .unwrap()
            .check_python((3, 11))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("Python 3.12") && err.contains("embeds Python 3.11"),
            "{err}"
        );
    }
}
