//! Completing a one-view shell by its symmetry: an object that is a solid of revolution about
//! an axis along its support's normal (a mug, a bottle, a bowl, a torus lying flat, a cone) is
//! the seen shell turned about that axis. The camera sees one side; the other is the same.
//!
//! The axis is found from the seen walls (the surface whose normal points away from or
//! toward the axis): a wall's horizontal normal lies along the radius, so the axis is where
//! the walls' normal lines meet (least squares). The shell is a solid of revolution when, in each slice, the walls
//! lie within the bound of the slice's outermost radius (outward walls) or innermost
//! (inward walls, seen through an opening), and the outward wall spans a quarter turn or more
//! about the axis. Each slice's solid is the ring from its innermost to its outermost radius,
//! or the whole disc when no inward wall was seen in it or above it. Below the lowest slice
//! with an inward wall, the hollow goes on down to the support (a torus's hole, a ring's)
//! unless a floor was seen inside it (an upward face within the inner radius: a mug's
//! bottom). The profile's closed polygon (outer wall up through the slices' middles, across
//! the top, inner wall down, across the bottom) turned about the axis is the completed solid,
//! closed and outward.
//!
//! The project's own: no crate completes partial scans by symmetry.

use glam::{Vec2, Vec3};
use tacmesh_source::TriMesh;

use crate::proxy::SupportPlane;

/// Sides of the completed solid around its axis.
const AROUND: u32 = 32;
/// The most slices the profile has.
const MAX_SLICES: usize = 12;
/// The fewest wall points a slice needs to count.
const MIN_SLICE_POINTS: usize = 4;
/// How much of the wall must lie on the slice's radii for the shell to be one of revolution.
const MIN_EXPLAINED: f32 = 0.8;
/// The least turn about the axis the outward wall must span, radians.
const MIN_ARC: f32 = std::f32::consts::FRAC_PI_2;
/// How much of a point's normal must be radial for it to be part of a wall.
const WALL_NORMAL: f32 = 0.7;

/// A one-view shell completed by turning it about an axis.
#[derive(Debug, Clone, PartialEq)]
pub struct Revolved {
    /// The completed solid, closed, counter-clockwise seen from outside, in the shell's frame.
    pub mesh: TriMesh,
    /// Where the axis meets the support, and its direction (the support's normal).
    pub axis_point: Vec3,
    pub axis: Vec3,
    /// The share of the seen walls within the bound of their slice's radii.
    pub explained: f32,
    /// The closed profile polygon the solid is turned from: (radius, height above the support).
    pub profile: Vec<Vec2>,
    /// Two directions across the axis, with it a right-handed frame (the profile's angle 0 is
    /// along the first).
    pub across: (Vec3, Vec3),
}

impl Revolved {
    /// Whether the completed solid lies within the closed `container` (a solid known to hold
    /// the object: its proxy) up to `bound_m`, as [`crate::lies_within`] asks of a primitive.
    pub fn lies_within(
        &self,
        container: &TriMesh,
        support: Option<SupportPlane>,
        bound_m: f32,
    ) -> Result<(), String> {
        let volume = crate::MassProperties::of_closed_mesh(&self.mesh)
            .map_err(|e| format!("the completed solid has no volume ({e})"))?
            .volume_m3;
        // Each face's corners and centroid, in along its normal.
        let surface: Vec<(Vec3, Vec3)> = samples(&self.mesh)
            .into_iter()
            .map(|s| (s.p, -s.normal))
            .collect();
        crate::primitive::within(volume, &surface, container, support, bound_m)
    }

    /// The solid's convex parts by its structure, each as the points whose hull it is: the
    /// profile cut into bands at its vertices' heights, neighbouring bands joined while their
    /// union stays convex within `tolerance_m`; a piece that reaches the axis is turned whole
    /// (a convex solid: a cone, a drum), a piece off it (a torus's ring, a mug's wall) is cut
    /// into wedges, as narrow as `max_parts` allows (one side of [`Self::mesh`] each at most;
    /// a convex polygon turned through a wedge lies within the hull of its copies at the
    /// wedge's sides). Empty when the profile is not one the bands can cut (two walls at one
    /// height on a side) or needs more parts.
    ///
    /// Why not the plane cuts every other solid gets: they know nothing of the axis, and on a
    /// torus a cut that leaves a flat ring of it as one part spans the hole with its hull.
    pub fn part_points(&self, tolerance_m: f32, max_parts: usize) -> Vec<Vec<Vec3>> {
        let Some(pieces) = convex_pieces(&self.profile, tolerance_m.max(0.0)) else {
            return Vec::new();
        };
        let (u, v) = self.across;
        let at = |q: Vec2, i: u32| {
            let a = std::f32::consts::TAU * (i % AROUND) as f32 / AROUND as f32;
            self.axis_point + self.axis * q.y + (u * a.cos() + v * a.sin()) * q.x
        };
        // Neighbouring pieces off the axis go round together, wedge by wedge (the hull of a
        // wedge of both bridges only the small dent between them), so that the parts fit in
        // `max_parts` with wedges as narrow as they can be.
        let mut turned_whole: Vec<&ProfilePiece> = Vec::new();
        let mut rings: Vec<Vec<Vec2>> = Vec::new();
        let mut last_off_axis = false;
        for piece in &pieces {
            if piece.on_axis {
                turned_whole.push(piece);
            } else {
                let outline = piece.right.iter().chain(&piece.left).copied();
                match rings.last_mut() {
                    Some(ring) if last_off_axis => ring.extend(outline),
                    _ => rings.push(outline.collect()),
                }
            }
            last_off_axis = !piece.on_axis;
        }
        let room = max_parts.saturating_sub(turned_whole.len());
        if !rings.is_empty() && room < rings.len() {
            return Vec::new();
        }
        // As many wedges as fit, a divisor of the sides around.
        let mut wedges = AROUND;
        while wedges > 1 && rings.len() * wedges as usize > room {
            wedges /= 2;
        }
        let span = AROUND / wedges;
        let mut parts = Vec::new();
        for piece in turned_whole {
            let mut points = Vec::new();
            for &q in &piece.right {
                if q.x <= 1e-7 {
                    points.push(at(q, 0));
                } else {
                    points.extend((0..AROUND).map(|i| at(q, i)));
                }
            }
            parts.push(points);
        }
        for ring in &rings {
            for w in 0..wedges {
                parts.push(
                    ring.iter()
                        .flat_map(|&q| (w * span..=(w + 1) * span).map(move |i| (q, i)))
                        .map(|(q, i)| at(q, i))
                        .collect(),
                );
            }
        }
        parts
    }
}

/// A convex piece of a profile: its outer chain bottom to top and its inner chain top to
/// bottom (on the axis: radius 0 all the way).
#[derive(Debug)]
struct ProfilePiece {
    right: Vec<Vec2>,
    left: Vec<Vec2>,
    on_axis: bool,
}

/// The closed `profile` polygon cut into horizontal bands at its vertices' heights (each band
/// a trapezoid between the polygon's two edges that span it), neighbouring bands joined while
/// both chains stay convex within `tolerance_m` and on the same side of the axis. `None` when
/// some band is not spanned by exactly two edges.
fn convex_pieces(profile: &[Vec2], tolerance_m: f32) -> Option<Vec<ProfilePiece>> {
    const EPS: f32 = 1e-6;
    let mut heights: Vec<f32> = profile.iter().map(|q| q.y).collect();
    heights.sort_by(f32::total_cmp);
    heights.dedup_by(|a, b| (*a - *b).abs() < EPS);
    let edges: Vec<(Vec2, Vec2)> = (0..profile.len())
        .map(|i| (profile[i], profile[(i + 1) % profile.len()]))
        .filter(|(a, b)| (a.y - b.y).abs() >= EPS)
        .collect();
    let mut pieces: Vec<ProfilePiece> = Vec::new();
    for w in heights.windows(2) {
        let (z0, z1) = (w[0], w[1]);
        // The radii at both heights of each edge that spans the band.
        let mut spans: Vec<(f32, f32)> = edges
            .iter()
            .filter(|(a, b)| a.y.min(b.y) <= z0 + EPS && a.y.max(b.y) >= z1 - EPS)
            .map(|(a, b)| {
                let r = |z: f32| (a.x + (b.x - a.x) * (z - a.y) / (b.y - a.y)).max(0.0);
                (r(z0), r(z1))
            })
            .collect();
        if spans.len() != 2 {
            return None;
        }
        spans.sort_by(|p, q| (p.0 + p.1).total_cmp(&(q.0 + q.1)));
        let (left, right) = (spans[0], spans[1]);
        let on_axis = left.0 <= EPS && left.1 <= EPS;
        let band = ProfilePiece {
            right: vec![Vec2::new(right.0, z0), Vec2::new(right.1, z1)],
            left: vec![Vec2::new(left.1, z1), Vec2::new(left.0, z0)],
            on_axis,
        };
        if let Some(last) = pieces.last_mut() {
            if last.on_axis == on_axis && joins(last, &band, tolerance_m) {
                last.right.push(band.right[1]);
                last.left.insert(0, band.left[0]);
                continue;
            }
        }
        pieces.push(band);
    }
    Some(pieces)
}

/// Whether `band` continues `piece` upward with both chains still convex within
/// `tolerance_m`: no point of the outer chain inside a chord between two others (by more than
/// the tolerance, across the height), none of the inner chain outside one.
fn joins(piece: &ProfilePiece, band: &ProfilePiece, tolerance_m: f32) -> bool {
    let continuous = |a: Vec2, b: Vec2| a.distance(b) < 1e-5;
    if !continuous(piece.right[piece.right.len() - 1], band.right[0])
        || !continuous(piece.left[0], band.left[1])
    {
        return false;
    }
    let mut right = piece.right.clone();
    right.push(band.right[1]);
    let mut left: Vec<Vec2> = piece.left.iter().rev().copied().collect();
    left.push(band.left[0]);
    // `sign` 1: the chain bulges outward (an outer wall); -1: inward (an inner wall).
    let convex = |chain: &[Vec2], sign: f32| {
        for i in 0..chain.len() {
            for j in i + 2..chain.len() {
                let (a, b) = (chain[i], chain[j]);
                for q in &chain[i + 1..j] {
                    let t = (q.y - a.y) / (b.y - a.y);
                    let chord = a.x + (b.x - a.x) * t;
                    if sign * (chord - q.x) > tolerance_m {
                        return false;
                    }
                }
            }
        }
        true
    };
    convex(&right, 1.0) && convex(&left, -1.0)
}

/// A surface sample: where, and the normal of the triangle it is on.
#[derive(Debug, Clone, Copy)]
struct Sample {
    p: Vec3,
    normal: Vec3,
}

/// Each triangle's corners and centroid with its normal (a simplified shell has few
/// vertices on large triangles: the centroids fill them in).
fn samples(mesh: &TriMesh) -> Vec<Sample> {
    let mut out = Vec::new();
    for t in &mesh.triangles {
        let corner = |k: usize| mesh.vertices.get(t[k] as usize).copied();
        let (Some(a), Some(b), Some(c)) = (corner(0), corner(1), corner(2)) else {
            continue;
        };
        let Some(normal) = (b - a).cross(c - a).try_normalize() else {
            continue;
        };
        for p in [
            a,
            b,
            c,
            (a + b + c) / 3.0,
            (a + b) * 0.5,
            (b + c) * 0.5,
            (c + a) * 0.5,
        ] {
            out.push(Sample { p, normal });
        }
    }
    out
}

/// The centre about which the wall points (bin, side: outward 0 or inward 1, where across
/// the axis) keep one radius per bin and side best: Gauss–Newton on the points' distances
/// from the centre, each bin and side's own radius eliminated (its mean), from `start`;
/// points farther than `tolerance_m` from their bin and side's median radius left out.
/// `start` when the walls do not pin a centre down.
fn common_centre(
    walls: &[(usize, usize, Vec2)],
    bins: usize,
    start: Vec2,
    tolerance_m: f32,
) -> Vec2 {
    let mut centre = start.as_dvec2();
    let trim = f64::from(tolerance_m);
    for _ in 0..12 {
        let measured: Vec<(usize, usize, f64, glam::DVec2)> = walls
            .iter()
            .filter_map(|&(bin, side, p)| {
                let d = p.as_dvec2() - centre;
                let r = d.length();
                (r > 1e-9 && bin < bins && side < 2).then(|| (bin, side, r, d / r))
            })
            .collect();
        // Each bin and side's median radius: points farther from it than the tolerance (a
        // mug's handle beside its wall) are left out from the first step.
        let mut radii = vec![[Vec::new(), Vec::new()]; bins];
        for &(bin, side, r, _) in &measured {
            radii[bin][side].push(r);
        }
        let medians: Vec<[Option<f64>; 2]> = radii
            .iter_mut()
            .map(|sides| {
                sides.each_mut().map(|r: &mut Vec<f64>| {
                    (r.len() >= 3).then(|| {
                        r.sort_by(f64::total_cmp);
                        r[r.len() / 2]
                    })
                })
            })
            .collect();
        let kept: Vec<&(usize, usize, f64, glam::DVec2)> = measured
            .iter()
            .filter(|(bin, side, r, _)| medians[*bin][*side].is_some_and(|m| (r - m).abs() <= trim))
            .collect();
        // Each bin and side's mean radius and mean direction, of the points kept.
        let mut sums = vec![[(0.0f64, glam::DVec2::ZERO, 0u32); 2]; bins];
        for &&(bin, side, r, dir) in &kept {
            let s = &mut sums[bin][side];
            s.0 += r;
            s.1 += dir;
            s.2 += 1;
        }
        // r(c + δ) ≈ r − dir·δ: the step that best evens each group's radii.
        let (mut m, mut rhs, mut used) = (glam::DMat2::ZERO, glam::DVec2::ZERO, 0usize);
        for &&(bin, side, r, dir) in &kept {
            let (sr, sd, n) = sums[bin][side];
            if n < 3 {
                continue;
            }
            let e = r - sr / f64::from(n);
            let a = dir - sd / f64::from(n);
            m += glam::DMat2::from_cols(a * a.x, a * a.y);
            rhs += a * e;
            used += 1;
        }
        if used < 2 * MIN_SLICE_POINTS || m.determinant().abs() < 1e-12 {
            return start;
        }
        let step = m.inverse() * rhs;
        if !step.is_finite() {
            return start;
        }
        centre += step;
        if step.length() < 1e-6 {
            break;
        }
    }
    // A centre that ran off (walls too straight to pin one) is no better than the start.
    let moved = centre.as_vec2();
    if moved.is_finite() && moved.distance(start) < 10.0 * tolerance_m {
        moved
    } else {
        start
    }
}

/// The most fused points a shell's walls are measured at (evenly thinned past it).
const MAX_WALL_POINTS: usize = 1024;

/// Each of `points` (at most [`MAX_WALL_POINTS`], evenly thinned) with the normal of the
/// nearest of the shell's `samples`: looked up in a grid of cells `cell_m` wide (the nearest
/// within one cell is the nearest of all; farther, all samples are searched). A room's shell
/// has thousands of samples: a search of them all for every point took 40 ms a body.
fn with_nearest_normals(points: &[Vec3], samples: &[Sample], cell_m: f32) -> Vec<Sample> {
    if samples.is_empty() || cell_m.is_nan() || cell_m <= 0.0 || cell_m.is_infinite() {
        return Vec::new();
    }
    let cell_of = |p: Vec3| {
        let c = (p / cell_m).floor();
        // Far beyond any scene: clamped, so the key is always defined (a clamped cell is
        // only a coarser one, and the search below stays exact).
        let c = c.clamp(Vec3::splat(-1e6), Vec3::splat(1e6));
        (c.x as i32, c.y as i32, c.z as i32)
    };
    let mut grid: rustc_hash::FxHashMap<(i32, i32, i32), Vec<usize>> =
        rustc_hash::FxHashMap::default();
    for (i, s) in samples.iter().enumerate() {
        if s.p.is_finite() {
            grid.entry(cell_of(s.p)).or_default().push(i);
        }
    }
    let nearest_of_all = |p: Vec3| {
        samples
            .iter()
            .min_by(|a, b| a.p.distance_squared(p).total_cmp(&b.p.distance_squared(p)))
    };
    let step = points.len().div_ceil(MAX_WALL_POINTS).max(1);
    points
        .iter()
        .step_by(step)
        .filter(|p| p.is_finite())
        .filter_map(|&p| {
            let (x, y, z) = cell_of(p);
            let mut best: Option<(f32, usize)> = None;
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        let Some(near) = grid.get(&(x + dx, y + dy, z + dz)) else {
                            continue;
                        };
                        for &i in near {
                            let d = samples[i].p.distance_squared(p);
                            if best.is_none_or(|(b, _)| d < b) {
                                best = Some((d, i));
                            }
                        }
                    }
                }
            }
            let nearest = match best {
                Some((d, i)) if d <= cell_m * cell_m => &samples[i],
                _ => nearest_of_all(p)?,
            };
            Some(Sample {
                p,
                normal: nearest.normal,
            })
        })
        .collect()
}

/// A circle through 2-D points, Kåsa's algebraic fit (least squares on x² + y² + D x + E y +
/// F = 0, about the mean for conditioning): its centre.
fn circle(points: &[Vec2]) -> Option<Vec2> {
    if points.len() < 3 {
        return None;
    }
    let mean = points.iter().copied().sum::<Vec2>() / points.len() as f32;
    let (mut m, mut rhs) = (glam::DMat3::ZERO, glam::DVec3::ZERO);
    for p in points {
        let q = (*p - mean).as_dvec2();
        let row = glam::DVec3::new(q.x, q.y, 1.0);
        m += glam::DMat3::from_cols(row * row.x, row * row.y, row * row.z);
        rhs -= row * q.length_squared();
    }
    if m.determinant().abs() < 1e-18 {
        return None;
    }
    let s = m.inverse() * rhs;
    let centre = glam::DVec2::new(-s.x / 2.0, -s.y / 2.0);
    centre.is_finite().then(|| centre.as_vec2() + mean)
}

/// The shell turned about an axis along the support's normal, if it is a solid of revolution
/// within `bound_m` (see the module's documentation). `None` when it is not, or when too
/// little of it was seen to tell.
///
/// `fused`: the points the shell was made from, fused (see [`crate::FusedPoints`]), if known.
/// The walls' radii are then theirs (each taking the normal of the shell's surface nearest
/// it): simplification leaves the shell's walls off the surface by up to the bound, and a
/// noisy cone's apex a blunt knob, where the points' median radius at each height is the
/// surface's. The walls may stray from one radius per height by the bound and the points'
/// roughness.
pub fn revolve(
    shell: &TriMesh,
    fused: Option<crate::FusedPoints<'_>>,
    support: SupportPlane,
    bound_m: f32,
) -> Option<Revolved> {
    let up = support.normal.try_normalize()?;
    if bound_m.is_nan() || bound_m <= 0.0 {
        return None;
    }
    let scatter_m = fused.map_or(0.0, |f| f.roughness_m);
    let tolerance_m = bound_m + crate::primitive::scatter_allowance_m(scatter_m);
    let u = up.any_orthonormal_vector();
    let v = up.cross(u);
    let flat = |p: Vec3| Vec2::new(p.dot(u), p.dot(v));
    let samples = samples(shell);
    let top = samples
        .iter()
        .map(|s| support.height(s.p))
        .fold(f32::NEG_INFINITY, f32::max);
    if top.is_nan() || top <= 4.0 * bound_m {
        return None;
    }
    let slices = ((top / bound_m).floor() as usize).clamp(3, MAX_SLICES);
    let dh = top / slices as f32;
    let slice_of = |p: Vec3| ((support.height(p).max(0.0) / dh) as usize).min(slices - 1);
    // Outward walls, per slice, for the axis.
    let horizontal = |s: &Sample| {
        let n = s.normal - up * s.normal.dot(up);
        n.length() >= WALL_NORMAL
    };
    // A wall's horizontal normal points along the radius, to or from the axis: the axis is
    // where the walls' normal lines meet, in the least-squares sense (a 2 × 2 system).
    let (mut m, mut rhs) = (glam::DMat2::ZERO, glam::DVec2::ZERO);
    let mut lines = 0usize;
    for s in samples.iter().filter(|s| horizontal(s)) {
        let Some(n) = flat(s.normal).try_normalize() else {
            continue;
        };
        let n = n.as_dvec2();
        let across = glam::DMat2::IDENTITY - glam::DMat2::from_cols(n * n.x, n * n.y);
        m += across;
        rhs += across * flat(s.p).as_dvec2();
        lines += 1;
    }
    if lines < 2 * MIN_SLICE_POINTS || m.determinant().abs() < 1e-12 {
        return None;
    }
    let rough = (m.inverse() * rhs).as_vec2();
    // Then, the outward wall told from the inward by that centre, a circle through each
    // height's outward wall (Kåsa 1976): their median centre. A faceted shell's normals are
    // coarse; the points of a half-turn of wall are not.
    let bins = ((top / bound_m).ceil() as usize).max(1);
    let bin_of = |p: Vec3| ((support.height(p).max(0.0) / bound_m) as usize).min(bins - 1);
    let mut arcs: Vec<Vec<Vec2>> = vec![Vec::new(); bins];
    for s in samples.iter().filter(|s| horizontal(s)) {
        let d = flat(s.p) - rough;
        if flat(s.normal).dot(d) > 0.0 {
            arcs[bin_of(s.p)].push(flat(s.p));
        }
    }
    let mut centres: Vec<Vec2> = arcs
        .iter()
        .filter(|a| a.len() >= 2 * MIN_SLICE_POINTS)
        .filter_map(|a| circle(a))
        .filter(|c| c.distance(rough) < 0.5 * top.max(bound_m * 10.0))
        .collect();
    let centre = if centres.len() >= 2 {
        let mut xs: Vec<f32> = centres.iter().map(|c| c.x).collect();
        let mut ys: Vec<f32> = centres.iter().map(|c| c.y).collect();
        xs.sort_by(f32::total_cmp);
        ys.sort_by(f32::total_cmp);
        Vec2::new(xs[xs.len() / 2], ys[ys.len() / 2])
    } else {
        rough
    };
    centres.clear();
    let wall_samples = fused
        .map(|f| with_nearest_normals(f.points, &samples, bound_m))
        .filter(|w| w.len() >= 2 * MIN_SLICE_POINTS)
        .unwrap_or_else(|| samples.clone());
    // Then the centre every wall's height keeps one radius about best (geometric least
    // squares): the circles' centres scatter with the noise on a short arc.
    let walls_flat: Vec<(usize, usize, Vec2)> = wall_samples
        .iter()
        .filter(|s| horizontal(s))
        .map(|s| {
            let inward = flat(s.normal).dot(flat(s.p) - centre) <= 0.0;
            (bin_of(s.p), usize::from(inward), flat(s.p))
        })
        .collect();
    let centre = common_centre(&walls_flat, bins, centre, tolerance_m);

    // Each slice's radii, and whether its walls lie on them.
    let radial = |p: Vec3| flat(p) - centre;
    let mut outer = vec![0.0f32; slices];
    let mut inner = vec![f32::INFINITY; slices];
    for s in &samples {
        let k = slice_of(s.p);
        let r = radial(s.p).length();
        outer[k] = outer[k].max(r);
        inner[k] = inner[k].min(r);
    }
    // A solid of revolution has one radius at each height, whatever the angle: the walls,
    // in bins as high as the bound, outward and inward apart, must keep to their bin's
    // median radius.
    let mut radii: Vec<[Vec<f32>; 2]> = vec![[Vec::new(), Vec::new()]; bins];
    let mut angles = Vec::new();
    let mut walls = Vec::new();
    for s in wall_samples.iter().filter(|s| horizontal(s)) {
        let d = radial(s.p);
        let Some(out_dir) = d.try_normalize() else {
            continue;
        };
        let facing_out = flat(s.normal).dot(out_dir) > 0.0;
        if facing_out {
            angles.push(out_dir.y.atan2(out_dir.x));
        }
        let side = usize::from(!facing_out);
        radii[bin_of(s.p)][side].push(d.length());
        walls.push((bin_of(s.p), side, d.length()));
    }
    let medians: Vec<[Option<f32>; 2]> = radii
        .iter_mut()
        .map(|sides| {
            sides.each_mut().map(|r| {
                (r.len() >= 3).then(|| {
                    r.sort_by(f32::total_cmp);
                    r[r.len() / 2]
                })
            })
        })
        .collect();
    // A slice's radii are its walls' (the mean of its bins' medians: a stray vertex of the
    // shell does not widen the solid, and a sloping wall, a cone's, is met at the slice's
    // middle), where it has walls; else its outermost and innermost points.
    let mut wall_outer = vec![(0.0f32, 0u32); slices];
    let mut wall_inner = vec![(0.0f32, 0u32); slices];
    for (bin, sides) in medians.iter().enumerate() {
        let k = (((bin as f32 + 0.5) * bound_m / dh) as usize).min(slices - 1);
        if let Some(r) = sides[0] {
            wall_outer[k].0 += r;
            wall_outer[k].1 += 1;
        }
        if let Some(r) = sides[1] {
            wall_inner[k].0 += r;
            wall_inner[k].1 += 1;
        }
    }
    // A slice with no wall of its own but fused points in it (a noisy cone's apex, where the
    // shell is a blunt knob): its points' median radius, not the knob's widest.
    let mut slice_radii: Vec<Vec<f32>> = vec![Vec::new(); slices];
    if fused.is_some() {
        for s in &wall_samples {
            slice_radii[slice_of(s.p)].push(radial(s.p).length());
        }
    }
    for k in 0..slices {
        if wall_outer[k].1 > 0 {
            outer[k] = wall_outer[k].0 / wall_outer[k].1 as f32;
        } else if slice_radii[k].len() >= MIN_SLICE_POINTS {
            if let Some(r) = crate::primitive::percentile(&mut slice_radii[k], 50) {
                outer[k] = outer[k].min(r);
            }
        }
        if wall_inner[k].1 > 0 {
            inner[k] = wall_inner[k].0 / wall_inner[k].1 as f32;
        }
    }
    let (mut explained, mut walls_seen) = (0usize, 0usize);
    for (bin, side, r) in walls {
        if let Some(median) = medians[bin][side] {
            walls_seen += 1;
            if (r - median).abs() <= tolerance_m {
                explained += 1;
            }
        }
    }
    let share = explained as f32 / walls_seen.max(1) as f32;
    let turn = arc(&mut angles);
    if walls_seen < MIN_SLICE_POINTS * 2 || share < MIN_EXPLAINED || turn < MIN_ARC {
        tracing::debug!(
            "no solid of revolution: {walls_seen} wall points, {:.0} % on their slice's radii, \
             the outer wall over {:.0}°",
            share * 100.0,
            turn.to_degrees()
        );
        return None;
    }
    mirror_below_the_widest(&mut outer, &mut inner, &wall_outer, &wall_inner, dh);
    tracing::trace!(
        "turning: slices {slices} of {dh:.4} m, outer {outer:?} (walls {:?}), inner {inner:?} \
         (walls {:?})",
        wall_outer.iter().map(|w| w.1).collect::<Vec<_>>(),
        wall_inner.iter().map(|w| w.1).collect::<Vec<_>>()
    );
    // Slices with nothing seen take their neighbours' radii.
    for k in 0..slices {
        if outer[k] <= 0.0 {
            let near = (0..slices)
                .filter(|&j| outer[j] > 0.0)
                .min_by_key(|&j| j.abs_diff(k))?;
            outer[k] = outer[near];
            inner[k] = inner[near];
        }
    }
    // Each slice's outer radius is a median of noisy points over a slice not much taller than
    // the noise is wide: a [1, 2, 1] smoothing keeps a straight wall straight and a curved one
    // within a millimetre or two, where the raw radii tilt the walls' normals by tens of degrees.
    smooth(&mut outer);
    // The hollow: rings from the top down through the slices with an inward wall, then on
    // down with the last inner radius unless a floor was seen inside it.
    let mut hollow = vec![0.0f32; slices];
    let mut radius = None;
    for k in (0..slices).rev() {
        // A ring: nothing seen near the axis, and its inner radius well inside its outer, or
        // an inward wall seen there (a torus's crown is a narrow ring, not a disc).
        let away = inner[k].is_finite() && inner[k] > 2.0 * bound_m;
        if away && (outer[k] - inner[k] > 2.0 * bound_m || wall_inner[k].1 > 0) {
            radius = Some(inner[k]);
        } else if let Some(r) = radius {
            // A floor lies well inside the hollow: an upward face by its wall is the wall's
            // own rounded top (a torus's crest beside its hole), not a bottom.
            let floor = samples.iter().any(|s| {
                slice_of(s.p) == k
                    && s.normal.dot(up) > WALL_NORMAL
                    && radial(s.p).length() < r - 2.0 * bound_m
            });
            if floor {
                radius = None;
            }
        }
        if let Some(r) = radius {
            hollow[k] = r.min(outer[k] - 2.0 * bound_m).max(0.0);
        }
    }
    // The top: flat only as far as a face turned up was seen there (a cone's is a point, a
    // torus's a ring), so that the top slice is not a slab as wide as its widest wall.
    let hollow_top = hollow[slices - 1];
    // It stands at the median height of those faces: the highest point is a bump of the
    // shell's, and a flat top there stands above the rest of what was seen.
    let (mut cap_inner, mut cap_outer) = (f32::INFINITY, f32::NEG_INFINITY);
    let mut cap_heights = Vec::new();
    for s in &samples {
        if support.height(s.p) > top - dh && s.normal.dot(up) > WALL_NORMAL {
            let r = radial(s.p).length();
            cap_inner = cap_inner.min(r);
            cap_outer = cap_outer.max(r);
            cap_heights.push(support.height(s.p));
        }
    }
    let cap_height = crate::primitive::percentile(&mut cap_heights, 50)
        .map_or(top, |h| h.clamp(top - 0.5 * dh, top));
    let cap = if cap_outer >= cap_inner {
        let outer_edge = cap_outer.clamp(hollow_top, outer[slices - 1]);
        (cap_inner.clamp(hollow_top, outer_edge), outer_edge)
    } else if hollow_top > 0.0 {
        let middle = 0.5 * (hollow_top + outer[slices - 1]);
        (middle, middle)
    } else {
        (0.0, 0.0)
    };
    let axis_point = up * support.offset + u * centre.x + v * centre.y;
    for run in hollow.split_mut(|r| *r <= 0.0) {
        smooth(run);
    }
    let profile = profile(&outer, &hollow, cap, cap_height, dh);
    let mesh = turned(&profile, axis_point, up, u, v);
    Some(Revolved {
        mesh,
        axis_point,
        axis: up,
        explained: share,
        profile,
        across: (u, v),
    })
}

/// The slices below the lowest one with a wall seen (`walls_*[k].1`: how many of its bins had
/// walls) completed by a mirror plane across the axis at half the object's height, when the
/// seen outer wall is widest there (within a slice and a half): each takes the radii at its
/// mirror height, where that height was seen. An object resting on its support that is its
/// own mirror image across a level plane has that plane at half its height; one widest at the
/// lowest slice seen may widen on below it, and is left alone. A torus seen from
/// above shows its upper half; its lower half is that half upside down, not a ring as wide as
/// its widest, filled down to the table. An object widest elsewhere keeps its slices.
fn mirror_below_the_widest(
    outer: &mut [f32],
    inner: &mut [f32],
    walls_outer: &[(f32, u32)],
    walls_inner: &[(f32, u32)],
    dh: f32,
) {
    let n = outer.len();
    let seen = |k: usize| walls_outer[k].1 > 0;
    let middle = |k: usize| (k as f32 + 0.5) * dh;
    let Some(lowest) = (0..n).find(|&k| seen(k)) else {
        return;
    };
    let Some(widest) = (0..n)
        .filter(|&k| seen(k))
        .max_by(|&a, &b| outer[a].total_cmp(&outer[b]))
    else {
        return;
    };
    let plane = 0.5 * n as f32 * dh;
    // Widest at the lowest slice seen, the object may go on widening below it (a cone).
    if lowest == 0 || widest == lowest || (middle(widest) - plane).abs() > 1.5 * dh {
        return;
    }
    // The radii at a height, between the slices' middles, from seen slices only.
    let at = |radii: &[f32], walls: &[(f32, u32)], h: f32| -> Option<f32> {
        let x = h / dh - 0.5;
        let k = x.floor().max(0.0) as usize;
        let t = (x - k as f32).clamp(0.0, 1.0);
        let (a, b) = (k.min(n - 1), (k + 1).min(n - 1));
        (walls[a].1 > 0 && walls[b].1 > 0).then(|| radii[a] + (radii[b] - radii[a]) * t)
    };
    let (seen_outer, seen_inner) = (outer.to_vec(), inner.to_vec());
    for k in 0..lowest {
        if let Some(r) = at(&seen_outer, walls_outer, 2.0 * plane - middle(k)) {
            outer[k] = r;
            inner[k] =
                at(&seen_inner, walls_inner, 2.0 * plane - middle(k)).unwrap_or(f32::INFINITY);
        }
    }
}

/// `radii` smoothed in place by a [1, 2, 1] / 4 kernel, its two ends kept.
fn smooth(radii: &mut [f32]) {
    if radii.len() < 3 {
        return;
    }
    let raw = radii.to_vec();
    for k in 1..raw.len() - 1 {
        radii[k] = 0.25 * (raw[k - 1] + 2.0 * raw[k] + raw[k + 1]);
    }
}

/// The widest turn about the axis the angles span, radians (2π less the widest gap between
/// them).
fn arc(angles: &mut [f32]) -> f32 {
    if angles.len() < 2 {
        return 0.0;
    }
    angles.sort_by(f32::total_cmp);
    let wrap = angles[0] + std::f32::consts::TAU - angles[angles.len() - 1];
    let gap = angles.windows(2).map(|w| w[1] - w[0]).fold(wrap, f32::max);
    std::f32::consts::TAU - gap
}

/// The closed profile polygon in (radius, height): the outer wall up from the support through
/// each slice's outer radius at its middle, across the top between the `cap`'s radii (inner,
/// outer: where a face turned up was seen) at height `top`, the inner wall down through each ring's inner
/// radius while the slices are rings, to the axis (or, rings all the way down, along the
/// support), and down the axis (points on the axis have radius 0).
fn profile(outer: &[f32], inner: &[f32], cap: (f32, f32), top: f32, dh: f32) -> Vec<Vec2> {
    let n = outer.len();
    let middle = |k: usize| (k as f32 + 0.5) * dh;
    // The outer wall goes on down to the support as it leaves the lowest slice (a cone's
    // slope, not a step at the slice's middle), not inside the hollow.
    let base = if n >= 2 {
        (1.5 * outer[0] - 0.5 * outer[1])
            .max(inner[0] + 1e-4)
            .max(0.0)
    } else {
        outer[0]
    };
    let mut polygon = vec![Vec2::new(base, 0.0)];
    polygon.extend((0..n).map(|k| Vec2::new(outer[k], middle(k))));
    polygon.push(Vec2::new(cap.1, top));
    let mut k = n;
    if inner[n - 1] > 0.0 {
        polygon.push(Vec2::new(cap.0, top));
        polygon.push(Vec2::new(inner[n - 1], middle(n - 1)));
        k -= 1;
    }
    while k > 0 && inner[k - 1] > 0.0 {
        polygon.push(Vec2::new(inner[k - 1], middle(k - 1)));
        k -= 1;
    }
    if k > 0 {
        let height = if k == n { top } else { k as f32 * dh };
        polygon.push(Vec2::new(0.0, height));
        polygon.push(Vec2::new(0.0, 0.0));
    } else {
        polygon.push(Vec2::new(inner[0], 0.0));
    }
    polygon.dedup_by(|a, b| a.distance(*b) < 1e-7);
    if polygon.len() > 1 && polygon[0].distance(polygon[polygon.len() - 1]) < 1e-7 {
        polygon.pop();
    }
    polygon
}

/// The profile polygon turned about the axis through `base` along `up` (with `u`, `v` across
/// it): a ring of [`AROUND`] vertices for each profile point off the axis, a pole for each on
/// it; wound outward.
fn turned(profile: &[Vec2], base: Vec3, up: Vec3, u: Vec3, v: Vec3) -> TriMesh {
    let mut vertices = Vec::new();
    // Each profile point's first vertex, and whether it is a pole.
    let mut rings: Vec<(u32, bool)> = Vec::new();
    for q in profile {
        let start = vertices.len() as u32;
        if q.x <= 1e-7 {
            vertices.push(base + up * q.y);
            rings.push((start, true));
        } else {
            for i in 0..AROUND {
                let a = std::f32::consts::TAU * i as f32 / AROUND as f32;
                vertices.push(base + up * q.y + (u * a.cos() + v * a.sin()) * q.x);
            }
            rings.push((start, false));
        }
    }
    let mut triangles = Vec::new();
    for j in 0..rings.len() {
        let (a, a_pole) = rings[j];
        let (b, b_pole) = rings[(j + 1) % rings.len()];
        for i in 0..AROUND {
            let next = (i + 1) % AROUND;
            match (a_pole, b_pole) {
                (true, true) => {}
                (false, false) => {
                    triangles.push([a + i, a + next, b + next]);
                    triangles.push([a + i, b + next, b + i]);
                }
                (false, true) => triangles.push([a + i, a + next, b]),
                (true, false) => triangles.push([a, b + next, b + i]),
            }
        }
    }
    let mut mesh = TriMesh::new(vertices, triangles);
    // The profile's winding decides the faces' side: outward is positive volume.
    let volume: f64 = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize].as_dvec3());
            a.dot(b.cross(c)) / 6.0
        })
        .sum();
    if volume < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::MassProperties;

    const TABLE: SupportPlane = SupportPlane {
        normal: Vec3::Z,
        offset: 0.0,
    };

    /// The faces of `mesh` a camera at `eye` sees (their normals turned to it), as a shell.
    fn seen_from(mesh: &TriMesh, eye: Vec3) -> TriMesh {
        let triangles = mesh
            .triangles
            .iter()
            .copied()
            .filter(|t| {
                let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
                (b - a).cross(c - a).dot(eye - (a + b + c) / 3.0) > 0.0
            })
            .collect();
        TriMesh::new(mesh.vertices.clone(), triangles)
    }

    fn placed(mesh: &TriMesh, at: Vec3) -> TriMesh {
        TriMesh::new(
            mesh.vertices.iter().map(|&p| p + at).collect(),
            mesh.triangles.clone(),
        )
    }

    /// A torus lying on the table, seen from 45° above: turned about its axis, it weighs
    /// about what the torus does, centred where it is; a box is no solid of revolution.
    #[test]
    fn a_torus_seen_from_one_side_is_completed_by_turning_it() {
        let torus = placed(
            &tacmesh_sim::torus(48, 24, 0.15, 0.05),
            Vec3::new(0.2, 0.1, 0.05),
        );
        let eye = Vec3::new(0.2, -0.9, 0.95);
        let shell = seen_from(&torus, eye);
        let revolved = revolve(&shell, None, TABLE, 0.004).expect("a solid of revolution");
        let truth = MassProperties::of_closed_mesh(&torus).expect("closed");
        let got = MassProperties::of_closed_mesh(&revolved.mesh).expect("a closed solid");
        let ratio = got.volume_m3 / truth.volume_m3;
        let off = got.centre_of_mass.distance(truth.centre_of_mass);
        eprintln!(
            "torus: {ratio:.3}× its volume, centre {:.1} mm off",
            off * 1e3
        );
        assert!((0.7..1.5).contains(&ratio), "{ratio}×");
        assert!(off < 0.02, "{off} m off");
        assert!(revolved.mesh.is_closed());

        let cube = placed(&tacmesh_sim::cube(0.2), Vec3::new(0.0, 0.0, 0.1));
        assert_eq!(revolve(&seen_from(&cube, eye), None, TABLE, 0.004), None);
    }

    /// The turned solid's parts follow its axis: a torus's ring in wedges whose hulls hold
    /// little more than the solid (no hull across its hole), a drum in one.
    #[test]
    fn a_turned_solid_is_cut_into_wedges_around_its_hole() {
        let torus = placed(
            &tacmesh_sim::torus(48, 24, 0.15, 0.05),
            Vec3::new(0.2, 0.1, 0.05),
        );
        let shell = seen_from(&torus, Vec3::new(0.2, -0.9, 0.95));
        let revolved = revolve(&shell, None, TABLE, 0.004).expect("a solid of revolution");
        let parts = revolved.part_points(0.001, 16);
        assert_eq!(parts.len(), 16);
        let config = crate::ConvexConfig {
            max_hulls: 16,
            concavity: 0.0,
            ..crate::ConvexConfig::default()
        };
        let convex =
            crate::convex_parts_with(&revolved.mesh, &config, |_, _| Ok(parts)).expect("parts");
        let ratio = convex.volume_ratio();
        eprintln!("torus: {} hulls, {ratio:.3}× the solid", convex.hulls.len());
        assert!(ratio < 1.1, "{ratio}×");
        // No hull reaches the axis: the hole stays open.
        for hull in &convex.hulls {
            for p in &hull.vertices {
                let off = (*p - revolved.axis_point)
                    .reject_from(revolved.axis)
                    .length();
                assert!(off > 0.05, "a hull reaches {off} m from the axis");
            }
        }

        let drum = placed(
            &tacmesh_sim::cylinder(48, 0.08, 0.2),
            Vec3::new(0.0, 0.0, 0.1),
        );
        let shell = seen_from(&drum, Vec3::new(0.0, -1.0, 0.8));
        let revolved = revolve(&shell, None, TABLE, 0.004).expect("a solid of revolution");
        assert_eq!(revolved.part_points(0.001, 16).len(), 1);
    }

    /// Half-turns of two walls of different radii about (0.3, -0.2), seen from one side and
    /// started 4 cm off: the centre they share comes back to within a millimetre; a straight
    /// wall pins no centre down and leaves the start.
    #[test]
    fn the_walls_common_centre_is_found_from_half_turns() {
        let truth = Vec2::new(0.3, -0.2);
        let mut walls = Vec::new();
        for i in 0..40 {
            let a = std::f32::consts::PI * i as f32 / 39.0;
            let dir = Vec2::new(a.cos(), -a.sin());
            // A millimetre of alternating noise on the radius.
            let wobble = if i % 2 == 0 { 0.001 } else { -0.001 };
            walls.push((0, 0, truth + dir * (0.12 + wobble)));
            walls.push((1, 0, truth + dir * (0.08 - wobble)));
        }
        let start = truth + Vec2::new(0.03, 0.03);
        let found = common_centre(&walls, 2, start, 0.01);
        assert!(found.distance(truth) < 0.001, "{found}");

        let straight: Vec<(usize, usize, Vec2)> = (0..40)
            .map(|i| (0, 0, Vec2::new(i as f32 * 0.01, 0.5)))
            .collect();
        let kept = common_centre(&straight, 1, Vec2::ZERO, 0.01);
        assert!(kept.distance(Vec2::ZERO) < 0.1, "{kept}");
    }

    /// A cone's profile is one convex piece on its axis; a ring's, beside it, off the axis;
    /// a profile with a waist (a bottle's neck) is cut at the waist.
    #[test]
    fn profiles_are_cut_into_convex_pieces() {
        let cone = [
            Vec2::new(0.5, 0.0),
            Vec2::new(0.25, 0.5),
            Vec2::new(0.0, 1.0),
            Vec2::new(0.0, 0.0),
        ];
        let pieces = convex_pieces(&cone, 0.001).expect("cut");
        assert_eq!(pieces.len(), 1);
        assert!(pieces[0].on_axis);
        let ring = [
            Vec2::new(0.5, 0.0),
            Vec2::new(0.55, 0.1),
            Vec2::new(0.5, 0.2),
            Vec2::new(0.3, 0.2),
            Vec2::new(0.25, 0.1),
            Vec2::new(0.3, 0.0),
        ];
        let pieces = convex_pieces(&ring, 0.001).expect("cut");
        assert_eq!(pieces.len(), 1);
        assert!(!pieces[0].on_axis);
        let bottle = [
            Vec2::new(0.1, 0.0),
            Vec2::new(0.1, 0.2),
            Vec2::new(0.03, 0.25),
            Vec2::new(0.03, 0.3),
            Vec2::new(0.0, 0.3),
            Vec2::new(0.0, 0.0),
        ];
        let pieces = convex_pieces(&bottle, 0.001).expect("cut");
        assert_eq!(pieces.len(), 2, "{pieces:?}");
    }

    /// A ring's slices seen from its middle up (radii widest at half its height) are mirrored
    /// into the unseen slices below; a cone's (widest at its foot, where nothing was seen) keep
    /// theirs.
    #[test]
    fn unseen_lower_slices_mirror_the_upper_half() {
        let walls = |seen: &[bool]| -> Vec<(f32, u32)> {
            seen.iter().map(|&s| (0.0, u32::from(s))).collect()
        };
        let seen = walls(&[false, false, true, true, true, true]);
        let mut outer = vec![0.5, 0.5, 0.48, 0.5, 0.48, 0.42];
        let mut inner = vec![0.2, 0.2, 0.32, 0.3, 0.32, 0.38];
        mirror_below_the_widest(&mut outer, &mut inner, &seen, &seen, 0.1);
        // Slice 0 (middle 0.05) mirrors 0.55 (slice 5), slice 1 (0.15) mirrors 0.45 (slice 4).
        assert_eq!(&outer[..2], &[0.42, 0.48]);
        assert_eq!(&inner[..2], &[0.38, 0.32]);

        let mut outer = vec![0.5, 0.5, 0.4, 0.3, 0.2, 0.1];
        let mut inner = vec![0.0; 6];
        mirror_below_the_widest(&mut outer, &mut inner, &seen, &seen, 0.1);
        assert_eq!(outer[0], 0.5);
    }

    /// A cylinder seen from the side and above is a disc in every slice: solid to its axis.
    #[test]
    fn a_standing_drum_is_solid_to_its_axis() {
        let drum = placed(
            &tacmesh_sim::cylinder(48, 0.08, 0.2),
            Vec3::new(0.0, 0.0, 0.1),
        );
        let shell = seen_from(&drum, Vec3::new(0.0, -1.0, 0.8));
        let revolved = revolve(&shell, None, TABLE, 0.004).expect("a solid of revolution");
        let truth = MassProperties::of_closed_mesh(&drum).expect("closed");
        let got = MassProperties::of_closed_mesh(&revolved.mesh).expect("closed");
        let ratio = got.volume_m3 / truth.volume_m3;
        assert!((0.9..1.15).contains(&ratio), "{ratio}×");
        assert!(got.centre_of_mass.distance(truth.centre_of_mass) < 0.01);
    }
}
