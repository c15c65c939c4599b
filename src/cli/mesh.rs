use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::glam::Vec3;
use tacmesh::pipeline::{mesh_cloud, Length, MeshConfig};

/// Mesh one point cloud (PLY, PCD or XYZ) into one simplified mesh (PLY or OBJ).
///
/// Reconstructs the surface with marching cubes over a smoothed signed distance near the
/// points, then simplifies by edge collapse until any further collapse would move the surface
/// farther than the residual bound from the reconstruction.
#[derive(Debug, Args)]
pub struct MeshArgs {
    /// Input point cloud: .ply, .pcd, .xyz
    cloud: PathBuf,
    /// Output mesh: .ply or .obj
    #[arg(short, long)]
    output: PathBuf,
    /// Marching-cubes voxel edge in metres [default: 1/50 of the cloud's largest side]
    #[arg(long)]
    voxel_m: Option<f32>,
    /// Residual bound in metres: how far simplification may move the surface [default: 2.5 % of
    /// the cloud's largest side]
    #[arg(long)]
    max_residual_m: Option<f32>,
    /// Sensor position "x,y,z" in the cloud's frame, for one-view scans (orients normals towards
    /// it); without it normals are oriented by propagation
    #[arg(long, value_parser = parse_vec3)]
    viewpoint: Option<Vec3>,
    /// Print one JSON object with face counts, the residual reached and per-stage milliseconds
    #[arg(long)]
    json: bool,
}

fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let parts: Vec<f32> = s
        .split(',')
        .map(|p| p.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("expected x,y,z: {e}"))?;
    match parts.as_slice() {
        [x, y, z] => Ok(Vec3::new(*x, *y, *z)),
        _ => Err(format!("expected three numbers x,y,z, got {}", parts.len())),
    }
}

pub fn run(args: MeshArgs) -> anyhow::Result<()> {
    let cloud = tacmesh::formats::read_cloud(&args.cloud)
        .with_context(|| format!("reading point cloud {}", args.cloud.display()))?;
    let mut config = MeshConfig {
        viewpoint: args.viewpoint,
        ..MeshConfig::default()
    };
    if let Some(v) = args.voxel_m {
        config.voxel_size = Length::Metres(v);
    }
    if let Some(r) = args.max_residual_m {
        config.max_residual = Length::Metres(r);
    }
    let (mesh, report) =
        mesh_cloud(&cloud, &config).with_context(|| format!("meshing {}", args.cloud.display()))?;
    tacmesh::formats::write_mesh(&args.output, &mesh)
        .with_context(|| format!("writing mesh {}", args.output.display()))?;
    if args.json {
        super::print_json(&report)?;
    } else {
        tracing::info!(
            points = report.points,
            recon_faces = report.recon_faces,
            faces = report.faces,
            max_residual_m = report.max_residual,
            total_ms = format!("{:.1}", report.total_ms),
            "wrote {}",
            args.output.display()
        );
    }
    Ok(())
}
