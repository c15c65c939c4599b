use std::path::PathBuf;
use std::process::Command;
use std::time::{Duration, Instant};

use tacmesh_openni2::{OpenNi2Options, OpenNi2Source};
use tacmesh_source::SourceError;

const CHILD: &str = "TACMESH_OPENNI2_TEST_CHILD";

/// Runs `body` in a fresh process: this test binary again, filtered to test `name`.
///
/// OpenNI2 is one process-wide library that stays initialised until exit (see `ffi.rs`), and
/// a device a test opens by URI (the dummy device) stays registered, so later `open(None)`
/// would find it. A process per test keeps tests independent, and its exit status checks
/// what matters most here: no crash on close, on shutdown or at exit.
pub fn isolated(name: &str, body: impl FnOnce()) {
    if std::env::var_os(CHILD).is_some() {
        body();
        return;
    }
    let exe = std::env::current_exe().expect("test binary path");
    let out = Command::new(exe)
        .args(["--exact", name, "--nocapture", "--test-threads=1"])
        .env(CHILD, name)
        .output()
        .expect("re-running the test binary");
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    eprintln!("{stderr}");
    assert!(
        out.status.success(),
        "{name} in its own process exited with {:?}\n{stdout}\n{stderr}",
        out.status
    );
    assert!(stdout.contains("1 passed"), "{name} did not run:\n{stdout}");
}

/// Opens `uri` with default options, timing the call.
pub fn open(uri: Option<&str>) -> (Result<OpenNi2Source, SourceError>, Duration) {
    let started = Instant::now();
    let source = OpenNi2Source::open(uri, OpenNi2Options::default());
    (source, started.elapsed())
}

/// Whether Debian's (or another) OpenNI2 ships the dummy driver next to the library.
pub fn dummy_driver_installed() -> bool {
    [
        "/usr/lib/x86_64-linux-gnu",
        "/usr/lib/aarch64-linux-gnu",
        "/usr/lib",
    ]
    .iter()
    .any(|dir| {
        std::path::Path::new(dir)
            .join("OpenNI2/Drivers/libDummyDevice.so")
            .exists()
    })
}

/// The real PrimeSense recording in `testdata/recordings` (see its SOURCES.md).
pub fn primesense_oni() -> PathBuf {
    tacmesh_testdata::path("recordings/openni1_primesense_12frames_640x480.oni")
}
