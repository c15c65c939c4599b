//! Per-object IoU of the daemon's segmentation (and `tacmesh mesh --objects`', the same
//! call: [`segment_scan`]) on labelled mOSD scans, per scan and per kind of scene:
//!
//! ```text
//! cargo run --release -p tacmesh-segment --example labelled_iou -- \
//!     ../shared/data/pointclouds/mosd_learn testdata/pointclouds/mosd
//! ```
//!
//! Arguments are PCD files or folders of them (each file named as the dataset names it, so
//! that its kind is known). Options: `--stride N` (default 2, the daemon's), `--set KEY=VALUE`
//! to try another value of a [`SegmentConfig`] field (`min_support_size_m`,
//! `concave_tolerance_deg`, `patch_size_m`, `max_valley_depth_m`, `cluster_tolerance_m`,
//! `plane_distance_m`, `voxel_size_m`), `--quiet` for the table alone, `--draw DIR` to write
//! one picture per organised scan into DIR: its colour, its labelled objects, and the
//! segments (each segment in the colour of the object it overlaps most, so that a split
//! object shows two shades of its colour; a segment on no object is white).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use tacmesh_formats::pcd::read_pcd;
use tacmesh_segment::labelled::{score, MosdKind, ScanScore};
use tacmesh_segment::{object_labels, segment_scan, SegmentConfig};

struct Options {
    files: Vec<PathBuf>,
    stride: u32,
    config: SegmentConfig,
    quiet: bool,
    draw: Option<PathBuf>,
}

fn parse_args() -> Result<Options, String> {
    let mut files = Vec::new();
    let mut stride = 2;
    let mut config = SegmentConfig::live();
    let mut quiet = false;
    let mut draw = None;
    let mut args = std::env::args().skip(1);
    while let Some(arg) = args.next() {
        match arg.as_str() {
            "--stride" => {
                let value = args.next().ok_or("--stride needs a value")?;
                stride = value
                    .parse()
                    .map_err(|_| format!("--stride {value}: not a whole number"))?;
            }
            "--set" => {
                let value = args.next().ok_or("--set needs KEY=VALUE")?;
                set(&mut config, &value)?;
            }
            "--quiet" => quiet = true,
            "--draw" => draw = Some(PathBuf::from(args.next().ok_or("--draw needs a folder")?)),
            _ => {
                let path = PathBuf::from(&arg);
                if path.is_dir() {
                    let entries = std::fs::read_dir(&path).map_err(|e| format!("{arg}: {e}"))?;
                    for entry in entries.flatten() {
                        if entry.path().extension().is_some_and(|e| e == "pcd") {
                            files.push(entry.path());
                        }
                    }
                } else {
                    files.push(path);
                }
            }
        }
    }
    files.sort_by_key(|f| (kind_of(f), number_of(f)));
    Ok(Options {
        files,
        stride,
        config,
        quiet,
        draw,
    })
}

fn set(config: &mut SegmentConfig, assignment: &str) -> Result<(), String> {
    let (key, value) = assignment
        .split_once('=')
        .ok_or(format!("--set {assignment}: expected KEY=VALUE"))?;
    let value: f32 = value
        .parse()
        .map_err(|_| format!("--set {assignment}: not a number"))?;
    let field = match key {
        "min_support_size_m" => &mut config.min_support_size_m,
        "concave_tolerance_deg" => &mut config.concave_tolerance_deg,
        "patch_size_m" => &mut config.patch_size_m,
        "max_valley_depth_m" => &mut config.max_valley_depth_m,
        "cluster_tolerance_m" => &mut config.cluster_tolerance_m,
        "plane_distance_m" => &mut config.plane_distance_m,
        "voxel_size_m" => &mut config.voxel_size_m,
        _ => return Err(format!("--set {key}: not a field this tool sets")),
    };
    *field = value;
    Ok(())
}

fn stem(file: &Path) -> String {
    file.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

fn kind_of(file: &Path) -> Option<MosdKind> {
    MosdKind::of_scan(&stem(file))
}

fn number_of(file: &Path) -> u32 {
    let name = stem(file);
    let digits = name.trim_start_matches(|c: char| !c.is_ascii_digit());
    digits.parse().unwrap_or(0)
}

fn score_file(
    file: &Path,
    stride: u32,
    config: &SegmentConfig,
    draw: Option<&Path>,
) -> Result<ScanScore, String> {
    let cloud = read_pcd(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let truth = cloud
        .labels
        .ok_or(format!("{}: no label field", file.display()))?;
    let grid = (cloud.height > 1).then_some((cloud.width, cloud.height));
    let segmentation = segment_scan(&cloud.points, grid, stride, config, &[]);
    let predicted = object_labels(&segmentation.objects, cloud.points.len());
    if let (Some(folder), true) = (draw, cloud.height > 1) {
        let out = folder.join(format!("{}.png", stem(file)));
        let colour = cloud.rgba.as_deref().unwrap_or(&[]);
        write_picture(&out, cloud.width, cloud.height, colour, &truth, &predicted)
            .map_err(|e| format!("{}: {e}", out.display()))?;
    }
    Ok(score(&truth, &predicted))
}

/// A distinct colour for a small number.
fn palette(k: u32) -> [u8; 3] {
    const COLOURS: [[u8; 3]; 10] = [
        [230, 25, 75],
        [60, 180, 75],
        [0, 130, 200],
        [245, 130, 48],
        [145, 30, 180],
        [70, 240, 240],
        [240, 50, 230],
        [210, 245, 60],
        [0, 128, 128],
        [170, 110, 40],
    ];
    COLOURS[k as usize % COLOURS.len()]
}

/// Colour, labelled objects (table grey) and segments side by side.
fn write_picture(
    out: &Path,
    width: u32,
    height: u32,
    colour: &[u32],
    truth: &[u32],
    predicted: &[u32],
) -> Result<(), String> {
    let (w, h) = (width as usize, height as usize);
    // Each segment in the colour of the object it overlaps most, darker for its second and
    // later segments of the same object.
    let mut overlap: BTreeMap<(u32, u32), usize> = BTreeMap::new();
    for (&t, &p) in truth.iter().zip(predicted) {
        if p > 0 {
            *overlap
                .entry((p, if t >= 20 { t / 10 } else { 0 }))
                .or_default() += 1;
        }
    }
    let mut owner: BTreeMap<u32, (u32, usize)> = BTreeMap::new();
    for (&(segment, object), &n) in &overlap {
        let entry = owner.entry(segment).or_insert((object, n));
        if n > entry.1 {
            *entry = (object, n);
        }
    }
    let mut shade: BTreeMap<u32, u32> = BTreeMap::new();
    let mut segment_colour: BTreeMap<u32, [u8; 3]> = BTreeMap::new();
    for (&segment, &(object, _)) in &owner {
        let nth = shade.entry(object).or_default();
        let [r, g, b] = if object == 0 {
            [255, 255, 255]
        } else {
            palette(object)
        };
        let dim = |c: u8| (c as u32 * 2 / (2 + *nth)) as u8;
        segment_colour.insert(segment, [dim(r), dim(g), dim(b)]);
        *nth += 1;
    }
    let mut image = vec![0u8; 3 * w * 3 * h];
    for v in 0..h {
        for u in 0..w {
            let i = v * w + u;
            let row = v * 3 * w;
            let rgb = colour
                .get(i)
                .map_or([0, 0, 0], |&c| [(c >> 16) as u8, (c >> 8) as u8, c as u8]);
            let t = truth.get(i).copied().unwrap_or(0);
            let truth_rgb = match t {
                0 => [0, 0, 0],
                1..=19 => [90, 90, 90],
                _ => palette(t / 10),
            };
            let p = predicted.get(i).copied().unwrap_or(0);
            let predicted_rgb = if p == 0 {
                if t == 0 {
                    [0, 0, 0]
                } else {
                    [40, 40, 40]
                }
            } else {
                segment_colour[&p]
            };
            for (panel, px) in [rgb, truth_rgb, predicted_rgb].into_iter().enumerate() {
                let at = 3 * (row + panel * w + u);
                image[at..at + 3].copy_from_slice(&px);
            }
        }
    }
    let file = std::fs::File::create(out).map_err(|e| e.to_string())?;
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), 3 * width, height);
    encoder.set_color(png::ColorType::Rgb);
    encoder.set_depth(png::BitDepth::Eight);
    let mut writer = encoder.write_header().map_err(|e| e.to_string())?;
    writer.write_image_data(&image).map_err(|e| e.to_string())
}

fn main() {
    let options = match parse_args() {
        Ok(options) => options,
        Err(message) => {
            eprintln!("labelled_iou: {message}");
            std::process::exit(2);
        }
    };
    let scores: Vec<(PathBuf, Result<ScanScore, String>)> = options
        .files
        .par_iter()
        .map(|file| {
            (
                file.clone(),
                score_file(
                    file,
                    options.stride,
                    &options.config,
                    options.draw.as_deref(),
                ),
            )
        })
        .collect();
    // Per kind: every object's IoU, split objects, merged objects, spurious segments.
    let mut kinds: BTreeMap<Option<MosdKind>, (Vec<f64>, usize, usize, usize)> = BTreeMap::new();
    let mut failed = false;
    for (file, result) in &scores {
        let score = match result {
            Ok(score) => score,
            Err(message) => {
                eprintln!("{message}");
                failed = true;
                continue;
            }
        };
        let entry = kinds.entry(kind_of(file)).or_default();
        entry.0.extend(score.objects.iter().map(|o| o.iou));
        entry.1 += score.objects.iter().filter(|o| o.pieces > 1).count();
        entry.2 += score.objects.iter().filter(|o| o.merged).count();
        entry.3 += score.spurious;
        if !options.quiet {
            let per_object: Vec<String> = score
                .objects
                .iter()
                .map(|o| {
                    let mark = match (o.pieces > 1, o.merged) {
                        (true, true) => "sm",
                        (true, false) => "s",
                        (false, true) => "m",
                        (false, false) => "",
                    };
                    format!("{:.2}{mark}", o.iou)
                })
                .collect();
            println!(
                "{:12} {:9} objects {:2} segments {:2} spurious {} mean {:.3}  {}",
                stem(file),
                kind_of(file).map_or("?", MosdKind::name),
                score.objects.len(),
                score.segments,
                score.spurious,
                score.mean_iou(),
                per_object.join(" ")
            );
        }
    }
    println!();
    println!("| kind | scans' objects | mean IoU | ≥ 0.8 | split | merged | spurious segments |");
    println!("|---|---|---|---|---|---|---|");
    let mut all = (Vec::new(), 0, 0, 0);
    for (kind, (ious, split, merged, spurious)) in &kinds {
        row(
            kind.map_or("other", MosdKind::name),
            ious,
            *split,
            *merged,
            *spurious,
        );
        all.0.extend(ious);
        all.1 += split;
        all.2 += merged;
        all.3 += spurious;
    }
    row("all", &all.0, all.1, all.2, all.3);
    if failed {
        std::process::exit(1);
    }
}

fn row(name: &str, ious: &[f64], split: usize, merged: usize, spurious: usize) {
    let n = ious.len().max(1) as f64;
    let mean = ious.iter().sum::<f64>() / n;
    let good = ious.iter().filter(|&&v| v >= 0.8).count() as f64 / n;
    println!(
        "| {name} | {} | {mean:.3} | {:.0} % | {split} | {merged} | {spurious} |",
        ious.len(),
        good * 100.0
    );
}
