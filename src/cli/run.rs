use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::{Daemon, DaemonConfig, StopSignal};

/// Run the daemon: read a depth sensor, keep a small mesh of every object in view, and serve
/// the meshes on a Unix socket.
///
/// With no options it runs the simulated demo scene (a table with objects that stand, move,
/// appear and leave) and serves on $XDG_RUNTIME_DIR/tacmesh.sock (or a file in the temporary
/// directory). Watch it from another terminal with `tacmesh subscribe`. Stop it with Ctrl-C or
/// SIGTERM.
#[derive(Debug, Args)]
pub struct RunArgs {
    /// Config file (TOML; see tacmesh.example.toml). Options given here override it.
    #[arg(long)]
    config: Option<PathBuf>,
    /// A sensor, repeatable (all feed one object map): `sim` (the demo scene),
    /// `sim:SCENE.toml` (a scene file, see scenes/), `replay:FILE.oni` (OpenNI recording),
    /// `replay:FILE.bag` (RealSense ROS bag), `serial:camsense:PORT`,
    /// `serial:rplidar:PORT[@BAUD]`. Replaces the config file's [[sensor]] list
    #[arg(long)]
    sensor: Vec<String>,
    /// Recordings: start again at the end instead of stopping
    #[arg(long = "loop")]
    looping: bool,
    /// Socket path [default: $XDG_RUNTIME_DIR/tacmesh.sock]
    #[arg(long)]
    socket: Option<PathBuf>,
    /// Take frames as fast as the pipeline consumes them instead of at the sensor's rate
    /// (simulated sensors only)
    #[arg(long)]
    unpaced: bool,
    /// Stop after this many seconds (for benchmarks and scripted runs)
    #[arg(long)]
    duration_s: Option<f64>,
}

pub fn run(args: RunArgs, verbose: u8) -> anyhow::Result<()> {
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
        let duration = std::time::Duration::from_secs_f64(seconds.max(0.0));
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
        "tacmesh: serving meshes on {}\ntacmesh: watch them with: tacmesh subscribe --socket {}",
        daemon.socket_path().display(),
        daemon.socket_path().display()
    ));
    daemon.run_until_stopped(&stop);
    Ok(())
}
