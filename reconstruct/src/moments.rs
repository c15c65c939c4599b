//! First and second moments of a set of points, and the plane they fit.
//!
//! Moments are additive: the moments of a union are the sum of the moments of its parts. That
//! is what makes the fused state cheap to grow (add a new frame's points to their voxels) and
//! cheap to query at any scale (sum the voxels of a neighbourhood, then fit once).

use std::cmp::Ordering;
use std::ops::{AddAssign, SubAssign};

use glam::{DMat3, DVec3, Vec3};

/// Count, sum and sum of outer products of points, in f64 (metres, m²).
///
/// Absolute coordinates in f64 keep the covariance exact to ~1e-14 m² for scenes within 100 m
/// of the origin, far below any sensor's noise.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PointMoments {
    pub count: f64,
    pub sum: DVec3,
    /// Upper triangle of Σ p pᵀ: xx, xy, xz, yy, yz, zz.
    pub sum_outer: [f64; 6],
}

/// A fitted plane: a point on it and its unit normal (sign not yet meaningful).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Plane {
    pub point: Vec3,
    pub normal: Vec3,
}

impl PointMoments {
    pub fn add_point(&mut self, p: Vec3) {
        let p = p.as_dvec3();
        self.count += 1.0;
        self.sum += p;
        let o = &mut self.sum_outer;
        o[0] += p.x * p.x;
        o[1] += p.x * p.y;
        o[2] += p.x * p.z;
        o[3] += p.y * p.y;
        o[4] += p.y * p.z;
        o[5] += p.z * p.z;
    }

    /// The same points weighed by `factor` (moments scale linearly, so the centroid and
    /// covariance, and with them the plane, are unchanged; only the weight is). The fused
    /// state's forgetting (a weight cap, free-space carving) is this scaling.
    pub fn scaled(&self, factor: f64) -> PointMoments {
        PointMoments {
            count: self.count * factor,
            sum: self.sum * factor,
            sum_outer: self.sum_outer.map(|v| v * factor),
        }
    }

    pub fn centroid(&self) -> Option<Vec3> {
        (self.count > 0.0).then(|| (self.sum / self.count).as_vec3())
    }

    /// Covariance about the centroid, m².
    pub fn covariance(&self) -> DMat3 {
        if self.count <= 0.0 {
            return DMat3::ZERO;
        }
        let c = self.sum / self.count;
        let o = self.sum_outer.map(|v| v / self.count);
        let xx = o[0] - c.x * c.x;
        let xy = o[1] - c.x * c.y;
        let xz = o[2] - c.x * c.z;
        let yy = o[3] - c.y * c.y;
        let yz = o[4] - c.y * c.z;
        let zz = o[5] - c.z * c.z;
        DMat3::from_cols(
            DVec3::new(xx, xy, xz),
            DVec3::new(xy, yy, yz),
            DVec3::new(xz, yz, zz),
        )
    }

    /// The least-squares plane through the points (normal along the least spread), or `None`
    /// with fewer than three points.
    pub fn plane(&self) -> Option<Plane> {
        if self.count < 3.0 {
            return None;
        }
        Some(Plane {
            point: self.centroid()?,
            normal: least_spread_direction(self.covariance()).as_vec3(),
        })
    }
}

impl AddAssign<&PointMoments> for PointMoments {
    fn add_assign(&mut self, other: &PointMoments) {
        self.count += other.count;
        self.sum += other.sum;
        for (a, b) in self.sum_outer.iter_mut().zip(other.sum_outer) {
            *a += b;
        }
    }
}

impl SubAssign<&PointMoments> for PointMoments {
    fn sub_assign(&mut self, other: &PointMoments) {
        self.count -= other.count;
        self.sum -= other.sum;
        for (a, b) in self.sum_outer.iter_mut().zip(other.sum_outer) {
            *a -= b;
        }
    }
}

/// The eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (the normal of the
/// points' plane): eigenvalues in closed form (Smith 1961), the eigenvector as the longest cross
/// product of two rows of `A − λI`; about ten times faster than iterating, which matters at one
/// fit per voxel. Where the two smallest eigenvalues nearly coincide (points along a line or in a
/// ball) the cross products vanish and the iterative [`smallest_eigenvector`] decides.
pub fn least_spread_direction(a: DMat3) -> DVec3 {
    let [c0, c1, c2] = a.to_cols_array_2d();
    let off = c1[0] * c1[0] + c2[0] * c2[0] + c2[1] * c2[1];
    let trace = c0[0] + c1[1] + c2[2];
    let scale = trace.abs().max(1e-300);
    if off <= 1e-24 * scale * scale {
        return smallest_eigenvector(a);
    }
    let q = trace / 3.0;
    let p2 = (c0[0] - q).powi(2) + (c1[1] - q).powi(2) + (c2[2] - q).powi(2) + 2.0 * off;
    let p = (p2 / 6.0).sqrt();
    let b = (a - DMat3::from_diagonal(DVec3::splat(q))) * (1.0 / p);
    let r = (b.determinant() / 2.0).clamp(-1.0, 1.0);
    let smallest = q + p * smallest_scaled_eigenvalue(r);
    let m = a - DMat3::from_diagonal(DVec3::splat(smallest));
    // Rows of a symmetric matrix are its columns.
    let (r0, r1, r2) = (m.x_axis, m.y_axis, m.z_axis);
    let candidates = [r0.cross(r1), r0.cross(r2), r1.cross(r2)];
    let best = candidates
        .into_iter()
        .max_by(|u, v| u.length_squared().total_cmp(&v.length_squared()))
        .unwrap_or(DVec3::ZERO);
    // Relative to the matrix's size squared: below this the smallest eigenvalue is (nearly)
    // double and the direction is not determined by the cross products.
    if best.length_squared() <= 1e-12 * p2 * p2 {
        return smallest_eigenvector(a);
    }
    best.normalize()
}

/// The smallest root of `β³ − 3β − 2r` for `r` in [−1, 1], which lies in [−2, −1]: the
/// smallest eigenvalue of the scaled matrix `B` of [`least_spread_direction`] (Smith's
/// `2 cos((acos r + 2π) / 3)`).
///
/// By Newton's method from −2: below −1 the cubic rises and bends down, so every step lands
/// short of the root and the steps shrink quadratically; the points of a surface (one small
/// eigenvalue, two large ones) put the root near −2, three or four steps away. The `acos` and
/// `cos` of the closed form were a quarter of each plane fit (1.7 % of meshing a 1 m cube on
/// one core). Where the two smallest eigenvalues nearly coincide (the root near −1 is nearly
/// double) Newton slows to halving, and the closed form answers instead.
fn smallest_scaled_eigenvalue(r: f64) -> f64 {
    const MAX_STEPS: usize = 8;
    let mut beta = -2.0f64;
    for _ in 0..MAX_STEPS {
        let f = beta * (beta * beta - 3.0) - 2.0 * r;
        if f >= 0.0 {
            return beta; // on the root, to rounding
        }
        let step = -f / (3.0 * (beta * beta - 1.0));
        beta += step;
        if step <= 1e-13 {
            return beta;
        }
    }
    2.0 * ((r.acos() + 2.0 * std::f64::consts::PI) / 3.0).cos()
}

/// The eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix (see
/// [`symmetric_eigen`]).
pub fn smallest_eigenvector(m: DMat3) -> DVec3 {
    let (values, vectors) = symmetric_eigen(&m.to_cols_array_2d());
    let smallest = (0..3)
        .min_by(|&i, &j| values[i].partial_cmp(&values[j]).unwrap_or(Ordering::Equal))
        .unwrap_or(0);
    DVec3::from_array(vectors[smallest]).normalize_or(DVec3::Z)
}

/// Eigenvalues and unit eigenvectors of a symmetric N×N matrix (`vectors[i]` belongs to
/// `values[i]`; unsorted), by cyclic Jacobi rotations. Written here because glam has no eigen
/// solver and a linear-algebra crate for the 3×3 plane fits and the tracker's 6×6 alignment
/// normal matrix is not worth its weight; Jacobi is unconditionally stable for symmetric
/// matrices and converges in a handful of sweeps.
// Index loops mirror the textbook rotation formulas (Numerical Recipes §11.1).
#[allow(clippy::needless_range_loop)]
pub fn symmetric_eigen<const N: usize>(m: &[[f64; N]; N]) -> ([f64; N], [[f64; N]; N]) {
    let mut a = *m;
    // Columns of `v` accumulate the rotations: column i ends as the eigenvector of a[i][i].
    let mut v = [[0.0f64; N]; N];
    for (i, row) in v.iter_mut().enumerate() {
        row[i] = 1.0;
    }
    for _sweep in 0..32 {
        let (mut off, mut diag) = (0.0, 0.0);
        for i in 0..N {
            diag += a[i][i].abs();
            for j in i + 1..N {
                off += a[i][j].abs();
            }
        }
        if off <= 1e-15 * diag || off == 0.0 {
            break;
        }
        for p in 0..N {
            for q in p + 1..N {
                if a[p][q] == 0.0 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..N {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..N {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in &mut v {
                    let (vp, vq) = (row[p], row[q]);
                    row[p] = c * vp - s * vq;
                    row[q] = s * vp + c * vq;
                }
            }
        }
    }
    let mut values = [0.0f64; N];
    let mut vectors = [[0.0f64; N]; N];
    for i in 0..N {
        values[i] = a[i][i];
        for k in 0..N {
            vectors[i][k] = v[k][i];
        }
    }
    (values, vectors)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Newton's root is the closed form's, over the whole range, including the nearly double
    /// root near r = 1 where it hands over to the closed form.
    #[test]
    fn the_smallest_scaled_eigenvalue_is_the_closed_forms() {
        for i in 0..=20_000 {
            let r = -1.0 + i as f64 / 10_000.0;
            let closed = 2.0 * ((r.acos() + 2.0 * std::f64::consts::PI) / 3.0).cos();
            let newton = smallest_scaled_eigenvalue(r);
            // The closed form itself is no better than this near r = 1 (acos's slope).
            let tolerance = if r > 0.999 { 1e-7 } else { 1e-13 };
            assert!(
                (newton - closed).abs() <= tolerance,
                "r {r}: {newton} vs {closed}"
            );
            let residual = newton * (newton * newton - 3.0) - 2.0 * r;
            assert!(
                residual.abs() <= 1e-12,
                "r {r}: cubic {residual} at {newton}"
            );
            assert!(
                (-2.0 - 1e-12..=-1.0 + 1e-12).contains(&newton),
                "r {r}: {newton}"
            );
        }
    }

    #[test]
    fn smallest_eigenvector_of_diagonal_is_its_axis() {
        let v = smallest_eigenvector(DMat3::from_diagonal(DVec3::new(3.0, 0.5, 2.0)));
        assert!((v.y.abs() - 1.0).abs() < 1e-9, "{v}");
    }

    #[test]
    fn closed_form_agrees_with_jacobi() {
        let mut seed = 12345u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        for _ in 0..1000 {
            let mut m = PointMoments::default();
            let squash = DVec3::new(1.0, 0.6, 0.05 + 0.3 * next().abs());
            for _ in 0..30 {
                let p = DVec3::new(next(), next(), next()) * squash;
                m.add_point(p.as_vec3());
            }
            let cov = m.covariance();
            let a = least_spread_direction(cov);
            let b = smallest_eigenvector(cov);
            assert!(a.dot(b).abs() > 1.0 - 1e-6, "{a} vs {b} for {cov}");
        }
    }

    #[test]
    fn plane_of_tilted_points_has_their_normal() {
        let normal = Vec3::new(1.0, 2.0, 2.0).normalize();
        let (u, w) = normal.any_orthonormal_pair();
        let mut m = PointMoments::default();
        for (a, b) in [(1.0, 0.0), (0.0, 1.0), (-1.0, 0.5), (0.3, -0.7), (0.2, 0.2)] {
            m.add_point(Vec3::splat(3.0) + u * a + w * b);
        }
        let plane = m.plane().unwrap();
        assert!(plane.normal.dot(normal).abs() > 1.0 - 1e-5);
        assert!((plane.point - Vec3::splat(3.0)).dot(normal).abs() < 1e-5);
    }

    #[test]
    fn moments_add_like_the_union() {
        let pts = [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE];
        let (mut all, mut a, mut b) = Default::default();
        for (i, &p) in pts.iter().enumerate() {
            PointMoments::add_point(&mut all, p);
            if i < 2 {
                PointMoments::add_point(&mut a, p)
            } else {
                PointMoments::add_point(&mut b, p)
            }
        }
        let mut merged: PointMoments = a;
        merged += &b;
        assert_eq!(merged, all);
    }

    #[test]
    fn fewer_than_three_points_fit_no_plane() {
        let mut m = PointMoments::default();
        m.add_point(Vec3::ZERO);
        m.add_point(Vec3::X);
        assert_eq!(m.plane(), None);
    }
}
