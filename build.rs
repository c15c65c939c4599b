//! With the `depthai` feature, gives the `tacmesh` binary an rpath to the libpython that pyo3
//! links: pyo3 links it by name only, and Pythons from pyenv, conda or a source build keep it
//! outside the loader's default directories, so without an rpath the binary either fails to
//! start or loads another Python's library. (A build script's link arguments apply to its own
//! package only, so `tacmesh-depthai`'s build script cannot do this for the binary.)

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    #[cfg(feature = "depthai")]
    pyo3_build_config::add_libpython_rpath_link_args();
}
