//! Pinhole intrinsics from the fields of view OpenNI2 reports
//! (`ONI_STREAM_PROPERTY_HORIZONTAL_FOV` / `VERTICAL_FOV`, radians).
//!
//! OpenNI2 has no principal point or focal length property; its own coordinate converter
//! (`VideoStream::convertDepthToWorld`) maps pixel `u` to `(u / width - 0.5) * z * 2 tan(hfov/2)`,
//! i.e. a pinhole with `fx = (width / 2) / tan(hfov / 2)`. The principal point is the centre of
//! the pixel grid in integer pixel coordinates, `((width - 1) / 2, (height - 1) / 2)`, as in
//! `tacmesh-oni`, so that one recording gives the same points through either backend (OpenNI2's
//! converter puts it half a pixel further, at `width / 2`; no calibration is that exact).

use tacmesh_source::Intrinsics;

/// Intrinsics of a `width`×`height` image with fields of view `hfov_rad`×`vfov_rad`, or
/// `None` if a size is zero or a field of view is not in (0, π).
pub fn intrinsics_from_fov(
    width: u32,
    height: u32,
    hfov_rad: f32,
    vfov_rad: f32,
) -> Option<Intrinsics> {
    let plausible = |fov: f32| fov > 0.0 && fov < std::f32::consts::PI;
    if width == 0 || height == 0 || !plausible(hfov_rad) || !plausible(vfov_rad) {
        return None;
    }
    let (half_w, half_h) = (width as f32 / 2.0, height as f32 / 2.0);
    Some(Intrinsics {
        width,
        height,
        fx: half_w / (hfov_rad / 2.0).tan(),
        fy: half_h / (vfov_rad / 2.0).tan(),
        cx: (width as f32 - 1.0) / 2.0,
        cy: (height as f32 - 1.0) / 2.0,
    })
}

/// Intrinsics of a crop: the full image's focal lengths, the principal point moved by the
/// crop origin, the crop's size.
pub fn cropped(full: Intrinsics, origin: (u32, u32), width: u32, height: u32) -> Intrinsics {
    Intrinsics {
        width,
        height,
        cx: full.cx - origin.0 as f32,
        cy: full.cy - origin.1 as f32,
        ..full
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ninety_degree_fov_gives_focal_length_of_half_the_width() {
        let k = intrinsics_from_fov(640, 480, 90f32.to_radians(), 90f32.to_radians()).unwrap();
        assert!((k.fx - 320.0).abs() < 1e-3, "{k:?}");
        assert!((k.fy - 240.0).abs() < 1e-3, "{k:?}");
        assert_eq!((k.cx, k.cy), (319.5, 239.5));
    }

    #[test]
    fn primesense_fov_gives_its_known_focal_length() {
        // Carmine 1.09 / Xtion report 1.0225 rad × 0.7959 rad; fx ≈ 570 px at 640×480 is the
        // value every ROS calibration of these sensors starts from.
        let k = intrinsics_from_fov(640, 480, 1.0225, 0.7959).unwrap();
        assert!((k.fx - 570.3).abs() < 1.0, "{k:?}");
        assert!((k.fy - 570.3).abs() < 1.0, "{k:?}");
    }

    #[test]
    fn image_edge_ray_matches_half_fov() {
        let hfov = 1.0f32;
        let k = intrinsics_from_fov(320, 240, hfov, 0.8).unwrap();
        // The outer edge of the first pixel column is at u = -0.5.
        let ray = k.ray(-0.5, k.cy);
        assert!((ray.x.abs() - (hfov / 2.0).tan()).abs() < 1e-5, "{ray:?}");
    }

    #[test]
    fn implausible_fov_or_empty_image_is_none() {
        assert_eq!(intrinsics_from_fov(640, 480, 0.0, 0.8), None);
        assert_eq!(intrinsics_from_fov(640, 480, 1.0, f32::NAN), None);
        assert_eq!(intrinsics_from_fov(640, 480, 4.0, 0.8), None);
        assert_eq!(intrinsics_from_fov(0, 480, 1.0, 0.8), None);
    }

    #[test]
    fn crop_moves_principal_point() {
        let full = intrinsics_from_fov(640, 480, 1.0, 0.8).unwrap();
        let k = cropped(full, (100, 40), 200, 100);
        assert_eq!(
            (k.width, k.height, k.fx, k.fy),
            (200, 100, full.fx, full.fy)
        );
        assert_eq!((k.cx, k.cy), (219.5, 199.5));
    }
}
