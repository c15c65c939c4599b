//! Exact point-to-triangle distance, prepared once per triangle and queried for many points.
//!
//! Follows C. Ericson, *Real-Time Collision Detection*, Morgan Kaufmann 2004, §5.1.5
//! ("Closest point on triangle to point"): classify the point against the Voronoi regions of the
//! triangle's vertices and edges using the two dot products `ab·ap` and `ac·ap` (the other four
//! follow from dot products of the edges, precomputed here), then measure to the vertex, the edge
//! or the plane. Degenerate triangles (no usable normal) fall back to the nearest of the three
//! edge segments. Units are those of the inputs (metres in tacmesh); results are squared.
//!
//! Most queries in the simplifier come from points that project inside the triangle, so that
//! case goes first: the barycentric coordinates of the projection are two dot products with the
//! dual basis of the two edges, precomputed per triangle.

use glam::Vec3;

/// A triangle prepared for repeated distance queries.
#[derive(Debug, Clone, Copy)]
pub(crate) struct TriangleQuery {
    a: Vec3,
    ab: Vec3,
    ac: Vec3,
    ab_ab: f32,
    ab_ac: f32,
    ac_ac: f32,
    /// Unit normal, or zero for a degenerate triangle.
    unit_normal: Vec3,
    /// Dual basis of `ab`, `ac` in the plane: `(dual_b·ap, dual_c·ap)` are the barycentric
    /// weights of `b` and `c` at the projection of `p`.
    dual_b: Vec3,
    dual_c: Vec3,
    degenerate: bool,
}

impl TriangleQuery {
    pub(crate) fn new(a: Vec3, b: Vec3, c: Vec3) -> Self {
        let ab = b - a;
        let ac = c - a;
        let cross = ab.cross(ac);
        let ab_ab = ab.length_squared();
        let ac_ac = ac.length_squared();
        let scale = ab_ab.max(ac_ac);
        // Twice the area against the squared longest side: below 1e-7 the plane is noise.
        let ab_ac = ab.dot(ac);
        let cross_sq = cross.length_squared(); // = ab_ab·ac_ac − ab_ac²
        let degenerate = cross_sq.is_nan() || cross_sq <= 1e-14 * scale * scale;
        let (unit_normal, dual_b, dual_c) = if degenerate {
            (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO)
        } else {
            let inv = 1.0 / cross_sq;
            (
                cross * inv.sqrt(),
                (ab * ac_ac - ac * ab_ac) * inv,
                (ac * ab_ab - ab * ab_ac) * inv,
            )
        };
        Self {
            a,
            ab,
            ac,
            ab_ab,
            ab_ac,
            ac_ac,
            unit_normal,
            dual_b,
            dual_c,
            degenerate,
        }
    }

    /// Signed distance from `p` to the triangle's plane; zero for a degenerate triangle, so it is
    /// always a lower bound of the true distance.
    #[inline]
    pub(crate) fn plane_distance(&self, p: Vec3) -> f32 {
        self.unit_normal.dot(p - self.a)
    }

    /// The point with barycentric weights `[wb, wc]` (of corners `b` and `c`).
    #[inline]
    pub(crate) fn point_at(&self, weights: [f32; 2]) -> Vec3 {
        self.a + self.ab * weights[0] + self.ac * weights[1]
    }

    /// Squared distance from `p` to the closest point of the (filled) triangle, and the
    /// barycentric weights `[wb, wc]` of that closest point.
    #[inline]
    pub(crate) fn closest(&self, p: Vec3) -> (f32, [f32; 2]) {
        if self.degenerate {
            return self.degenerate_closest(p);
        }
        let ap = p - self.a;
        let beta = self.dual_b.dot(ap);
        let gamma = self.dual_c.dot(ap);
        if beta >= 0.0 && gamma >= 0.0 && beta + gamma <= 1.0 {
            let h = ap.dot(self.unit_normal); // projects inside: the plane distance
            return (h * h, [beta, gamma]);
        }
        self.outside_closest(ap)
    }

    /// [`Self::closest`] for a point whose projection falls outside the triangle: Ericson's
    /// walk over the Voronoi regions of the vertices and edges.
    fn outside_closest(&self, ap: Vec3) -> (f32, [f32; 2]) {
        let d1 = self.ab.dot(ap);
        let d2 = self.ac.dot(ap);
        if d1 <= 0.0 && d2 <= 0.0 {
            return (ap.length_squared(), [0.0, 0.0]); // vertex a
        }
        let d3 = d1 - self.ab_ab; // ab·bp
        let d4 = d2 - self.ab_ac; // ac·bp
        if d3 >= 0.0 && d4 <= d3 {
            return ((ap - self.ab).length_squared(), [1.0, 0.0]); // vertex b
        }
        let vc = d1 * d4 - d3 * d2;
        if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
            let v = d1 / (d1 - d3);
            return ((ap - self.ab * v).length_squared(), [v, 0.0]); // edge ab
        }
        let d5 = d1 - self.ab_ac; // ab·cp
        let d6 = d2 - self.ac_ac; // ac·cp
        if d6 >= 0.0 && d5 <= d6 {
            return ((ap - self.ac).length_squared(), [0.0, 1.0]); // vertex c
        }
        let vb = d5 * d2 - d1 * d6;
        if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
            let w = d2 / (d2 - d6);
            return ((ap - self.ac * w).length_squared(), [0.0, w]); // edge ac
        }
        let along_bc = d4 - d3;
        let beyond_c = d5 - d6;
        let w = (along_bc / (along_bc + beyond_c)).clamp(0.0, 1.0);
        let bp = ap - self.ab;
        (
            (bp - (self.ac - self.ab) * w).length_squared(),
            [1.0 - w, w],
        ) // edge bc
    }

    #[cold]
    fn degenerate_closest(&self, p: Vec3) -> (f32, [f32; 2]) {
        let b = self.a + self.ab;
        let c = self.a + self.ac;
        let (d_ab, t_ab) = segment_closest(p, self.a, b);
        let (d_ac, t_ac) = segment_closest(p, self.a, c);
        let (d_bc, t_bc) = segment_closest(p, b, c);
        if d_ab <= d_ac && d_ab <= d_bc {
            (d_ab, [t_ab, 0.0])
        } else if d_ac <= d_bc {
            (d_ac, [0.0, t_ac])
        } else {
            (d_bc, [1.0 - t_bc, t_bc])
        }
    }

    /// Squared distance from `p` to the closest point of the (filled) triangle.
    #[inline]
    pub(crate) fn distance_sq(&self, p: Vec3) -> f32 {
        self.closest(p).0
    }
}

/// Squared distance from `p` to the segment `a`–`b`, and the parameter of the closest point.
fn segment_closest(p: Vec3, a: Vec3, b: Vec3) -> (f32, f32) {
    let ab = b - a;
    let len_sq = ab.length_squared();
    let t = if len_sq > 0.0 {
        ((p - a).dot(ab) / len_sq).clamp(0.0, 1.0)
    } else {
        0.0
    };
    ((p - (a + ab * t)).length_squared(), t)
}
#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the minimum over a fine barycentric sampling of the triangle.
    fn sampled_distance_sq(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
        let n = 200;
        let mut best = f32::INFINITY;
        for i in 0..=n {
            for j in 0..=(n - i) {
                let u = i as f32 / n as f32;
                let v = j as f32 / n as f32;
                let q = a + (b - a) * u + (c - a) * v;
                best = best.min((p - q).length_squared());
            }
        }
        best
    }

    #[test]
    fn distance_matches_sampling_in_every_voronoi_region() {
        let (a, b, c) = (
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.1, 0.0),
            Vec3::new(0.2, 0.9, 0.3),
        );
        let query = TriangleQuery::new(a, b, c);
        let mut state = 12345u32;
        for _ in 0..300 {
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                (state as f32 / u32::MAX as f32) * 3.0 - 1.0
            };
            let p = Vec3::new(next(), next(), next());
            let exact = query.distance_sq(p).sqrt();
            let sampled = sampled_distance_sq(p, a, b, c).sqrt();
            assert!(exact <= sampled + 1e-5, "{p}: {exact} > {sampled}");
            assert!(sampled - exact < 0.01, "{p}: {exact} vs {sampled}");
            assert!(query.plane_distance(p).abs() <= exact + 1e-5);
            let (d, weights) = query.closest(p);
            assert!((p.distance_squared(query.point_at(weights)) - d).abs() < 1e-5);
            assert!(
                weights.iter().all(|w| (0.0..=1.0).contains(w))
                    && weights[0] + weights[1] <= 1.0 + 1e-5
            );
        }
    }

    #[test]
    fn degenerate_triangle_measures_to_its_segments() {
        let query = TriangleQuery::new(Vec3::ZERO, Vec3::X, Vec3::X * 2.0);
        let p = Vec3::new(1.5, 1.0, 0.0);
        assert!((query.distance_sq(p) - 1.0).abs() < 1e-6);
        let (_, weights) = query.closest(p);
        assert!(query.point_at(weights).distance(Vec3::new(1.5, 0.0, 0.0)) < 1e-6);
        assert_eq!(query.plane_distance(Vec3::Y), 0.0);
    }
}
