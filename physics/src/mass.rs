//! Volume, centre of mass and inertia of a closed mesh, exactly, from signed tetrahedra; and
//! of a set of convex parts, as their sum.
//!
//! Each triangle spans a tetrahedron with a reference point; its signed volume, first and
//! second moments are closed forms (the canonical-tetrahedron covariance, as in Blow and
//! Binstock, "How to find the inertia tensor (or other mass properties) of a 3D solid body
//! represented by a triangle mesh", 2004), and their sums are the solid's, whatever the
//! reference point, when the mesh is closed and faces outward.
//!
//! These are our own few lines rather than parry3d's `MassProperties::from_trimesh`: they
//! accumulate in f64 about the mesh's own centroid (a 0.1 m object 2 m from the origin keeps
//! its digits), return the full inertia tensor about the centre of mass that MJCF's
//! `fullinertia` takes (parry returns principal moments and a rotation), and refuse a mesh
//! that encloses no volume instead of returning a negative mass.
//!
//! Entry points: [`MassProperties::of_closed_mesh`], [`MassProperties::sum`].

use glam::{DMat3, DVec3, Vec3};
use tacmesh_source::TriMesh;

use crate::error::PhysicsError;

/// Mass properties of a solid of unit density (1 kg/m³), so that the mass in kilograms equals
/// the volume in cubic metres; multiply by a density for a real body
/// ([`MassProperties::mass_kg`], [`MassProperties::inertia_kg_m2`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MassProperties {
    /// Enclosed volume in m³ (positive).
    pub volume_m3: f32,
    /// Centre of mass in the mesh's frame, metres.
    pub centre_of_mass: Vec3,
    /// Inertia tensor about the centre of mass, axes of the mesh's frame, for unit density:
    /// kg·m² per kg/m³, that is m⁵. Symmetric; row-major `[[Ixx, Ixy, Ixz], …]` with the
    /// products of inertia carrying their minus sign (`Ixy = -∫xy dV`).
    pub inertia: [[f32; 3]; 3],
}

/// Volume, first moment and second moment (∫ x xᵀ dV) about one reference point.
#[derive(Debug, Clone, Copy)]
struct Moments {
    volume: f64,
    first: DVec3,
    second: DMat3,
}

impl Moments {
    const ZERO: Moments = Moments {
        volume: 0.0,
        first: DVec3::ZERO,
        second: DMat3::ZERO,
    };

    /// The moments of the tetrahedron (reference, a, b, c), corners relative to the reference.
    fn of_tetrahedron(a: DVec3, b: DVec3, c: DVec3) -> Moments {
        let volume = a.dot(b.cross(c)) / 6.0;
        let s = a + b + c;
        let outer = |v: DVec3| DMat3::from_cols(v * v.x, v * v.y, v * v.z);
        Moments {
            volume,
            first: s * (volume / 4.0),
            second: (outer(a) + outer(b) + outer(c) + outer(s)) * (volume / 20.0),
        }
    }

    fn add(self, other: Moments) -> Moments {
        Moments {
            volume: self.volume + other.volume,
            first: self.first + other.first,
            second: self.second + other.second,
        }
    }

    /// Mass properties about the centre of mass; `reference` is where these moments were taken.
    fn into_properties(self, reference: DVec3) -> MassProperties {
        let com = self.first / self.volume;
        let outer_com = DMat3::from_cols(com * com.x, com * com.y, com * com.z);
        let about_com = self.second - outer_com * self.volume;
        let trace = about_com.x_axis.x + about_com.y_axis.y + about_com.z_axis.z;
        let inertia = DMat3::IDENTITY * trace - about_com;
        MassProperties {
            volume_m3: self.volume as f32,
            centre_of_mass: (reference + com).as_vec3(),
            inertia: rows_f32(inertia),
        }
    }
}

fn rows_f32(m: DMat3) -> [[f32; 3]; 3] {
    // Symmetric, so columns and rows are the same.
    [
        m.x_axis.as_vec3().to_array(),
        m.y_axis.as_vec3().to_array(),
        m.z_axis.as_vec3().to_array(),
    ]
}

fn dmat3_from_rows(rows: &[[f32; 3]; 3]) -> DMat3 {
    let row = |i: usize| Vec3::from_array(rows[i]).as_dvec3();
    DMat3::from_cols(row(0), row(1), row(2)).transpose()
}

impl MassProperties {
    /// Exact mass properties of the solid a closed, outward-facing mesh encloses.
    ///
    /// Errors: [`PhysicsError::EmptyMesh`] for no triangles or a bad index,
    /// [`PhysicsError::NoVolume`] when the enclosed volume is not positive (an open shell or
    /// inward-facing triangles). A mesh with holes gets no error if its volume still comes out
    /// positive, but then the figures are those of the holes' caps being missing: close it
    /// first.
    pub fn of_closed_mesh(mesh: &TriMesh) -> Result<MassProperties, PhysicsError> {
        if mesh.triangles.is_empty() {
            return Err(PhysicsError::EmptyMesh {
                reason: "no triangles".into(),
            });
        }
        if let Some((t, i)) = mesh.first_bad_index() {
            return Err(PhysicsError::EmptyMesh {
                reason: format!(
                    "triangle {t} refers to vertex {i} of {}",
                    mesh.vertices.len()
                ),
            });
        }
        let reference = mesh
            .vertices
            .iter()
            .fold(DVec3::ZERO, |sum, v| sum + v.as_dvec3())
            / mesh.vertices.len() as f64;
        let corner = |i: u32| mesh.vertices[i as usize].as_dvec3() - reference;
        let moments = mesh
            .triangles
            .iter()
            .map(|&[a, b, c]| Moments::of_tetrahedron(corner(a), corner(b), corner(c)))
            .fold(Moments::ZERO, Moments::add);
        // Relative to the mesh's size, so that a 1 cm die is not "no volume".
        let tiny = mesh
            .bounds()
            .map(|(lo, hi)| f64::from((hi - lo).max_element()).powi(3) * 1e-9)
            .unwrap_or(0.0);
        let encloses_volume = moments.volume > tiny; // false for NaN too
        if !encloses_volume {
            return Err(PhysicsError::NoVolume {
                volume_m3: moments.volume,
            });
        }
        Ok(moments.into_properties(reference))
    }

    /// The mass properties of several solids together (convex parts of one body), each
    /// counted whole: where parts overlap, the overlap is counted once per part.
    ///
    /// Errors: [`PhysicsError::NoVolume`] for no parts.
    pub fn sum(parts: &[MassProperties]) -> Result<MassProperties, PhysicsError> {
        let Some(first) = parts.first() else {
            return Err(PhysicsError::NoVolume { volume_m3: 0.0 });
        };
        // Moments about the first part's centre of mass, to keep the digits.
        let reference = first.centre_of_mass.as_dvec3();
        let total = parts
            .iter()
            .map(|p| p.moments_about(reference))
            .fold(Moments::ZERO, Moments::add);
        let encloses_volume = total.volume > 0.0;
        if !encloses_volume {
            return Err(PhysicsError::NoVolume {
                volume_m3: total.volume,
            });
        }
        Ok(total.into_properties(reference))
    }

    /// Volume, first and second moments about `reference`.
    fn moments_about(&self, reference: DVec3) -> Moments {
        let volume = f64::from(self.volume_m3);
        let inertia = dmat3_from_rows(&self.inertia);
        let trace = inertia.x_axis.x + inertia.y_axis.y + inertia.z_axis.z;
        // I = tr(C) 1 − C and tr(I) = 2 tr(C), so C = tr(I)/2 · 1 − I.
        let about_com = DMat3::IDENTITY * (trace / 2.0) - inertia;
        let com = self.centre_of_mass.as_dvec3() - reference;
        let outer_com = DMat3::from_cols(com * com.x, com * com.y, com * com.z);
        Moments {
            volume,
            first: com * volume,
            second: about_com + outer_com * volume,
        }
    }

    /// Mass in kilograms at `density_kg_m3`.
    /// Why these are not the mass properties of a solid an engine can simulate, or `None`:
    /// a volume that is not positive, a centre of mass that is not finite, an inertia that is
    /// not symmetric positive definite or whose principal moments break the triangle
    /// inequality (each at most the sum of the other two, as for every real body: MuJoCo
    /// refuses such a body, "inertia must satisfy A + B >= C", and Bullet simulates it wrong).
    pub fn implausible(&self) -> Option<String> {
        if !(self.volume_m3.is_finite() && self.volume_m3 > 0.0) {
            return Some(format!("its volume {} m³ is not positive", self.volume_m3));
        }
        if !self.centre_of_mass.is_finite() {
            return Some("its centre of mass is not finite".to_owned());
        }
        let i = self.inertia;
        let flat = i.iter().flatten();
        if flat.clone().any(|v| !v.is_finite()) {
            return Some("its inertia is not finite".to_owned());
        }
        let scale = flat.fold(0.0f32, |m, v| m.max(v.abs()));
        let asymmetry = (i[0][1] - i[1][0])
            .abs()
            .max((i[0][2] - i[2][0]).abs())
            .max((i[1][2] - i[2][1]).abs());
        if asymmetry > 1e-4 * scale {
            return Some("its inertia is not symmetric".to_owned());
        }
        let [a, b, c] = self.principal_moments();
        let tolerance = 1e-5 * scale;
        if a.min(b).min(c) <= 0.0 {
            return Some(format!(
                "its inertia is not positive definite (principal moments {a:e}, {b:e}, {c:e} m⁵)"
            ));
        }
        if a > b + c + tolerance || b > a + c + tolerance || c > a + b + tolerance {
            return Some(format!(
                "its principal moments {a:e}, {b:e}, {c:e} m⁵ break the triangle inequality"
            ));
        }
        None
    }

    /// The inertia's principal moments (its eigenvalues), smallest first, m⁵: what two
    /// bodies' inertias are compared by whatever their frames.
    pub fn principal_moments(&self) -> [f32; 3] {
        let m = parry3d::math::Mat3::from_cols_array_2d(&self.inertia);
        let mut moments = parry3d::math::SymmetricEigen3::new(m)
            .eigenvalues
            .to_array();
        moments.sort_by(f32::total_cmp);
        moments
    }

    pub fn mass_kg(&self, density_kg_m3: f32) -> f32 {
        self.volume_m3 * density_kg_m3
    }

    /// Inertia tensor about the centre of mass in kg·m² at `density_kg_m3`.
    pub fn inertia_kg_m2(&self, density_kg_m3: f32) -> [[f32; 3]; 3] {
        self.inertia.map(|row| row.map(|x| x * density_kg_m3))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An axis-aligned box from `lo` to `hi`, outward.
    fn cuboid(lo: Vec3, hi: Vec3) -> TriMesh {
        let v = |x: bool, y: bool, z: bool| {
            Vec3::new(
                if x { hi.x } else { lo.x },
                if y { hi.y } else { lo.y },
                if z { hi.z } else { lo.z },
            )
        };
        let vertices = vec![
            v(false, false, false),
            v(true, false, false),
            v(true, true, false),
            v(false, true, false),
            v(false, false, true),
            v(true, false, true),
            v(true, true, true),
            v(false, true, true),
        ];
        let triangles = vec![
            [0, 2, 1],
            [0, 3, 2],
            [4, 5, 6],
            [4, 6, 7],
            [0, 1, 5],
            [0, 5, 4],
            [1, 2, 6],
            [1, 6, 5],
            [2, 3, 7],
            [2, 7, 6],
            [3, 0, 4],
            [3, 4, 7],
        ];
        TriMesh::new(vertices, triangles)
    }

    fn assert_close(a: f32, b: f32, tolerance: f32, what: &str) {
        assert!((a - b).abs() <= tolerance, "{what}: {a} vs {b}");
    }

    #[test]
    fn unit_cube_has_closed_form_inertia() {
        let m = MassProperties::of_closed_mesh(&cuboid(Vec3::ZERO, Vec3::ONE)).unwrap();
        assert_close(m.volume_m3, 1.0, 1e-6, "volume");
        assert!((m.centre_of_mass - Vec3::splat(0.5)).length() < 1e-6);
        for i in 0..3 {
            for j in 0..3 {
                let expected = if i == j { 1.0 / 6.0 } else { 0.0 };
                assert_close(m.inertia[i][j], expected, 1e-6, "inertia");
            }
        }
    }

    #[test]
    fn box_inertia_follows_its_sides() {
        // a × b × c box: Ixx = V (b² + c²) / 12.
        let (a, b, c) = (0.2f32, 0.1, 0.05);
        let m = MassProperties::of_closed_mesh(&cuboid(Vec3::ZERO, Vec3::new(a, b, c))).unwrap();
        let v = a * b * c;
        assert_close(m.volume_m3, v, 1e-9, "volume");
        assert_close(m.inertia[0][0], v * (b * b + c * c) / 12.0, 1e-10, "Ixx");
        assert_close(m.inertia[1][1], v * (a * a + c * c) / 12.0, 1e-10, "Iyy");
        assert_close(m.inertia[2][2], v * (a * a + b * b) / 12.0, 1e-10, "Izz");
    }

    #[test]
    fn translated_cube_moves_its_centre_of_mass_only() {
        let offset = Vec3::new(3.0, -2.0, 10.0);
        let m = MassProperties::of_closed_mesh(&cuboid(offset, offset + Vec3::splat(0.1))).unwrap();
        assert!((m.centre_of_mass - (offset + Vec3::splat(0.05))).length() < 1e-5);
        assert_close(m.volume_m3, 1e-3, 1e-8, "volume");
        assert_close(m.inertia[0][0], 1e-3 * 0.02 / 12.0, 1e-10, "Ixx");
        assert_close(m.inertia[0][1], 0.0, 1e-11, "Ixy");
    }

    #[test]
    fn tessellated_sphere_is_near_the_closed_form() {
        let sphere = tacmesh_sim::uv_sphere(64, 32, 1.0);
        let m = MassProperties::of_closed_mesh(&sphere).unwrap();
        let volume = 4.0 / 3.0 * std::f32::consts::PI;
        // An inscribed polyhedron of 64 × 32 is about 0.3 % short in volume.
        assert!(
            m.volume_m3 < volume && m.volume_m3 > 0.99 * volume,
            "{}",
            m.volume_m3
        );
        assert!(m.centre_of_mass.length() < 1e-4);
        let moment = 0.4 * volume; // 2/5 M r²
        for i in 0..3 {
            assert!(
                m.inertia[i][i] < moment && m.inertia[i][i] > 0.98 * moment,
                "I{i}{i} = {}",
                m.inertia[i][i]
            );
        }
    }

    #[test]
    fn two_halves_sum_to_the_whole() {
        let whole =
            MassProperties::of_closed_mesh(&cuboid(Vec3::ZERO, Vec3::new(2.0, 1.0, 1.0))).unwrap();
        let left = MassProperties::of_closed_mesh(&cuboid(Vec3::ZERO, Vec3::ONE)).unwrap();
        let right =
            MassProperties::of_closed_mesh(&cuboid(Vec3::X, Vec3::new(2.0, 1.0, 1.0))).unwrap();
        let sum = MassProperties::sum(&[left, right]).unwrap();
        assert_close(sum.volume_m3, whole.volume_m3, 1e-6, "volume");
        assert!((sum.centre_of_mass - whole.centre_of_mass).length() < 1e-6);
        for i in 0..3 {
            for j in 0..3 {
                assert_close(sum.inertia[i][j], whole.inertia[i][j], 1e-5, "inertia");
            }
        }
    }

    #[test]
    fn inward_mesh_has_no_volume() {
        let mut cube = cuboid(Vec3::ZERO, Vec3::ONE);
        for t in &mut cube.triangles {
            t.swap(1, 2);
        }
        assert!(matches!(
            MassProperties::of_closed_mesh(&cube),
            Err(PhysicsError::NoVolume { .. })
        ));
    }

    #[test]
    fn what_an_engine_cannot_simulate_is_said() {
        let good =
            MassProperties::of_closed_mesh(&cuboid(Vec3::ZERO, Vec3::new(0.1, 0.2, 0.3))).unwrap();
        assert_eq!(good.implausible(), None);
        // The subscriber's old fallback body on slambook: a negative diagonal.
        let mut negative = good;
        negative.inertia[1][1] = -negative.inertia[1][1];
        assert!(negative
            .implausible()
            .unwrap()
            .contains("positive definite"));
        // Positive, but one moment larger than the other two together.
        let mut lopsided = good;
        lopsided.inertia = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]];
        assert!(lopsided.implausible().unwrap().contains("triangle"));
        let mut nan = good;
        nan.centre_of_mass.x = f32::NAN;
        assert!(nan.implausible().is_some());
    }

    #[test]
    fn empty_mesh_is_refused() {
        assert!(matches!(
            MassProperties::of_closed_mesh(&TriMesh::default()),
            Err(PhysicsError::EmptyMesh { .. })
        ));
    }
}
