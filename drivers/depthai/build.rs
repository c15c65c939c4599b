//! With the `device` feature, gives this crate's own test and example binaries an rpath to the
//! libpython pyo3 links: pyo3 links it by name only, so without one the loader takes whichever
//! `libpython3.X.so` comes first on its search path, or none (pyenv and venv-based Pythons keep
//! theirs outside the system directories). The daemon binary gets the same from the root
//! crate's build script.

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "device")]
    pyo3_build_config::add_libpython_rpath_link_args();
}
