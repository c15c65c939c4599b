//! Tracker settings, with units in the names and the defaults the daemon uses.

use std::time::Duration;

/// Why a [`TrackConfig`] was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TrackError {
    #[error("track setting `{name}` = {value} must be a positive finite number ({hint})")]
    NotPositive {
        name: &'static str,
        value: f64,
        hint: &'static str,
    },
    #[error(
        "track setting `occupied_cell_points` ({occupied}) must be at least 1 and below \
         `saturated_cell_points` ({saturated})"
    )]
    CellCounts { occupied: u32, saturated: u32 },
    #[error("track setting `{name}` = {value} is a fraction and must be within [0, 1]")]
    Fraction { name: &'static str, value: f32 },
}

/// How objects are told apart, fused, aligned and offered for meshing.
///
/// Lengths in metres, angles in radians, times on the capture clock (the sensor's timestamps,
/// never the wall clock, so replayed and simulated streams behave like live ones).
#[derive(Debug, Clone, PartialEq)]
pub struct TrackConfig {
    /// Voxel edge of each object's fused moment grid, metres. Default 0.005.
    pub voxel_size_m: f32,
    /// Largest distance between a cluster's centroid and a track's predicted centroid that
    /// still associates them, metres. Default 0.08.
    pub match_distance_m: f32,
    /// A track not seen for this long (capture time) is removed. Default 1 s.
    pub leave_after: Duration,
    /// Frames an object must be seen in before it is offered for meshing. Default 3.
    pub confirm_frames: u32,
    /// A cluster whose nearest point is farther than this from the sensor may add to an
    /// object seen from nearer, but never starts one, metres. Default 3.5: a Kinect-class
    /// depth step there is 4.3 cm (0.0035 r²) and its noise 3 cm, ten times the mesh's
    /// residual bound, so what is seen there is a staircase of depth levels (the slices of
    /// floor and wall the PrimeSense and slambook recordings published at 3.3–4.2 m), not a
    /// shape to touch.
    pub max_birth_range_m: f32,
    /// Least time between two meshing runs of one object (capture time). Default 0.25 s.
    pub remesh_interval: Duration,
    /// Fraction of an object's voxels, weighed by their point counts capped at
    /// `saturated_cell_points`, that must have changed enough (see `occupied_cell_points`)
    /// since its last meshing to mesh it again. Default 0.03.
    pub remesh_min_change: f32,
    /// Clusters with fewer finite points than this are ignored (no track, no fusion).
    /// Default 20.
    pub min_cluster_points: usize,
    /// Points a voxel needs to count as part of the surface for change tracking: a voxel that
    /// reaches it has changed. Default 4.
    pub occupied_cell_points: u32,
    /// Points beyond which more points in a voxel no longer change its plane enough to matter:
    /// below it a voxel whose count doubled since the last meshing has changed, at it the voxel
    /// is settled. Default 64.
    pub saturated_cell_points: u32,
    /// Weight cap of a fused voxel, in points: a full voxel forgets one point's worth for each
    /// point it gains, so it averages its newest points and jitter or drift cannot pile up
    /// (see `TrackedObject`'s fusion). Default 256: about 25 frames of a surface voxel at 1 m,
    /// and four times `saturated_cell_points`, so planes are as steady as without a cap.
    pub max_cell_points: u32,
    /// Share of a voxel's weight forgotten each frame that sees through it (free-space
    /// carving, see `crate::free_space`); 0 turns carving off. Default 0.3.
    pub carve_fraction: f32,
    /// A voxel is seen through when the nearest surface measured in its direction is farther
    /// than the voxel by `carve_margin_m + carve_margin_per_m2 · z²` (z its depth, metres):
    /// depth noise and a stereo or structured-light camera's disparity step grow with z².
    /// Defaults 0.015 m and 0.005 /m (2 cm at 1 m, 7.6 cm at 3.5 m, where a Kinect's depth
    /// step is 4.5 cm).
    pub carve_margin_m: f32,
    pub carve_margin_per_m2: f32,
    /// Translation of the object's origin below which an aligned pose is taken as noise and
    /// the published pose is kept, metres. Default 0.0025 (half a voxel).
    pub move_threshold_m: f32,
    /// Rotation below which an aligned pose is taken as noise, radians. Default 1°.
    pub move_threshold_rad: f32,
    /// Depth noise of the sensor, as a standard deviation per square metre of range, metres.
    /// An object is fused on voxels of at least two of these at its range (see
    /// [`TrackConfig::voxel_at_range`]), and alignment rejects correspondences beyond three of
    /// these where that is more than `icp_reject_voxels` voxels, and accepts an RMS residual of
    /// 1.5 of them where that is more than `icp_max_rms_m`. Default 0.0025, a RealSense D435
    /// (local plane fits on its recording: σ 1.0 mm at 0.7 m, 8 mm at 1.8 m, 12 mm at 2.3 m;
    /// Kinect-class recordings measured 1–1.5 mm/m²). Within 1 m the fixed sizes rule.
    pub depth_noise_per_m2: f32,
    /// Alignment: the coarse level's voxel is this many fused voxels wide (capture range about
    /// one coarse voxel). Default 4.
    pub icp_coarse_factor: i32,
    /// Alignment uses at most this many of a cluster's points (an even stride through them);
    /// fusion uses them all. Default 1000: sub-millimetre alignment needs no more, and
    /// alignment is most of the cost of a frame.
    pub icp_max_points: usize,
    /// Alignment iterations on the coarse level, then on the fine level. Defaults 4 and 6.
    pub icp_coarse_iterations: u32,
    pub icp_fine_iterations: u32,
    /// Correspondences farther than this many voxels (of the level being aligned) from their
    /// plane are rejected as outliers. Default 3.
    pub icp_reject_voxels: f32,
    /// Alignment fails (and the object's fused state is reset to the new cluster) when the RMS
    /// point-to-plane residual of the inliers exceeds this, metres. Default 0.01.
    pub icp_max_rms_m: f32,
    /// Alignment fails when fewer than this fraction of the cluster's points (or fewer than
    /// `icp_min_inliers`) find a plane within the rejection distance. Defaults 0.5 and 30.
    pub icp_min_inlier_fraction: f32,
    pub icp_min_inliers: usize,
    /// Weight of the prior that keeps unobservable motion (a sphere spinning about its centre,
    /// a plane sliding along itself) at the predicted pose, per point, relative to one point's
    /// squared residual. Default 1e-3.
    pub icp_prior_weight: f32,
    /// Motion directions whose curvature (in the alignment's normal equations, rotations
    /// scaled to displacements) is below this fraction of the best-constrained direction's are
    /// unobservable and kept at the prediction. Default 0.05 (a partial sphere's spin scores
    /// about 0.02, a cube's worst-seen face about 0.1).
    pub icp_degenerate_ratio: f32,
    /// Estimate each frame's camera error from the objects that stand still and correct the
    /// frame by it before aligning any object (see `crate::camera_error`). Default true; off,
    /// a pose error moves every object.
    pub estimate_camera_error: bool,
}

impl TrackConfig {
    /// How far behind a fused voxel the nearest measured surface must lie for the camera to
    /// see through it (`carve_margin_m`, `carve_margin_per_m2`).
    pub fn carve_margin(&self) -> crate::free_space::DepthMargin {
        crate::free_space::DepthMargin {
            margin_m: self.carve_margin_m,
            per_m2: self.carve_margin_per_m2,
        }
    }

    /// The alignment's settings (the accepted residual before widening for range noise).
    pub fn icp_settings(&self) -> crate::icp::IcpSettings {
        crate::icp::IcpSettings {
            min_inliers: self.icp_min_inliers,
            min_inlier_fraction: self.icp_min_inlier_fraction,
            max_rms_m: self.icp_max_rms_m,
            prior_weight: self.icp_prior_weight,
            degenerate_ratio: self.icp_degenerate_ratio,
        }
    }

    /// The fused voxel of an object first seen `range_m` from the sensor: `voxel_size_m`, or
    /// twice the depth noise there (`depth_noise_per_m2`), whichever is larger. Finer voxels
    /// than the noise is thick hold one or two points of a frame each, so that the next
    /// frame's points mostly land in empty voxels and find no surface to align to; and they
    /// only cost memory and time for detail the sensor does not give. With the defaults: 5 mm
    /// to 1 m, 11 mm at 1.5 m, 20 mm at 2 m, 45 mm at 3 m.
    pub fn voxel_at_range(&self, range_m: f32) -> f32 {
        let noise_m = self.depth_noise_per_m2 * range_m * range_m;
        if noise_m.is_finite() {
            self.voxel_size_m.max(2.0 * noise_m)
        } else {
            self.voxel_size_m
        }
    }
}

impl Default for TrackConfig {
    fn default() -> Self {
        Self {
            voxel_size_m: 0.005,
            match_distance_m: 0.08,
            leave_after: Duration::from_secs(1),
            confirm_frames: 3,
            max_birth_range_m: 3.5,
            remesh_interval: Duration::from_millis(250),
            remesh_min_change: 0.03,
            min_cluster_points: 20,
            occupied_cell_points: 4,
            saturated_cell_points: 64,
            max_cell_points: 256,
            carve_fraction: 0.3,
            carve_margin_m: 0.015,
            carve_margin_per_m2: 0.005,
            depth_noise_per_m2: 0.0025,
            move_threshold_m: 0.0025,
            move_threshold_rad: 1f32.to_radians(),
            icp_coarse_factor: 4,
            icp_max_points: 1000,
            icp_coarse_iterations: 4,
            icp_fine_iterations: 6,
            icp_reject_voxels: 3.0,
            icp_max_rms_m: 0.01,
            icp_min_inlier_fraction: 0.5,
            icp_min_inliers: 30,
            icp_prior_weight: 1e-3,
            icp_degenerate_ratio: 0.02,
            estimate_camera_error: true,
        }
    }
}

impl TrackConfig {
    /// Checks every setting; the tracker refuses a config that fails.
    pub fn validate(&self) -> Result<(), TrackError> {
        let positive = [
            (
                "voxel_size_m",
                self.voxel_size_m,
                "a few millimetres for tabletop objects",
            ),
            (
                "match_distance_m",
                self.match_distance_m,
                "about how far an object moves between frames, plus margin",
            ),
            (
                "move_threshold_m",
                self.move_threshold_m,
                "about half a voxel",
            ),
            ("move_threshold_rad", self.move_threshold_rad, "about 1°"),
            (
                "icp_reject_voxels",
                self.icp_reject_voxels,
                "about 3 voxels",
            ),
            (
                "icp_max_rms_m",
                self.icp_max_rms_m,
                "about twice the sensor noise",
            ),
            (
                "icp_prior_weight",
                self.icp_prior_weight,
                "small, such as 1e-3",
            ),
            (
                "carve_margin_m",
                self.carve_margin_m,
                "a few times the depth noise near the camera, such as 0.015",
            ),
        ];
        for (name, value, hint) in positive {
            if !(value.is_finite() && value > 0.0) {
                return Err(TrackError::NotPositive {
                    name,
                    value: f64::from(value),
                    hint,
                });
            }
        }
        // Infinity is allowed: every cluster may start an object.
        if self.max_birth_range_m.is_nan() || self.max_birth_range_m <= 0.0 {
            return Err(TrackError::NotPositive {
                name: "max_birth_range_m",
                value: f64::from(self.max_birth_range_m),
                hint: "the range beyond which the sensor sees no shape, such as 3.5",
            });
        }
        if self.icp_max_points < self.icp_min_inliers.max(6) {
            return Err(TrackError::NotPositive {
                name: "icp_max_points",
                value: self.icp_max_points as f64,
                hint: "at least `icp_min_inliers`; about 1000",
            });
        }
        if self.icp_coarse_factor < 1 {
            return Err(TrackError::NotPositive {
                name: "icp_coarse_factor",
                value: f64::from(self.icp_coarse_factor),
                hint: "an integer such as 4",
            });
        }
        if self.occupied_cell_points == 0 || self.occupied_cell_points >= self.saturated_cell_points
        {
            return Err(TrackError::CellCounts {
                occupied: self.occupied_cell_points,
                saturated: self.saturated_cell_points,
            });
        }
        if self.max_cell_points < self.saturated_cell_points {
            return Err(TrackError::NotPositive {
                name: "max_cell_points",
                value: f64::from(self.max_cell_points),
                hint: "at least `saturated_cell_points`; about 256",
            });
        }
        if !(self.depth_noise_per_m2.is_finite() && self.depth_noise_per_m2 >= 0.0) {
            return Err(TrackError::NotPositive {
                name: "depth_noise_per_m2",
                value: f64::from(self.depth_noise_per_m2),
                hint: "0 or more, such as 0.0025",
            });
        }
        if !(self.carve_margin_per_m2.is_finite() && self.carve_margin_per_m2 >= 0.0) {
            return Err(TrackError::NotPositive {
                name: "carve_margin_per_m2",
                value: f64::from(self.carve_margin_per_m2),
                hint: "0 or more, such as 0.005",
            });
        }
        for (name, value) in [
            ("carve_fraction", self.carve_fraction),
            ("remesh_min_change", self.remesh_min_change),
            ("icp_degenerate_ratio", self.icp_degenerate_ratio),
            ("icp_min_inlier_fraction", self.icp_min_inlier_fraction),
        ] {
            if !(0.0..=1.0).contains(&value) {
                return Err(TrackError::Fraction { name, value });
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn voxels_follow_the_depth_noise_beyond_a_metre() {
        let config = TrackConfig::default();
        assert_eq!(config.voxel_at_range(0.6), config.voxel_size_m);
        assert_eq!(config.voxel_at_range(1.0), config.voxel_size_m);
        assert!((config.voxel_at_range(2.0) - 0.02).abs() < 1e-6);
        assert_eq!(config.voxel_at_range(f32::NAN), config.voxel_size_m);
        let bad = TrackConfig {
            depth_noise_per_m2: -1.0,
            ..TrackConfig::default()
        };
        assert!(bad.validate().is_err());
    }
}
