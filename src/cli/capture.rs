//! `tacmesh capture`: what a sensor delivers, as point clouds in the world frame, without
//! running the daemon: to look at a recording or a new camera, and to draw the daemon's meshes
//! over the data they came from (`scripts/draw_scene.py`); with `--segments`, also how the
//! daemon's segmentation cuts each frame, as a picture.

use std::path::{Path, PathBuf};

use anyhow::Context;
use clap::Args;
use tacmesh::daemon::config::SensorSection;
use tacmesh::daemon::{points_in_workspace, segment_config, DaemonConfig, SensorSpec};
use tacmesh::glam::Vec3;
use tacmesh::segment::{segment_scan, FlyingPixels, SegmentConfig};
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
    /// Also write frame-K-segments.png for each frame with a pixel grid (a depth camera, an
    /// organised cloud): its range in grey beside the daemon's segmentation of it (one colour
    /// per object, support planes pale blue, walls and other background planes brown,
    /// flying pixels white, what is none of these dark grey, no reading black)
    #[arg(long)]
    segments: bool,
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
        // The frame in the world frame, one point per pixel where it has a pixel grid.
        let (organised, grid, world_from_sensor) = match observation {
            Observation::Depth(mut frame) => {
                frame
                    .check()
                    .with_context(|| format!("frame {k} of {} is malformed", section.spec))?;
                frame.world_from_sensor = world_from_rig * frame.world_from_sensor;
                let grid = (frame.intrinsics.width, frame.intrinsics.height);
                (
                    frame.deproject_organised(max_range_m).points_in_world,
                    Some(grid),
                    frame.world_from_sensor,
                )
            }
            Observation::Cloud {
                cloud,
                grid,
                world_from_sensor,
                ..
            } => {
                let world_from_sensor = world_from_rig * world_from_sensor;
                let points = cloud
                    .points
                    .iter()
                    .map(|&p| world_from_sensor.transform_point3(p))
                    .collect();
                let grid = grid
                    .filter(|g| g.check(&cloud).is_ok())
                    .map(|g| (g.width, g.height));
                (points, grid, world_from_sensor)
            }
        };
        if args.segments {
            let path = args.out.join(format!("frame-{k}-segments.png"));
            match grid {
                Some((width, height)) => {
                    // As `tacmesh run` with this config would segment the frame.
                    let segment_config = segment_config(&config.workspace, world_from_sensor);
                    let in_workspace = points_in_workspace(&config.workspace, &organised);
                    let picture = segments_picture(
                        in_workspace.as_deref().unwrap_or(&organised),
                        (width as usize, height as usize),
                        config.pipeline.segment_stride,
                        &segment_config,
                    );
                    write_png(&path, 2 * width, height, &picture)
                        .with_context(|| format!("cannot write {}", path.display()))?;
                    tacmesh::log_sink::eprint_line(&format!("tacmesh: wrote {}", path.display()));
                }
                None => tacmesh::log_sink::eprint_line(&format!(
                    "tacmesh: frame {k} of {} has no pixel grid: no {}",
                    section.spec,
                    path.display()
                )),
            }
        }
        let points: Vec<Vec3> = organised.into_iter().filter(|p| p.is_finite()).collect();
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

/// A range picture of an organised cloud (grey, nearer brighter) beside the daemon's
/// segmentation of it, as RGB rows of `2 × width` pixels (see `CaptureArgs::segments`).
fn segments_picture(
    points: &[Vec3],
    (width, height): (usize, usize),
    stride: u32,
    config: &SegmentConfig,
) -> Vec<u8> {
    const NO_READING: [u8; 3] = [0, 0, 0];
    const SUPPORT: [u8; 3] = [170, 200, 235];
    const BACKGROUND: [u8; 3] = [120, 80, 50];
    const FLYING: [u8; 3] = [255, 255, 255];
    const NONE: [u8; 3] = [60, 60, 60];
    // Twelve colours apart from the ones above, for the objects in turn.
    const OBJECTS: [[u8; 3]; 12] = [
        [230, 25, 75],
        [60, 180, 75],
        [255, 225, 25],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [0, 128, 128],
        [250, 190, 212],
        [170, 110, 40],
    ];
    let pixels = width * height;
    let points = &points[..pixels.min(points.len())];
    let scan = segment_scan(
        points,
        Some((width as u32, height as u32)),
        stride,
        config,
        &[],
    );
    let mut object = vec![0usize; points.len()];
    for (k, indices) in scan.objects.iter().enumerate() {
        for &i in indices {
            object[i as usize] = k + 1;
        }
    }
    let flying = FlyingPixels::new(points, width, config);
    let viewpoint = config.viewpoint_m;
    let (near, far) = points
        .iter()
        .filter(|p| p.is_finite())
        .map(|p| p.distance(viewpoint))
        .fold((f32::INFINITY, 0.0f32), |(lo, hi), r| {
            (lo.min(r), hi.max(r))
        });
    let on = |planes: &[tacmesh::segment::SupportPlane], p: Vec3| {
        let band = config.plane_distance_at(p);
        planes
            .iter()
            .any(|plane| plane.signed_distance_m(p).abs() <= band)
    };
    let mut image = vec![0u8; 3 * 2 * pixels];
    for (i, &p) in points.iter().enumerate() {
        let (u, v) = (i % width, i / width);
        let (range_rgb, segment_rgb) = if !p.is_finite() {
            (NO_READING, NO_READING)
        } else {
            let r = p.distance(viewpoint);
            let grey = (230.0 - 200.0 * (r - near) / (far - near).max(1e-6)) as u8;
            let segment = if flying.flies(i) {
                FLYING
            } else if object[i] > 0 {
                OBJECTS[(object[i] - 1) % OBJECTS.len()]
            } else if on(&scan.strided.planes, p) {
                SUPPORT
            } else if on(&scan.strided.background, p) {
                BACKGROUND
            } else {
                NONE
            };
            ([grey; 3], segment)
        };
        for (panel, rgb) in [range_rgb, segment_rgb].into_iter().enumerate() {
            let at = 3 * (v * 2 * width + panel * width + u);
            image[at..at + 3].copy_from_slice(&rgb);
        }
    }
    image
}

/// Writes RGB rows (`width × height` pixels) as a PNG file.
fn write_png(path: &Path, width: u32, height: u32, rgb: &[u8]) -> anyhow::Result<()> {
    let file = std::io::BufWriter::new(std::fs::File::create(path)?);
    let mut encoder = png::Encoder::new(file, width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header()?;
    writer.write_image_data(rgb)?;
    writer.finish()?;
    Ok(())
}
