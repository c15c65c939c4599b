//! How noisy and how dense a cloud is: the spread of its points across the surface, and how
//! many points cover a square metre of it, from the same plane fits the reconstruction makes.
//!
//! In a box of the surface a few noise widths across, the points' covariance has two large
//! eigenvalues (the surface's extent in the box) and a small one along the normal: the noise's
//! variance plus what the surface's curvature adds. The median over boxes of the square root
//! of that smallest eigenvalue estimates the noise's standard deviation: curved boxes and
//! boxes across edges spread more, but they are the minority on any object larger than a few
//! boxes, and the median ignores them.
//!
//! The density is the median number of points in such a box divided by the area of the surface
//! inside it (a plane through the middle of a cube of side `L` cuts between `L²` and `1.3 L²`;
//! 1.2 `L²` is taken). Unlike the distance between nearest neighbours it does not depend on
//! the noise: noise spreads the points into a slab and pushes neighbours apart, so the same
//! points per area look twice as sparse at 20 mm noise as with none.
//!
//! Entry points: [`estimate_noise_m`], [`estimate_points_per_m2`], and both at once (sharing
//! their boxes where they can) [`estimate_noise_and_density`].

use glam::Vec3;

use crate::cell_index::CellIndex;
use crate::moment_grid::sorted_voxel_moments;

/// At most this many points go into the estimate (an even subsample of the cloud): the median
/// of a few hundred boxes is as good as that of thousands, and the estimate stays cheap.
const MAX_POINTS: usize = 8_000;

/// At most this many boxes are fitted per set of cells: centred on every `k`-th occupied cell
/// in the cells' sorted order, `k` the smallest that keeps them within it. A median of a
/// thousand spreads is as good as one of thousands, and the boxes' plane fits were most of the
/// estimate (the 1 m cube at 40,000 points has 4,860 cells).
const MAX_BOXES: usize = 1_000;

/// Boxes with fewer points than this are not used.
const MIN_POINTS_PER_BOX: f64 = 10.0;

/// Fewer usable boxes than this: no estimate.
const MIN_BOXES: usize = 8;

/// The standard deviation of the points' spread across the surface, metres, estimated over
/// boxes three cells wide centred on the surface, cells at least `cell_m` wide: a box narrower
/// than the noise clips it, so when the spread found is more than a third of the box the
/// estimate is made again with cells twice the spread. `None` when too few boxes hold enough
/// points.
pub fn estimate_noise_m(points: &[Vec3], cell_m: f32) -> Option<f32> {
    estimate_noise_and_density(points, cell_m).noise_m
}

/// Points per square metre of surface, estimated over boxes three `cell_m` cells wide centred on
/// the surface (`cell_m` at least twice the noise, so that a box holds the noise's spread).
/// `None` when too few boxes hold a plane.
pub fn estimate_points_per_m2(points: &[Vec3], cell_m: f32) -> Option<f32> {
    if !(cell_m.is_finite() && cell_m > 0.0) {
        return None;
    }
    let (sample, finite) = finite_sample(points);
    density_of(
        &centred_boxes(&sample, cell_m),
        cell_m,
        finite,
        sample.len(),
    )
}

/// A cloud's noise and density, each `None` when it could not be told.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseAndDensity {
    /// As [`estimate_noise_m`] finds it from cells of at least `cell_m`.
    pub noise_m: Option<f32>,
    /// As [`estimate_points_per_m2`] finds it from cells of `cell_m` or twice the noise,
    /// whichever is larger.
    pub points_per_m2: Option<f32>,
}

/// [`estimate_noise_m`] from cells of at least `cell_m`, and [`estimate_points_per_m2`] from
/// cells of `cell_m` or twice the noise found (0 when none), whichever is larger, as the
/// pipeline sizes its voxel from them: when the density's cells are ones the noise was already
/// measured on (a cloud whose noise is under half the cell), their boxes are read once.
pub fn estimate_noise_and_density(points: &[Vec3], cell_m: f32) -> NoiseAndDensity {
    if !(cell_m.is_finite() && cell_m > 0.0) {
        return NoiseAndDensity {
            noise_m: None,
            points_per_m2: None,
        };
    }
    let (sample, finite) = finite_sample(points);
    let first_boxes = centred_boxes(&sample, cell_m);
    let mut last = (cell_m, None);
    let noise_m = (|| {
        let mut cell_m = cell_m;
        let mut estimate = median_spread_m(&first_boxes)?;
        for _ in 0..2 {
            if estimate <= cell_m / 2.0 {
                break;
            }
            cell_m = 2.0 * estimate;
            let boxes = centred_boxes(&sample, cell_m);
            estimate = median_spread_m(&boxes)?;
            last = (cell_m, Some(boxes));
        }
        Some(estimate)
    })();
    let density_cell_m = cell_m.max(2.0 * noise_m.unwrap_or(0.0));
    let points_per_m2 = match last {
        _ if density_cell_m == cell_m => {
            density_of(&first_boxes, density_cell_m, finite, sample.len())
        }
        (last_cell_m, Some(boxes)) if last_cell_m == density_cell_m => {
            density_of(&boxes, density_cell_m, finite, sample.len())
        }
        _ => density_of(
            &centred_boxes(&sample, density_cell_m),
            density_cell_m,
            finite,
            sample.len(),
        ),
    };
    NoiseAndDensity {
        noise_m,
        points_per_m2,
    }
}

/// Points per square metre from the boxes of `cell_m` cells of a sample of `sampled` of the
/// cloud's `finite` points.
fn density_of(boxes: &[CentredBox], cell_m: f32, finite: usize, sampled: usize) -> Option<f32> {
    let counts = boxes.iter().map(|b| b.points).collect();
    let median = median_of_boxes(counts)?;
    let box_side_m = 3.0 * f64::from(cell_m);
    let per_sample_point = finite as f64 / sampled as f64;
    Some((median * per_sample_point / (CROSS_SECTION * box_side_m * box_side_m)) as f32)
}

/// The surface inside a box of side `L` centred on it, in `L²`: between 1 (parallel to a face)
/// and 1.3 (the hexagon across the diagonal).
const CROSS_SECTION: f64 = 1.2;

/// A plane needs three points.
const MIN_POINTS_FOR_A_PLANE: f64 = 3.0;

/// At most [`MAX_POINTS`] of the finite points, evenly through the cloud, and how many finite
/// points there are.
fn finite_sample(points: &[Vec3]) -> (Vec<Vec3>, usize) {
    let finite = points.iter().filter(|p| p.is_finite()).count();
    let stride = finite.div_ceil(MAX_POINTS).max(1);
    let sample = points
        .iter()
        .copied()
        .filter(|p| p.is_finite())
        .step_by(stride)
        .collect();
    (sample, finite)
}

/// The median of a figure over boxes; `None` with fewer than [`MIN_BOXES`] boxes.
fn median_of_boxes(mut values: Vec<f64>) -> Option<f64> {
    if values.len() < MIN_BOXES {
        return None;
    }
    let middle = values.len() / 2;
    Some(*values.select_nth_unstable_by(middle, f64::total_cmp).1)
}

/// A box of 3 × 3 × 3 cells centred on the surface: how many points it holds, and their
/// standard deviation along the normal of their plane.
struct CentredBox {
    points: f64,
    spread_m: f64,
}

/// The boxes of 3 × 3 × 3 `cell_m` cells, with enough points for a plane, whose points' plane
/// crosses the middle cell. The points are binned by sorting (no hash map), and as the coarse
/// plane fits do (`cell_planes`) the 27 cells of each box are read through a [`CellIndex`]
/// over the list of cells. The estimate runs before meshing starts, once or up to four times.
/// A box centred on every cell took 2 ms a run for the 1 m cube's 4,860 cells on one core, most
/// of it in the plane fits; fitting them in parallel did not shorten it on two cores. Boxes on
/// every `k`-th cell, at most [`MAX_BOXES`], take about 0.7 ms.
fn centred_boxes(points: &[Vec3], cell_m: f32) -> Vec<CentredBox> {
    let (cells, moments) = sorted_voxel_moments(points, cell_m);
    let index = CellIndex::new(&cells);
    let stride = cells.len().div_ceil(MAX_BOXES).max(1);
    cells
        .iter()
        .step_by(stride)
        .filter_map(|&cell| {
            let around = index.moments_around(&moments, cell);
            if around.count < MIN_POINTS_FOR_A_PLANE {
                return None;
            }
            let plane = around.plane()?;
            // A box beside the surface holds only one tail of the noise (and a sliver of the
            // surface): only boxes centred on it measure the whole.
            let centre = (cell.as_vec3() + 0.5) * cell_m;
            if plane.normal.dot(centre - plane.point).abs() > cell_m / 2.0 {
                return None;
            }
            let normal = plane.normal.as_dvec3();
            Some(CentredBox {
                points: around.count,
                spread_m: normal.dot(around.covariance() * normal).max(0.0).sqrt(),
            })
        })
        .collect()
}

/// The median, over the boxes with at least [`MIN_POINTS_PER_BOX`] points, of the points'
/// standard deviation along their plane's normal.
fn median_spread_m(boxes: &[CentredBox]) -> Option<f32> {
    let spreads = boxes
        .iter()
        .filter(|b| b.points >= MIN_POINTS_PER_BOX)
        .map(|b| b.spread_m)
        .collect();
    median_of_boxes(spreads).map(|spread| spread as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::{Distribution, Normal};

    /// A 1 m square with Gaussian noise of `sigma_m` across it.
    fn noisy_square(sigma_m: f32, points: usize) -> Vec<Vec3> {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let noise = Normal::new(0.0, sigma_m.max(1e-9)).unwrap();
        (0..points)
            .map(|_| {
                Vec3::new(
                    rng.random::<f32>(),
                    rng.random::<f32>(),
                    if sigma_m > 0.0 {
                        noise.sample(&mut rng)
                    } else {
                        0.0
                    },
                )
            })
            .collect()
    }

    #[test]
    fn the_noise_of_a_flat_cloud_is_found() {
        for sigma in [0.0, 0.01, 0.02, 0.04] {
            let estimate = estimate_noise_m(&noisy_square(sigma, 40_000), 0.06).unwrap();
            assert!(
                (estimate - sigma).abs() <= 0.15 * sigma + 1e-4,
                "σ {sigma}: estimated {estimate}"
            );
        }
    }

    /// 40,000 points on 1 m²: the density is found within the cross-section's uncertainty,
    /// whatever the noise.
    #[test]
    fn the_density_of_a_flat_cloud_is_found_whatever_its_noise() {
        for sigma in [0.0, 0.02, 0.04] {
            let density =
                estimate_points_per_m2(&noisy_square(sigma, 40_000), 0.04_f32.max(2.0 * sigma))
                    .unwrap();
            assert!(
                (density / 40_000.0 - 1.0).abs() < 0.25,
                "σ {sigma}: {density} points per m²"
            );
        }
    }

    #[test]
    fn too_few_points_give_no_estimate() {
        assert_eq!(estimate_noise_m(&noisy_square(0.02, 20), 0.06), None);
        assert_eq!(estimate_noise_m(&noisy_square(0.02, 1000), 0.0), None);
    }
}
