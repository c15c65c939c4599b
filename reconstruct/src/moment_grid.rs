//! The fused state of an object: point moments per voxel, in a sparse hash map.
//!
//! Integrating a frame adds each new point to its voxel's moments, so the cost follows the new
//! data, not the object's history, and the state stays bounded by the object's surface area.
//! Voxel `ijk` covers `[ijk, ijk + 1) · voxel_size_m` in the object's frame (origin at 0, so two
//! grids of the same size line up).

use glam::{IVec3, Vec3};
use rustc_hash::FxHashMap;

use crate::cell_index::{floor_div, CellBox, CellIndex};
use crate::moments::PointMoments;

/// Sparse voxel grid of point moments.
#[derive(Debug, Clone)]
pub struct MomentGrid {
    voxel_size_m: f32,
    cells: FxHashMap<IVec3, PointMoments>,
}

impl MomentGrid {
    pub fn new(voxel_size_m: f32) -> Self {
        Self {
            voxel_size_m,
            cells: FxHashMap::default(),
        }
    }

    pub fn voxel_size_m(&self) -> f32 {
        self.voxel_size_m
    }

    /// The voxel holding `p`.
    pub fn cell_of(&self, p: Vec3) -> IVec3 {
        tacmesh_source::floor_ivec3(p / self.voxel_size_m)
    }

    /// Adds finite points to their voxels; returns how many were added.
    pub fn integrate(&mut self, points: &[Vec3]) -> usize {
        // Sized from the surface, not the point count: the voxels follow the surface's area,
        // not the points, and a map sized for a quarter of the points made every look-up a
        // cache miss (96 MB of buckets at 2.56 million points) and integration superlinear.
        // Grown from empty instead, it rehashed through every power of two into fresh pages.
        self.cells
            .reserve(surface_voxels_estimate(points, self.voxel_size_m));
        let mut added = 0;
        for &p in points.iter().filter(|p| p.is_finite()) {
            self.cells.entry(self.cell_of(p)).or_default().add_point(p);
            added += 1;
        }
        added
    }

    /// Adds one point to its voxel and returns the voxel with its moments after the addition,
    /// or `None` (and no change) for a non-finite point. For callers that follow per-voxel change
    /// as they fuse (the tracker's dirty marking) without a second look-up.
    pub fn add_point(&mut self, p: Vec3) -> Option<(IVec3, &PointMoments)> {
        if !p.is_finite() {
            return None;
        }
        let cell = self.cell_of(p);
        let moments = self.cells.entry(cell).or_default();
        moments.add_point(p);
        Some((cell, moments))
    }

    /// As [`Self::add_point`], into a voxel that keeps at most `cap` points: a full voxel
    /// first has its moments scaled down to `cap − 1` points (which keeps their plane), in the
    /// same look-up. Also returns the share forgotten (zero when the voxel was not full), for
    /// a coarser grid of the same points to [`Self::subtract`].
    pub fn add_point_capped(
        &mut self,
        p: Vec3,
        cap: f64,
    ) -> Option<(IVec3, &PointMoments, PointMoments)> {
        if !p.is_finite() {
            return None;
        }
        let cell = self.cell_of(p);
        let moments = self.cells.entry(cell).or_default();
        let mut forgotten = PointMoments::default();
        if moments.count > cap - 1.0 {
            forgotten = moments.scaled(1.0 - (cap - 1.0) / moments.count);
            *moments -= &forgotten;
        }
        moments.add_point(p);
        Some((cell, moments, forgotten))
    }

    /// Takes `part` (moments that were added to `cell` before: a share of its points) out of
    /// `cell`, and empties the voxel when what is left weighs less than `min_count` points.
    /// Returns whether the voxel is gone. For forgetting (see `tacmesh_track`), where the
    /// share is a scaled copy of the voxel's own moments or of a finer voxel's inside it.
    pub fn subtract(&mut self, cell: IVec3, part: &PointMoments, min_count: f64) -> bool {
        let Some(moments) = self.cells.get_mut(&cell) else {
            return true;
        };
        *moments -= part;
        if moments.count < min_count {
            self.cells.remove(&cell);
            return true;
        }
        false
    }

    /// Occupied voxels with their moments, in hash order (use [`Self::sorted_cells`] where the
    /// order matters).
    pub fn iter(&self) -> impl Iterator<Item = (IVec3, &PointMoments)> + '_ {
        self.cells.iter().map(|(&cell, m)| (cell, m))
    }

    /// The means of the voxels the surface runs through (those holding at least a quarter of
    /// the median voxel's samples), evenly thinned to at most `max_points` in (z, y, x) order
    /// of their cells, and how rough they are: the 95th percentile of each mean's distance
    /// from the plane through its 3 × 3 × 3 neighbourhood. Where the sensor's noise is as wide
    /// as a voxel the means keep most of it (each voxel holds its own slice of the noise
    /// across the surface); the roughness says how much, so a fit to them can be judged
    /// against it.
    pub fn surface_means(&self, max_points: usize) -> SurfaceMeans {
        let mut counts: Vec<f64> = self.cells.values().map(|m| m.count).collect();
        if counts.is_empty() || max_points == 0 {
            return SurfaceMeans::default();
        }
        let middle = counts.len() / 2;
        let (_, median, _) = counts.select_nth_unstable_by(middle, f64::total_cmp);
        let least = (0.25 * *median).max(2.0);
        let mut surface: Vec<(IVec3, &PointMoments)> = self
            .cells
            .iter()
            .filter(|(_, m)| m.count >= least)
            .map(|(&cell, m)| (cell, m))
            .collect();
        sort_zyx(&mut surface, |&(cell, _)| cell);
        let step = surface.len().div_ceil(max_points).max(1);
        let mut points = Vec::new();
        let mut off_plane = Vec::new();
        for &(cell, m) in surface.iter().step_by(step) {
            let Some(mean) = m.centroid() else {
                continue;
            };
            points.push(mean);
            if let Some(plane) = self.neighbourhood(cell, 1).plane() {
                off_plane.push((mean - plane.point).dot(plane.normal).abs());
            }
        }
        let roughness_m = if off_plane.is_empty() {
            0.0
        } else {
            let k = (off_plane.len() * 95 / 100).min(off_plane.len() - 1);
            *off_plane.select_nth_unstable_by(k, f32::total_cmp).1
        };
        SurfaceMeans {
            points,
            roughness_m,
        }
    }

    pub fn get(&self, cell: IVec3) -> Option<&PointMoments> {
        self.cells.get(&cell)
    }

    /// Occupied voxels in a fixed order (z, y, x), so results never depend on hash order.
    pub fn sorted_cells(&self) -> Vec<IVec3> {
        let mut keys: Vec<IVec3> = self.cells.keys().copied().collect();
        sort_zyx(&mut keys, |&cell| cell);
        keys
    }

    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The occupied voxels in (z, y, x) order, each with its moments (borrowed, not copied).
    pub fn sorted_voxels(&self) -> Vec<(IVec3, &PointMoments)> {
        let mut voxels: Vec<(IVec3, &PointMoments)> =
            self.cells.iter().map(|(&cell, m)| (cell, m)).collect();
        sort_zyx(&mut voxels, |&(cell, _)| cell);
        voxels
    }

    /// Whether any voxel within `radius` voxels (a cube) of `cell` holds points: the
    /// occupancy question without summing moments, stopping at the first voxel found.
    pub fn any_near(&self, cell: IVec3, radius: i32) -> bool {
        (-radius..=radius).any(|dz| {
            (-radius..=radius).any(|dy| {
                (-radius..=radius)
                    .any(|dx| self.cells.contains_key(&(cell + IVec3::new(dx, dy, dz))))
            })
        })
    }

    /// Sum of the moments of the voxels within `radius` voxels (a cube) of `cell`.
    pub fn neighbourhood(&self, cell: IVec3, radius: i32) -> PointMoments {
        let mut sum = PointMoments::default();
        for dz in -radius..=radius {
            for dy in -radius..=radius {
                for dx in -radius..=radius {
                    if let Some(m) = self.cells.get(&(cell + IVec3::new(dx, dy, dz))) {
                        sum += m;
                    }
                }
            }
        }
        sum
    }
}

/// What [`MomentGrid::surface_means`] gives: the surface voxels' means and their roughness.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SurfaceMeans {
    pub points: Vec<Vec3>,
    /// The 95th percentile of the means' distances from their neighbourhoods' planes, metres.
    pub roughness_m: f32,
}

/// Voxels with their moments in (z, y, x) order of their cells: a grid that is read in order
/// and by position (the plane fits' dense index, the fit's samples), never looked up by key,
/// so it needs no map.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SortedVoxels {
    pub voxel_size_m: f32,
    pub cells: Vec<IVec3>,
    /// `moments[i]` are those of `cells[i]`.
    pub moments: Vec<PointMoments>,
}

impl SortedVoxels {
    /// The points of `voxels` (distinct cells of edge `voxel_size_m`, in (z, y, x) order, as
    /// [`MomentGrid::sorted_voxels`] gives them) in voxels `factor` times larger. Each coarse
    /// voxel adds its voxels in their (z, y, x) order, so the sums never depend on hash order.
    ///
    /// The voxels are put in order of their coarse voxel by a stable sort, which keeps each
    /// coarse voxel's own in (z, y, x) order, and each run is summed where it lies: adding
    /// every voxel into a map by its coarse key took a hash look-up per fine voxel (a 1 m
    /// cube's 22,300 at 20 mm noise: 4 % of the one-core pipeline), and the callers then sorted
    /// the map's keys again and looked each one up.
    pub fn coarsened(voxels: &[(IVec3, &PointMoments)], factor: i32, voxel_size_m: f32) -> Self {
        let factor = factor.max(1);
        let mut by_parent: Vec<(IVec3, &PointMoments)> = voxels
            .iter()
            .map(|&(cell, m)| (floor_div(cell, factor), m))
            .collect();
        sort_zyx(&mut by_parent, |&(parent, _)| parent);
        let mut coarse = SortedVoxels {
            voxel_size_m: voxel_size_m * factor as f32,
            cells: Vec::with_capacity(voxels.len() / (factor * factor) as usize),
            moments: Vec::with_capacity(voxels.len() / (factor * factor) as usize),
        };
        for (cell, m) in by_parent {
            if coarse.cells.last() != Some(&cell) {
                coarse.cells.push(cell);
                coarse.moments.push(PointMoments::default());
            }
            if let Some(sum) = coarse.moments.last_mut() {
                *sum += m;
            }
        }
        coarse
    }

    /// For each voxel, whether it holds fewer points than `fraction` of the mean count of the
    /// occupied voxels of its 3 × 3 × 3 neighbourhood (itself included). Under noise as wide
    /// as a voxel or wider, such a voxel lies beside the surface and holds only a tail of the
    /// noise: its centroid is a standard deviation or more off the surface, to the outside
    /// where the surface turns away (a convex edge or rim). With little noise a thin voxel is
    /// one that clips the surface (an edge, a corner, the end of a thin part), and its centroid
    /// is as good as any: only a caller that knows the noise dominates should drop them.
    pub fn thin_voxels(&self, fraction: f64) -> Vec<bool> {
        let index = CellIndex::new(&self.cells);
        self.cells
            .iter()
            .zip(&self.moments)
            .map(|(&cell, own)| {
                let (mut count, mut occupied) = (0.0f64, 0u32);
                index.for_each_in_box::<3>(cell - IVec3::ONE, |i| {
                    count += self.moments[i as usize].count;
                    occupied += 1;
                });
                // `occupied` counts the voxel itself, so it is at least 1.
                own.count < fraction * count / f64::from(occupied.max(1))
            })
            .collect()
    }
}

/// The voxels of edge `voxel_size_m` that the finite `points` fall in, in (z, y, x) order, and
/// their moments: what [`MomentGrid::integrate`] then [`MomentGrid::sorted_cells`] give, to the
/// bit (each voxel's points are added in the order given), without a hash map: for points
/// binned once and then read in order, such as the noise estimate's sample, there is no map
/// to build only to list its keys. (Integrating a whole cloud this way was slower than the
/// sized map: 1.5-2 times at 40,000 points.)
pub fn sorted_voxel_moments(points: &[Vec3], voxel_size_m: f32) -> (Vec<IVec3>, Vec<PointMoments>) {
    let grid = MomentGrid::new(voxel_size_m);
    let mut keyed: Vec<(IVec3, Vec3)> = points
        .iter()
        .filter(|p| p.is_finite())
        .map(|&p| (grid.cell_of(p), p))
        .collect();
    sort_zyx(&mut keyed, |&(cell, _)| cell);
    let mut cells: Vec<IVec3> = Vec::new();
    let mut moments: Vec<PointMoments> = Vec::new();
    for (cell, p) in keyed {
        if cells.last() != Some(&cell) {
            cells.push(cell);
            moments.push(PointMoments::default());
        }
        if let Some(m) = moments.last_mut() {
            m.add_point(p);
        }
    }
    (cells, moments)
}

/// How many voxels of edge `voxel_size_m` a surface sampled by `points` is likely to fill, to
/// size the map once instead of growing it through every power of two (each growth moves every
/// entry into freshly faulted pages: a third of integrating 40,000 points): 1.5 times the
/// area of the points' bounding box in voxel faces, never more than the points. On the six
/// test shapes at 20 mm noise the voxels filled are 0.56-1.63 times that area (Suzanne and the
/// torus least, the cube most), so the map ends at the size it would have grown to. A far
/// outlier inflates the box, so the estimate stops at [`MAX_RESERVED_VOXELS`]: past it, the
/// map grows as before.
fn surface_voxels_estimate(points: &[Vec3], voxel_size_m: f32) -> usize {
    // An estimate needs no exact box: evenly spaced points (at most `BOX_SAMPLES`) keep this
    // a small fraction of integrating millions.
    const BOX_SAMPLES: usize = 32_768;
    let stride = points.len().div_ceil(BOX_SAMPLES).max(1);
    let mut finite = points.iter().step_by(stride).filter(|p| p.is_finite());
    let Some(&first) = finite.next() else {
        return 0;
    };
    let (lo, hi) = finite.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    let size = (hi - lo) / voxel_size_m + Vec3::ONE;
    let area = 2.0 * (size.x * size.y + size.y * size.z + size.z * size.x);
    let estimate = 1.5 * area as f64;
    if estimate.is_finite() {
        (estimate as usize)
            .min(points.len())
            .min(MAX_RESERVED_VOXELS)
    } else {
        0
    }
}

/// The most voxels [`MomentGrid::integrate`] sizes its map for up front (about 6 MB).
const MAX_RESERVED_VOXELS: usize = 1 << 16;

/// Sorts `items` by their voxel's (z, y, x), keeping the order of items in the same voxel.
///
/// An object's voxels fill a compact box (see [`CellBox`]), and a counting sort over the box
/// orders them in two passes over the items and one over the box: a 1 m cube's 22,700 voxels
/// at 20 mm noise took 0.9-1.2 ms by comparison, of a 7 ms normals stage that sorts them twice.
/// Written here rather than taken from a radix-sort crate because the key is a box position
/// the caller's voxels already give. Voxels spread far apart (a scene with distant outliers)
/// are sorted by comparison: one packed 64-bit key when each index fits in 21 bits (a
/// kilometre in millimetre voxels), about twice as fast as comparing three, else three.
fn sort_zyx<T: Copy>(items: &mut [T], cell: impl Fn(&T) -> IVec3) {
    /// The counting sort's box may have at most this many cells per item (4 bytes each).
    const MAX_BOX_CELLS_PER_ITEM: i64 = 32;
    let compact =
        CellBox::compact_around(items.iter().map(&cell), items.len(), MAX_BOX_CELLS_PER_ITEM);
    if let Some(cell_box) = compact {
        let slot = |item: &T| cell_box.slot_inside(cell(item));
        // starts[s + 1] counts the items in box cell s, then starts[s] is where its first goes.
        let mut starts = vec![0u32; cell_box.len() + 1];
        for item in items.iter() {
            starts[slot(item) + 1] += 1;
        }
        for s in 1..starts.len() {
            starts[s] += starts[s - 1];
        }
        let mut sorted = vec![items[0]; items.len()];
        for item in items.iter() {
            let next = &mut starts[slot(item)];
            sorted[*next as usize] = *item;
            *next += 1;
        }
        items.copy_from_slice(&sorted);
        return;
    }
    const BIAS: i32 = 1 << 20;
    let fits = |c: IVec3| c.cmpge(IVec3::splat(-BIAS)).all() && c.cmplt(IVec3::splat(BIAS)).all();
    if items.iter().all(|item| fits(cell(item))) {
        let packed = |c: IVec3| {
            let biased = (c + IVec3::splat(BIAS)).as_uvec3();
            (u64::from(biased.z) << 42) | (u64::from(biased.y) << 21) | u64::from(biased.x)
        };
        items.sort_by_key(|item| packed(cell(item)));
    } else {
        items.sort_by_key(|item| {
            let c = cell(item);
            (c.z, c.y, c.x)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sorted_voxel_moments_are_the_grids_to_the_bit() {
        // Points in a few voxels on both sides of zero, in no order, repeats and non-finite
        // ones among them.
        let mut points = Vec::new();
        let mut state = 7u32;
        for i in 0..3_000 {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let u = |shift: u32| ((state >> shift) & 1023) as f32 / 1023.0 - 0.5;
            points.push(Vec3::new(u(0), u(10), u(20)) * 0.37);
            if i % 500 == 0 {
                points.push(Vec3::NAN);
                points.push(points[i / 2]);
            }
        }
        let mut grid = MomentGrid::new(0.05);
        grid.integrate(&points);
        let (cells, moments) = sorted_voxel_moments(&points, 0.05);
        assert_eq!(cells, grid.sorted_cells());
        for (cell, m) in cells.iter().zip(&moments) {
            assert_eq!(Some(m), grid.get(*cell), "{cell}");
        }
        assert_eq!(sorted_voxel_moments(&[Vec3::NAN], 0.05), (vec![], vec![]));
    }

    #[test]
    fn the_map_is_sized_near_the_voxels_a_surface_fills() {
        // A sphere of radius 0.5 m sampled on a golden-angle spiral, 20 mm voxels.
        let spiral = |n: usize| -> Vec<Vec3> {
            (0..n)
                .map(|i| {
                    let z = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
                    let r = (1.0 - z * z).sqrt();
                    let phi = i as f32 * 2.399_963;
                    0.5 * Vec3::new(r * phi.cos(), r * phi.sin(), z)
                })
                .collect()
        };
        let sphere = spiral(40_000);
        let mut grid = MomentGrid::new(0.02);
        grid.integrate(&sphere);
        let estimate = surface_voxels_estimate(&sphere, 0.02);
        let filled = grid.len();
        // Without noise a sphere fills the fewest voxels for its box (9,859 here, 2.4 times
        // fewer than the estimate); sized for the points (40,000) the map would be 4 times
        // too large.
        assert!(
            (filled / 2..filled * 5 / 2).contains(&estimate),
            "estimate {estimate} for {filled} voxels"
        );
        // Never more than the points, nothing from no finite point, and a far outlier does
        // not size the map for a box a hundred metres wide.
        let sparse: Vec<Vec3> = sphere.iter().copied().step_by(400).collect();
        assert_eq!(surface_voxels_estimate(&sparse, 0.02), 100);
        assert_eq!(surface_voxels_estimate(&[Vec3::NAN; 10], 0.02), 0);
        assert_eq!(surface_voxels_estimate(&[], 0.02), 0);
        let mut with_outlier = spiral(100_000);
        with_outlier[0] = Vec3::splat(100.0);
        assert_eq!(
            surface_voxels_estimate(&with_outlier, 0.02),
            MAX_RESERVED_VOXELS
        );
    }

    #[test]
    fn integrate_skips_non_finite_points() {
        let mut grid = MomentGrid::new(0.1);
        let added = grid.integrate(&[Vec3::ZERO, Vec3::NAN, Vec3::new(0.05, 0.0, 0.0)]);
        assert_eq!(added, 2);
        assert_eq!(grid.len(), 1);
        assert_eq!(grid.get(IVec3::ZERO).map(|m| m.count), Some(2.0));
    }

    #[test]
    fn negative_coordinates_land_in_negative_cells() {
        let grid = MomentGrid::new(0.1);
        assert_eq!(
            grid.cell_of(Vec3::new(-0.01, 0.15, -0.2)),
            IVec3::new(-1, 1, -2)
        );
    }

    #[test]
    fn subtracting_a_share_keeps_the_plane_and_empties_a_light_voxel() {
        let mut grid = MomentGrid::new(1.0);
        grid.integrate(&[
            Vec3::new(0.1, 0.1, 0.5),
            Vec3::new(0.9, 0.2, 0.5),
            Vec3::new(0.5, 0.8, 0.5),
            Vec3::new(0.4, 0.4, 0.5),
        ]);
        let whole = *grid.get(IVec3::ZERO).unwrap();
        assert!(!grid.subtract(IVec3::ZERO, &whole.scaled(0.75), 0.5));
        let left = grid.get(IVec3::ZERO).unwrap();
        assert!((left.count - 1.0).abs() < 1e-12);
        assert!(left.centroid().unwrap().distance(whole.centroid().unwrap()) < 1e-6);
        assert!(left.plane().is_none(), "one point's weight fits no plane");
        let left = *left;
        assert!(grid.subtract(IVec3::ZERO, &left.scaled(0.6), 0.5));
        assert!(grid.is_empty());
    }

    #[test]
    fn a_capped_voxel_averages_its_newest_points() {
        let mut grid = MomentGrid::new(1.0);
        for _ in 0..10 {
            let (_, _, forgotten) = grid.add_point_capped(Vec3::splat(0.25), 4.0).unwrap();
            assert!(forgotten.count <= 1.0 + 1e-12);
        }
        let (_, m, forgotten) = grid.add_point_capped(Vec3::splat(0.75), 4.0).unwrap();
        assert!((m.count - 4.0).abs() < 1e-12, "{}", m.count);
        assert!((forgotten.count - 1.0).abs() < 1e-12);
        // Three points' worth at 0.25 and the newest at 0.75.
        let centroid = m.centroid().unwrap();
        assert!(centroid.distance(Vec3::splat(0.375)) < 1e-6, "{centroid}");
        assert!(grid.add_point_capped(Vec3::NAN, 4.0).is_none());
    }

    /// Compact lists (counting sort), lists spread past the box limit (packed keys) and past
    /// 21 bits (three keys) all come out in (z, y, x) order, items of one voxel in the order
    /// they came.
    #[test]
    fn voxels_sort_by_z_then_y_then_x_near_and_far() {
        let near = [
            IVec3::new(3, -1, 0),
            IVec3::new(-2, 5, 0),
            IVec3::new(0, 0, -1),
            IVec3::new(-2, -1, 0),
        ];
        // 3,000 voxels in a 30-voxel box around the origin, many of them twice.
        let mut state = 0x2545_f491_u32;
        let mut next = |range: i32| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            (state % range as u32) as i32 - range / 2
        };
        let compact: Vec<IVec3> = (0..3000)
            .map(|_| IVec3::new(next(30), next(30), next(30)))
            .collect();
        let spread = near.map(|c| c * 5000);
        let far = near.map(|c| c + IVec3::new(0, 0, 1 << 22));
        for cells in [
            near.to_vec(),
            compact,
            [near.as_slice(), &spread].concat(),
            [near.as_slice(), &far].concat(),
        ] {
            // Each item is its voxel and where it came in the list.
            let mut items: Vec<(IVec3, usize)> = cells.iter().copied().zip(0..).collect();
            sort_zyx(&mut items, |&(c, _)| c);
            let mut expected: Vec<(IVec3, usize)> = cells.iter().copied().zip(0..).collect();
            expected.sort_by_key(|&(c, i)| (c.z, c.y, c.x, i));
            assert_eq!(items, expected);
        }
    }

    #[test]
    fn coarsening_keeps_every_point() {
        let count_at = |coarse: &SortedVoxels, cell: IVec3| {
            let at = coarse.cells.iter().position(|&c| c == cell)?;
            Some(coarse.moments[at].count)
        };
        let mut grid = MomentGrid::new(0.1);
        grid.integrate(&[Vec3::splat(0.05), Vec3::splat(0.15), Vec3::splat(-0.05)]);
        let coarse = SortedVoxels::coarsened(&grid.sorted_voxels(), 2, grid.voxel_size_m());
        assert_eq!(count_at(&coarse, IVec3::ZERO), Some(2.0));
        assert_eq!(count_at(&coarse, IVec3::splat(-1)), Some(1.0));
        // A factor that is not a power of two: voxels -3..=2 of 0.1 m by threes.
        let mut grid = MomentGrid::new(0.1);
        let points: Vec<Vec3> = (-3..=2)
            .map(|i| Vec3::new(i as f32 * 0.1 + 0.05, 0.05, 0.05))
            .collect();
        grid.integrate(&points);
        let coarse = SortedVoxels::coarsened(&grid.sorted_voxels(), 3, grid.voxel_size_m());
        assert_eq!(coarse.cells.len(), 2);
        assert_eq!(count_at(&coarse, IVec3::new(-1, 0, 0)), Some(3.0));
        assert_eq!(count_at(&coarse, IVec3::ZERO), Some(3.0));
    }

    /// The sorted coarsening lists every coarse voxel once, in (z, y, x) order, with the sum of
    /// its voxels added in their (z, y, x) order, as adding them into a map one by one does:
    /// the same moments to the bit, for factors that are powers of two and one that is not.
    #[test]
    fn sorted_coarsening_sums_each_coarse_voxel_as_the_map_does() {
        let points: Vec<Vec3> = (0..3_000)
            .map(|i| {
                let t = i as f32 * 0.618_034;
                Vec3::new(t.sin(), (1.3 * t).cos(), (0.7 * t).sin()) * 0.4
            })
            .collect();
        let mut grid = MomentGrid::new(0.03);
        grid.integrate(&points);
        let voxels = grid.sorted_voxels();
        for factor in [1, 2, 3, 4] {
            let coarse = SortedVoxels::coarsened(&voxels, factor, grid.voxel_size_m());
            let mut expected: FxHashMap<IVec3, PointMoments> = FxHashMap::default();
            for &(cell, m) in &voxels {
                *expected
                    .entry(cell.div_euclid(IVec3::splat(factor)))
                    .or_default() += m;
            }
            assert_eq!(coarse.cells.len(), expected.len());
            assert!(coarse
                .cells
                .windows(2)
                .all(|w| (w[0].z, w[0].y, w[0].x) < (w[1].z, w[1].y, w[1].x)));
            for (cell, m) in coarse.cells.iter().zip(&coarse.moments) {
                assert_eq!(Some(m), expected.get(cell), "{cell} by {factor}");
            }
            assert_eq!(coarse.voxel_size_m, 0.03 * factor as f32);
        }
    }

    /// A 1 m square under noise as wide as a voxel: the two layers of voxels the surface runs
    /// through are never thin, and nearly all voxels two or more layers off it are. On a
    /// noiseless square none is.
    #[test]
    fn thin_voxels_are_the_noises_tails() {
        use rand::{Rng, SeedableRng};
        use rand_distr::{Distribution, Normal};
        let voxel = 0.05;
        let square = |sigma: f32| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
            let noise = Normal::new(0.0, sigma.max(1e-9)).unwrap();
            let points: Vec<Vec3> = (0..100_000)
                .map(|_| {
                    let z = if sigma > 0.0 {
                        noise.sample(&mut rng)
                    } else {
                        0.5 * voxel
                    };
                    Vec3::new(rng.random::<f32>(), rng.random::<f32>(), z)
                })
                .collect();
            let mut grid = MomentGrid::new(voxel);
            grid.integrate(&points);
            SortedVoxels::coarsened(&grid.sorted_voxels(), 1, voxel)
        };
        let noisy = square(voxel);
        let thin = noisy.thin_voxels(0.7);
        let layer = |want: fn(i32) -> bool| {
            let flags: Vec<bool> = noisy
                .cells
                .iter()
                .zip(&thin)
                .filter(|(c, _)| want(c.z))
                .map(|(_, &t)| t)
                .collect();
            (flags.iter().filter(|&&t| t).count(), flags.len())
        };
        let (thin_on, on) = layer(|z| z == -1 || z == 0);
        assert_eq!(
            thin_on, 0,
            "{thin_on} of the {on} voxels on the surface are thin"
        );
        let (thin_off, off) = layer(|z| !(-2..=1).contains(&z));
        assert!(
            off > 100 && thin_off * 10 >= off * 9,
            "{thin_off} of the {off} voxels off the surface are thin"
        );
        let clean = square(0.0);
        assert_eq!(clean.cells.len(), 400);
        assert!(clean.thin_voxels(0.7).iter().all(|&t| !t));
    }

    #[test]
    fn neighbourhood_sums_adjacent_cells_only() {
        let mut grid = MomentGrid::new(1.0);
        grid.integrate(&[Vec3::splat(0.5), Vec3::splat(1.5), Vec3::splat(3.5)]);
        assert_eq!(grid.neighbourhood(IVec3::ZERO, 1).count, 2.0);
        assert!(grid.any_near(IVec3::ZERO, 1));
        assert!(grid.any_near(IVec3::splat(4), 1));
        assert!(!grid.any_near(IVec3::splat(-2), 1));
        assert!(!grid.any_near(IVec3::new(6, 0, 0), 1));
    }
}
