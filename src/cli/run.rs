use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::{Daemon, DaemonConfig, StopSignal};

/// `--sensor` in `--help`: every spec the parser takes (`SpecKind::ALL`; a test checks that
/// each of its prefixes is here).
const SENSOR_HELP: &str = "\
A sensor, repeatable (all feed one object map); replaces the config file's [[sensor]] list.
SPEC is one of:
  sim | sim:demo        the simulated demo scene
  sim:SCENE.toml        a simulated camera over a scene file (see scenes/)
  replay:FILE.oni       an OpenNI recording
  replay:FILE.bag       a RealSense ROS bag
  replay:PATH?fx=…&fy=…&cx=…&cy=…[&depth_scale_m=0.001&rate=recorded|max|FPS]
                        depth images (16-bit PNG, TIFF, PGM, Z16): one file, a folder or a
                        TUM depth.txt; the intrinsics are required
  replay:PATH           point clouds (PLY, PCD, XYZ): one file or a folder
  serial:camsense:PORT  a Camsense X1-style 360° scanner
  serial:rplidar:PORT[@BAUD]
                        an RPLIDAR A1/A2 (115200 baud; an A3: @256000)
  v4l2:/dev/videoN?fx=…&fy=…&cx=…&cy=…[&width=640&height=480&fps=30&depth_scale_m=0.001]
                        a V4L2 depth camera (Z16/Y16); build with --features v4l2
  openni2:[URI]         a Kinect, Xtion or Orbbec through OpenNI2: the first one found, a
                        device URI or an .oni file; build with --features openni2
  depthai:[DEVICE][?width=…&height=…&fps=…&align=…&preset=…&record=FILE.mcap&venv=DIR]
                        a Luxonis OAK camera: the first one found, or by id or IP; build
                        with --features depthai
  depthai:FILE.mcap[?rate=max&venv=DIR]
                        a DepthAI recording (same feature)";

/// Run the daemon: read a depth sensor, keep a small mesh of every object in view, and serve
/// the meshes on a Unix socket.
///
/// With no options it runs the simulated demo scene (a table with objects that stand, move,
/// appear and leave) and serves on $XDG_RUNTIME_DIR/tacmesh.sock (without a runtime directory,
/// /tmp/tacmesh-UID/tacmesh.sock in a directory of your own, UID being your numeric user id).
/// Watch it from another terminal with `tacmesh subscribe`. Stop it with Ctrl-C or SIGTERM.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Config file (TOML; see tacmesh.example.toml). Options given here override it.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    #[arg(
        long,
        value_name = "SPEC",
        help = "A sensor, repeatable (all feed one object map): sim, sim:SCENE.toml, \
                replay:PATH, serial:…, v4l2:…, openni2:…, depthai:…; --help lists them",
        long_help = SENSOR_HELP
    )]
    sensor: Vec<String>,
    /// Recordings: start again at the end instead of stopping. Without it a recording plays
    /// once, and what it showed is meshed when it ends
    #[arg(long = "loop")]
    looping: bool,
    /// Socket path [default: $XDG_RUNTIME_DIR/tacmesh.sock; without a runtime directory,
    /// /tmp/tacmesh-UID/tacmesh.sock (UID: your numeric user id; $TMPDIR instead of /tmp when
    /// set)]
    #[arg(long, value_name = "PATH")]
    socket: Option<PathBuf>,
    /// Recordings and simulated sensors: take frames as fast as the pipeline consumes them
    /// instead of at the recorded (or simulated) rate. Live devices keep their own rate
    #[arg(long)]
    unpaced: bool,
    /// Stop after this many seconds (for benchmarks and scripted runs): 0 to 31536000 (a year)
    #[arg(long, value_name = "S", value_parser = parse_duration_s, allow_hyphen_values = true)]
    duration_s: Option<f64>,
}

/// How to run this binary again from a shell: `tacmesh` when that is what `PATH` finds, else
/// its full path (after `cargo run`, `tacmesh` may be another build or none at all).
fn this_command() -> String {
    let Ok(me) = std::env::current_exe().and_then(|p| p.canonicalize()) else {
        return "tacmesh".to_owned();
    };
    let on_path = std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|dir| dir.join("tacmesh"))
            .find(|candidate| candidate.is_file())
    });
    match on_path.and_then(|p| p.canonicalize().ok()) {
        Some(found) if found == me => "tacmesh".to_owned(),
        _ => me.display().to_string(),
    }
}

/// The longest `--duration-s`: a year.
const MAX_DURATION_S: f64 = 365.0 * 24.0 * 3600.0;

fn parse_duration_s(text: &str) -> Result<f64, String> {
    match text.trim().parse::<f64>() {
        Ok(seconds) if (0.0..=MAX_DURATION_S).contains(&seconds) => Ok(seconds),
        _ => Err(format!("give seconds from 0 to {MAX_DURATION_S} (a year)")),
    }
}

/// Malloc arenas the daemon allows itself.
const MALLOC_ARENAS: i32 = 1;

/// Caps glibc's malloc arenas. By default glibc makes an arena per thread that allocates, up
/// to eight per core; the daemon's threads (sensors, perception, meshers and their pools, two
/// per subscriber) then keep memory in arenas they no longer use. Soaks of the demo scene
/// (BENCHMARKS.md, "Soak"): with the default arenas RSS rose in steps from 44 to 57 MB over
/// 20 minutes (issue 39's audit); with two, from 37 to 55 MB over the hour; with one it was
/// flat at 40.3 MB from the eighth minute on, with no frame dropped. A `MALLOC_ARENA_MAX` in the
/// environment (the systemd units set it too) is left to win.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn cap_malloc_arenas() {
    if std::env::var_os("MALLOC_ARENA_MAX").is_some() {
        return;
    }
    // SAFETY: mallopt takes two integers and only sets a tunable of glibc's allocator; it
    // touches no memory of ours, and is called before the daemon starts its threads.
    let set = unsafe { libc::mallopt(libc::M_ARENA_MAX, MALLOC_ARENAS) };
    if set != 1 {
        tracing::debug!("mallopt(M_ARENA_MAX, {MALLOC_ARENAS}) was refused");
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn cap_malloc_arenas() {}

pub fn run(args: RunArgs, verbose: u8) -> anyhow::Result<()> {
    cap_malloc_arenas();
    let mut config = match &args.config {
        Some(path) => DaemonConfig::load(path)?,
        None => DaemonConfig::default(),
    };
    super::init_logging(verbose, Some(&config.log.level));
    if !args.sensor.is_empty() {
        config.sensor = args
            .sensor
            .iter()
            .map(|spec| tacmesh::daemon::config::SensorSection {
                spec: spec.clone(),
                ..Default::default()
            })
            .collect();
    }
    if let Some(socket) = args.socket {
        config.socket.path = Some(socket);
    }
    for sensor in &mut config.sensor {
        if args.unpaced {
            sensor.paced = Some(false);
        }
        if args.looping {
            sensor.looping = true;
        }
    }

    let stop = StopSignal::new();
    let handler_stop = stop.clone();
    ctrlc::set_handler(move || handler_stop.request())
        .context("cannot install the SIGINT/SIGTERM handler")?;
    if let Some(seconds) = args.duration_s {
        let timer_stop = stop.clone();
        let duration = std::time::Duration::try_from_secs_f64(seconds).unwrap_or_default();
        std::thread::Builder::new()
            .name("duration".into())
            .spawn(move || {
                if !timer_stop.wait_timeout(duration) {
                    timer_stop.request();
                }
            })
            .context("cannot start the --duration-s timer")?;
    }

    let daemon = Daemon::start(config).context("tacmesh run cannot start")?;
    tacmesh::log_sink::eprint_line(&format!(
        "tacmesh: watch them with: {} subscribe --socket {}",
        this_command(),
        daemon.socket_path().display()
    ));
    daemon.run_until_stopped(&stop);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `--duration-s inf` once aborted in `Duration::from_secs_f64`; it and every other
    /// number outside 0 s to a year is refused by the parser, saying the range.
    #[test]
    fn duration_s_is_checked_where_it_is_parsed() {
        for good in ["0", "2.5", "31536000"] {
            assert!(parse_duration_s(good).is_ok(), "{good}");
        }
        for bad in ["inf", "-1", "NaN", "1e30", "31536001", "soon"] {
            let err = parse_duration_s(bad).expect_err(bad);
            assert!(err.contains("a year"), "{bad}: {err}");
        }
    }
}
