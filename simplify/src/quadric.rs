//! Plane quadrics: the squared distance to a weighted set of planes as one symmetric 4×4 form.
//!
//! Follows M. Garland and P. S. Heckbert, "Surface Simplification Using Quadric Error Metrics",
//! SIGGRAPH 1997, §5: a plane `n·p + d = 0` (unit `n`) contributes `w (n·p + d)²`, which is
//! `pᵀ A p + 2 bᵀ p + c` with `A = w n nᵀ`, `b = w d n`, `c = w d²`; quadrics add, and the point
//! minimising a quadric solves `A p = -b`. Everything here is `f64`: sums over thousands of
//! nearly parallel planes lose too much in `f32`.

use glam::DVec3;

/// `Σ w (n·p + d)²` over a set of planes, plus the total face area that went into it.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Quadric {
    /// Upper triangle of `A`: xx, xy, xz, yy, yz, zz.
    a: [f64; 6],
    b: DVec3,
    c: f64,
    /// Sum of the face areas (m²) added with [`Quadric::add_face`]; scales the spring term.
    area_m2: f64,
}

impl Quadric {
    /// The plane through `point` with unit `normal`, weighted by `weight`.
    pub(crate) fn from_plane(normal: DVec3, point: DVec3, weight: f64) -> Self {
        let n = normal;
        let d = -n.dot(point);
        Self {
            a: [
                weight * n.x * n.x,
                weight * n.x * n.y,
                weight * n.x * n.z,
                weight * n.y * n.y,
                weight * n.y * n.z,
                weight * n.z * n.z,
            ],
            b: n * (weight * d),
            c: weight * d * d,
            area_m2: 0.0,
        }
    }

    /// The plane of a face with unit `normal` through `point`, weighted by its area (m²).
    pub(crate) fn from_face(normal: DVec3, point: DVec3, area_m2: f64) -> Self {
        let mut q = Self::from_plane(normal, point, area_m2);
        q.area_m2 = area_m2;
        q
    }

    /// Total face area (m²) summed into this quadric.
    pub(crate) fn area_m2(&self) -> f64 {
        self.area_m2
    }

    /// `Σ w (n·p + d)²` at `p`, clamped at zero against rounding (units: weight × m²).
    pub(crate) fn error(&self, p: DVec3) -> f64 {
        let [xx, xy, xz, yy, yz, zz] = self.a;
        let ap = DVec3::new(
            xx * p.x + xy * p.y + xz * p.z,
            xy * p.x + yy * p.y + yz * p.z,
            xz * p.x + yz * p.y + zz * p.z,
        );
        (p.dot(ap) + 2.0 * self.b.dot(p) + self.c).max(0.0)
    }

    /// The point minimising `error(p) + spring · |p - anchor|²`, or `None` when that system is
    /// too ill-conditioned to trust (determinant below 1e-10 of the cube of its mean diagonal).
    /// Solved by the adjugate of the symmetric 3×3 matrix.
    pub(crate) fn minimiser(&self, anchor: DVec3, spring: f64) -> Option<DVec3> {
        let [xx, xy, xz, yy, yz, zz] = self.a;
        let (xx, yy, zz) = (xx + spring, yy + spring, zz + spring);
        let scale = (xx + yy + zz) / 3.0;
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        let c00 = yy * zz - yz * yz;
        let c01 = xz * yz - xy * zz;
        let c02 = xy * yz - xz * yy;
        let c11 = xx * zz - xz * xz;
        let c12 = xy * xz - xx * yz;
        let c22 = xx * yy - xy * xy;
        let det = xx * c00 + xy * c01 + xz * c02;
        if det.is_nan() || det.abs() <= 1e-10 * scale * scale * scale {
            return None;
        }
        let r = anchor * spring - self.b;
        let p = DVec3::new(
            c00 * r.x + c01 * r.y + c02 * r.z,
            c01 * r.x + c11 * r.y + c12 * r.z,
            c02 * r.x + c12 * r.y + c22 * r.z,
        ) / det;
        p.is_finite().then_some(p)
    }
}

impl std::ops::Add for Quadric {
    type Output = Quadric;
    fn add(mut self, rhs: Quadric) -> Quadric {
        self += rhs;
        self
    }
}

impl std::ops::AddAssign for Quadric {
    fn add_assign(&mut self, rhs: Quadric) {
        for (a, b) in self.a.iter_mut().zip(rhs.a) {
            *a += b;
        }
        self.b += rhs.b;
        self.c += rhs.c;
        self.area_m2 += rhs.area_m2;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_quadric_measures_weighted_squared_distance() {
        let q = Quadric::from_plane(DVec3::Z, DVec3::new(0.0, 0.0, 1.0), 2.0);
        assert!((q.error(DVec3::new(5.0, -3.0, 4.0)) - 2.0 * 9.0).abs() < 1e-9);
        assert!(q.error(DVec3::new(1.0, 2.0, 1.0)) < 1e-12);
    }

    #[test]
    fn three_planes_meet_at_their_corner() {
        let corner = DVec3::new(0.5, -0.25, 2.0);
        let q = Quadric::from_plane(DVec3::X, corner, 1.0)
            + Quadric::from_plane(DVec3::Y, corner, 1.0)
            + Quadric::from_plane(DVec3::Z, corner, 1.0);
        let p = q.minimiser(DVec3::ZERO, 1e-9).expect("well conditioned");
        assert!((p - corner).length() < 1e-6);
    }

    #[test]
    fn one_plane_minimiser_is_anchor_projected_onto_it() {
        let q = Quadric::from_face(DVec3::Z, DVec3::ZERO, 1.0);
        let p = q
            .minimiser(DVec3::new(0.3, 0.4, 0.5), 1e-3)
            .expect("spring regularises");
        assert!((p - DVec3::new(0.3, 0.4, 0.0)).length() < 1e-3);
        assert!(q.minimiser(DVec3::ZERO, 0.0).is_none());
    }
}
