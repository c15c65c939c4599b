//! Splitting a cluster into objects where its surface bends concavely: Stein et al., "Object
//! partitioning using local convexity" (LCCP, CVPR 2014), on patches grown as in Papon et al.,
//! "Voxel cloud connectivity segmentation" (VCCS, CVPR 2013).
//!
//! Objects that touch (a box on a box, a cup on a book, a box leaning on another) form one
//! Euclidean cluster. Where two objects meet, their surfaces meet in a concave crease; the
//! surface of one object is convex or flat almost everywhere. So the cluster's surface is cut
//! into small patches, each adjacent pair of patches is judged convex or concave from their
//! centroids and normals, and the objects are what convex connections join.
//!
//! Stages, one function each, in the order they run:
//! 1. `link_cells`: the cluster's cells (voxel centroids) and the pairs of them within the
//!    linking distance: the links Euclidean clustering found (`links.rs`), taken, not
//!    searched again.
//! 2. Each cell's normal, from the plane through its neighbours within a radius (Hoppe et
//!    al. 1992), turned towards the sensor: the crease test's local planes (`creases.rs`),
//!    computed once for both.
//! 3. `grow_patches`: seeds on a grid of the patch size; every cell joins the seed it is
//!    cheapest to reach along the links, where a step costs its length plus a penalty for
//!    turning away from the seed's normal (VCCS's distance, grown as a geodesic flood instead of
//!    VCCS's iterated local k-means: one pass, and a patch never jumps a gap).
//! 4. `judge_connection`: LCCP's convexity: two adjacent patches are joined if the
//!    connection is convex, or concave by less than a tolerance (noise on a flat or gently
//!    curved surface).
//! 5. `join_patches`: pieces merged where most of the links between them are judged joined
//!    (a vote, where LCCP takes any one convex connection); pieces too small to be an object
//!    join the neighbour they share most links with.
//! 6. `join_dished`: a piece dished away from the sensor (the inside of a cup or a bowl,
//!    concave everywhere, which LCCP cuts off) joins its neighbour.
//!
//! [`split_at_concave_creases`] is the entry point.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

use glam::{DMat4, DVec4, Vec3};
use rustc_hash::FxHashMap;

use crate::links::Links as CellLinks;
use crate::planes::fit_plane;
use crate::sets::DisjointSets;
use tacmesh_source::floor_i32;

/// The settings of [`split_at_concave_creases`].
#[derive(Debug, Clone, Copy)]
pub(crate) struct ConvexityParams {
    /// Spacing of the patch seeds, in metres, where the cells are `cell_m`; it grows with the
    /// cells far away.
    pub(crate) patch_m: f32,
    /// A concave connection whose normals differ by less than this, in degrees, is noise on a
    /// smooth surface and joins.
    pub(crate) concave_tolerance_deg: f32,
    /// Pieces weighing less than this (in input points) join a neighbour.
    pub(crate) min_piece_weight: usize,
    /// The sensor position, towards which normals are turned.
    pub(crate) viewpoint: Vec3,
    /// The sensor's depth step per square metre of range (see the `range` module); patches
    /// grow with it.
    pub(crate) range_step_per_m2: f32,
}

/// A patch is at least this many depth steps across, so that the sensor's noise does not
/// decide its normal: for a Kinect-class camera (a step of 0.0035·r²), rounded up to the
/// patch size times a power of two, 3 cm up to 0.73 m, 6 cm to 1.04 m, 12 cm to 1.46 m.
/// With 3 cm patches everywhere the D435 recording's backpack at 1.5 m came out in 16 pieces
/// and the PrimeSense room in 34 objects; at 16 steps they are 2 and 25 objects, and the mOSD
/// scans (0.6–0.95 m) score 0.935 mean IoU against 0.922 at 8 steps and 0.936 at 12.
const PATCH_DEPTH_STEPS: f32 = 16.0;

impl ConvexityParams {
    /// Whether the split runs at all (a positive, finite patch size).
    pub(crate) fn enabled(&self) -> bool {
        self.patch_m > 0.0 && self.patch_m.is_finite()
    }
}

/// The links of one cluster's cells: `neighbours[start[k]..start[k + 1]]` are the positions
/// (in the cluster) of the cells linked to the cell at position `k`.
struct Links {
    start: Vec<u32>,
    neighbours: Vec<u32>,
}

impl Links {
    fn of(&self, k: usize) -> &[u32] {
        &self.neighbours[self.start[k] as usize..self.start[k + 1] as usize]
    }
}

/// Values grouped by a key below a bound, each group in the order the values came: `of(k)`.
struct Grouped {
    start: Vec<u32>,
    values: Vec<u32>,
}

impl Grouped {
    /// Groups the values of `(key, value)` pairs by key (`key < keys`; pairs keyed `u32::MAX`
    /// are left out), by counting sort.
    fn new(keys: usize, pairs: impl Iterator<Item = (u32, u32)> + Clone) -> Self {
        let mut start = vec![0u32; keys + 1];
        for (key, _) in pairs.clone() {
            if key != u32::MAX {
                start[key as usize + 1] += 1;
            }
        }
        for k in 0..keys {
            start[k + 1] += start[k];
        }
        let mut fill = start.clone();
        let mut values = vec![0u32; start[keys] as usize];
        for (key, value) in pairs {
            if key != u32::MAX {
                values[fill[key as usize] as usize] = value;
                fill[key as usize] += 1;
            }
        }
        Self { start, values }
    }

    fn of(&self, key: usize) -> &[u32] {
        &self.values[self.start[key] as usize..self.start[key + 1] as usize]
    }
}

/// Stage 1: the links of `cluster`'s cells among themselves, from the links of all cells
/// (`cell_links.of(c)`, the cells linked to cell `c`), with `position[c]` the position of
/// cell `c` in its cluster: a linked cell is in this cluster if this cluster has it there.
fn link_cells(cluster: &[u32], (cell_links, position): (&CellLinks, &[u32])) -> Links {
    let mut start = Vec::with_capacity(cluster.len() + 1);
    let mut neighbours = Vec::new();
    start.push(0);
    for &c in cluster {
        for &j in cell_links.of(c as usize) {
            let k = position[j as usize];
            if cluster.get(k as usize) == Some(&j) {
                neighbours.push(k);
            }
        }
        start.push(neighbours.len() as u32);
    }
    Links { start, neighbours }
}

/// Stage 3: the patch of each cell (by position in the cluster), and the number of patches.
/// Seeds are the cells nearest the centres of the occupied squares of a grid of `seed_m(p)`;
/// a step along a link from `a` to `b` for the patch of seed `s` costs
/// `|a − b| / seed_m + NORMAL_WEIGHT · (1 − n_b · n_s)`.
fn grow_patches(
    centroids: &[Vec3],
    cluster: &[u32],
    links: &Links,
    normals: &[Vec3],
    seed_m: impl Fn(Vec3) -> f32,
) -> (Vec<u32>, usize) {
    /// How much turning away from the seed's normal costs against distance: VCCS weighs
    /// normals 4× the spatial term for Kinect scans of tabletop objects (its paper's OSD
    /// settings; 1 − cos 30° ≈ 0.13 then costs half a patch's width).
    const NORMAL_WEIGHT: f32 = 4.0;
    // The seed of each occupied grid square: the cell nearest the square's centre.
    let mut nearest: FxHashMap<[i32; 4], (f32, u32)> =
        FxHashMap::with_capacity_and_hasher(cluster.len(), Default::default());
    for (k, &c) in cluster.iter().enumerate() {
        let p = centroids[c as usize];
        let side = seed_m(p);
        let q = p / side;
        let square = [floor_i32(q.x), floor_i32(q.y), floor_i32(q.z)];
        // Squares of different sides do not share keys: the side is part of the key.
        let key = [square[0], square[1], square[2], side.to_bits() as i32];
        let d = (q - floored(q, square) - Vec3::splat(0.5)).length_squared();
        let entry = nearest.entry(key).or_insert((f32::INFINITY, u32::MAX));
        if (d, k as u32) < *entry {
            *entry = (d, k as u32);
        }
    }
    let mut seeds: Vec<u32> = nearest.values().map(|&(_, k)| k).collect();
    if seeds.len() == cluster.len() {
        // Every cell seeds its own patch (far away, where a patch's square holds one cell).
        return ((0..cluster.len() as u32).collect(), cluster.len());
    }
    seeds.sort_unstable();

    let mut patch = vec![u32::MAX; cluster.len()];
    let mut cost = vec![f32::INFINITY; cluster.len()];
    // (cost, cell position, patch): the order of equal costs is by position and patch, so
    // the result does not depend on hash order.
    for &k in &seeds {
        cost[k as usize] = 0.0;
    }
    let mut heap: BinaryHeap<Reverse<(OrderedCost, u32, u32)>> = seeds
        .iter()
        .enumerate()
        .map(|(s, &k)| Reverse((OrderedCost(0.0), k, s as u32)))
        .collect();
    while let Some(Reverse((OrderedCost(c), k, s))) = heap.pop() {
        if patch[k as usize] != u32::MAX {
            continue;
        }
        patch[k as usize] = s;
        let seed = seeds[s as usize] as usize;
        let (p, n_seed) = (centroids[cluster[k as usize] as usize], normals[seed]);
        let side = seed_m(p);
        for &j in links.of(k as usize) {
            if patch[j as usize] != u32::MAX {
                continue;
            }
            let q = centroids[cluster[j as usize] as usize];
            let turn = if n_seed == Vec3::ZERO || normals[j as usize] == Vec3::ZERO {
                0.0
            } else {
                1.0 - normals[j as usize].dot(n_seed)
            };
            let next = c + p.distance(q) / side + NORMAL_WEIGHT * turn.max(0.0);
            if next < cost[j as usize] {
                cost[j as usize] = next;
                heap.push(Reverse((OrderedCost(next), j, s)));
            }
        }
    }
    (patch, seeds.len())
}

/// `q.floor()` from `square`, its components floored to integers (by `floor_i32`), without
/// calling `floorf`: the same values, but that a negative zero may come out positive (which
/// no difference from it tells apart).
fn floored(q: Vec3, square: [i32; 3]) -> Vec3 {
    // Beyond 2^23 every float is an integer, and its own floor.
    let exact = |x: f32, k: i32| if x.abs() < 8_388_608.0 { k as f32 } else { x };
    Vec3::new(
        exact(q.x, square[0]),
        exact(q.y, square[1]),
        exact(q.z, square[2]),
    )
}

/// A finite, non-negative cost, totally ordered for the heap.
#[derive(Debug, Clone, Copy, PartialEq)]
struct OrderedCost(f32);

impl Eq for OrderedCost {}

impl PartialOrd for OrderedCost {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for OrderedCost {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&other.0)
    }
}

/// A patch: its weighted centroid and its normal (towards the sensor).
#[derive(Debug, Clone, Copy)]
struct Patch {
    centroid: Vec3,
    normal: Vec3,
}

/// Stage 4: whether two adjacent patches belong to one object (LCCP's basic convexity
/// criterion; Stein et al. 2014, §3.2).
///
/// With `d` the unit vector from `b`'s centroid to `a`'s, the connection is convex when
/// `(n_a − n_b) · d > 0`: each normal leans away from the other patch, as on the two faces of a
/// box's edge; concave, as where a box stands on another, when they lean towards each other.
/// A concave connection whose normals differ by less than `concave_tolerance_deg` is noise on a
/// smooth surface and joins too.
///
/// LCCP's sanity criterion (cut a connection that runs nearly along the line where the two
/// planes meet, a step) was tried and left out: on 3 cm patches around a 5 cm cylinder the
/// normals of neighbouring patches differ by 30–40°, diagonal neighbours then fail it, and it
/// cut every cylinder of the mOSD scans into pieces (mean IoU 0.80 against 0.92 without it).
fn judge_connection(a: &Patch, b: &Patch, concave_tolerance_deg: f32) -> bool {
    if a.normal == Vec3::ZERO || b.normal == Vec3::ZERO {
        // No plane on one side (a patch of one or two cells): nothing to judge.
        return true;
    }
    let Some(d) = (a.centroid - b.centroid).try_normalize() else {
        return true;
    };
    let convex = (a.normal - b.normal).dot(d) > 0.0;
    convex || a.normal.dot(b.normal) >= concave_tolerance_deg.to_radians().cos()
}

/// A piece of fewer patches is not an object of its own (LCCP's minimum segment size): about
/// 50 cm² of surface at 3 cm patches. Fewer cut the stereo-scanned PCL mug's handle, a
/// 1 cm tube, into three; on the mOSD scans 1 to 8 score alike.
const MIN_PIECE_PATCHES: usize = 6;

/// Stage 5: the pieces (sets of patches) that the judged connections join, and the piece of
/// each patch.
///
/// LCCP joins the components of the convex connections (single linkage), so one convex
/// connection across a crease, from a noisy normal, merges two objects. Here the connections
/// vote instead: in rounds, adjacent pieces most of whose cell links run through connections
/// judged joined are merged, the best-agreeing pairs first and each piece at most once a
/// round, until no pair has a majority. Then pieces lighter than `min_weight` (input points)
/// or of fewer than [`MIN_PIECE_PATCHES`] patches join the neighbouring piece they share the
/// most links with, lightest first.
fn join_patches(
    patch_weights: Vec<usize>,
    connections: &[((u32, u32), u32, bool)],
    min_weight: usize,
) -> Vec<u32> {
    let patches = patch_weights.len();
    let mut sets = DisjointSets::new(patch_weights);
    if connections.iter().all(|&(_, _, joined)| joined) {
        // Every pair of adjacent pieces agrees, in every round, until no two pieces touch: the
        // pieces are the components of the connections, whatever order the rounds merge in,
        // and none is left touching another to join.
        return components(patches, connections.iter().map(|&(pair, _, _)| pair));
    }
    // (links through joined connections, all links) between each pair of pieces.
    let mut between: Vec<PiecesLinked> = connections
        .iter()
        .map(|&(pair, links, joined)| (pair, (if joined { links } else { 0 }, links)))
        .collect();
    loop {
        contract(&mut between, &mut sets);
        // The best-agreeing pairs first (the larger share of joined links, then more links,
        // then the lower pair), as one integer to sort by: a share above one half is a
        // positive float, whose bits order as it does.
        let mut agreeing: Vec<u128> = between
            .iter()
            .filter(|(_, (joined, all))| 2 * joined > *all)
            .map(|&((a, b), (joined, all))| {
                let share = joined as f32 / all as f32;
                (u128::from(!share.to_bits()) << 96)
                    | (u128::from(!all) << 64)
                    | (u128::from(a) << 32)
                    | u128::from(b)
            })
            .collect();
        if agreeing.is_empty() {
            break;
        }
        agreeing.sort_unstable();
        let mut merged = vec![false; patches];
        for key in agreeing {
            let (a, b) = ((key >> 32) as u32, key as u32);
            if !merged[a as usize] && !merged[b as usize] {
                merged[a as usize] = true;
                merged[b as usize] = true;
                sets.union(a, b);
            }
        }
    }
    loop {
        contract(&mut between, &mut sets);
        let mut patches_in = vec![0usize; patches];
        for p in 0..patches as u32 {
            patches_in[sets.find(p) as usize] += 1;
        }
        let small = |r: u32| {
            sets.weight[r as usize] < min_weight || patches_in[r as usize] < MIN_PIECE_PATCHES
        };
        let lightest = between
            .iter()
            .flat_map(|&((a, b), _)| [a, b])
            .filter(|&r| small(r))
            .min_by_key(|&r| (sets.weight[r as usize], r));
        let Some(small) = lightest else { break };
        let into = between
            .iter()
            .filter_map(|&((a, b), (_, links))| {
                if a == small {
                    Some((b, links))
                } else if b == small {
                    Some((a, links))
                } else {
                    None
                }
            })
            .max_by_key(|&(other, links)| (links, Reverse(other)))
            .map(|(other, _)| other);
        match into {
            Some(other) => {
                sets.union(small, other);
            }
            None => break,
        }
    }
    (0..patches as u32).map(|p| sets.find(p)).collect()
}

/// The cell links between different patches (`patch_of` each cell's, `u32::MAX` for none), as
/// pairs of patches, the lower first, once per cell link.
fn patch_links<'a>(patch_of: &'a [u32], links: &'a Links) -> impl Iterator<Item = (u32, u32)> + 'a {
    patch_of.iter().enumerate().flat_map(move |(k, &a)| {
        links.of(k).iter().filter_map(move |&j| {
            let b = patch_of[j as usize];
            (a < b && b != u32::MAX).then_some((a, b))
        })
    })
}

/// The component of each of `patches` in the graph of the `links` between them (a patch's
/// component named by one of its patches).
fn components(patches: usize, links: impl Iterator<Item = (u32, u32)>) -> Vec<u32> {
    let mut sets = DisjointSets::singletons(patches);
    for (a, b) in links {
        sets.union(a, b);
    }
    (0..patches as u32).map(|p| sets.find(p)).collect()
}

/// Two pieces (the lower first) and the links between them: (through connections judged
/// joined, all).
type PiecesLinked = ((u32, u32), (u32, u32));

/// Keys `between` by the pieces' current roots, drops the links inside a piece and sums those
/// between the same two pieces: the list shrinks as pieces merge, where recounting every
/// connection each round cost the split most of its time.
fn contract(between: &mut Vec<PiecesLinked>, sets: &mut DisjointSets) {
    for ((a, b), _) in between.iter_mut() {
        let (ra, rb) = (sets.find(*a), sets.find(*b));
        (*a, *b) = (ra.min(rb), ra.max(rb));
    }
    between.retain(|((a, b), _)| a != b);
    between.sort_unstable_by_key(|&(pair, _)| pair);
    between.dedup_by(|later, kept| {
        let same = later.0 == kept.0;
        if same {
            kept.1 .0 += later.1 .0;
            kept.1 .1 += later.1 .1;
        }
        same
    });
}

/// The mean curvature, in 1/m, of the quadric `h = a x² + b xy + c y² + d` fitted by least
/// squares to `cells`, in the frame of their plane (`h` along its normal, towards the sensor at
/// `viewpoint`; no linear terms, as the plane through the cells' centroid already takes the
/// tilt): positive where the surface is dished away from the sensor, as the inside of a cup or
/// a bowl is; negative on a box's corner or a cylinder's outside; zero when too few cells
/// determine it.
fn dish_curvature(centroids: &[Vec3], cells: &[u32], viewpoint: Vec3) -> f32 {
    if cells.len() < 12 {
        return 0.0;
    }
    let centroid = cells
        .iter()
        .fold(Vec3::ZERO, |s, &c| s + centroids[c as usize])
        / cells.len() as f32;
    let normal = match fit_plane(centroids, cells) {
        Some((n, _)) if n.dot(viewpoint - centroid) < 0.0 => -n,
        Some((n, _)) => n,
        None => return 0.0,
    };
    let (u, v) = normal.any_orthonormal_pair();
    // Normal equations of the four coefficients.
    let mut m = DMat4::ZERO;
    let mut rhs = DVec4::ZERO;
    for &c in cells {
        let r = centroids[c as usize] - centroid;
        let (x, y, h) = (r.dot(u) as f64, r.dot(v) as f64, r.dot(normal) as f64);
        let row = DVec4::new(x * x, x * y, y * y, 1.0);
        m += DMat4::from_cols(row * row.x, row * row.y, row * row.z, row * row.w);
        rhs += row * h;
    }
    if m.determinant().abs() <= 1e-30 {
        return 0.0;
    }
    let [a, _, c, _] = (m.inverse() * rhs).to_array();
    (a + c) as f32
}

/// Stage 6: joins each dished piece (`dish_curvature` above `MIN_DISH_PER_M`: the inside of a
/// cup or a bowl, which LCCP cuts off because it is concave everywhere) to the adjacent piece
/// it shares the most links with, most dished first, until none is left; `piece_of` is
/// indexed by patch.
fn join_dished(
    centroids: &[Vec3],
    cluster: &[u32],
    patch_of: &[u32],
    links: &Links,
    piece_of: &mut [u32],
    viewpoint: Vec3,
) {
    /// 1/m: a dish of up to 50 cm radius. The objects of the mOSD scans score −18 to +0.1
    /// (boxes, cylinders, and a box's top and front, where the quadric is a saddle), the
    /// insides of their bowl and cup +2.5 to +11 (the cup's least on every 2nd pixel); noise
    /// on a quadric fitted over 5 cm of Kinect data is about 1.
    const MIN_DISH_PER_M: f32 = 2.0;
    let piece_at = |k: usize, piece_of: &[u32]| {
        let p = patch_of[k];
        (p != u32::MAX).then(|| piece_of[p as usize])
    };
    loop {
        let mut cells_of: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
        let mut shared: FxHashMap<(u32, u32), u32> = FxHashMap::default();
        for (k, &cell) in cluster.iter().enumerate() {
            let Some(a) = piece_at(k, piece_of) else {
                continue;
            };
            cells_of.entry(a).or_default().push(cell);
            for &j in links.of(k) {
                match piece_at(j as usize, piece_of) {
                    Some(b) if b != a => *shared.entry((a, b)).or_default() += 1,
                    _ => {}
                }
            }
        }
        if cells_of.len() < 2 {
            return;
        }
        let mut dished: Vec<(f32, u32)> = cells_of
            .iter()
            .map(|(&piece, cells)| (dish_curvature(centroids, cells, viewpoint), piece))
            .filter(|&(k, _)| k > MIN_DISH_PER_M)
            .collect();
        dished.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)));
        let merge = dished.iter().find_map(|&(_, dish)| {
            shared
                .iter()
                .filter(|(&(piece, _), _)| piece == dish)
                .max_by_key(|(&(_, other), &n)| (n, Reverse(other)))
                .map(|(&(_, other), _)| (dish, other))
        });
        let Some((dish, into)) = merge else {
            return;
        };
        for piece in piece_of.iter_mut() {
            if *piece == dish {
                *piece = into;
            }
        }
    }
}

/// Splits one cluster (indices into `centroids`, each cell standing for `weights[c]` points
/// and with the unit normal `cell_normals[c]` towards the sensor, zero if undetermined) at
/// its concave creases; returns the pieces, each ascending, heaviest first. A cluster with
/// no concave crease comes back whole. `links` are the clustering's links of every cell
/// (`links.rs`) and each cell's position in its cluster (see `link_cells`); `cell_m(p)` is
/// the side of the cell at `p`.
pub(crate) fn split_at_concave_creases(
    centroids: &[Vec3],
    weights: &[u32],
    cell_normals: &[Vec3],
    cluster: &[u32],
    links: (&CellLinks, &[u32]),
    params: &ConvexityParams,
    cell_m: impl Fn(Vec3) -> f32,
) -> Vec<Vec<u32>> {
    if cluster.len() < 4 || !params.enabled() {
        return vec![cluster.to_vec()];
    }
    // Patches grow with range: at least three cells across (far cells are 2^k times larger),
    // and at least `PATCH_DEPTH_STEPS` depth steps.
    let seed_m = |p: Vec3| {
        let steps_m =
            PATCH_DEPTH_STEPS * params.range_step_per_m2 * p.distance_squared(params.viewpoint);
        let side = params.patch_m.max(3.0 * cell_m(p)).max(steps_m);
        // In powers of two of the patch size, as the cells are: the seed squares are keyed by
        // their side, and neighbouring cells must share a side to share a square.
        params.patch_m * (side / params.patch_m).log2().ceil().exp2()
    };
    let links = link_cells(cluster, links);
    let normals: Vec<Vec3> = cluster
        .iter()
        .map(|&c| cell_normals.get(c as usize).copied().unwrap_or(Vec3::ZERO))
        .collect();
    let (patch_of, patch_count) = grow_patches(centroids, cluster, &links, &normals, seed_m);

    // Each patch's cells (in cluster order), weight, centroid and normal (the plane through
    // its cells).
    let weight_of = |c: u32| weights.get(c as usize).map_or(1, |&w| w as usize);
    let members = Grouped::new(
        patch_count,
        patch_of.iter().zip(cluster).map(|(&p, &c)| (p, c)),
    );
    let patch_weights: Vec<usize> = (0..patch_count)
        .map(|p| members.of(p).iter().map(|&c| weight_of(c)).sum())
        .collect();
    let patches: Vec<Patch> = (0..patch_count)
        .zip(&patch_weights)
        .map(|(p, &w)| {
            let m = members.of(p);
            let centroid = m.iter().fold(Vec3::ZERO, |s, &c| {
                s + centroids[c as usize] * weight_of(c) as f32
            }) / w.max(1) as f32;
            let normal = match fit_plane(centroids, m) {
                Some((n, _)) if n.dot(params.viewpoint - centroid) < 0.0 => -n,
                Some((n, _)) => n,
                None => Vec3::ZERO,
            };
            Patch { centroid, normal }
        })
        .collect();

    let piece_of = if patches.iter().all(|patch| patch.normal == Vec3::ZERO) {
        // No patch has a normal to judge by (each has fewer than three cells, as far away,
        // where cells are as large as patches): every connection is judged joined, so the
        // pieces are the components of the links between patches (see `join_patches`), and
        // no two pieces touch for `join_dished` to join.
        components(patch_count, patch_links(&patch_of, &links))
    } else {
        // Adjacent patches, how many cell links join them, and the judgement of each
        // connection, in the order of the patches.
        let mut adjacent: Vec<(u32, u32)> = patch_links(&patch_of, &links).collect();
        adjacent.sort_unstable();
        let connections: Vec<((u32, u32), u32, bool)> = adjacent
            .chunk_by(|x, y| x == y)
            .map(|run| {
                let (a, b) = run[0];
                let joined = judge_connection(
                    &patches[a as usize],
                    &patches[b as usize],
                    params.concave_tolerance_deg,
                );
                ((a, b), run.len() as u32, joined)
            })
            .collect();
        let mut piece_of = join_patches(patch_weights, &connections, params.min_piece_weight);
        join_dished(
            centroids,
            cluster,
            &patch_of,
            &links,
            &mut piece_of,
            params.viewpoint,
        );
        piece_of
    };

    let mut pieces: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    for (k, &p) in patch_of.iter().enumerate() {
        let piece = if p == u32::MAX {
            u32::MAX
        } else {
            piece_of[p as usize]
        };
        pieces.entry(piece).or_default().push(cluster[k]);
    }
    let mut pieces: Vec<(usize, Vec<u32>)> = pieces
        .into_values()
        .map(|mut cells| {
            cells.sort_unstable();
            (cells.iter().map(|&c| weight_of(c)).sum(), cells)
        })
        .collect();
    pieces.sort_by(|a, b| b.0.cmp(&a.0).then(a.1[0].cmp(&b.1[0])));
    pieces.into_iter().map(|(_, cells)| cells).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points every `step` on the visible faces of an axis-aligned box (corner `lo`, size
    /// `size`) seen from above and from −x, −y (world z up): its top and its −x and −y sides.
    fn box_faces(lo: Vec3, size: Vec3, step: f32) -> Vec<Vec3> {
        let n = |len: f32| (len / step).round() as i32;
        let mut points = Vec::new();
        for i in 0..=n(size.x) {
            for j in 0..=n(size.y) {
                points.push(lo + Vec3::new(i as f32 * step, j as f32 * step, size.z));
            }
        }
        for h in 0..n(size.z) {
            let z = h as f32 * step;
            for i in 0..=n(size.x) {
                points.push(lo + Vec3::new(i as f32 * step, 0.0, z));
            }
            for j in 1..=n(size.y) {
                points.push(lo + Vec3::new(0.0, j as f32 * step, z));
            }
        }
        points
    }

    fn params() -> ConvexityParams {
        ConvexityParams {
            patch_m: 0.03,
            concave_tolerance_deg: 20.0,
            min_piece_weight: 50,
            viewpoint: Vec3::new(-1.0, -1.0, 1.5),
            range_step_per_m2: 0.0,
        }
    }

    fn split(points: &[Vec3]) -> Vec<Vec<u32>> {
        let all: Vec<u32> = (0..points.len() as u32).collect();
        let normals: Vec<Vec3> =
            crate::creases::local_planes(points, &all, 0.025, params().viewpoint)
                .iter()
                .map(|plane| plane.normal)
                .collect();
        let reach = crate::range::RangeDistance::new(0.012, 0.0, 1.0, params().viewpoint);
        let links = CellLinks::new(points, &all, &reach);
        split_at_concave_creases(
            points,
            &[],
            &normals,
            &all,
            (&links, &all),
            &params(),
            |_| 0.008,
        )
    }

    #[test]
    fn a_box_is_convex_and_stays_whole() {
        let points = box_faces(Vec3::ZERO, Vec3::new(0.2, 0.15, 0.12), 0.008);
        let pieces = split(&points);
        assert_eq!(
            pieces.len(),
            1,
            "{:?}",
            pieces.iter().map(Vec::len).collect::<Vec<_>>()
        );
        assert_eq!(pieces[0].len(), points.len());
    }

    #[test]
    fn a_box_standing_on_a_box_is_cut_at_the_crease() {
        // A 30 × 30 × 10 cm box with a 12 cm cube standing in the middle of its top: their
        // surfaces meet in a concave crease all round the cube's foot.
        let mut points = box_faces(Vec3::ZERO, Vec3::new(0.3, 0.3, 0.1), 0.008);
        let cube_lo = Vec3::new(0.09, 0.09, 0.1);
        points.retain(|p| {
            !(p.z > 0.099 && (0.09..=0.21).contains(&p.x) && (0.09..=0.21).contains(&p.y))
        });
        let bottom = points.len();
        points.extend(box_faces(cube_lo, Vec3::splat(0.12), 0.008));
        let pieces = split(&points);
        assert_eq!(
            pieces.len(),
            2,
            "{:?}",
            pieces.iter().map(Vec::len).collect::<Vec<_>>()
        );
        // Each piece is (almost all) one box.
        for piece in &pieces {
            let lower = piece.iter().filter(|&&i| (i as usize) < bottom).count();
            let purity = lower.max(piece.len() - lower) as f32 / piece.len() as f32;
            assert!(purity > 0.9, "purity {purity}");
        }
    }

    #[test]
    fn the_inside_of_a_bowl_stays_with_the_bowl() {
        // A hemispherical bowl of 8 cm radius seen from above: its inside is concave
        // everywhere, and its rim joins the outside; one object.
        let mut points = Vec::new();
        let radius = 0.08;
        for i in 0..40 {
            for j in 0..80 {
                let theta = std::f32::consts::FRAC_PI_2 * (i as f32 + 0.5) / 40.0;
                let phi = std::f32::consts::TAU * j as f32 / 80.0;
                let dir = Vec3::new(
                    theta.sin() * phi.cos(),
                    theta.sin() * phi.sin(),
                    -theta.cos(),
                );
                points.push(dir * radius);
            }
        }
        let pieces = split(&points);
        assert_eq!(
            pieces.len(),
            1,
            "{:?}",
            pieces.iter().map(Vec::len).collect::<Vec<_>>()
        );
    }

    #[test]
    fn convexity_is_judged_from_normals_leaning_apart_or_together() {
        let up = Patch {
            centroid: Vec3::new(0.0, 0.0, 0.1),
            normal: Vec3::Z,
        };
        // A box's top and its side below the edge: convex.
        let side = Patch {
            centroid: Vec3::new(0.03, 0.0, 0.07),
            normal: Vec3::X,
        };
        assert!(judge_connection(&up, &side, 20.0));
        // A table's top and the side of a box standing on it: concave.
        let wall = Patch {
            centroid: Vec3::new(-0.03, 0.0, 0.13),
            normal: Vec3::X,
        };
        assert!(!judge_connection(&up, &wall, 20.0));
        // Concave by 10°: noise on a flat face.
        let tilted = Patch {
            centroid: Vec3::new(0.03, 0.0, 0.1),
            normal: Vec3::new(-(10f32.to_radians().sin()), 0.0, 10f32.to_radians().cos()),
        };
        assert!(judge_connection(&up, &tilted, 20.0));
    }

    #[test]
    fn pieces_that_all_agree_are_the_components_of_their_connections() {
        // Patches 0–2 and 3–4 joined along two chains, 5 alone: three pieces, however small
        // (no piece touches another to join it).
        let connections = [((0, 1), 3, true), ((1, 2), 1, true), ((3, 4), 2, true)];
        let pieces = join_patches(vec![10; 6], &connections, 1000);
        assert!(pieces[..3].iter().all(|&p| p == pieces[0]));
        assert_eq!(pieces[3], pieces[4]);
        let mut distinct = vec![pieces[0], pieces[3], pieces[5]];
        distinct.sort_unstable();
        distinct.dedup();
        assert_eq!(distinct.len(), 3, "{pieces:?}");
    }

    #[test]
    fn pieces_join_where_most_of_their_links_agree() {
        // Two chains of eight patches (0–7 and 8–15), each joined along itself; between them
        // 7 and 8 are linked `joined` times through a connection judged joined and `cut` times
        // through one judged cut.
        let pieces_with = |joined: u32, cut: u32| {
            let mut connections: Vec<((u32, u32), u32, bool)> = (0..15)
                .filter(|&k| k != 7)
                .map(|k| ((k, k + 1), 10, true))
                .collect();
            connections.push(((7, 8), joined, true));
            connections.push(((7, 8), cut, false));
            join_patches(vec![100; 16], &connections, 1)
        };
        let pieces = pieces_with(3, 7);
        assert!(pieces[..8].iter().all(|&p| p == pieces[0]));
        assert!(pieces[8..].iter().all(|&p| p == pieces[8]));
        assert_ne!(pieces[0], pieces[8]);
        let pieces = pieces_with(7, 3);
        assert!(pieces.iter().all(|&p| p == pieces[0]));
    }
}
