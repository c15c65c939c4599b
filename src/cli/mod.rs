//! Subcommands of the `tacmesh` binary. `anyhow` lives here and nowhere in the library.
//!
//! - `mesh`: one point cloud to one simplified mesh ([`mesh`]).
//! - `eval`: mean Hausdorff error of a mesh against ground truth, and with `--contact` its
//!   contact fidelity ([`eval`]).
//! - `sim`: the paper's shapes and noisy samples of them ([`sim`]).
//! - `run`: the daemon ([`run`]); `subscribe`: a client of it ([`subscribe`]).
//! - `capture`: a sensor's frames as world-frame point clouds ([`capture`]).

mod capture;
mod eval;
mod mesh;
mod run;
mod sim;
mod subscribe;

use std::path::Path;

use anyhow::Context;
use clap::{Parser, Subcommand};
use tacmesh::sim::Shape;
use tacmesh::TriMesh;

#[derive(Debug, Parser)]
#[command(
    name = "tacmesh",
    version,
    about = "Depth scans to small, accurate, physics-ready meshes",
    long_about = "Depth scans to small, accurate, physics-ready meshes.\n\n\
        Live: `tacmesh run` serves meshes of a simulated scene; `tacmesh subscribe` watches them.\n\
        Offline: `tacmesh sim sample cube -o cube.ply`, then `tacmesh mesh cube.ply -o mesh.ply`, \
        then `tacmesh eval cube mesh.ply`.\n\
        Logs go to standard error; set RUST_LOG (e.g. RUST_LOG=debug) or pass -v for more."
)]
pub struct Cli {
    /// More log output on standard error (-v debug, -vv trace).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    Run(run::RunArgs),
    Capture(capture::CaptureArgs),
    Subscribe(subscribe::SubscribeArgs),
    Mesh(mesh::MeshArgs),
    Eval(eval::EvalArgs),
    #[command(subcommand)]
    Sim(sim::SimCommand),
}

/// Logging to standard error, set up once, when the command knows its settings. The filter:
/// `RUST_LOG` when set, else `-v` (debug) or `-vv` (trace), else `config_level` (the daemon
/// config's `[log] level`), else info. Colours only on a terminal. When standard error is the
/// journal (systemd names it in `JOURNAL_STREAM`), lines carry no timestamp, since the journal
/// stamps each entry itself, and start with their syslog priority (`<4>` for a warning), which
/// journald turns into the entry's priority (`journalctl -p warning`).
pub fn init_logging(verbose: u8, config_level: Option<&str>) {
    let fallback = match verbose {
        0 => config_level.unwrap_or("info"),
        1 => "debug",
        _ => "trace",
    };
    // Zenoh (with the `zenoh` feature) logs every network interface it can be reached on at
    // info; at the default level only its warnings come through.
    let fallback = if fallback == "info" {
        "info,zenoh=warn"
    } else {
        fallback
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(fallback));
    // A closed or broken standard error (a log reader that went away, a restarted journald)
    // drops and counts lines instead of failing the write (see `log_sink`).
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(tacmesh::log_sink::StderrSink)
        .log_internal_errors(false);
    if stderr_is_journal() {
        builder
            .with_ansi(false)
            .event_format(JournalPriority(
                tracing_subscriber::fmt::format()
                    .without_time()
                    .with_level(false),
            ))
            .init();
    } else {
        builder
            .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
            .init();
    }
}

/// True when standard error is the journal stream that `JOURNAL_STREAM` (`DEVICE:INODE`)
/// names; a process whose standard error was redirected elsewhere inherits the variable but
/// not the stream, so the variable alone is not enough (systemd.exec(5)).
fn stderr_is_journal() -> bool {
    use std::os::fd::AsFd;
    use std::os::unix::fs::MetadataExt;
    let Some(stream) = std::env::var_os("JOURNAL_STREAM") else {
        return false;
    };
    let Some((device, inode)) = stream.to_str().and_then(|s| s.split_once(':')) else {
        return false;
    };
    let Ok(stderr) = std::io::stderr().as_fd().try_clone_to_owned() else {
        return false;
    };
    let Ok(metadata) = std::fs::File::from(stderr).metadata() else {
        return false;
    };
    device.parse() == Ok(metadata.dev()) && inode.parse() == Ok(metadata.ino())
}

/// An event format that starts each line with its syslog priority (`<3>` error, `<4>` warning,
/// `<6>` info, `<7>` debug and trace), as journald reads it from a service's output, then the
/// level's name (unpadded: journald keeps what follows the priority as it is).
struct JournalPriority<F>(F);

impl<S, N, F> tracing_subscriber::fmt::FormatEvent<S, N> for JournalPriority<F>
where
    S: tracing::Subscriber + for<'a> tracing_subscriber::registry::LookupSpan<'a>,
    N: for<'a> tracing_subscriber::fmt::FormatFields<'a> + 'static,
    F: tracing_subscriber::fmt::FormatEvent<S, N>,
{
    fn format_event(
        &self,
        ctx: &tracing_subscriber::fmt::FmtContext<'_, S, N>,
        mut writer: tracing_subscriber::fmt::format::Writer<'_>,
        event: &tracing::Event<'_>,
    ) -> std::fmt::Result {
        let level = *event.metadata().level();
        let priority = match level {
            tracing::Level::ERROR => 3,
            tracing::Level::WARN => 4,
            tracing::Level::INFO => 6,
            tracing::Level::DEBUG | tracing::Level::TRACE => 7,
        };
        write!(writer, "<{priority}>{level} ")?;
        self.0.format_event(ctx, writer, event)
    }
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    // `run` sets up logging itself once it has read its config (for `[log] level`); a bad
    // config is reported by `main`, which needs no logging.
    if !matches!(cli.command, Command::Run(_)) {
        init_logging(cli.verbose, None);
    }
    match cli.command {
        Command::Run(args) => run::run(args, cli.verbose),
        Command::Capture(args) => capture::run(args),
        Command::Subscribe(args) => subscribe::run(args),
        Command::Mesh(args) => mesh::run(args),
        Command::Eval(args) => eval::run(args),
        Command::Sim(cmd) => sim::run(cmd),
    }
}

/// A mesh named either as one of the paper's shapes (`cube`, `torus`, ...) at its 1 m size,
/// or as a mesh file.
pub(crate) fn shape_or_mesh_file(name: &str) -> anyhow::Result<TriMesh> {
    if let Some(shape) = Shape::from_name(name) {
        return Ok(shape.mesh());
    }
    let path = Path::new(name);
    if !path.exists() {
        let shapes: Vec<&str> = Shape::ALL.iter().map(|s| s.name()).collect();
        anyhow::bail!(
            "{name} is neither a shape ({}) nor an existing mesh file",
            shapes.join(", ")
        );
    }
    let mesh = tacmesh::formats::read_mesh(path).context("reading the mesh")?;
    warn_if_implausible_mesh(name, &mesh);
    Ok(mesh)
}

/// Warns when a mesh file is larger than anything a depth camera sees, or smaller than it
/// resolves: most likely in other units than metres (a millimetre mesh read as metres is a
/// 1000 times too large; its Hausdorff error comes out in kilometres).
fn warn_if_implausible_mesh(name: &str, mesh: &TriMesh) {
    let Some((lo, hi)) = mesh.bounds() else {
        return;
    };
    let extent_m = (hi - lo).max_element();
    let (min, max) = mesh::PLAUSIBLE_EXTENT_M.into_inner();
    if extent_m > max {
        tracing::warn!(
            "{name}: the mesh is {extent_m:.0} m across, more than a depth camera sees (up to \
             about {max:.0} m): tacmesh reads metres; if its unit is millimetres, scale it by \
             0.001 (`sim sample` takes --extent-m)"
        );
    } else if extent_m < min {
        tracing::warn!(
            "{name}: the mesh is {:.2} mm across, less than a depth camera resolves: tacmesh \
             reads metres",
            extent_m * 1e3
        );
    }
}

/// A direction "x,y,z" (any length but zero), as a unit vector.
pub(crate) fn parse_direction(s: &str) -> Result<tacmesh::glam::Vec3, String> {
    parse_vec3(s)?
        .try_normalize()
        .ok_or_else(|| "a direction cannot be 0,0,0".to_owned())
}

/// Parses `x,y,z` (a position in metres) for clap; NaN and infinities are refused.
pub(crate) fn parse_vec3(s: &str) -> Result<tacmesh::glam::Vec3, String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("expected x,y,z: {e}"))?;
    match parts.as_slice() {
        [x, y, z] if [x, y, z].iter().all(|v| v.is_finite()) => {
            Ok(tacmesh::glam::Vec3::new(*x, *y, *z))
        }
        [_, _, _] => Err("expected three finite numbers x,y,z".into()),
        _ => Err(format!("expected three numbers x,y,z, got {}", parts.len())),
    }
}

/// Prints `value` as one JSON object on standard output.
pub(crate) fn print_json(value: &impl serde::Serialize) -> anyhow::Result<()> {
    print_line(&serde_json::to_string(value)?)
}

/// Prints `line` on standard output. A closed standard output (`tacmesh eval … | head -0`) is
/// an error the caller reports, not a panic as with `println!`.
pub(crate) fn print_line(line: &str) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{line}")
        .and_then(|()| out.flush())
        .context("cannot write to standard output")
}
