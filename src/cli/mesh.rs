use std::path::PathBuf;

use anyhow::Context;
use clap::Args;
use tacmesh::formats::{read_cloud_file, CloudFile, NonFinite};
use tacmesh::glam::Vec3;
use tacmesh::physics_scene::OfflineObject;
use tacmesh::pipeline::{mesh_cloud, residual_for_target_mhe_m, Length, MeshConfig};
use tacmesh::segment::{object_labels, segment_scan, SegmentConfig};

/// Mesh one point cloud (PLY, PCD, or XYZ text: .xyz, .txt, .pts) into one simplified mesh (PLY
/// or OBJ).
///
/// Reconstructs the surface with marching cubes over a smoothed signed distance near the
/// points, then simplifies by edge collapse until any further collapse would move the surface
/// farther than the residual bound from the reconstruction.
#[derive(Debug, Args)]
pub struct MeshArgs {
    /// Input point cloud: .ply, .pcd, or XYZ text in .xyz, .txt or .pts (x y z or x y z nx ny
    /// nz per line, separated by spaces or commas)
    cloud: PathBuf,
    /// Output mesh: .ply or .obj (a folder with --objects)
    #[arg(short, long)]
    output: PathBuf,
    /// Voxel edge in metres: the points are fused and their planes fitted per voxel, used as
    /// given [default: 1/50 of the cloud's largest side, grown for noisy or sparse clouds (see
    /// the README)]
    #[arg(long, value_parser = parse_voxel_m, allow_hyphen_values = true)]
    voxel_m: Option<f32>,
    /// Marching-cubes cell edge in voxels, 1 to 4 [default, for a cloud with no viewpoint: 2
    /// when the noise reaches the default voxel, 3 for a dense cloud (the cell within 10 % of
    /// its largest side), 2 while the cell stays within 6 % of it, else 1; 1 with a viewpoint. A
    /// closed object whose coarser mesh comes out open (or, on 3, in pieces) is meshed again on
    /// finer corners]
    #[arg(long, value_name = "VOXELS", value_parser = clap::value_parser!(i32).range(1..=4))]
    mesh_step_voxels: Option<i32>,
    /// Residual bound in metres: how far simplification may move the surface [default: 2.5 % of
    /// the cloud's largest side]
    #[arg(long)]
    max_residual_m: Option<f32>,
    /// Error target mode: the mean Hausdorff error, metres, to aim at with as few faces as
    /// that allows; sets the residual bound to 3.5 times it (on the paper's shapes at 20 mm
    /// noise the error comes out at 0.02–0.27 of the bound, flat shapes lowest)
    #[arg(long, value_name = "METRES", value_parser = parse_target_mhe, allow_hyphen_values = true, conflicts_with = "max_residual_m")]
    target_mhe_m: Option<f32>,
    /// Multiply the cloud's coordinates by FACTOR to make them metres: 0.001 for a cloud in
    /// millimetres, 0.01 for centimetres. The mesh is written in metres, and --voxel-m,
    /// --max-residual-m and --viewpoint are in metres too
    #[arg(long, value_name = "FACTOR", value_parser = parse_scale, allow_hyphen_values = true)]
    scale: Option<f32>,
    /// Sensor position "x,y,z" in metres in the cloud's frame, for one-view scans (orients
    /// normals towards it) [default: the file's own (a PCD's VIEWPOINT); without one normals
    /// are oriented by propagation]
    #[arg(long, value_parser = super::parse_vec3, allow_hyphen_values = true)]
    viewpoint: Option<Vec3>,
    /// With --objects: up, "x,y,z" in the cloud's frame (supports face it; any length)
    /// [default: -y, up in a camera's optical frame held upright; give 0,0,1 for a cloud in a
    /// z-up world frame, such as `tacmesh capture` writes]. The sensor then looks from
    /// --viewpoint towards the cloud's centre
    #[arg(long, value_parser = super::parse_direction, allow_hyphen_values = true)]
    up: Option<Vec3>,
    /// Print one JSON object with face counts, the residual reached, the fit's distance to the
    /// data before and after (measuring it after costs one more pass), per-stage milliseconds,
    /// the points left out for a NaN or infinite coordinate and the viewpoint used
    #[arg(long)]
    json: bool,
    /// Treat CLOUD as a scene: find its support planes and objects with the daemon's
    /// segmentation, and write into the folder -o one mesh per object (object-K.ply, K from 1,
    /// largest first) and labels.txt (one object id per input point, in input order; 0 for
    /// support planes, unassigned and invalid points)
    #[arg(long)]
    objects: bool,
    /// Also write a MuJoCo scene of what was meshed into the folder DIR (scene.xml, meshes/):
    /// the body `tacmesh subscribe --mjcf` would keep of it (a box, cylinder or sphere when one
    /// explains the mesh, else its convex parts, an open one-view shell first closed down onto
    /// its support; mass at 500 kg/m³). One cloud gives one free body; with --objects, the
    /// scene's objects on its supports as finite slabs
    #[arg(long, value_name = "DIR")]
    mjcf: Option<PathBuf>,
    /// As --mjcf, as an SDFormat world (DIR/scene.sdf) for Gazebo and PyBullet
    #[arg(long, value_name = "DIR")]
    sdf: Option<PathBuf>,
    /// As --mjcf, as URDF: one robot per body and support in DIR/urdf/ and DIR/urdf/scene.json
    /// placing them
    #[arg(long, value_name = "DIR")]
    urdf: Option<PathBuf>,
}

impl MeshArgs {
    fn wants_physics(&self) -> bool {
        self.mjcf.is_some() || self.sdf.is_some() || self.urdf.is_some()
    }
}

/// Writes the physics files `--mjcf`, `--sdf` and `--urdf` ask for, of `objects` (meshes with
/// their residual bounds) on `supports` (outlines), and says what each object became.
fn write_physics(
    args: &MeshArgs,
    objects: &[OfflineObject],
    supports: &[Vec<Vec3>],
    viewpoint: Option<Vec3>,
) -> anyhow::Result<()> {
    let update = tacmesh::physics_scene::offline_scene(objects, supports, viewpoint, !args.objects);
    anyhow::ensure!(
        !update.scene.bodies.is_empty(),
        "no body could be made of what was meshed: {}",
        update
            .left_out
            .iter()
            .map(|(id, why)| format!("object {id}: {why}"))
            .collect::<Vec<_>>()
            .join("; ")
    );
    for (id, why) in &update.left_out {
        tracing::warn!("object {id} is left out of the physics scene: {why}");
    }
    for (id, why) in &update.held_still {
        tracing::info!("object {id} is static in the physics scene: {why}");
    }
    for (id, fit) in &update.primitives {
        if let Some((kind, residual_m)) = fit {
            tracing::info!(
                "object {id} is a {kind} ({:.1} mm from its mesh at the 95th percentile)",
                residual_m * 1e3
            );
        }
    }
    for (a, b, depth_m) in &update.overlaps {
        tracing::info!(
            "{a} and {b} start {:.0} mm inside each other: they do not collide with each other",
            depth_m * 1e3
        );
    }
    use tacmesh::physics::{write_mjcf, write_sdf, write_urdf, MjcfConfig, SdfConfig, UrdfConfig};
    if let Some(dir) = &args.mjcf {
        let written = write_mjcf(dir, &update.scene, &MjcfConfig::default())
            .with_context(|| format!("writing the MuJoCo scene in {}", dir.display()))?;
        tracing::info!("wrote {}", written.scene_file.display());
    }
    if let Some(dir) = &args.sdf {
        let written = write_sdf(dir, &update.scene, &SdfConfig::default())
            .with_context(|| format!("writing the SDF world in {}", dir.display()))?;
        tracing::info!("wrote {}", written.scene_file.display());
    }
    if let Some(dir) = &args.urdf {
        let written = write_urdf(dir, &update.scene, &UrdfConfig::default())
            .with_context(|| format!("writing the URDF files in {}", dir.display()))?;
        tracing::info!("wrote {}", written.index_file.display());
    }
    Ok(())
}

fn parse_target_mhe(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(m) if m.is_finite() && m > 0.0 => Ok(m),
        _ => Err("expected a mean error in metres > 0, e.g. 0.01".into()),
    }
}

/// `--voxel-m`: from 0.1 mm to 10 m (a voxel of 1e30 m once gave an empty mesh, exit 0).
fn parse_voxel_m(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(v) if (0.0001..=10.0).contains(&v) => Ok(v),
        _ => Err("give a voxel edge in metres from 0.0001 to 10".into()),
    }
}

fn parse_scale(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(f) if f.is_finite() && f > 0.0 => Ok(f),
        _ => Err("expected a positive number, e.g. 0.001 for millimetres".into()),
    }
}

/// The extents, metres, of what a depth camera can scan: from a small object a few centimetres
/// across (1 cm allows for a part of one) to a room or a yard (about 20 m, beyond the range of
/// any of the cameras tacmesh reads). A cloud outside is in other units, most likely
/// millimetres.
pub(crate) const PLAUSIBLE_EXTENT_M: std::ops::RangeInclusive<f32> = 0.01..=20.0;

/// Multiplies the points, and the sensor position the file records, by `factor` (positive, so
/// normals keep their direction).
fn scale(file: &mut CloudFile, factor: f32) {
    for p in &mut file.cloud.points {
        *p *= factor;
    }
    if let Some(pose) = &mut file.cloud_from_sensor {
        pose.translation *= factor;
    }
}

/// Warns when the cloud's extent is not what a depth camera sees, and says how to fix it.
fn warn_if_implausible(args: &MeshArgs, cloud: &tacmesh::PointCloud) {
    let Some(extent_m) = tacmesh::pipeline::robust_extent_m(&cloud.points) else {
        return;
    };
    let scaled = match args.scale {
        Some(factor) => format!(" (after --scale {factor})"),
        None => String::new(),
    };
    let (min, max) = PLAUSIBLE_EXTENT_M.into_inner();
    if extent_m > max {
        tracing::warn!(
            "{}: the cloud is {extent_m:.0} m across{scaled}, more than a depth camera sees \
             (up to about {max:.0} m): if its unit is millimetres, mesh it with --scale 0.001 \
             (centimetres: --scale 0.01)",
            args.cloud.display()
        );
    } else if extent_m < min {
        tracing::warn!(
            "{}: the cloud is {:.2} mm across{scaled}, less than a depth camera resolves \
             (about {:.0} mm): if its unit is not metres, give --scale with the factor to \
             metres (1000 for kilometres)",
            args.cloud.display(),
            extent_m * 1e3,
            min * 1e3
        );
    }
}

pub fn run(args: MeshArgs) -> anyhow::Result<()> {
    // With --objects in file order with the invalid points, so that labels.txt lines up with
    // the file; they are labelled 0 and meshed with no object.
    let non_finite = if args.objects {
        NonFinite::Keep
    } else {
        NonFinite::Drop
    };
    if !args.objects {
        // Before the work whose result it would take.
        tacmesh::formats::check_mesh_path(&args.output).context("the output mesh")?;
    }
    let reading = std::time::Instant::now();
    let mut file = read_cloud_file(&args.cloud, non_finite).context("reading the point cloud")?;
    let read_ms = reading.elapsed().as_secs_f64() * 1e3;
    if file.non_finite > 0 {
        tracing::info!(
            "{}: left out {} points with a NaN or infinite coordinate",
            args.cloud.display(),
            file.non_finite
        );
    }
    if let Some(factor) = args.scale {
        scale(&mut file, factor);
    }
    warn_if_implausible(&args, &file.cloud);
    let viewpoint = viewpoint(&args, &file);
    if args.objects {
        return mesh_objects(&args, &file, viewpoint);
    }
    let cloud = file.cloud;
    let config = mesh_config(&args, viewpoint);
    let (mesh, report) =
        mesh_cloud(&cloud, &config).with_context(|| format!("meshing {}", args.cloud.display()))?;
    // A cloud spread far past its voxels (1,000 points over ±1e30 m) fuses into nothing.
    anyhow::ensure!(
        !mesh.triangles.is_empty(),
        "meshing {} gave no surface: its {} points are too far apart for a voxel of {:.3} m to \
         join them (is the cloud in metres? give --voxel-m, or --scale for other units)",
        args.cloud.display(),
        report.points,
        report.voxel_size_m
    );
    tacmesh::formats::write_mesh(&args.output, &mesh).context("writing the mesh")?;
    if args.wants_physics() {
        let object = OfflineObject {
            id: 1,
            mesh,
            residual_m: report.max_residual,
            points: cloud.points,
            voxel_m: report.voxel_size_m,
        };
        write_physics(&args, &[object], &[], config.viewpoint)?;
    }
    if args.json {
        super::print_json(&MeshOutput {
            non_finite_points: file.non_finite,
            viewpoint: viewpoint.map(|v| v.to_array()),
            read_ms,
            peak_memory_mb: peak_resident_mb(),
            report,
        })?;
    } else {
        tracing::info!(
            points = report.points,
            recon_faces = report.recon_faces,
            faces = report.faces,
            max_residual_m = report.max_residual,
            closed = report.closed,
            volume_m3 = report
                .volume_m3
                .map_or("none (open)".to_owned(), |v| format!("{v:.4}")),
            total_ms = format!("{:.1}", report.total_ms),
            "wrote {}",
            args.output.display()
        );
    }
    Ok(())
}

/// The pipeline's settings from the defaults and `--voxel-m`, `--mesh-step-voxels`,
/// `--max-residual-m` and `--target-mhe-m` (one cloud and `--objects` alike).
fn mesh_config(args: &MeshArgs, viewpoint: Option<Vec3>) -> MeshConfig {
    let mut config = MeshConfig {
        viewpoint,
        // The JSON report carries the fit's distance to the data after (`fit_rms_after`).
        measure_fit: args.json,
        ..MeshConfig::default()
    };
    if let Some(v) = args.voxel_m {
        config.voxel_size = Length::Metres(v);
    }
    config.mesh_step_voxels = args.mesh_step_voxels;
    if let Some(r) = args.max_residual_m {
        config.max_residual = Length::Metres(r);
    }
    if let Some(target) = args.target_mhe_m {
        config.max_residual = Length::Metres(residual_for_target_mhe_m(target));
    }
    config
}

/// Where normals face: `--viewpoint`, else the sensor position the file records (a PCD's
/// `VIEWPOINT`: PCL writes one for every scan), else none (orientation by propagation).
fn viewpoint(args: &MeshArgs, file: &CloudFile) -> Option<Vec3> {
    if args.viewpoint.is_some() {
        return args.viewpoint;
    }
    let v = Vec3::from(file.cloud_from_sensor?.translation);
    tracing::info!(
        "{}: normals face the viewpoint the file records, {},{},{} (--viewpoint overrides it)",
        args.cloud.display(),
        v.x,
        v.y,
        v.z
    );
    Some(v)
}

/// What `--json` prints: the pipeline's report and what reading the file found.
#[derive(serde::Serialize)]
struct MeshOutput {
    /// Points of the file with a NaN or infinite coordinate, left out of the mesh.
    non_finite_points: usize,
    /// Where the normals were made to face, `null` when they were oriented by propagation.
    viewpoint: Option<[f32; 3]>,
    /// Reading and parsing the file, milliseconds (not in the report's `total_ms`).
    read_ms: f64,
    /// The process's peak resident memory so far (reading, meshing, writing), MiB; `null`
    /// where the kernel does not say (`VmHWM` in `/proc/self/status`, Linux).
    peak_memory_mb: Option<f64>,
    #[serde(flatten)]
    report: tacmesh::pipeline::MeshReport,
}

/// The peak resident set of this process, MiB, from `/proc/self/status`.
fn peak_resident_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib / 1024.0)
}

/// One line of `--objects --json`.
#[derive(serde::Serialize)]
struct ObjectReport {
    id: usize,
    file: String,
    #[serde(flatten)]
    report: tacmesh::pipeline::MeshReport,
}

/// `--objects`: segment the scene, mesh each object, write the meshes and `labels.txt`.
fn mesh_objects(args: &MeshArgs, file: &CloudFile, viewpoint: Option<Vec3>) -> anyhow::Result<()> {
    let cloud = &file.cloud;
    let dir = &args.output;
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create the output folder {}", dir.display()))?;
    // Scans are in the sensor frame unless a viewpoint says otherwise.
    let viewpoint = viewpoint.unwrap_or(Vec3::ZERO);
    // The daemon's segmentation, call for call: its settings, on every `segment_stride`-th
    // pixel of an organised scan as the daemon segments each frame, so that a scan meshed here
    // and the same scan replayed live give the same objects.
    let live = SegmentConfig::live();
    // Another frame than the optical one: the sensor looks from the viewpoint towards the
    // cloud's centre (depth steps grow along it).
    let (up, forward) = match args.up {
        Some(up) => {
            let finite = cloud.points.iter().filter(|p| p.is_finite());
            let (sum, n) = finite.fold((Vec3::ZERO, 0usize), |(s, n), p| (s + *p, n + 1));
            let centre = sum / n.max(1) as f32;
            let forward = (centre - viewpoint).try_normalize().unwrap_or(live.forward);
            (up, forward)
        }
        None => (live.up, live.forward),
    };
    let pipeline = tacmesh::daemon::config::PipelineSection::default();
    let workspace = tacmesh::daemon::config::WorkspaceSection::default();
    let scan = segment_scan(
        &cloud.points,
        file.grid.map(|grid| (grid.width, grid.height)),
        pipeline.segment_stride,
        &SegmentConfig {
            viewpoint_m: viewpoint,
            up,
            forward,
            max_object_size_m: workspace.max_object_size_m,
            ..live
        },
        &[],
    );
    let (planes, objects) = (scan.strided.planes, scan.objects);
    tracing::info!(
        planes = planes.len(),
        objects = objects.len(),
        "segmented {}",
        args.cloud.display()
    );
    let config = mesh_config(args, Some(viewpoint));
    let mut reports = Vec::new();
    let mut meshed = Vec::new();
    for (k, indices) in objects.iter().enumerate() {
        let id = k + 1;
        let points = indices.iter().map(|&i| cloud.points[i as usize]).collect();
        let object = tacmesh::PointCloud::new(points);
        let file = dir.join(format!("object-{id}.ply"));
        match mesh_cloud(&object, &config) {
            Ok((mesh, report)) => {
                tacmesh::formats::write_mesh(&file, &mesh).context("writing the mesh")?;
                if args.wants_physics() {
                    meshed.push(OfflineObject {
                        id: id as u64,
                        mesh,
                        residual_m: report.max_residual,
                        points: object.points,
                        voxel_m: report.voxel_size_m,
                    });
                }
                tracing::info!(
                    points = report.points,
                    faces = report.faces,
                    "object {id}: wrote {}",
                    file.display()
                );
                reports.push(ObjectReport {
                    id,
                    file: file.display().to_string(),
                    report,
                });
            }
            // A sliver of a few hundred points may be too thin to reconstruct; its points
            // keep their label, it just has no mesh.
            Err(err) => tracing::warn!("object {id} ({} points): no mesh: {err}", indices.len()),
        }
    }
    // Nothing found is said, and is a failure: the caller asked for objects.
    anyhow::ensure!(
        !objects.is_empty(),
        "{}: no object found: no cluster of points was left once the {} support plane{} and \
         the background were taken out (is the cloud in metres, seen from --viewpoint?)",
        args.cloud.display(),
        planes.len(),
        if planes.len() == 1 { "" } else { "s" }
    );
    if args.wants_physics() {
        let outlines: Vec<Vec<Vec3>> = planes.iter().map(|p| p.outline()).collect();
        write_physics(args, &meshed, &outlines, Some(viewpoint))?;
    }
    let labels_path = dir.join("labels.txt");
    // One label per point of the file: `k` for the points of object-k, 0 for the rest.
    let label_of = object_labels(&objects, cloud.points.len());
    let mut labels = String::with_capacity(label_of.len() * 2);
    for label in &label_of {
        labels.push_str(&label.to_string());
        labels.push('\n');
    }
    std::fs::write(&labels_path, labels)
        .with_context(|| format!("writing {}", labels_path.display()))?;
    if args.json {
        super::print_json(&serde_json::json!({
            "non_finite_points": file.non_finite,
            "planes": planes.len(),
            "objects": reports,
        }))?;
    }
    Ok(())
}
