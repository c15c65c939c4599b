//! Dominant support planes (table, floor) by RANSAC, refined by least squares.
//!
//! Method: RANSAC (Fischler & Bolles, "Random sample consensus", CACM 1981) in the form PCL's
//! `SACSegmentation` with `SACMODEL_PLANE` uses for tabletop scenes (Rusu, "Semantic 3D object
//! maps for everyday manipulation in human living environments", 2009, §6): sample three points,
//! count the points within a distance threshold of their plane, keep the plane with most inliers.
//! The winner is refined by total least squares on its inliers (the plane through their centroid
//! normal to the smallest principal axis of their covariance, found with cyclic Jacobi
//! rotations), the inliers recomputed, and refined once more. Repeated on what is left for up to
//! `max_planes` planes while a plane holds at least `min_plane_fraction` of the finite points.
//!
//! Hypotheses are scored on a fixed random subset of the candidates (at most
//! [`SCORE_SAMPLE`] points), which ranks planes as well as the full set for planes large enough
//! to matter, and in parallel; the sampling is seeded, so the result depends only on the input
//! and the seed.
//!
//! Stages in order: [`XorShift`] (seeded sampling) → `hypothesis` → `score` → `refine`
//! (`fit_plane`, with the eigen solver of `tacmesh_reconstruct::moments`) → `outline_on_plane`
//! (Andrew's monotone chain) → [`find_planes`] (the entry point).

use glam::{DMat3, DVec3, Vec2, Vec3};
use rayon::prelude::*;
use tacmesh_reconstruct::moments::least_spread_direction;

use crate::range::RangeDistance;
use tacmesh_source::floor_i32;

/// How many hypotheses RANSAC tries per plane. With a plane holding a fraction `w` of the
/// candidates, the chance that none of `k` samples is all-inlier is `(1 - w³)^k`: for `w = 0.3`
/// and `k = 400` that is 2e-5.
const HYPOTHESES: usize = 400;

/// Hypotheses are scored on at most this many candidates (a fixed random subset).
const SCORE_SAMPLE: usize = 20_000;

/// Preemptive scoring (Nistér 2003): every hypothesis is first scored on `PREEMPT_SAMPLE`
/// points spread evenly through the scoring sample, and only the best [`PREEMPT_KEEP`] on all
/// of it. A plane worth finding holds hundreds of those points, so its best hypotheses are among
/// the kept ones; the search costs a tenth of scoring every hypothesis on the whole sample
/// (the daemon runs one search per frame after its hints, which was a tenth of its CPU time on
/// the TUM desk).
const PREEMPT_SAMPLE: usize = 2_000;
const PREEMPT_KEEP: usize = 16;

/// A support plane: `normal · p = offset_m` for points `p` on it, with `normal` a unit vector
/// pointing to the side the sensor (the viewpoint) is on, which is the side objects rest on.
#[derive(Debug, Clone, PartialEq)]
pub struct SupportPlane {
    /// Unit normal, towards the viewpoint.
    pub normal: Vec3,
    /// Signed distance of the plane from the origin along `normal`, in metres.
    pub offset_m: f32,
    /// Indices (into the input points) of the points assigned to this plane, ascending.
    pub inliers: Vec<u32>,
    /// Convex hull of the inliers projected onto the plane, counter-clockwise about `normal`.
    pub(crate) outline: Vec<Vec3>,
    /// How far the plane's inliers reach across it (see [`SupportPlane::extent_m`]).
    pub(crate) extent_m: f32,
    /// See [`SupportPlane::area_m2`].
    pub(crate) area_m2: f32,
}

impl SupportPlane {
    /// The same plane in a world moved by `new_from_old` (the tracker's correction of a camera
    /// pose that was off): normal, offset and outline move with it.
    pub fn moved(&self, new_from_old: &glam::Affine3A) -> Self {
        let normal = new_from_old.transform_vector3(self.normal);
        Self {
            normal,
            offset_m: self.offset_m + normal.dot(new_from_old.translation.into()),
            outline: self
                .outline
                .iter()
                .map(|&p| new_from_old.transform_point3(p))
                .collect(),
            ..self.clone()
        }
    }

    /// Signed distance of `p` from the plane in metres, positive on the viewpoint side.
    pub fn signed_distance_m(&self, p: Vec3) -> f32 {
        self.normal.dot(p) - self.offset_m
    }

    /// The extent of the plane's inliers: the corners of their 2-D convex hull on the plane, in
    /// order, counter-clockwise seen from the viewpoint side. A fan from the first corner
    /// triangulates it (`corners.len() - 2` triangles). Empty if the inliers are degenerate.
    pub fn outline(&self) -> Vec<Vec3> {
        self.outline.clone()
    }

    /// The plane's size, in metres: how far the largest connected region of its inliers
    /// reaches along two axes in the plane and their diagonals (the larger). The region is
    /// made of 4 cm squares holding inliers, joined at edges and corners: the few points
    /// elsewhere that happen to lie on the same infinite plane, which the outline includes,
    /// do not count.
    pub fn extent_m(&self) -> f32 {
        self.extent_m
    }

    /// The area of the largest connected region of the plane's inliers (see
    /// [`SupportPlane::extent_m`]), in square metres. A RANSAC plane that only grazes the tops
    /// of a few objects has a large outline but a small region; a table or a wall has both.
    pub fn area_m2(&self) -> f32 {
        self.area_m2
    }
}

/// The side of the squares a plane's extent and area are measured in, in metres.
const AREA_CELL_M: f32 = 0.04;

/// [`SupportPlane::extent_m`] and [`SupportPlane::area_m2`] of the plane with normal `n`: the
/// inliers binned into squares of [`AREA_CELL_M`] on the plane, the largest 8-connected region
/// of squares found by flood fill, and its area and its spread along two axes and their
/// diagonals.
fn extent_and_area(points: &[Vec3], inliers: &[u32], n: Vec3) -> (f32, f32) {
    let (u, v) = plane_basis(n);
    // Sorted as one integer each (the order of the pairs), which compares in one step.
    let mut keys: Vec<u64> = inliers
        .iter()
        .map(|&i| {
            let p = points[i as usize];
            let (a, b) = (
                floor_i32(u.dot(p) / AREA_CELL_M),
                floor_i32(v.dot(p) / AREA_CELL_M),
            );
            (u64::from(a as u32 ^ SIGN) << 32) | u64::from(b as u32 ^ SIGN)
        })
        .collect();
    keys.sort_unstable();
    keys.dedup();
    let squares: Vec<(i32, i32)> = keys
        .into_iter()
        .map(|key| {
            (
                ((key >> 32) as u32 ^ SIGN) as i32,
                (key as u32 ^ SIGN) as i32,
            )
        })
        .collect();
    let mut seen = vec![false; squares.len()];
    let mut best: Vec<(i32, i32)> = Vec::new();
    for start in 0..squares.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let mut region = vec![squares[start]];
        let mut next = 0;
        while next < region.len() {
            let (a, b) = region[next];
            next += 1;
            for da in -1..=1 {
                for db in -1..=1 {
                    if let Ok(k) = squares.binary_search(&(a + da, b + db)) {
                        if !seen[k] {
                            seen[k] = true;
                            region.push(squares[k]);
                        }
                    }
                }
            }
        }
        if region.len() > best.len() {
            best = region;
        }
    }
    if best.is_empty() {
        return (0.0, 0.0);
    }
    let spread = |f: &dyn Fn((i32, i32)) -> f32| {
        let (lo, hi) = best
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &q| {
                (lo.min(f(q)), hi.max(f(q)))
            });
        hi - lo
    };
    let diagonal = std::f32::consts::FRAC_1_SQRT_2;
    let extent_cells = [
        spread(&|(a, _)| a as f32),
        spread(&|(_, b)| b as f32),
        spread(&|(a, b)| (a + b) as f32 * diagonal),
        spread(&|(a, b)| (a - b) as f32 * diagonal),
    ]
    .into_iter()
    .fold(0.0, f32::max);
    (
        (extent_cells + 1.0) * AREA_CELL_M,
        best.len() as f32 * AREA_CELL_M * AREA_CELL_M,
    )
}

/// Xorshift64* (Vigna, "An experimental exploration of Marsaglia's xorshift generators", 2016):
/// enough for sampling, and keeps the crate free of a RNG dependency.
pub(crate) struct XorShift(u64);

impl XorShift {
    pub(crate) fn new(seed: u64) -> Self {
        // Mix the seed (splitmix64 finaliser) so that small seeds give unrelated streams, and
        // avoid the all-zero state.
        let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        Self(if z == 0 { 1 } else { z })
    }

    fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `0..n` (n > 0), by the multiply-shift method (bias below 2^-32 here).
    fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }
}

/// A plane through three points, or `None` if they are (nearly) collinear.
fn hypothesis(a: Vec3, b: Vec3, c: Vec3) -> Option<(Vec3, f32)> {
    let n = (b - a).cross(c - a);
    let len = n.length();
    // Reject slivers: sine of the smallest angle-ish below ~1e-3 of the edge lengths.
    let scale = (b - a).length() * (c - a).length();
    if scale <= 0.0 || len.is_nan() || len <= 1e-3 * scale {
        return None;
    }
    let n = n / len;
    Some((n, n.dot(a)))
}

/// Number of `sample` points within their inlier distance of the plane. The sample is a
/// contiguous copy of the points and their distances (not indices into them): scoring reads it
/// once per hypothesis, and gathering through random indices every time cost more than the
/// arithmetic.
fn score(sample: &[(Vec3, f32)], (n, d): (Vec3, f32)) -> usize {
    sample
        .iter()
        .filter(|&&(p, threshold_m)| (n.dot(p) - d).abs() <= threshold_m)
        .count()
}

/// Total-least-squares plane through `indices`: centroid and smallest principal axis.
/// Sums in f64 around a provisional centre so that far-off clouds keep their precision.
pub(crate) fn fit_plane(points: &[Vec3], indices: &[u32]) -> Option<(Vec3, f32)> {
    if indices.len() < 3 {
        return None;
    }
    let origin = points[indices[0] as usize].as_dvec3();
    let mut sum = DVec3::ZERO;
    for &i in indices {
        sum += points[i as usize].as_dvec3() - origin;
    }
    let mean = sum / indices.len() as f64;
    // The six distinct entries of the symmetric covariance.
    let (mut xx, mut xy, mut xz, mut yy, mut yz, mut zz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for &i in indices {
        let r = points[i as usize].as_dvec3() - origin - mean;
        xx += r.x * r.x;
        xy += r.x * r.y;
        xz += r.x * r.z;
        yy += r.y * r.y;
        yz += r.y * r.z;
        zz += r.z * r.z;
    }
    let c = DMat3::from_cols_array(&[xx, xy, xz, xy, yy, yz, xz, yz, zz]);
    let n = least_spread_direction(c).normalize_or_zero();
    if n == DVec3::ZERO {
        return None;
    }
    let centroid = origin + mean;
    Some((n.as_vec3(), n.dot(centroid) as f32))
}

/// Candidates within their inlier distance (`band_m[i]` for point `i`) of the plane.
fn inliers_of(
    points: &[Vec3],
    candidates: &[u32],
    (n, d): (Vec3, f32),
    band_m: &[f32],
) -> Vec<u32> {
    candidates
        .par_iter()
        .copied()
        .filter(|&i| (n.dot(points[i as usize]) - d).abs() <= band_m[i as usize])
        .collect()
}

/// Least-squares refinement: fit, re-collect inliers, three times.
fn refine(
    points: &[Vec3],
    candidates: &[u32],
    mut plane: (Vec3, f32),
    band_m: &[f32],
) -> ((Vec3, f32), Vec<u32>) {
    let mut inliers = inliers_of(points, candidates, plane, band_m);
    for _ in 0..3 {
        let Some(fitted) = fit_plane(points, &inliers) else {
            break;
        };
        // Always take the fit, even if it holds a few points fewer: a hypothesis tilted within
        // the threshold can hold more (the feet of objects) and still be the worse plane.
        plane = fitted;
        inliers = inliers_of(points, candidates, fitted, band_m);
    }
    (plane, inliers)
}

/// Two unit vectors spanning the plane with normal `n`, right-handed with it.
fn plane_basis(n: Vec3) -> (Vec3, Vec3) {
    let u = n.any_orthonormal_vector();
    (u, n.cross(u))
}

/// Outline corners closer than this to the chord of their neighbours are dropped, in metres.
const OUTLINE_TOLERANCE_M: f32 = 0.01;

/// Drops hull corners, flattest first, while one lies within `tolerance_m` of the chord joining
/// its neighbours (and more than three remain). The polygon stays convex and shrinks by less
/// than `tolerance_m` per dropped corner. Quadratic in the corners, which are few.
fn simplify_hull(hull: &mut Vec<Vec2>, tolerance_m: f32) {
    while hull.len() > 3 {
        let n = hull.len();
        let height = |k: usize| {
            let (a, p, b) = (hull[(k + n - 1) % n], hull[k], hull[(k + 1) % n]);
            let chord = b - a;
            let len = chord.length();
            if len > 0.0 {
                chord.perp_dot(p - a).abs() / len
            } else {
                (p - a).length()
            }
        };
        let Some((k, h)) = (0..n)
            .map(|k| (k, height(k)))
            .min_by(|x, y| x.1.total_cmp(&y.1))
        else {
            break;
        };
        if h >= tolerance_m {
            break;
        }
        hull.remove(k);
    }
}

/// Flipping the sign bit orders `i32`s as `u32`s.
const SIGN: u32 = 1 << 31;

/// The bits of `x`, turned so that their order as integers is `f32::total_cmp`'s: a positive
/// float's sign bit set, a negative float's bits all flipped.
fn ordered_bits(x: f32) -> u32 {
    let bits = x.to_bits();
    if bits & SIGN == 0 {
        bits | SIGN
    } else {
        !bits
    }
}

/// The float of [`ordered_bits`].
fn from_ordered_bits(bits: u32) -> f32 {
    f32::from_bits(if bits & SIGN != 0 {
        bits & !SIGN
    } else {
        !bits
    })
}

/// The convex outline of `points` projected onto the plane `normal · p = offset_m` (unit
/// normal), as [`SupportPlane::outline`] is of a plane's inliers: counter-clockwise about
/// `normal`, nearly straight corners dropped; empty when the points span no area. For
/// outlines built up over frames (the daemon's supports grow as more of them is seen).
pub fn convex_outline(points: &[Vec3], normal: Vec3, offset_m: f32) -> Vec<Vec3> {
    let all: Vec<u32> = (0..points.len() as u32).collect();
    outline_on_plane(points, &all, normal, offset_m)
}

/// Convex hull of the inliers projected onto the plane, by Andrew's monotone chain (Andrew,
/// "Another efficient algorithm for convex hulls in two dimensions", IPL 1979), lifted back to
/// 3-D, with corners flatter than [`OUTLINE_TOLERANCE_M`] dropped. Counter-clockwise about `n`.
fn outline_on_plane(points: &[Vec3], inliers: &[u32], n: Vec3, d: f32) -> Vec<Vec3> {
    let (u, v) = plane_basis(n);
    let mut flat: Vec<Vec2> = inliers
        .iter()
        .map(|&i| {
            let p = points[i as usize];
            Vec2::new(u.dot(p), v.dot(p))
        })
        .collect();
    // By x, then y, in `total_cmp`'s order, as one integer each.
    let mut keys: Vec<u64> = flat
        .iter()
        .map(|q| (u64::from(ordered_bits(q.x)) << 32) | u64::from(ordered_bits(q.y)))
        .collect();
    keys.sort_unstable();
    flat.clear();
    flat.extend(keys.into_iter().map(|key| {
        Vec2::new(
            from_ordered_bits((key >> 32) as u32),
            from_ordered_bits(key as u32),
        )
    }));
    flat.dedup();
    if flat.len() < 3 {
        return Vec::new();
    }
    let cross = |o: Vec2, a: Vec2, b: Vec2| (a - o).perp_dot(b - o);
    let mut hull: Vec<Vec2> = Vec::with_capacity(64);
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &Vec2>> = if pass == 0 {
            Box::new(flat.iter())
        } else {
            Box::new(flat.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop(); // the last point of each chain starts the other one
    }
    simplify_hull(&mut hull, OUTLINE_TOLERANCE_M);
    if hull.len() < 3 {
        return Vec::new();
    }
    hull.into_iter()
        .map(|q| u * q.x + v * q.y + n * d)
        .collect()
}

/// Finds up to `max_planes` planes among `candidates` (indices of finite points).
///
/// Each plane's `inliers` are the candidates within `band` of it (at their range); a plane is
/// accepted only if it holds at least `min_inliers` points. Normals are turned towards the
/// band's viewpoint. Returns the planes, largest first; inliers of one plane are not
/// candidates for the next.
///
/// `hints` (e.g. the previous frame's planes) are tried first, in order: a hint whose refined
/// plane holds at least `min_inliers` points is taken without RANSAC; the others are skipped.
/// Without hints, planes come from RANSAC until one is too small. With hints, at most one
/// RANSAC search follows them: a scene of several planes is found over a few frames, and a
/// frame does not pay for a search that fails every time (a room has fewer large planes
/// than `max_planes`).
pub(crate) fn find_planes(
    points: &[Vec3],
    candidates: &[u32],
    band: &RangeDistance,
    max_planes: usize,
    min_inliers: usize,
    seed: u64,
    hints: &[(Vec3, f32)],
) -> Vec<SupportPlane> {
    let viewpoint = band.viewpoint;
    // Each candidate's inlier distance, which every refinement reads again.
    let mut band_m = vec![0.0; points.len()];
    for &i in candidates {
        band_m[i as usize] = band.at(points[i as usize]);
    }
    let mut rng = XorShift::new(seed);
    let mut remaining: Vec<u32> = candidates.to_vec();
    let mut planes = Vec::new();
    let min_inliers = min_inliers.max(3);
    let mut searches_left = if hints.is_empty() { usize::MAX } else { 1 };
    let mut hints = hints.iter();
    while planes.len() < max_planes && remaining.len() >= min_inliers {
        // A hint that still holds enough points after refinement saves the RANSAC search.
        let hinted = hints.by_ref().find_map(|&hint| {
            let (plane, inliers) = refine(points, &remaining, hint, &band_m);
            (inliers.len() >= min_inliers).then_some((plane, inliers))
        });
        if let Some(((n, d), inliers)) = hinted {
            push_plane(
                &mut planes,
                &mut remaining,
                points,
                (n, d),
                inliers,
                viewpoint,
            );
            continue;
        }
        if searches_left == 0 {
            break;
        }
        searches_left -= 1;
        // A fixed random scoring subset (with replacement; duplicates are harmless), each point
        // with its inlier distance.
        let with_band = |i: u32| (points[i as usize], band_m[i as usize]);
        let sample: Vec<(Vec3, f32)> = if remaining.len() <= SCORE_SAMPLE {
            remaining.iter().map(|&i| with_band(i)).collect()
        } else {
            (0..SCORE_SAMPLE)
                .map(|_| with_band(remaining[rng.below(remaining.len())]))
                .collect()
        };
        // Draw all hypotheses first (sequential, seeded), then score them in parallel.
        let hypotheses: Vec<(Vec3, f32)> = (0..HYPOTHESES)
            .filter_map(|_| {
                let pick =
                    |rng: &mut XorShift| points[remaining[rng.below(remaining.len())] as usize];
                hypothesis(pick(&mut rng), pick(&mut rng), pick(&mut rng))
            })
            .collect();
        // Ties go to the earliest hypothesis so that the result is deterministic.
        let ranked = |a: &(usize, usize), b: &(usize, usize)| a.0.cmp(&b.0).then(b.1.cmp(&a.1));
        // An even stride through the sample: when the candidates are fewer than
        // SCORE_SAMPLE, the sample is all of them in image order, and its first points would
        // be the top rows of the image only.
        let stride = sample.len().div_ceil(PREEMPT_SAMPLE).max(1);
        let first: Vec<(Vec3, f32)> = sample.iter().step_by(stride).copied().collect();
        let mut preliminary: Vec<(usize, usize)> = hypotheses
            .par_iter()
            .enumerate()
            .map(|(k, &h)| (score(&first, h), k))
            .collect();
        preliminary.sort_unstable_by(|a, b| ranked(b, a));
        preliminary.truncate(PREEMPT_KEEP);
        let best = preliminary
            .par_iter()
            .map(|&(_, k)| (score(&sample, hypotheses[k]), k))
            .max_by(ranked);
        let Some((_, k)) = best else { break };
        let (plane, inliers) = refine(points, &remaining, hypotheses[k], &band_m);
        if inliers.len() < min_inliers {
            break;
        }
        push_plane(
            &mut planes,
            &mut remaining,
            points,
            plane,
            inliers,
            viewpoint,
        );
    }
    // Largest first, as RANSAC finds them: hinted planes come before the search's, and the
    // scene model takes the first plane facing up for the table (`scene::plane_roles`). After
    // mOSD scene 45, its table, 3.5° off scene 57's, refined into a plane 12° from the new
    // table that held a strip of it and the feet of the objects there; found first, it was
    // taken for the table and sliced two objects away, and as its own hint came back every
    // frame. The real table, with twice its points, came second.
    planes.sort_by_key(|plane| std::cmp::Reverse(plane.inliers.len()));
    planes
}

/// Accepts a refined plane: turns its normal towards `viewpoint`, outlines it, and removes its
/// inliers from `remaining`.
fn push_plane(
    planes: &mut Vec<SupportPlane>,
    remaining: &mut Vec<u32>,
    points: &[Vec3],
    (mut n, mut d): (Vec3, f32),
    inliers: Vec<u32>,
    viewpoint: Vec3,
) {
    if n.dot(viewpoint) - d < 0.0 {
        n = -n;
        d = -d;
    }
    let outline = outline_on_plane(points, &inliers, n, d);
    let (extent_m, area_m2) = extent_and_area(points, &inliers, n);
    *remaining = difference(remaining, &inliers);
    planes.push(SupportPlane {
        normal: n,
        offset_m: d,
        inliers,
        outline,
        extent_m,
        area_m2,
    });
}

/// `a \ b` for ascending index lists.
fn difference(a: &[u32], b: &[u32]) -> Vec<u32> {
    let mut out = Vec::with_capacity(a.len().saturating_sub(b.len()));
    let mut j = 0;
    for &x in a {
        while j < b.len() && b[j] < x {
            j += 1;
        }
        if j < b.len() && b[j] == x {
            continue;
        }
        out.push(x);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ordered_bits_order_as_total_cmp_and_round_trip() {
        let values = [
            f32::NEG_INFINITY,
            -3.5,
            -f32::MIN_POSITIVE,
            -0.0,
            0.0,
            1e-40,
            0.25,
            7.0,
            f32::INFINITY,
            f32::NAN,
        ];
        for a in values {
            assert_eq!(from_ordered_bits(ordered_bits(a)).to_bits(), a.to_bits());
            for b in values {
                assert_eq!(
                    ordered_bits(a).cmp(&ordered_bits(b)),
                    a.total_cmp(&b),
                    "{a} {b}"
                );
            }
        }
    }

    #[test]
    fn fit_plane_recovers_a_tilted_plane() {
        let n = Vec3::new(0.3, -0.2, 1.0).normalize();
        let (u, v) = plane_basis(n);
        let mut points = Vec::new();
        for i in 0..50 {
            for j in 0..40 {
                points.push(u * (i as f32 * 0.02) + v * (j as f32 * 0.03) + n * 0.7);
            }
        }
        let all: Vec<u32> = (0..points.len() as u32).collect();
        let (m, d) = fit_plane(&points, &all).unwrap();
        let (m, d) = if m.dot(n) < 0.0 { (-m, -d) } else { (m, d) };
        assert!(m.dot(n) > 0.999_99, "{m} vs {n}");
        assert!((d - 0.7).abs() < 1e-4, "{d}");
    }

    #[test]
    fn outline_of_square_grid_is_its_four_corners() {
        let mut points = Vec::new();
        for i in 0..=10 {
            for j in 0..=10 {
                points.push(Vec3::new(i as f32 * 0.1, j as f32 * 0.1, 0.5));
            }
        }
        let inliers: Vec<u32> = (0..points.len() as u32).collect();
        let hull = outline_on_plane(&points, &inliers, Vec3::Z, 0.5);
        assert_eq!(hull.len(), 4, "{hull:?}");
        for c in &hull {
            assert!((c.z - 0.5).abs() < 1e-6);
            assert!(
                (c.x.abs() < 1e-5 || (c.x - 1.0).abs() < 1e-5)
                    && (c.y.abs() < 1e-5 || (c.y - 1.0).abs() < 1e-5)
            );
        }
        // Counter-clockwise about +z.
        let area: f32 = (0..4)
            .map(|k| hull[k].truncate().perp_dot(hull[(k + 1) % 4].truncate()))
            .sum();
        assert!(area > 0.0);
    }
}
