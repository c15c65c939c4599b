//! Subcommands of the `tacmesh` binary. `anyhow` lives here and nowhere in the library.
//!
//! - `mesh`: one point cloud to one simplified mesh ([`mesh`]).
//! - `eval`: mean Hausdorff error of a mesh against ground truth ([`eval`]).
//! - `sim`: the paper's shapes and noisy samples of them ([`sim`]).
//! - `run`: the daemon ([`run`]); `subscribe`: a client of it ([`subscribe`]).

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
    Subscribe(subscribe::SubscribeArgs),
    Mesh(mesh::MeshArgs),
    Eval(eval::EvalArgs),
    #[command(subcommand)]
    Sim(sim::SimCommand),
}

pub fn init_logging(verbose: u8) {
    let default = match verbose {
        0 => "info",
        1 => "debug",
        _ => "trace",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
}

pub fn run(cli: Cli) -> anyhow::Result<()> {
    match cli.command {
        Command::Run(args) => run::run(args),
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
    tacmesh::formats::read_mesh(path).with_context(|| format!("reading mesh {name}"))
}

/// Prints `value` as one JSON object on standard output.
pub(crate) fn print_json(value: &impl serde::Serialize) -> anyhow::Result<()> {
    println!("{}", serde_json::to_string(value)?);
    Ok(())
}
