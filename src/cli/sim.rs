use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, Subcommand};
use tacmesh::sim::{fit_to_extent, sample_cloud, SampleConfig};

/// The paper's test shapes and noisy point clouds sampled from them.
#[derive(Debug, Subcommand)]
pub enum SimCommand {
    Sample(SampleArgs),
    Shape(ShapeArgs),
}

/// Sample a shape or mesh file into a noisy point cloud (area-weighted Monte-Carlo, Gaussian
/// noise on each axis), seeded and reproducible.
#[derive(Debug, Args)]
pub struct SampleArgs {
    /// cone, cube, cylinder, monkey, torus, sphere (scaled to a 1 m bounding box), or a mesh file
    shape: String,
    /// Standard deviation of the Gaussian noise on each axis, millimetres
    #[arg(long, default_value_t = 20.0)]
    noise_mm: f32,
    /// Number of points
    #[arg(long, default_value_t = 50_000)]
    points: usize,
    /// Random seed
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Scale a mesh file so its largest side is this many metres (shapes are always 1 m)
    #[arg(long)]
    extent_m: Option<f32>,
    /// Output cloud: .ply or .xyz
    #[arg(short, long)]
    output: PathBuf,
}

/// Write one of the paper's shapes (1 m bounding box) as a mesh file: the ground truth.
#[derive(Debug, Args)]
pub struct ShapeArgs {
    /// cone, cube, cylinder, monkey, torus, sphere
    shape: String,
    /// Output mesh: .ply or .obj
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(cmd: SimCommand) -> anyhow::Result<()> {
    match cmd {
        SimCommand::Sample(args) => {
            let mut mesh = super::shape_or_mesh_file(&args.shape)?;
            if let Some(extent) = args.extent_m {
                fit_to_extent(&mut mesh, extent);
            }
            let cloud = sample_cloud(
                &mesh,
                &SampleConfig {
                    points: args.points,
                    noise_sigma_m: args.noise_mm / 1000.0,
                    seed: args.seed,
                },
            )
            .with_context(|| format!("sampling {}", args.shape))?;
            tacmesh::formats::write_cloud(&args.output, &cloud).context("writing the output")?;
            tracing::info!(points = cloud.len(), "wrote {}", args.output.display());
            Ok(())
        }
        SimCommand::Shape(args) => {
            let mesh = super::shape_or_mesh_file(&args.shape)?;
            tacmesh::formats::write_mesh(&args.output, &mesh).context("writing the output")?;
            Ok(())
        }
    }
}
