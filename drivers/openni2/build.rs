//! Links libOpenNI2 only when the `device` feature is on; the default build needs nothing.
//!
//! Where the library is looked for, first hit wins:
//! 1. `OPENNI2_REDIST64` / `OPENNI2_REDIST` (what the vendor SDK installers set);
//! 2. `pkg-config --variable=libdir libopenni2`, if that directory really holds the library
//!    (Debian's `libopenni2.pc` says `libdir=/usr/lib`, but the library is in the multiarch
//!    directory, so this is usually skipped there);
//! 3. `/usr/lib/<arch>-linux-gnu` (Debian and Ubuntu's `libopenni2-dev`).
//!
//! OpenNI2 loads its drivers from `OpenNI2/Drivers` next to `libOpenNI2.so` itself, so a
//! library outside the system directories gets an rpath: then both it and its drivers are
//! found at run time without `LD_LIBRARY_PATH`.

use std::env;
use std::path::{Path, PathBuf};
use std::process::Command;

const LIBRARY_FILE: &str = "libOpenNI2.so";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    for var in ["OPENNI2_REDIST64", "OPENNI2_REDIST", "PKG_CONFIG_PATH"] {
        println!("cargo:rerun-if-env-changed={var}");
    }
    if env::var_os("CARGO_FEATURE_DEVICE").is_none() {
        return;
    }
    match library_dir() {
        Some(dir) => {
            println!("cargo:rustc-link-search=native={}", dir.display());
            if !is_system_dir(&dir) {
                println!("cargo:rustc-link-arg=-Wl,-rpath,{}", dir.display());
            }
        }
        None => println!(
            "cargo:warning=no {LIBRARY_FILE} found (install libopenni2-dev or set \
             OPENNI2_REDIST64); linking may fail"
        ),
    }
    println!("cargo:rustc-link-lib=dylib=OpenNI2");
}

fn library_dir() -> Option<PathBuf> {
    let from_env = ["OPENNI2_REDIST64", "OPENNI2_REDIST"]
        .into_iter()
        .filter_map(env::var_os)
        .map(PathBuf::from);
    from_env
        .chain(pkg_config_libdir())
        .chain(multiarch_dir())
        .find(|dir| dir.join(LIBRARY_FILE).exists())
}

fn pkg_config_libdir() -> Option<PathBuf> {
    let out = Command::new("pkg-config")
        .args(["--variable=libdir", "libopenni2"])
        .output()
        .ok()?;
    let dir = String::from_utf8(out.stdout).ok()?;
    let dir = dir.trim();
    (out.status.success() && !dir.is_empty()).then(|| PathBuf::from(dir))
}

fn multiarch_dir() -> Option<PathBuf> {
    let arch = env::var("CARGO_CFG_TARGET_ARCH").ok()?;
    Some(PathBuf::from(format!("/usr/lib/{arch}-linux-gnu")))
}

fn is_system_dir(dir: &Path) -> bool {
    let dir = dir.to_string_lossy();
    dir == "/usr/lib"
        || dir == "/lib"
        || (dir.starts_with("/usr/lib/") && dir.ends_with("-linux-gnu"))
}
