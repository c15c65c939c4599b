//! Joining the pieces of one object that something in front of it cut apart, on an organised
//! cloud (a depth image), where what is in front of what can be read off neighbouring pixels.
//!
//! Two cases, both after clustering and the convexity split:
//! - **An occluder in front**: a box behind a can shows on both sides of it, as two clusters
//!   with nothing linking them. Two pieces are joined when one plane holds a large part of
//!   each (the box's face seen on both sides), and every pixel on the image line between them
//!   is either one of them, has no depth, or is not beyond that plane, and some are nearer
//!   (the occluder; not the table seen between two boxes that happen to be aligned).
//! - **The object's own near wall**: a pot, a bowl or a cup seen from above shows its outer
//!   wall in front and its inner far wall behind, and the rim between them hides what joins
//!   them. The farther piece is joined to the nearer one when the nearer one hides it (they
//!   meet in the image with the nearer one in front), the nearer one's footprint on the
//!   support is an arc of a circle facing the sensor, the farther piece stands inside that
//!   circle, and it rises no higher than the nearer one (a can standing on a tin is not
//!   inside it).
//!
//! - **A container's bottom**: seen over the rim, a pot's or a bowl's inner bottom lies a few
//!   millimetres above the table, within the support's band and margin, and went to the
//!   support. A patch of support that one object's walls enclose in the image and that is
//!   raised above the support by more than its noise joins the object (the table seen through
//!   a mug's handle is not raised).
//!
//! [`join_hidden_pieces`] is the entry point; it runs on the strided image of
//! `organised.rs`. On the labelled mOSD scans (the learning set and the eight test scans,
//! `cargo run --release -p tacmesh-segment --example labelled_iou`), the three joins took the
//! mean IoU of the occluded objects from 0.80 to 0.94 and of the cylinders (bowls, pots and
//! cups among them) from 0.81 to 0.91, with no segment holding two objects.

use std::cell::OnceCell;

use glam::{DMat3, DVec3, Vec3};
use rustc_hash::FxHashMap;

use crate::planes::{fit_plane, SupportPlane};
use crate::range::RangeDistance;
use crate::sets::DisjointSets;
use crate::SegmentConfig;

/// Boundary pixels at which one piece is in front of another before that counts as hiding
/// it (a few pixels of noise at a shared edge do not).
const MIN_HIDING_PIXELS: usize = 4;

/// How far apart, in strided pixels, two pieces may meet across pixels with no depth or no
/// label: a Kinect's shadow beside a box 15 cm in front of another at 0.6 m is 14 pixels wide,
/// 7 at stride 2.
const SHADOW_PIXELS: usize = 8;

/// Neighbouring pixels this much nearer, in metres, are in front (farther apart than the
/// clustering links, so that the two pieces are not one surface).
const IN_FRONT_M: f32 = 0.02;

/// A plane holds this share of a piece's points to stand for it.
const MIN_PLANE_SHARE: f32 = 0.3;

/// Two pieces are on one plane when this share of each lies within three plane bands of it,
/// on average within this many.
const SAME_PLANE_BANDS: f32 = 1.5;

/// A footprint arc fits a circle of radius within these bounds, in metres: a cup to a pot.
const CIRCLE_RADIUS_M: (f32, f32) = (0.02, 0.3);

/// The farther piece is inside the circle when this share of its footprint is within the
/// nearer piece's widest radius plus [`CIRCLE_TOLERANCE_M`].
const INSIDE_SHARE: f32 = 0.9;
const CIRCLE_TOLERANCE_M: f32 = 0.01;

/// The near wall's footprint is a ring: this share of it ([`INSIDE_SHARE`]) at least this
/// fraction of the radius from the centre (a bowl's base is about 0.4 of its rim) …
const HOLLOW: f32 = 0.3;

/// … around at least this angle of the circle, in radians (a quarter), and at most this
/// (two thirds: the sensor sees the near half of a wall, a little more from above; a box's
/// top, which a circle also fits, lies all around its centre).
const MIN_ARC_RAD: f64 = std::f64::consts::FRAC_PI_2;
const MAX_ARC_RAD: f64 = 4.0 * std::f64::consts::FRAC_PI_3;

/// An enclosed patch of support is an object's bottom when its median height above the
/// support is at least this many plane bands (half: 4 mm at 1 m on a Kinect; its noise there
/// is about 1.5 mm).
const RAISED_BANDS: f32 = 0.5;

/// A patch of support is enclosed when this share of its border is with its walls: the
/// labels with at least [`MIN_CONTACT_SHARE`] of it each, at most [`MAX_WALL_PIECES`] of them.
const ENCLOSED_SHARE: f32 = 0.9;
const MIN_CONTACT_SHARE: f32 = 0.1;
const MAX_WALL_PIECES: usize = 3;

/// A bottom is at least this many pixels (a pocket of edge pixels between two objects is
/// not).
const MIN_BOTTOM_PIXELS: usize = 12;

/// Walls beside the largest are at most this share of its pixels: pieces of it (a band cut
/// off its foot), not a second object that happens to close the ring (a tin before a pot).
const MAX_SIDE_WALL_SHARE: f32 = 1.0 / 3.0;

/// One piece: its strided pixels, and what the tests need of it.
struct Piece<'a> {
    pixels: &'a [u32],
    /// The corners of its bounding box.
    lo: Vec3,
    hi: Vec3,
    centroid: Vec3,
    range_m: f32,
    /// The largest planes through it (at most two), each holding [`MIN_PLANE_SHARE`]; found
    /// when first asked for ([`Piece::planes`]), as only pieces an occluder hides need them.
    planes: OnceCell<Vec<(Vec3, f32)>>,
}

/// The pieces' sets (`sets.rs`), each with its bounding box: no join makes an object larger
/// than the largest object.
struct Joins {
    sets: DisjointSets,
    /// The bounding box of each set, at its root.
    boxes: Vec<(Vec3, Vec3)>,
    max_size_m: f32,
}

impl Joins {
    fn new(pieces: &[Piece], max_size_m: f32) -> Self {
        Self {
            sets: DisjointSets::new(pieces.iter().map(|p| p.pixels.len()).collect()),
            boxes: pieces.iter().map(|p| (p.lo, p.hi)).collect(),
            max_size_m,
        }
    }

    fn find(&mut self, x: u32) -> u32 {
        self.sets.find(x)
    }

    /// Joins the sets of `a` and `b` unless the two together would be larger than the
    /// largest object (the diagonal of their bounding box).
    fn join(&mut self, a: u32, b: u32) {
        let (a, b) = (self.find(a), self.find(b));
        if a == b {
            return;
        }
        let (la, ha) = self.boxes[a as usize];
        let (lb, hb) = self.boxes[b as usize];
        let (lo, hi) = (la.min(lb), ha.max(hb));
        if lo.distance(hi) > self.max_size_m {
            return;
        }
        let root = self.sets.union(a, b);
        self.boxes[root as usize] = (lo, hi);
    }
}

/// Joins the pieces of `objects` (indices into `points`, the strided image `width` wide) that
/// an occluder or their own near wall cut apart (see the module docs), relabelling `labels`
/// (one per point: `k` for `objects[k - 1]`, 0 for none). Objects stay ascending, largest
/// first. Footprints are taken along the first of `supports`' normal. Also joins the inner
/// bottom of a container, which its walls enclose, to it (see `inner_bottoms`); returns, per
/// pixel, whether it was so taken off the support (so that the caller keeps it off the
/// support at full resolution too).
pub(crate) fn join_hidden_pieces(
    points: &[Vec3],
    width: usize,
    objects: &mut Vec<Vec<u32>>,
    labels: &mut [u32],
    band: &RangeDistance,
    config: &SegmentConfig,
    supports: &[SupportPlane],
) -> Vec<bool> {
    let up = supports.first().map_or(config.up, |support| support.normal);
    let mut filled = vec![false; labels.len()];
    if objects.is_empty() || width == 0 {
        return filled;
    }
    let viewpoint = config.viewpoint_m;
    let range = |i: u32| points[i as usize].distance(viewpoint);
    // Boundary pixels at which piece a (index) is in front of piece b.
    let mut in_front: FxHashMap<(u32, u32), usize> = FxHashMap::default();
    let height = labels.len() / width;
    // Along rows and columns, the next labelled pixel within `SHADOW_PIXELS`, across pixels
    // with no depth or no label (the sensor's shadow beside an occluder, unlabelled edges).
    let look = |i: usize, j: usize, in_front: &mut FxHashMap<(u32, u32), usize>| {
        let (a, b) = (labels[i], labels[j]);
        let (ra, rb) = (range(i as u32), range(j as u32));
        if ra + IN_FRONT_M < rb {
            *in_front.entry((a - 1, b - 1)).or_default() += 1;
        } else if rb + IN_FRONT_M < ra {
            *in_front.entry((b - 1, a - 1)).or_default() += 1;
        }
    };
    for v in 0..height {
        for u in 0..width {
            let i = v * width + u;
            if labels[i] == 0 {
                continue;
            }
            for (du, dv) in [(1usize, 0usize), (0, 1)] {
                for k in 1..=SHADOW_PIXELS {
                    let (nu, nv) = (u + k * du, v + k * dv);
                    if nu >= width || nv >= height {
                        break;
                    }
                    let j = nv * width + nu;
                    if labels[j] == labels[i] {
                        break;
                    }
                    if labels[j] != 0 {
                        look(i, j, &mut in_front);
                        break;
                    }
                    // The support seen between two pieces: they do not meet here.
                    let p = points[j];
                    if p.is_finite()
                        && supports
                            .iter()
                            .any(|s| s.signed_distance_m(p).abs() <= 2.0 * band.at(p))
                    {
                        break;
                    }
                }
            }
        }
    }
    let bottoms = inner_bottoms(points, width, labels, band, supports);
    let hides = |a: u32, b: u32| in_front.get(&(a, b)).copied().unwrap_or(0) >= MIN_HIDING_PIXELS;
    let mut pairs: Vec<(u32, u32)> = in_front
        .iter()
        .filter(|&(_, &n)| n >= MIN_HIDING_PIXELS)
        .map(|(&pair, _)| pair)
        .collect();
    if pairs.is_empty() && bottoms.is_empty() {
        return filled;
    }
    pairs.sort_unstable();

    let pieces: Vec<Piece> = objects
        .iter()
        .map(|pixels| piece(points, pixels, viewpoint))
        .collect();
    let mut joins = Joins::new(&pieces, config.max_object_size_m);

    // The object's own near wall.
    for &(near, far) in &pairs {
        if hides(far, near) {
            continue;
        }
        if inside_the_near_wall(
            points,
            &pieces[near as usize],
            &pieces[far as usize],
            config,
            up,
        ) {
            joins.join(near, far);
        }
    }
    // An occluder in front: two pieces it hides, on one plane, with only it between them.
    let mut hidden_by: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    for &(near, far) in &pairs {
        hidden_by.entry(near).or_default().push(far);
    }
    let mut occluders: Vec<u32> = hidden_by.keys().copied().collect();
    occluders.sort_unstable();
    for occluder in occluders {
        let hidden = &hidden_by[&occluder];
        for (k, &a) in hidden.iter().enumerate() {
            for &b in &hidden[k + 1..] {
                if joins.find(a) == joins.find(b) {
                    continue;
                }
                let (pa, pb) = (&pieces[a as usize], &pieces[b as usize]);
                let shared = shared_plane(points, pa, pb, band);
                let Some(plane) = shared else {
                    continue;
                };
                if only_nearer_between(points, width, labels, pa, pb, (a, b), plane, viewpoint) {
                    joins.join(a, b);
                }
            }
        }
    }

    // A container's walls, in pieces around its bottom, are one object: the walls as the
    // joins above left them (the near and far wall of a pot are one by now), when one is the
    // container and the others are pieces of it.
    let mut root_size: FxHashMap<u32, usize> = FxHashMap::default();
    for k in 0..objects.len() as u32 {
        *root_size.entry(joins.find(k)).or_default() += objects[k as usize].len();
    }
    let bottoms: Vec<(Vec<u32>, Vec<u32>)> = bottoms
        .into_iter()
        .filter_map(|(pixels, walls)| {
            let mut roots: Vec<u32> = walls.iter().map(|&w| joins.find(w - 1)).collect();
            roots.sort_unstable();
            roots.dedup();
            let size = |root: &u32| root_size[root] as f32;
            let largest = roots.iter().map(size).fold(0.0, f32::max);
            let large = roots
                .iter()
                .filter(|r| size(r) > MAX_SIDE_WALL_SHARE * largest)
                .count();
            (large == 1).then(|| (pixels, roots.iter().map(|r| r + 1).collect()))
        })
        .collect();
    for (_, walls) in &bottoms {
        for pair in walls.windows(2) {
            joins.join(pair[0] - 1, pair[1] - 1);
        }
    }
    let roots: Vec<u32> = (0..objects.len() as u32).map(|k| joins.find(k)).collect();
    // The bottoms join their container, by its root.
    let bottoms: Vec<(Vec<u32>, u32)> = bottoms
        .into_iter()
        .map(|(pixels, walls)| (pixels, roots[walls[0] as usize - 1]))
        .collect();
    if bottoms.is_empty() && roots.iter().enumerate().all(|(k, &r)| r == k as u32) {
        return filled;
    }
    let mut joined: FxHashMap<u32, Vec<u32>> = FxHashMap::default();
    for (k, object) in objects.drain(..).enumerate() {
        joined.entry(roots[k]).or_default().extend(object);
    }
    for (pixels, root) in bottoms {
        for &i in &pixels {
            filled[i as usize] = true;
        }
        joined.entry(root).or_default().extend(pixels);
    }
    let mut merged: Vec<Vec<u32>> = joined
        .into_values()
        .map(|mut o| {
            o.sort_unstable();
            o
        })
        .collect();
    crate::largest_first(&mut merged);
    labels.copy_from_slice(&crate::object_labels(&merged, labels.len()));
    *objects = merged;
    filled
}

/// A piece's bounding box, centroid and range.
fn piece<'a>(points: &[Vec3], pixels: &'a [u32], viewpoint: Vec3) -> Piece<'a> {
    let n = pixels.len().max(1) as f32;
    let (mut sum, mut lo, mut hi) = (Vec3::ZERO, Vec3::INFINITY, Vec3::NEG_INFINITY);
    for &i in pixels {
        let p = points[i as usize];
        sum += p;
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let centroid = sum / n;
    Piece {
        pixels,
        lo,
        hi,
        centroid,
        range_m: centroid.distance(viewpoint),
        planes: OnceCell::new(),
    }
}

/// The nearest pixels of two pieces are looked for among this many of each (an even stride).
const NEAREST_SAMPLE: usize = 256;

impl Piece<'_> {
    /// The largest planes through the piece (by a few seeded RANSAC rounds on a sample).
    fn planes(&self, points: &[Vec3], band: &RangeDistance) -> &[(Vec3, f32)] {
        self.planes.get_or_init(|| {
            let n = self.pixels.len().max(1) as f32;
            let mut planes = Vec::new();
            let mut rest: Vec<u32> = self.pixels.to_vec();
            // A small deterministic generator: the same input gives the same planes.
            let mut state = 0x9E37_79B9_7F4A_7C15u64 ^ self.pixels.len() as u64;
            let mut next = |bound: usize| {
                state = state
                    .wrapping_mul(6_364_136_223_846_793_005)
                    .wrapping_add(1_442_695_040_888_963_407);
                ((state >> 33) as usize) % bound.max(1)
            };
            let band_m = band.at(self.centroid);
            let on = |(normal, d): (Vec3, f32), i: u32| {
                (normal.dot(points[i as usize]) - d).abs() <= band_m
            };
            for _ in 0..2 {
                if (rest.len() as f32) < MIN_PLANE_SHARE * n || rest.len() < 3 {
                    break;
                }
                let mut best: Option<(usize, Vec3, f32)> = None;
                for _ in 0..48 {
                    let (a, b, c) = (
                        points[rest[next(rest.len())] as usize],
                        points[rest[next(rest.len())] as usize],
                        points[rest[next(rest.len())] as usize],
                    );
                    let Some(normal) = (b - a).cross(c - a).try_normalize() else {
                        continue;
                    };
                    let d = normal.dot(a);
                    let count = rest.iter().filter(|&&i| on((normal, d), i)).count();
                    if best.is_none_or(|(m, _, _)| count > m) {
                        best = Some((count, normal, d));
                    }
                }
                let Some((_, normal, d)) = best else {
                    break;
                };
                let (inliers, outliers): (Vec<u32>, Vec<u32>) =
                    rest.iter().partition(|&&i| on((normal, d), i));
                if (inliers.len() as f32) < MIN_PLANE_SHARE * n {
                    break;
                }
                if let Some(plane) = fit_plane(points, &inliers) {
                    planes.push(plane);
                }
                rest = outliers;
            }
            planes
        })
    }
}

/// A plane of either piece that both lie on: [`MIN_PLANE_SHARE`] of each piece's points
/// within three plane bands of it, on average within [`SAME_PLANE_BANDS`].
fn shared_plane(
    points: &[Vec3],
    a: &Piece,
    b: &Piece,
    band: &RangeDistance,
) -> Option<(Vec3, f32)> {
    let on = |piece: &Piece, (n, d): (Vec3, f32)| {
        let near: Vec<f32> = piece
            .pixels
            .iter()
            .map(|&i| (n.dot(points[i as usize]) - d).abs() / band.at(points[i as usize]))
            .filter(|&bands| bands <= 3.0)
            .collect();
        let share = near.len() as f32 / piece.pixels.len().max(1) as f32;
        let mean = near.iter().sum::<f32>() / near.len().max(1) as f32;
        share >= MIN_PLANE_SHARE && mean <= SAME_PLANE_BANDS
    };
    a.planes(points, band)
        .iter()
        .chain(b.planes(points, band))
        .copied()
        .find(|&plane| on(a, plane) && on(b, plane))
}

/// Whether no pixel on the image line between the nearest pixels of `a` and `b` lies beyond
/// `plane` along its ray (which would see through where the surface joining them would be),
/// and at least one is nearer than it (the occluder).
#[allow(clippy::too_many_arguments)]
fn only_nearer_between(
    points: &[Vec3],
    width: usize,
    labels: &[u32],
    a: &Piece,
    b: &Piece,
    (label_a, label_b): (u32, u32),
    (normal, d): (Vec3, f32),
    viewpoint: Vec3,
) -> bool {
    let at = |i: u32| ((i as usize % width) as i64, (i as usize / width) as i64);
    // The nearest pair of pixels, on a sample of each piece's pixels.
    let sample = |p: &Piece| -> Vec<(i64, i64, u32)> {
        let step = p.pixels.len().div_ceil(NEAREST_SAMPLE).max(1);
        p.pixels
            .iter()
            .step_by(step)
            .map(|&i| {
                let (u, v) = at(i);
                (u, v, i)
            })
            .collect()
    };
    let (sa, sb) = (sample(a), sample(b));
    let mut best = (i64::MAX, 0u32, 0u32);
    for &(ui, vi, i) in &sa {
        for &(uj, vj, j) in &sb {
            let d2 = (ui - uj).pow(2) + (vi - vj).pow(2);
            if d2 < best.0 {
                best = (d2, i, j);
            }
        }
    }
    let ((u0, v0), (u1, v1)) = (at(best.1), at(best.2));
    let steps = (u1 - u0).abs().max((v1 - v0).abs());
    let mut occluded = 0;
    for s in 0..=steps {
        let t = s as f64 / steps.max(1) as f64;
        let u = (u0 as f64 + t * (u1 - u0) as f64).round() as usize;
        let v = (v0 as f64 + t * (v1 - v0) as f64).round() as usize;
        let i = v * width + u;
        let label = labels[i];
        if label == label_a + 1 || label == label_b + 1 {
            continue;
        }
        let p = points[i];
        if !p.is_finite() {
            continue;
        }
        // Where this pixel's ray meets the plane, as a multiple of the way to the point.
        let ray = p - viewpoint;
        let across = normal.dot(ray);
        if across.abs() < 1e-6 {
            return false;
        }
        let (to_plane, to_point) = (
            (d - normal.dot(viewpoint)) / across * ray.length(),
            ray.length(),
        );
        // Seen through where the surface would be: it is not there.
        if to_point > to_plane + IN_FRONT_M {
            return false;
        }
        if to_point + IN_FRONT_M < to_plane {
            occluded += 1;
        }
    }
    occluded > 0
}

/// Whether `far` is the inner far wall of the container whose outer near wall is `near` (see
/// the module docs).
fn inside_the_near_wall(
    points: &[Vec3],
    near: &Piece,
    far: &Piece,
    config: &SegmentConfig,
    up: Vec3,
) -> bool {
    if far.range_m <= near.range_m {
        return false;
    }
    let up = up.normalize_or_zero();
    if up == Vec3::ZERO {
        return false;
    }
    let (e1, e2) = up.any_orthonormal_pair();
    let foot = |p: Vec3| (p.dot(e1) as f64, p.dot(e2) as f64);
    // Kåsa's algebraic circle fit to the near wall's footprint: x² + y² + D x + E y + F = 0.
    let mut m = DMat3::ZERO;
    let mut rhs = DVec3::ZERO;
    for &i in near.pixels {
        let (x, y) = foot(points[i as usize]);
        let row = DVec3::new(x, y, 1.0);
        m += DMat3::from_cols(row * row.x, row * row.y, row * row.z);
        rhs -= row * (x * x + y * y);
    }
    if m.determinant().abs() <= 1e-18 {
        return false;
    }
    let [dx, ey, f] = (m.inverse() * rhs).to_array();
    let (cx, cy) = (-dx / 2.0, -ey / 2.0);
    let radius_sq = cx * cx + cy * cy - f;
    if radius_sq.is_nan() || radius_sq <= 0.0 {
        return false;
    }
    let radius = radius_sq.sqrt() as f32;
    if !(CIRCLE_RADIUS_M.0..=CIRCLE_RADIUS_M.1).contains(&radius) {
        return false;
    }
    // The arc faces the sensor: its centre is beyond the near wall, seen from the sensor.
    let (vx, vy) = foot(config.viewpoint_m);
    let (nx, ny) = foot(near.centroid);
    if (cx - nx) * (nx - vx) + (cy - ny) * (ny - vy) <= 0.0 {
        return false;
    }
    let from_centre = |p: Vec3| {
        let (x, y) = foot(p);
        ((x - cx).powi(2) + (y - cy).powi(2)).sqrt() as f32
    };
    // A wall: its footprint is a ring around the centre, not a disc (a box's top fits a
    // circle too, but covers its centre), and it runs around a quarter of the circle.
    let mut hollow = 0usize;
    let (mut widest, mut lo_angle, mut hi_angle) = (0.0f32, f64::INFINITY, f64::NEG_INFINITY);
    let facing = (ny - cy).atan2(nx - cx);
    for &i in near.pixels {
        let p = points[i as usize];
        let r = from_centre(p);
        widest = widest.max(r);
        if r >= HOLLOW * radius {
            hollow += 1;
        }
        let (x, y) = foot(p);
        // The angle around the centre from the wall's middle, in (−π, π].
        let mut angle = (y - cy).atan2(x - cx) - facing;
        if angle > std::f64::consts::PI {
            angle -= std::f64::consts::TAU;
        } else if angle <= -std::f64::consts::PI {
            angle += std::f64::consts::TAU;
        }
        lo_angle = lo_angle.min(angle);
        hi_angle = hi_angle.max(angle);
    }
    if (hollow as f32) < INSIDE_SHARE * near.pixels.len() as f32
        || !(MIN_ARC_RAD..=MAX_ARC_RAD).contains(&(hi_angle - lo_angle))
    {
        return false;
    }
    // The far piece is the back of the ring: beyond the centre, seen from the near wall.
    let (fx, fy) = foot(far.centroid);
    if (fx - cx) * (cx - nx) + (fy - cy) * (cy - ny) <= 0.0 {
        return false;
    }
    let inside = far
        .pixels
        .iter()
        .filter(|&&i| from_centre(points[i as usize]) <= widest + CIRCLE_TOLERANCE_M)
        .count();
    if (inside as f32) < INSIDE_SHARE * far.pixels.len() as f32 {
        return false;
    }
    // No higher than the near wall's top.
    let top = |p: &Piece| {
        p.pixels
            .iter()
            .map(|&i| points[i as usize].dot(up))
            .fold(f32::NEG_INFINITY, f32::max)
    };
    top(far) <= top(near) + CIRCLE_TOLERANCE_M
}

/// The inner bottoms of containers: support pixels (label 0, near a support) that objects
/// enclose in the image, raised above the support by more than its noise (the bottom's
/// thickness) where the table seen through a mug's handle is not. They went to the support
/// with its band and margin. Returns each bottom's pixels (finite ones) and the labels that
/// enclose it (those with at least [`MIN_CONTACT_SHARE`] of its border: the container's
/// walls, which may be two pieces).
fn inner_bottoms(
    points: &[Vec3],
    width: usize,
    labels: &[u32],
    band: &RangeDistance,
    supports: &[SupportPlane],
) -> Vec<(Vec<u32>, Vec<u32>)> {
    let mut bottoms = Vec::new();
    if width == 0 || supports.is_empty() {
        return bottoms;
    }
    let height = labels.len() / width;
    let mut seen = vec![false; labels.len()];
    let mut stack = Vec::new();
    for start in 0..labels.len() {
        if seen[start] || labels[start] != 0 {
            continue;
        }
        // One 4-connected component of unlabelled pixels, its contacts with each label around
        // it, and whether it reaches the image's border.
        let mut component = Vec::new();
        let mut around: FxHashMap<u32, usize> = FxHashMap::default();
        let mut enclosed = true;
        seen[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            component.push(i);
            let (u, v) = (i % width, i / width);
            if u == 0 || v == 0 || u + 1 == width || v + 1 == height {
                enclosed = false;
            }
            let neighbours = [
                (u > 0).then(|| i - 1),
                (u + 1 < width).then(|| i + 1),
                (v > 0).then(|| i - width),
                (v + 1 < height).then(|| i + width),
            ];
            for j in neighbours.into_iter().flatten() {
                match labels[j] {
                    0 if !seen[j] => {
                        seen[j] = true;
                        stack.push(j);
                    }
                    0 => {}
                    label => *around.entry(label).or_default() += 1,
                }
            }
        }
        let contacts: usize = around.values().sum();
        let mut walls: Vec<u32> = around
            .iter()
            .filter(|&(_, &n)| n as f32 >= MIN_CONTACT_SHARE * contacts as f32)
            .map(|(&label, _)| label)
            .collect();
        walls.sort_unstable();
        let walled: usize = walls.iter().map(|l| around[l]).sum();
        // Enclosed: nowhere the image's border, and (nearly) all around by its walls.
        if !enclosed
            || component.len() < MIN_BOTTOM_PIXELS
            || walls.is_empty()
            || walls.len() > MAX_WALL_PIECES
            || (walled as f32) < ENCLOSED_SHARE * contacts as f32
        {
            continue;
        }
        // Raised above the support under it: the median height over the nearest support,
        // against the plane band there.
        let finite: Vec<u32> = component
            .iter()
            .filter(|&&i| points[i].is_finite())
            .map(|&i| i as u32)
            .collect();
        let mut raised: Vec<f32> = finite
            .iter()
            .filter_map(|&i| {
                let p = points[i as usize];
                supports
                    .iter()
                    .map(|s| s.signed_distance_m(p))
                    .filter(|d| d.abs() <= 3.0 * band.at(p))
                    .min_by(|a, b| a.abs().total_cmp(&b.abs()))
                    .map(|d| d / band.at(p))
            })
            .collect();
        if raised.is_empty() {
            continue;
        }
        let middle = raised.len() / 2;
        let median = *raised.select_nth_unstable_by(middle, f32::total_cmp).1;
        if median >= RAISED_BANDS {
            bottoms.push((finite, walls));
        }
    }
    bottoms
}
