//! Segmenting an organised cloud (a deprojected depth image: one point per pixel, non-finite
//! where a pixel has no reading) on every `stride`-th pixel in each direction, as the daemon
//! does at 30 frames a second, joining the pieces of objects that something in front cut
//! apart (`occlusion.rs`, which needs the image), then labelling every pixel from its strided
//! neighbour.
//!
//! At stride 2 a 640×480 frame is segmented on a quarter of its points; neighbouring pixels
//! of one surface are millimetres apart, so the segmentation hardly changes (mean IoU on the
//! labelled mOSD scans 0.89 against 0.93 at full resolution, `tests/real_data.rs`), and the
//! full-resolution object points go on to tracking and fusion.
//!
//! Entry points: [`segment_organised`], and [`segment_organised_timed`], which also returns
//! the stage times.

use std::time::Instant;

use glam::Vec3;

use crate::{segment_timed, SegmentConfig, Segmentation, StageTimes, SupportPlane};

/// A full-resolution point joins the object of its strided neighbour only within this
/// distance, in metres, so pixels across a depth edge do not.
const LABEL_SPREAD_M: f32 = 0.02;

/// The result of [`segment_organised`].
#[derive(Debug, Clone, PartialEq)]
pub struct OrganisedSegmentation {
    /// The segmentation of the strided points (row-major, `width.div_ceil(stride)` per row):
    /// planes, background, objects and labels index those points, not the input's.
    pub strided: Segmentation,
    /// Each object of `strided.objects` in full resolution: indices into the input points,
    /// ascending.
    pub objects: Vec<Vec<u32>>,
}

/// A scan or a frame as the daemon segments it, and `tacmesh mesh --objects` too, so that a
/// scan offline and the same scan replayed live give the same objects: an organised cloud
/// (`grid`, width × height) on every `stride`-th pixel by [`segment_organised`], any other
/// cloud point by point by [`segment_with_hints`](crate::segment_with_hints). The objects are
/// in full resolution either way.
pub fn segment_scan(
    points: &[Vec3],
    grid: Option<(u32, u32)>,
    stride: u32,
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> OrganisedSegmentation {
    match grid {
        Some((width, height)) => segment_organised(points, width, height, stride, config, hints),
        None => {
            let strided = crate::segment_with_hints(points, config, hints);
            let objects = strided.objects.clone();
            OrganisedSegmentation { strided, objects }
        }
    }
}

/// Segments every `stride`-th pixel (in each direction) of the organised cloud `points`
/// (`width × height`, row-major) with `config`, whose cluster sizes count full-resolution
/// points (they are divided by `stride²` for the strided cloud), starting from the plane
/// `hints` as [`segment_with_hints`](crate::segment_with_hints) does. Then each remaining
/// point joins the object of its strided neighbour (the top-left pixel of its `stride ×
/// stride` block) when the two are within `LABEL_SPREAD_M` and the point is on no support or
/// background plane.
///
/// Stride 1 is [`segment_with_hints`](crate::segment_with_hints) itself. Never panics: a
/// cloud shorter than `width × height` is segmented on the pixels it has.
pub fn segment_organised(
    points: &[Vec3],
    width: u32,
    height: u32,
    stride: u32,
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> OrganisedSegmentation {
    segment_organised_timed(points, width, height, stride, config, hints).0
}

/// [`segment_organised`], also returning how long each stage took; picking the strided pixels
/// and labelling every pixel from its strided neighbour is [`StageTimes::organised`].
pub fn segment_organised_timed(
    points: &[Vec3],
    width: u32,
    height: u32,
    stride: u32,
    config: &SegmentConfig,
    hints: &[SupportPlane],
) -> (OrganisedSegmentation, StageTimes) {
    let clock = Instant::now();
    let stride = stride.max(1) as usize;
    let width = width as usize;
    let height = (height as usize).min(points.len() / width.max(1));
    let sub_width = width.div_ceil(stride);
    let scaled = |n: usize| (n / (stride * stride)).max(20);
    let config = if stride > 1 {
        SegmentConfig {
            // Cluster sizes count segmented points: one in stride² of an organised frame.
            min_cluster_points: scaled(config.min_cluster_points),
            // The same for the largest: walls and furniture are background, not objects, at
            // any stride (unscaled, a stride-2 wall passed as a 400,000-point "object").
            max_cluster_points: scaled(config.max_cluster_points),
            ..config.clone()
        }
    } else {
        config.clone()
    };
    let mut sub: Vec<Vec3> = Vec::with_capacity(height.div_ceil(stride) * sub_width);
    if width > 0 {
        for row in points[..height * width].chunks_exact(width).step_by(stride) {
            sub.extend(row.iter().step_by(stride));
        }
    }
    let gathered = clock.elapsed();
    let (mut strided, mut times) = segment_timed(&sub, &config, hints);
    times.organised = gathered;
    let clock = Instant::now();
    let filled = crate::occlusion::join_hidden_pieces(
        &sub,
        sub_width,
        &mut strided.objects,
        &mut strided.labels,
        &crate::plane_band(&config),
        &config,
        &strided.planes,
    );
    times.organised += clock.elapsed();
    if stride == 1 {
        let objects = strided.objects.clone();
        return (OrganisedSegmentation { strided, objects }, times);
    }

    let clock = Instant::now();
    let band = crate::plane_band(&config);
    let mut objects = vec![Vec::new(); strided.objects.len()];
    for v in 0..height {
        // The strided pixels of this row's blocks; the pixels of an unlabelled block are not
        // looked at.
        let blocks = (v / stride) * sub_width..(v / stride + 1) * sub_width;
        for (block, ((&label, &anchor), &inner_bottom)) in strided.labels[blocks.clone()]
            .iter()
            .zip(&sub[blocks.clone()])
            .zip(&filled[blocks])
            .enumerate()
        {
            if label == 0 {
                continue;
            }
            for u in block * stride..((block + 1) * stride).min(width) {
                let i = v * width + u;
                let p = points[i];
                if !p.is_finite() || p.distance(anchor) > LABEL_SPREAD_M {
                    continue;
                }
                let band_m = band.at(p);
                // On a support: within its band, or its margin above it. Below a support is
                // not on it: a chair under a table is an object (the lowest support's underside
                // was never an object to begin with). An object's inner bottom, which its walls
                // enclose, is not the support.
                let on_plane = !inner_bottom
                    && (strided.planes.iter().any(|plane| {
                        (-band_m..=band_m + config.plane_margin_m)
                            .contains(&plane.signed_distance_m(p))
                    }) || strided
                        .background
                        .iter()
                        .any(|plane| plane.signed_distance_m(p).abs() <= band_m));
                if !on_plane {
                    objects[label as usize - 1].push(i as u32);
                }
            }
        }
    }
    times.organised += clock.elapsed();
    (OrganisedSegmentation { strided, objects }, times)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 120 × 90 depth image of a table 1 m below a camera looking straight down (world z up,
    /// the camera at the origin), with a 10 cm cube standing on it in the middle (its top is
    /// what the camera sees), and one pixel with no reading.
    fn table_with_cube() -> (Vec<Vec3>, u32, u32) {
        let (width, height) = (120u32, 90u32);
        let mut points = Vec::new();
        for v in 0..height {
            for u in 0..width {
                let (x, y) = ((u as f32 - 60.0) * 0.005, (v as f32 - 45.0) * 0.005);
                let on_cube = x.abs() < 0.05 && y.abs() < 0.05;
                // A millimetre of deterministic noise, as a depth camera has.
                let noise = ((u * 7 + v * 13) % 5) as f32 * 0.0005 - 0.001;
                let z = if on_cube { -0.9 } else { -1.0 } + noise;
                points.push(if u == 3 && v == 4 {
                    Vec3::NAN
                } else {
                    Vec3::new(x, y, z)
                });
            }
        }
        (points, width, height)
    }

    fn looking_down() -> SegmentConfig {
        SegmentConfig {
            up: Vec3::Z,
            forward: Vec3::NEG_Z,
            min_cluster_points: 100,
            min_support_size_m: 0.3,
            // A height map has no sides: seen alone, the cube's top would be as flat as one
            // disparity step, a slice of far depth to a Kinect's settings.
            range_step_per_m2: 0.0,
            ..SegmentConfig::default()
        }
    }

    #[test]
    fn each_pixel_of_the_cube_takes_its_strided_neighbours_label() {
        let (points, width, height) = table_with_cube();
        let organised = segment_organised(&points, width, height, 2, &looking_down(), &[]);
        assert_eq!(organised.strided.objects.len(), 1);
        assert_eq!(organised.strided.labels.len(), 60 * 45);
        // The cube's pixels, except an edge row and column whose strided neighbour (the
        // top-left pixel of their 2 × 2 block) is on the table: those are left out.
        let cube: Vec<u32> = (0..points.len() as u32)
            .filter(|&i| points[i as usize].z > -0.95)
            .filter(|&i| {
                let (u, v) = (i % width, i / width);
                points[((v & !1) * width + (u & !1)) as usize].z > -0.95
            })
            .collect();
        assert_eq!(organised.objects, vec![cube]);
    }

    #[test]
    fn stride_one_is_the_plain_segmentation() {
        let (points, width, height) = table_with_cube();
        let config = looking_down();
        let organised = segment_organised(&points, width, height, 1, &config, &[]);
        let plain = crate::segment(&points, &config);
        assert_eq!(organised.strided, plain);
        assert_eq!(organised.objects, plain.objects);
    }

    #[test]
    fn an_empty_image_is_no_objects() {
        let (points, _, _) = table_with_cube();
        for (width, height) in [(0, 90), (120, 0), (0, 0)] {
            let organised = segment_organised(&points, width, height, 2, &looking_down(), &[]);
            assert!(organised.objects.is_empty(), "{width}×{height}");
        }
    }

    #[test]
    fn a_short_cloud_is_segmented_on_the_rows_it_has() {
        let (mut points, width, height) = table_with_cube();
        points.truncate(points.len() / 2 + 7);
        let organised = segment_organised(&points, width, height, 2, &looking_down(), &[]);
        assert!(organised
            .objects
            .iter()
            .flatten()
            .all(|&i| (i as usize) < points.len()));
    }

    #[test]
    fn an_object_below_a_raised_support_keeps_its_points() {
        // A floor 1.5 m below the camera, a 0.6 m square table top 0.6 m above the floor on
        // the left, and a 12 cm box on the floor on the right: the box is below the table's
        // plane, beside the table, not on it.
        let (width, height) = (240u32, 160u32);
        let mut points = Vec::new();
        for v in 0..height {
            for u in 0..width {
                let (x, y) = ((u as f32 - 120.0) * 0.006, (v as f32 - 80.0) * 0.006);
                let noise = ((u * 7 + v * 13) % 5) as f32 * 0.0005 - 0.001;
                let z = if (-0.7..-0.1).contains(&x) && (-0.3..0.3).contains(&y) {
                    -0.9
                } else if (0.3..0.42).contains(&x) && (-0.06..0.06).contains(&y) {
                    -1.38
                } else {
                    -1.5
                };
                points.push(Vec3::new(x, y, z + noise));
            }
        }
        let config = SegmentConfig {
            range_step_per_m2: 0.0,
            ..looking_down()
        };
        let organised = segment_organised(&points, width, height, 2, &config, &[]);
        assert_eq!(organised.strided.planes.len(), 2, "the floor and the table");
        assert_eq!(organised.objects.len(), 1);
        let on_box = organised.objects[0]
            .iter()
            .filter(|&&i| (points[i as usize].z + 1.38).abs() < 0.01)
            .count();
        assert!(on_box > 300, "{on_box} of the box's ~400 pixels");
    }
}
