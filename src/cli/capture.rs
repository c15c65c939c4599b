//! `tacmesh capture`: what a sensor delivers, as point clouds in the world frame, without
//! running the daemon: to look at a recording or a new camera, and to draw the daemon's meshes
//! over the data they came from (`scripts/draw_scene.py`).

use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::config::SensorSection;
use tacmesh::daemon::{DaemonConfig, SensorSpec};
use tacmesh::source::{Observation, PointCloud};

/// Write frames of a sensor as PLY point clouds in the world frame (the sensor's configured
/// pose applied, pixels beyond the pipeline's max range left out), as the daemon sees them.
#[derive(Debug, Args)]
pub struct CaptureArgs {
    /// The sensor (see `tacmesh run --help` for the specs)
    #[arg(long, value_name = "SPEC")]
    sensor: String,
    /// Config file: its `[pipeline] max_range_m` and, for a sensor with the same spec, its pose
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Frames to pass over first
    #[arg(long, value_name = "N", default_value_t = 0)]
    skip: usize,
    /// Frames to write
    #[arg(long, value_name = "N", default_value_t = 1)]
    frames: usize,
    /// Output folder: frame-K.ply for the K-th frame read (from 0, skipped ones counted)
    #[arg(long, short, value_name = "DIR")]
    out: PathBuf,
}

pub fn run(args: CaptureArgs) -> anyhow::Result<()> {
    let config = match &args.config {
        Some(path) => DaemonConfig::load(path)?,
        None => DaemonConfig::default(),
    };
    let section = config
        .sensor
        .iter()
        .find(|s| s.spec == args.sensor)
        .cloned()
        .unwrap_or_else(|| SensorSection {
            spec: args.sensor.clone(),
            paced: Some(false),
            ..Default::default()
        });
    let world_from_rig = section
        .pose
        .as_ref()
        .map(|p| p.world_from_sensor())
        .unwrap_or(tacmesh::glam::Affine3A::IDENTITY);
    let spec = SensorSpec::parse(&section.spec)?;
    let mut source = spec
        .open(&section)
        .with_context(|| format!("cannot open {}", section.spec))?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let max_range_m = config.pipeline.max_range_m;
    let mut written = 0;
    for k in 0..args.skip + args.frames {
        let observation = match source.next_observation() {
            Ok(observation) => observation,
            // A recording shorter than asked: what it had is written, and said.
            Err(tacmesh::source::SourceError::EndOfStream { .. }) => {
                anyhow::ensure!(
                    written > 0,
                    "{} ended after {k} frames, before the first of the {} to write (--skip {})",
                    section.spec,
                    args.frames,
                    args.skip
                );
                tacmesh::log_sink::eprint_line(&format!(
                    "tacmesh: {} ended after {k} frames: wrote {written} of the {} asked for",
                    section.spec, args.frames
                ));
                return Ok(());
            }
            Err(err) => return Err(err).with_context(|| format!("frame {k} of {}", section.spec)),
        };
        if k < args.skip {
            continue;
        }
        let points = match observation {
            Observation::Depth(mut frame) => {
                frame
                    .check()
                    .with_context(|| format!("frame {k} of {} is malformed", section.spec))?;
                frame.world_from_sensor = world_from_rig * frame.world_from_sensor;
                frame.deproject(max_range_m).points_in_world
            }
            Observation::Cloud {
                cloud,
                world_from_sensor,
                ..
            } => {
                let world_from_sensor = world_from_rig * world_from_sensor;
                cloud
                    .points
                    .iter()
                    .filter(|p| p.is_finite())
                    .map(|&p| world_from_sensor.transform_point3(p))
                    .collect()
            }
        };
        let path = args.out.join(format!("frame-{k}.ply"));
        let cloud = PointCloud::new(points);
        tacmesh::formats::write_cloud(&path, &cloud)
            .with_context(|| format!("cannot write {}", path.display()))?;
        written += 1;
        tacmesh::log_sink::eprint_line(&format!(
            "tacmesh: wrote {} ({} points)",
            path.display(),
            cloud.points.len()
        ));
    }
    Ok(())
}
