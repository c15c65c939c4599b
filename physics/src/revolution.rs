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
const AROUND: u32 = 16;
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
}

/// A surface sample: where, and the normal of the triangle it is on.
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
/// little of it was seen to tell. `scatter_m` is how far the data the shell was made from
/// scatter about their surface (the fused points' roughness; 0 when unknown): the shell's walls
/// may stray from one radius per height by the bound and that much.
pub fn revolve(
    shell: &TriMesh,
    support: SupportPlane,
    bound_m: f32,
    scatter_m: f32,
) -> Option<Revolved> {
    let up = support.normal.try_normalize()?;
    if bound_m.is_nan() || bound_m <= 0.0 {
        return None;
    }
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
    for s in samples.iter().filter(|s| horizontal(s)) {
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
    for k in 0..slices {
        if wall_outer[k].1 > 0 {
            outer[k] = wall_outer[k].0 / wall_outer[k].1 as f32;
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
    // The hollow: rings from the top down through the slices with an inward wall, then on
    // down with the last inner radius unless a floor was seen inside it.
    let mut hollow = vec![0.0f32; slices];
    let mut radius = None;
    for k in (0..slices).rev() {
        // A ring: nothing seen near the axis, and its inner radius well inside its outer.
        if inner[k].is_finite() && inner[k] > 2.0 * bound_m && outer[k] - inner[k] > 2.0 * bound_m {
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
    let profile = profile(&outer, &hollow, cap, cap_height, dh);
    let mesh = turned(&profile, axis_point, up, u, v);
    Some(Revolved {
        mesh,
        axis_point,
        axis: up,
        explained: share,
    })
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
    let mut polygon = vec![Vec2::new(outer[0], 0.0)];
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
        let revolved = revolve(&shell, TABLE, 0.004, 0.0).expect("a solid of revolution");
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
        assert_eq!(revolve(&seen_from(&cube, eye), TABLE, 0.004, 0.0), None);
    }

    /// A cylinder seen from the side and above is a disc in every slice: solid to its axis.
    #[test]
    fn a_standing_drum_is_solid_to_its_axis() {
        let drum = placed(
            &tacmesh_sim::cylinder(48, 0.08, 0.2),
            Vec3::new(0.0, 0.0, 0.1),
        );
        let shell = seen_from(&drum, Vec3::new(0.0, -1.0, 0.8));
        let revolved = revolve(&shell, TABLE, 0.004, 0.0).expect("a solid of revolution");
        let truth = MassProperties::of_closed_mesh(&drum).expect("closed");
        let got = MassProperties::of_closed_mesh(&revolved.mesh).expect("closed");
        let ratio = got.volume_m3 / truth.volume_m3;
        assert!((0.9..1.15).contains(&ratio), "{ratio}×");
        assert!(got.centre_of_mass.distance(truth.centre_of_mass) < 0.01);
    }
}
