use std::path::PathBuf;
use std::time::{Duration, Instant};

use tacmesh_depthai::{record_depth_frames, DepthAiError, DepthAiOptions, DepthAiSource, Mode};
use tacmesh_sim::SceneFile;
use tacmesh_source::{DepthFrame, DepthSource, Observation, SourceError};

/// The venv holding `depthai`, as CI names it.
fn venv() -> Option<PathBuf> {
    std::env::var_os("TACMESH_DEPTHAI_VENV").map(PathBuf::from)
}

/// Frames of the simulated demo scene (a table with objects, 640×480), as a camera delivers
/// them.
fn simulated_frames(count: usize) -> Vec<DepthFrame> {
    let mut camera = SceneFile::demo().into_camera().unwrap();
    camera.set_paced(false);
    (0..count)
        .map(|_| match camera.next_observation().unwrap() {
            Observation::Depth(frame) => frame,
            other => panic!("the simulator gave {other:?}"),
        })
        .collect()
}

fn replay_options(path: &std::path::Path, rest: &str) -> DepthAiOptions {
    let mut options = DepthAiOptions::parse_spec(&format!("{}{rest}", path.display())).unwrap();
    options.venv = venv();
    options
}

fn read_all(source: &mut DepthAiSource) -> (Vec<DepthFrame>, SourceError) {
    let mut frames = Vec::new();
    loop {
        match source.next_observation() {
            Ok(Observation::Depth(frame)) => frames.push(frame),
            Ok(other) => panic!("a cloud from DepthAI: {other:?}"),
            Err(err) => return (frames, err),
        }
    }
}

#[test]
fn recorded_depth_plays_back_frame_for_frame() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sim.mcap");
    let originals = simulated_frames(12);
    let written = record_depth_frames(&path, venv().as_deref(), &originals).unwrap();
    assert_eq!(written, 12);
    assert!(std::fs::metadata(&path).unwrap().len() > 1000);

    let mut source = DepthAiSource::open(replay_options(&path, "?rate=max")).unwrap();
    assert!(source.name().ends_with("sim.mcap"), "{}", source.name());
    let (frames, end) = read_all(&mut source);
    assert!(matches!(end, SourceError::EndOfStream { .. }), "{end}");
    assert_eq!(
        frames.len(),
        originals.len(),
        "every recorded frame comes back"
    );
    for (i, (got, sent)) in frames.iter().zip(&originals).enumerate() {
        // The intrinsics travel in each frame's ImgTransformation.
        assert_eq!(got.intrinsics, sent.intrinsics, "frame {i}");
        assert_eq!(got.depth_m.len(), sent.depth_m.len());
        let mut valid = 0;
        for (&z, &z0) in got.depth_m.iter().zip(&sent.depth_m) {
            if z0.is_finite() && z0 > 0.0005 {
                // Millimetre quantisation, as StereoDepth delivers depth.
                assert!((z - z0).abs() <= 0.0005 + 1e-6, "frame {i}: {z} vs {z0}");
                valid += 1;
            } else {
                assert_eq!(z, 0.0, "frame {i}: no reading stays no reading");
            }
        }
        assert!(valid > 100_000, "frame {i} has {valid} valid pixels");
    }
    // The recording's own capture times are not reused: frames are stamped when read.
    assert!(frames
        .windows(2)
        .all(|w| w[0].capture_time <= w[1].capture_time));
}

#[test]
fn looping_replays_start_over() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("loop.mcap");
    record_depth_frames(&path, venv().as_deref(), &simulated_frames(3)).unwrap();
    let mut options = replay_options(&path, "?rate=max");
    if let Mode::Replay(replay) = &mut options.mode {
        replay.looping = true;
    }
    let mut source = DepthAiSource::open(options).unwrap();
    for i in 0..8 {
        match source.next_observation() {
            Ok(Observation::Depth(frame)) => assert_eq!(frame.intrinsics.width, 640),
            other => panic!("frame {i} of a looping 3-frame recording: {other:?}"),
        }
    }
}

#[test]
fn a_missing_camera_fails_clearly_within_the_search_timeout() {
    let mut options = DepthAiOptions::parse_spec("?search_timeout_ms=1000").unwrap();
    options.venv = venv();
    let started = Instant::now();
    let err = DepthAiSource::open(options).unwrap_err();
    let took = started.elapsed();
    eprintln!("no camera: {took:?}: {err}");
    assert!(matches!(err, DepthAiError::NoDevice { .. }), "{err}");
    let text = err.to_string();
    assert!(
        text.contains("1000 ms") && text.contains("DEPTHAI_SEARCH_TIMEOUT"),
        "{text}"
    );
    // Not a timing assertion: a guard that the search ends rather than hangs.
    assert!(took < Duration::from_secs(60), "the search took {took:?}");
    // The daemon's supervisor sees a missing device, which it retries with backoff.
    assert!(matches!(
        err.into_source_error("depthai: (the first device found)"),
        SourceError::DeviceMissing { .. }
    ));
}

#[test]
fn bad_recordings_are_errors_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("nothing.mcap");
    let err = DepthAiSource::open(replay_options(&missing, "")).unwrap_err();
    assert!(
        err.to_string().contains("nothing.mcap") && err.to_string().contains("no such file"),
        "{err}"
    );
    let garbage = dir.path().join("garbage.mcap");
    std::fs::write(&garbage, b"\x89MCAP0\r\nthis is not a recording").unwrap();
    match DepthAiSource::open(replay_options(&garbage, "")) {
        Err(err) => assert!(err.to_string().contains("garbage.mcap"), "{err}"),
        Ok(mut source) => {
            // DepthAI may open it and fail on reading: then the stream ends or fails, and
            // yields no frame.
            let (frames, end) = read_all(&mut source);
            assert!(frames.is_empty(), "{} frames from garbage", frames.len());
            eprintln!("garbage recording: {end}");
        }
    }
}

#[test]
fn the_interpreter_is_one_per_process_and_venvs_are_checked() {
    let (python, depthai) = DepthAiSource::versions(venv().as_deref()).unwrap();
    assert!(python.starts_with("3."), "{python}");
    assert!(
        depthai.starts_with('3'),
        "DepthAI {depthai}: the bridge is written for v3"
    );
    // Not a venv at all (before Python runs, this is refused before anything starts: see the
    // venv module's tests).
    let empty = tempfile::tempdir().unwrap();
    let err = DepthAiSource::versions(Some(empty.path()))
        .unwrap_err()
        .to_string();
    assert!(err.contains(&empty.path().display().to_string()), "{err}");
    // Another venv once Python runs: refused, naming both.
    let other = tempfile::tempdir().unwrap();
    std::fs::write(other.path().join("pyvenv.cfg"), "version = 3.99.0\n").unwrap();
    std::fs::create_dir_all(other.path().join("lib/python3.99/site-packages")).unwrap();
    let err = DepthAiSource::versions(Some(other.path()))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(&other.path().display().to_string()) && err.contains("one interpreter"),
        "{err}"
    );
}
